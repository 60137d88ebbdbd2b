// raygrid: data-parallel ray tracing with ray queues in the leaves of a shallow octree (thesis
// §5.3, Algorithm 5.1; after Pharr et al.'s Toro scheduling grid, targeted at the top of the
// memory hierarchy instead of disk I/O). Structure: structures/octree.h.
//
// Every ray is added to the queue of the octree leaf that contains its origin (or, for a ray
// from outside, its entry point into the scene bounds). A queue holds M rays by value in SoA
// form — origin, direction, tmin, nearest distance, ray index: 8 floats and an integer, the
// thesis' 36-byte record (§5.3.2 "Ray data"); hit records live in the output array, addressed by
// the index. Queues sit on three lists (§5.3.2 "Ray Queues"): empty queues, partially filled ones
// (each leaf owns at most one) and full ones. Full queues are processed first — processing one
// can fill the queues of neighbouring leaves — then partial ones, until no ray is active
// (§5.3.3). Processing a queue (Alg. 5.1 `process`):
//   1. the per-ray constants of the node and triangle tests are computed for the whole queue,
//      eight rays per AVX2 instruction straight from the SoA record (the thesis' reason for SoA:
//      "intersect the rays with the boundary planes of an octree node using SIMD code");
//   2. the rays traverse the leaf's mini-MBVH as one MBVH/RS stream (Tsakok 2009, thesis Alg.
//      2.9: task stack, one active-ray stack per SIMD lane, children ordered by summed entry
//      distance, one-ray streams finishing with ordinary single-ray traversal; a leaf's rays are
//      tested two per AVX2 pass) — the kernel of traversal/mbvh_stream.h, shared with mbvh_rs;
//   3. hits found go to the output; the exit distance and face of every ray are computed in SIMD;
//      a ray whose closest hit so far lies inside the leaf (t <= exit distance) is finished, the
//      others leave through the exit face's neighbour link and descend to the leaf containing
//      the exit point (§5.3.2 "Octree"), where they are queued again.
// A triangle that spans several leaves may be hit beyond the current leaf: that hit is kept as
// the ray's best so far but does not finish it, since a later leaf may hold a closer one.
//
// Refinements that do not change results:
// - a ray crosses leaves without triangles on the spot instead of being queued there, and
//   leaves whose clipped geometry leaves much of them empty only when it reaches that geometry
//   before its closest hit (the octree walk costs far less than a queue round trip);
// - a leaf's full queues are processed back to back while its mini-MBVH is in cache;
// - `feed` (default: all rays first, as Alg. 5.1) feeds rays in slices, each only when no full
//   queue is waiting — the thesis' low-memory alternative (§5.3.4), slower here: fewer rays in
//   flight means fuller partial queues are rarer.
//
// Robustness (watertight like every scheme of the suite): the walk position is computed in
// float, and leaves reference every triangle within Octree::pad of their box (structures/
// octree.h), so a hit point rounding puts just across a face is still found; exits through
// edges and corners go through one face and continue from the neighbour at the same distance;
// axis-parallel rays never exit through faces they run along, and a ray on a shared face picks
// the side its direction points to. A ray that has been queued kMaxSteps times (a walk that does
// not advance — never seen) or whose walk through empty leaves exceeds the number of leaves is
// finished by a full traversal of every leaf's mini-MBVH and counted in RayGridStats::fallbacks.
//
// Parameters: queue (M, default 768: the thesis found 384 best for 4-wide nodes, §5.3.5; with
// 8-wide ones 768 measured 2-5% faster on bounce:3), leaf_prims (default 4096, §5.4.1), max_depth
// (default 10), feed (rays per slice), width of the mini-MBVHs (default 8, see stream), and
// leaf_size / merge / bins of their binary builds (4 / 4 / 16,
// as mbvh4_single), and spatial / split_* (spatial splits in the mini-BVHs, Stich et al. 2009, as
// every BVH-based scheme takes them; off, as the thesis built them: measured neutral, 0.975-1.015
// of spatial=0 on primary and bounce:3 of 8 scenes, since the octree has already clipped every
// triangle to its cells; docs/PERFORMANCE.md, session 38).
#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>

#include "structures/octree.h"
#include "traversal/bvh_common.h"
#include "traversal/mbvh_stream.h"
#include "traversal/raygrid_stats.h"
#include "traversal/scratch_pool.h"

namespace tb {

std::string RayGridStats::describe() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "rays=%llu queues=%llu (full %llu, partial %llu) avg_fill=%.1f/%u leaf_visits_per_ray=%.2f "
                "skipped_leaves=%llu outside=%llu fallbacks=%llu peak_queues=%llu peak_bytes=%llu",
                (unsigned long long)rays, (unsigned long long)queues, (unsigned long long)full_queues,
                (unsigned long long)partial_queues, avg_fill(), queue_size, leaf_visits_per_ray(),
                (unsigned long long)skipped_leaves, (unsigned long long)outside, (unsigned long long)fallbacks,
                (unsigned long long)peak_queues, (unsigned long long)peak_bytes);
  return buf;
}

namespace {

constexpr uint32_t kNone = 0xFFFFFFFFu;
constexpr uint32_t kFallback = 0xFFFFFFFEu;
// The ray record: nine 4-byte fields, each an array of M in the queue (SoA).
enum Field : uint32_t { kOX, kOY, kOZ, kDX, kDY, kDZ, kTmin, kTbest, kId, kFields };
constexpr uint32_t kRecordBytes = kFields * 4;
static_assert(kRecordBytes == 36);
// The index field: the ray's index in its chunk (24 bits) and how often it has been queued
// (8 bits), the step limit of the robustness guard.
constexpr uint32_t kIdBits = 24, kIdMask = (1u << kIdBits) - 1, kMaxSteps = 255;
constexpr uint32_t kMaxChunk = 1u << kIdBits;

// The per-ray constants of the octree walk, computed for a whole queue at once (SoA, eight rays
// per AVX2 instruction; the thesis' reason for SoA queues, §5.3.2). The node and triangle tests'
// constants and the hits are in the per-ray records (mbvh_stream::RayRecord, one 64-byte line
// for the node test and one for leaves: a queue's rays thin out below its mini-MBVH's root).
enum Derived : uint32_t { kIX, kIY, kIZ, kTexit, kDerived };

// What the octree walk needs of a ray.
struct WalkRay {
  Vec3 org, dir, inv;
  float tmin, tbest;
};

// box_entry of kernels.h for a WalkRay: the kernel library's slab test (same NaN semantics: a slab
// whose plane holds the origin of an axis-parallel ray constrains nothing; Ize's padding).
inline float walk_entry(const WalkRay& w, const AABB& b) {
  const bool sx = std::signbit(w.inv.x), sy = std::signbit(w.inv.y), sz = std::signbit(w.inv.z);
  const float xn[3] = {(sx ? b.hi.x : b.lo.x) - w.org.x, (sy ? b.hi.y : b.lo.y) - w.org.y,
                       (sz ? b.hi.z : b.lo.z) - w.org.z};
  const float xf[3] = {(sx ? b.lo.x : b.hi.x) - w.org.x, (sy ? b.lo.y : b.hi.y) - w.org.y,
                       (sz ? b.lo.z : b.hi.z) - w.org.z};
  const float rn[3] = {w.inv.x, w.inv.y, w.inv.z};
  float tn;
  return slab<1, false>(xn, xf, rn, rn, w.tmin, w.tbest, tn) ? tn : INFINITY;
}

// The queue being processed: the shared stream record (traversal/mbvh_stream.h) over the queue's
// SoA fields and the derived constants, plus what the octree walk needs.
struct Stream : mbvh_stream::Rays {
  const uint32_t* index;  // the index field
  float* texit;         // exit distance from the leaf box
  uint32_t* axis;       // exit axis
};

// Per-call counters, added to the traverser's totals once per call.
struct Counters {
  uint64_t rays = 0, outside = 0, queues = 0, full = 0, partial = 0, queued_rays = 0, skipped = 0, fallbacks = 0;
  uint64_t peak_queues = 0;
};

// Scratch of one call: the queues and the stream buffers. Pooled by the traverser so repeated
// calls do not fault in fresh pages; one call owns one scratch, so concurrent calls on disjoint
// ranges never share.
struct Scratch {
  uint32_t mp = 0;                    // the field arrays' stride (mbvh_stream::field_stride)
  // Queues: data[q * kFields * mp + f * mp + slot], every field array 32-byte aligned; left
  // uninitialised, as every slot is written when a ray is queued, before it is read.
  uninit_vector<float> data;
  std::vector<uint32_t> count, leaf, prev, next;
  std::vector<uint32_t> empty;        // stack of empty queues
  // Full queues: a chain per leaf (through `next`), and a stack of the leaves that have one, so
  // that a leaf's full queues are processed back to back while its geometry is in cache.
  std::vector<uint32_t> leaf_full, full_leaves;
  std::vector<uint8_t> leaf_listed;
  uint32_t partial_head = kNone, partial_tail = kNone;
  uint32_t allocated = 0;             // queues handed out so far (the rest are untouched)
  std::vector<uint32_t> leaf_partial; // per octree leaf: its partial queue or kNone
  // The queue being processed: derived per-ray constants (SoA), the per-ray records (with the
  // hits), and the MBVH/RS stacks.
  aligned_vector<float> derived;      // f * mp + slot
  aligned_vector<mbvh_stream::RayRecord> rec;
  aligned_vector<uint32_t> axis;
  std::vector<uint32_t> moving;       // the rays of the queue that move on to another leaf
  mbvh_stream::Scratch st;            // the MBVH/RS stacks (and the one-ray fallback's)
};

class RayGrid final : public TraverserBase<RayGrid> {
 public:
  explicit RayGrid(const SchemeConfig& cfg) : cfg_(cfg) {
    m_ = cfg.get_int("queue");
    feed_ = uint32_t(cfg.get_int("feed"));
    params_.leaf_prims = cfg.get_int("leaf_prims");
    params_.max_depth = cfg.get_int("max_depth");
    params_.bvh.max_leaf = cfg.get_int("leaf_size");
    params_.bvh.bins = cfg.get_int("bins");
    read_spatial_params(cfg, params_.bvh);
    params_.width = cfg.get_int("width");
    params_.merge = cfg.get_int("merge");
    order_ = mbvh_stream::order_of(cfg);
  }
  std::string_view name() const override { return "raygrid"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    oct_ = cache.get<Octree>(params_.key(), [&] { return Octree::build(scene, params_); });
    tris_.reset();
    if (cfg_.kernel != TriKernel::watertight) {
      const bool planes = cfg_.kernel == TriKernel::plane || cfg_.kernel == TriKernel::plane_rcp;
      tris_ = cache.get<TriangleSet>(params_.key() + (planes ? ":tris+planes" : ":tris"), [&] {
        TriangleSet t;
        t.build(scene, params_.width == 8 ? oct_->mini8.lane_prims() : oct_->mini.lane_prims(), cfg_.kernel);
        return t;
      });
    }
    depth_ = (params_.width == 8 ? oct_->mini8.stats.max_depth : oct_->mini.stats.max_depth) + 1;
    pool_.clear();
  }
  std::string structure_info() const override {
    if (!oct_) return {};
    const uint64_t om = uint64_t(oct_->stats.leaves) * uint64_t(m_) * kRecordBytes;
    return oct_->stats.describe() + " mbvh_width=" + std::to_string(params_.width) +
           " mbvh_nodes=" + std::to_string(oct_->mini.stats.nodes + oct_->mini8.stats.nodes) +
           " queue=" + std::to_string(m_) + " record_bytes=" + std::to_string(kRecordBytes) +
           " queue_bytes=(O*M+N)*36=" + std::to_string(om) + "+36N";
  }
  // Queues fill from the rays of one call: fewer than a few dozen full queues per call and RayGrid
  // degrades to per-leaf single-ray work (2 threads on 16-packet chunks scaled only 1.6x).
  uint32_t preferred_chunk_rays() const override { return 65536; }
  StructureBytes memory() const override {
    if (!oct_) return {};
    return {oct_->stats.bytes - oct_->stats.tri_bytes,
            oct_->stats.tri_bytes + (tris_ ? tris_->size() * (TriangleSet::bytes(cfg_.kernel) + sizeof(uint32_t)) : 0)};
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    dispatch_kernel(cfg_.kernel, [&](auto k) { run_kernel<decltype(k)::value>(batch, range, hits, probe); });
  }

  RayGridStats stats() const {
    RayGridStats s;
    s.calls = calls_.load(), s.rays = rays_.load(), s.outside = outside_.load(), s.queues = queues_.load();
    s.full_queues = full_.load(), s.partial_queues = partial_.load(), s.queued_rays = queued_rays_.load();
    s.skipped_leaves = skipped_.load(), s.fallbacks = fallbacks_.load(), s.peak_queues = peak_queues_.load();
    s.peak_bytes = s.peak_queues * uint64_t(m_) * kRecordBytes;
    s.queue_size = uint32_t(m_);
    return s;
  }
  void reset_stats() const {
    for (auto* a : {&calls_, &rays_, &outside_, &queues_, &full_, &partial_, &queued_rays_, &skipped_, &fallbacks_,
                    &peak_queues_})
      a->store(0);
  }
  const Octree* octree() const { return oct_.get(); }

 private:
  // ------------------------------------------------------------------------------------------
  // Queues (§5.3.2 "Ray Queues")

  static float* qbase(Scratch& s, uint32_t q) { return s.data.data() + size_t(q) * kFields * s.mp; }

  static void unlink_partial(Scratch& s, uint32_t q) {
    const uint32_t p = s.prev[q], n = s.next[q];
    (p == kNone ? s.partial_head : s.next[p]) = n;
    (n == kNone ? s.partial_tail : s.prev[n]) = p;
    s.leaf_partial[s.leaf[q]] = kNone;
  }

  // Adds a ray to the leaf's partial queue (taking an empty queue if it has none); a queue that
  // becomes full leaves its leaf and goes onto the full list.
  template <class P>
  void push(Scratch& s, uint32_t leaf, const WalkRay& w, uint32_t rec, Counters& c, P& probe) const {
    uint32_t q = s.leaf_partial[leaf];
    if (q == kNone) {
      if (!s.empty.empty()) {
        q = s.empty.back();
        s.empty.pop_back();
      } else {
        q = s.allocated++;
        c.peak_queues = std::max<uint64_t>(c.peak_queues, s.allocated);
      }
      s.count[q] = 0;
      s.leaf[q] = leaf;
      s.leaf_partial[leaf] = q;
      s.prev[q] = s.partial_tail;
      s.next[q] = kNone;
      (s.partial_tail == kNone ? s.partial_head : s.next[s.partial_tail]) = q;
      s.partial_tail = q;
    }
    const uint32_t k = s.count[q]++;
    const size_t M = s.mp;
    float* b = qbase(s, q) + k;
    b[kOX * M] = w.org.x, b[kOY * M] = w.org.y, b[kOZ * M] = w.org.z;
    b[kDX * M] = w.dir.x, b[kDY * M] = w.dir.y, b[kDZ * M] = w.dir.z;
    b[kTmin * M] = w.tmin, b[kTbest * M] = w.tbest;
    std::memcpy(&b[kId * M], &rec, 4);
    if constexpr (P::enabled)
      for (uint32_t f = 0; f < kFields; ++f) probe.write(&b[f * M], 4);
    if (s.count[q] == uint32_t(m_)) {
      unlink_partial(s, q);
      s.next[q] = s.leaf_full[leaf];
      s.leaf_full[leaf] = q;
      if (!s.leaf_listed[leaf]) {
        s.leaf_listed[leaf] = 1;
        s.full_leaves.push_back(leaf);
      }
    }
  }

  // ------------------------------------------------------------------------------------------
  // Octree walk (§5.3.2 "Octree", Fig. 31)

  // Whether a ray in leaf node `node` has anything to intersect there: the leaf has triangles
  // and, where their (clipped) bounds leave much of the leaf empty, the ray reaches those bounds
  // before its closest hit so far. (Testing leaves that are full of geometry costs more than the
  // rare queue round trip it saves.)
  bool worth(const WalkRay& w, uint32_t node) const {
    const OctreeLeaf& lf = oct_->leaves[oct_->nodes[node].leaf];
    return !lf.empty() && (!lf.cull_tight || walk_entry(w, lf.cull) != INFINITY);
  }

  // Exit distance and axis of a ray leaving leaf node `nd`: the nearest far slab plane among the
  // axes the ray is not parallel to (direction +-0, or denormal under DAZ: reciprocal +-inf);
  // the first axis on ties. axis = -1 when there is none.
  static float exit_of(const OctreeNode& nd, const WalkRay& w, int& axis) {
    float t_exit = INFINITY;
    axis = -1;
    for (int a = 0; a < 3; ++a) {
      if (std::isinf(w.inv[a])) continue;
      const float plane = std::signbit(w.inv[a]) ? nd.lo[a] : nd.hi[a];
      const float t = (plane - w.org[a]) * w.inv[a];
      if (t < t_exit) t_exit = t, axis = a;
    }
    return t_exit;
  }

  // Crosses the exit face (axis, at t_exit) of leaf node `node`: the face's neighbour link, then
  // the descent to the leaf containing the exit point, clamped to the face so that the next leaf
  // always shares part of it. kNone at the scene boundary.
  template <class P>
  uint32_t cross(const WalkRay& w, uint32_t node, int axis, float t_exit, P& probe) const {
    const OctreeNode& nd = oct_->nodes[node];
    probe.read(&nd, sizeof(OctreeNode));
    const int side = std::signbit(w.inv[axis]) ? 0 : 1;
    const uint32_t nb = nd.nbr[face_of(axis, side)];
    if (nb == kNoNode) return kNone;
    Vec3 p;
    for (int b = 0; b < 3; ++b)
      p[b] = b == axis ? (side ? nd.hi[b] : nd.lo[b]) : std::clamp(w.org[b] + w.dir[b] * t_exit, nd.lo[b], nd.hi[b]);
    const uint32_t next = oct_->locate(nb, p, w.dir);
    if constexpr (P::enabled) {
      probe.read(&oct_->nodes[nb], sizeof(OctreeNode));
      if (next != nb) probe.read(&oct_->nodes[next], sizeof(OctreeNode));
      probe.read(&oct_->leaves[oct_->nodes[next].leaf], sizeof(OctreeLeaf));
    }
    return next;
  }

  // From leaf node `node` to the next leaf worth queueing the ray in, crossing leaves with
  // nothing to intersect on the spot. Returns that leaf node, kNone when the ray is finished (its
  // closest hit lies inside the leaf it leaves: t <= exit distance; or it leaves the scene), or
  // kFallback when the walk exceeds the step limit.
  template <class P>
  uint32_t advance(const WalkRay& w, uint32_t node, Counters& c, P& probe) const {
    const uint32_t limit = uint32_t(oct_->leaves.size()) + 8;
    for (uint32_t step = 0; step < limit; ++step) {
      const OctreeNode& nd = oct_->nodes[node];
      probe.read(&nd, sizeof(OctreeNode));
      int axis;
      const float t_exit = exit_of(nd, w, axis);
      if (axis < 0 || w.tbest <= t_exit) return kNone;
      node = cross(w, node, axis, t_exit, probe);
      if (node == kNone) return kNone;
      if (worth(w, node)) return node;
      c.skipped++;
    }
    return kFallback;
  }

  // The guard's way out: the ray against every leaf's mini-MBVH, one ray at a time.
  template <int N, TriKernel K, class P>
  void full_traversal(Scratch& s, const WalkRay& w, Hit& out, P& probe) const {
    const Octree& oct = *oct_;
    Ray ray{w.org, w.tmin, w.dir, w.tbest};
    const RayCtx rc(ray);
    const NodeRay<N> nr(rc, w.tmin, mini<N>().coord_bound);
    const TriRay<4> tr(rc, w.tmin);
    Hit h{w.tbest, kNoHit, 0.f, 0.f};
    WalkRay cur = w;
    for (const OctreeLeaf& lf : oct.leaves) {
      if (lf.empty()) continue;
      cur.tbest = h.t;
      if (walk_entry(cur, lf.cull) == INFINITY) continue;
      mbvh_traverse<N, 4, K>(mini<N>(), tris_.get(), nr, tr, &rc, lf.mbvh_root, h, s.st.single.data(), probe);
    }
    if (h.prim != kNoHit) out = h;
  }

  // ------------------------------------------------------------------------------------------
  // Per-queue SIMD passes over the SoA records

  // Exit distance and axis (exit_of) of rays [0, n) leaving the leaf box, eight at a time, and
  // the rays that move on: those whose closest hit so far lies beyond the exit (listed in
  // `moving`, their number returned; compacted without a branch per ray).
  static uint32_t exit_stream(const Stream& v, uint32_t n, const OctreeNode& nd, uint32_t* moving) {
    const __m256 inf = _mm256_set1_ps(INFINITY);
    const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
    const __m256i one = _mm256_set1_epi32(1), two = _mm256_set1_epi32(2);
    // Hit::t of 8 consecutive records (x 4 bytes).
    const __m256i hit_t = _mm256_mullo_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
                                             _mm256_set1_epi32(int(sizeof(mbvh_stream::RayRecord) / 4)));
    const float* o[3] = {v.ox, v.oy, v.oz};
    const float* in[3] = {v.ix, v.iy, v.iz};
    uint32_t count = 0;
    for (uint32_t k = 0; k < n; k += 8) {
      __m256 t[3];
      for (int a = 0; a < 3; ++a) {
        const __m256 inv = _mm256_load_ps(in[a] + k);
        // Far plane: hi, or lo where the reciprocal is negative (blendv reads its sign bit).
        const __m256 plane = _mm256_blendv_ps(_mm256_set1_ps(nd.hi[a]), _mm256_set1_ps(nd.lo[a]), inv);
        const __m256 ta = _mm256_mul_ps(_mm256_sub_ps(plane, _mm256_load_ps(o[a] + k)), inv);
        t[a] = _mm256_blendv_ps(ta, inf, _mm256_cmp_ps(_mm256_and_ps(inv, absmask), inf, _CMP_EQ_OQ));
      }
      const __m256 tyz = _mm256_min_ps(t[1], t[2]);
      const __m256 texit = _mm256_min_ps(t[0], tyz);
      const __m256i a0 = _mm256_castps_si256(_mm256_cmp_ps(t[0], tyz, _CMP_LE_OQ));
      const __m256i a1 = _mm256_castps_si256(_mm256_cmp_ps(t[1], t[2], _CMP_LE_OQ));
      const __m256i ax = _mm256_andnot_si256(a0, _mm256_blendv_epi8(two, one, a1));
      _mm256_store_ps(v.texit + k, texit);
      _mm256_store_si256(reinterpret_cast<__m256i*>(v.axis + k), ax);
      // Moving on: tbest > t_exit (an infinite t_exit never: no face to leave through).
      const __m256 tbest = _mm256_i32gather_ps(&v.rec[k].hit.t, hit_t, 4);
      unsigned m = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(tbest, texit, _CMP_GT_OQ)));
      if (k + 8 > n) m &= (1u << (n - k)) - 1;
      for (; m; m &= m - 1) moving[count++] = k + uint32_t(std::countr_zero(m));
    }
    return count;
  }

  template <int N>
  const MBVH<N, 4>& mini() const {
    if constexpr (N == 8) return oct_->mini8;
    else return oct_->mini;
  }

  // ------------------------------------------------------------------------------------------
  // Algorithm 5.1

  template <TriKernel K, class P>
  void run_kernel(const RayBatch& batch, PacketRange range, std::span<Hit> out, P& probe) const {
    const uint32_t begin = batch.packet_begin[range.first], end = batch.packet_begin[range.last];
    if (begin >= end) return;
    std::unique_ptr<Scratch> sp = pool_.acquire();
    Scratch& s = *sp;
    Counters c;
    for (uint32_t first = begin; first < end; first += kMaxChunk)
      if (params_.width == 8) run_chunk<8, K>(s, batch, first, std::min(end, first + kMaxChunk), out, c, probe);
      else run_chunk<4, K>(s, batch, first, std::min(end, first + kMaxChunk), out, c, probe);
    pool_.release(std::move(sp));
    calls_ += 1, rays_ += c.rays, outside_ += c.outside, queues_ += c.queues, full_ += c.full, partial_ += c.partial;
    queued_rays_ += c.queued_rays, skipped_ += c.skipped, fallbacks_ += c.fallbacks;
    for (uint64_t p = peak_queues_.load(); c.peak_queues > p && !peak_queues_.compare_exchange_weak(p, c.peak_queues);) {
    }
  }

  template <int N, TriKernel K, class P>
  void run_chunk(Scratch& s, const RayBatch& batch, uint32_t first, uint32_t last, std::span<Hit> out, Counters& c,
                 P& probe) const {
    const Octree& oct = *oct_;
    const uint32_t n = last - first, M = uint32_t(m_);
    s.mp = uint32_t(mbvh_stream::field_stride(M));
    const size_t mp = s.mp;
    // At most every ray queued once, plus one partial queue per leaf, plus the queue being
    // processed: (O * M + N) records (§5.3.5). Only the queues actually used are touched.
    const size_t nq = (size_t(n) + M - 1) / M + oct.leaves.size() + 2;
    if (s.data.size() < nq * kFields * mp) s.data.resize(nq * kFields * mp);
    for (auto* v : {&s.count, &s.leaf, &s.prev, &s.next})
      if (v->size() < nq) v->resize(nq);
    s.empty.clear();
    s.full_leaves.clear();
    s.leaf_full.assign(oct.leaves.size(), kNone);
    s.leaf_listed.assign(oct.leaves.size(), 0);
    s.partial_head = s.partial_tail = kNone;
    s.allocated = 0;
    s.leaf_partial.assign(oct.leaves.size(), kNone);
    if (s.derived.size() < kDerived * mp) {
      s.derived.resize(kDerived * mp);
      s.rec.resize(mp);
      s.axis.resize(mp);
      s.moving.resize(mp);
    }
    s.st.reserve(N, depth_, M);
    c.rays += n;
    if constexpr (P::enabled)
      if (probe.counts) probe.counts->rays += n;

    // Feed: rays go into the queue of the leaf that holds their origin or scene entry point. By
    // default all of them before any queue is processed (Alg. 5.1); with `feed` in slices, each
    // only when no full queue is waiting (the second strategy of §5.3.4: "feeding new rays only
    // when no full ray queues are available, memory requirements stay low").
    const OctreeNode& root = oct.nodes[0];
    const AABB root_box{root.lo, root.hi};
    uint32_t last_node = kNone;
    auto feed = [&](uint32_t lo, uint32_t hi) {
      for (uint32_t i = lo; i < hi; ++i) {
        const Ray& ray = batch.rays[i];
        probe.read(&ray, sizeof(Ray));
        out[i] = Hit{};
        probe.write(&out[i], sizeof(Hit));
        if (!(ray.tmin < ray.tmax)) continue;  // the empty interval [t, t): nothing to find
        WalkRay w{ray.org, ray.dir, {}, ray.tmin, ray.tmax};
        uint32_t node;
        if (ray.tmin == 0.f && oct.strictly_inside(0, ray.org)) {
          // The common case (bounce and shadow rays): the origin's leaf. It holds the surface the
          // ray starts from, so it is worth queueing in without a test.
          node = last_node != kNone && oct.strictly_inside(last_node, ray.org) ? last_node
                                                                              : (last_node = oct.locate(0, ray.org, ray.dir));
          if (oct.leaves[oct.nodes[node].leaf].empty()) {
            w.inv = {1.f / ray.dir.x, 1.f / ray.dir.y, 1.f / ray.dir.z};
            c.skipped++;
            node = advance(w, node, c, probe);
          }
        } else {
          // From outside the scene bounds (or from tmin on): start at the entry point.
          w.inv = {1.f / ray.dir.x, 1.f / ray.dir.y, 1.f / ray.dir.z};
          const float t0 = walk_entry(w, root_box);
          if (t0 == INFINITY) {
            c.outside++;
            continue;
          }
          Vec3 p;
          for (int a = 0; a < 3; ++a) p[a] = std::clamp(w.org[a] + w.dir[a] * t0, root.lo[a], root.hi[a]);
          node = oct.locate(0, p, w.dir);
          if (!worth(w, node)) {
            c.skipped++;
            node = advance(w, node, c, probe);
          }
        }
        if (node == kNone) continue;
        if (node == kFallback) {
          c.fallbacks++;
          full_traversal<N, K>(s, w, out[i], probe);
          continue;
        }
        push(s, oct.nodes[node].leaf, w, i - first, c, probe);
      }
    };

    // Process full queues first — a leaf's full queues back to back — then partial ones, until
    // no ray is active.
    float* d = s.derived.data();
    uint32_t cur = kNone;  // the leaf whose full queues are being processed
    uint32_t next_ray = first;
    for (;;) {
      uint32_t q = kNone;
      if (cur == kNone || s.leaf_full[cur] == kNone) {
        cur = kNone;
        while (!s.full_leaves.empty()) {
          const uint32_t l = s.full_leaves.back();
          if (s.leaf_full[l] != kNone) {
            cur = l;
            break;
          }
          s.full_leaves.pop_back();
          s.leaf_listed[l] = 0;
        }
      }
      if (cur != kNone) {
        q = s.leaf_full[cur];
        s.leaf_full[cur] = s.next[q];
        c.full++;
      } else if (next_ray < last) {
        const uint32_t hi = last - next_ray > feed_ ? next_ray + feed_ : last;
        feed(next_ray, hi);
        next_ray = hi;
        continue;
      } else if (s.partial_head != kNone) {
        q = s.partial_head;
        unlink_partial(s, q);
        c.partial++;
      } else {
        break;
      }
      const uint32_t leaf = s.leaf[q], cnt = s.count[q];
      const OctreeLeaf& lf = oct.leaves[leaf];
      const OctreeNode& lnode = oct.nodes[lf.node];
      c.queues++;
      c.queued_rays += cnt;
      const float* b = qbase(s, q);
      const Stream v{{b + kOX * mp, b + kOY * mp, b + kOZ * mp, b + kDX * mp, b + kDY * mp, b + kDZ * mp,
                      b + kTmin * mp, d + kIX * mp, d + kIY * mp, d + kIZ * mp, s.rec.data()},
                     reinterpret_cast<const uint32_t*>(b + kId * mp), d + kTexit * mp, s.axis.data()};
      if constexpr (P::enabled)
        for (uint32_t k = 0; k < cnt; ++k)
          for (uint32_t f = 0; f < kFields; ++f) probe.read(&b[f * mp + k], 4);
      mbvh_stream::prepare(v, cnt, mini<N>().coord_bound);
      for (uint32_t k = 0; k < cnt; ++k) v.rec[k].hit = Hit{b[kTbest * mp + k], kNoHit, 0.f, 0.f};

      mbvh_stream::trace<N, K>(mini<N>(), tris_.get(), s.st, v, cnt, lf.mbvh_root, order_, probe);

      // Finish or move on (Alg. 5.1, second half of `process`): the hits found here go to the
      // output (a ray's best hit only ever improves), the exits of the whole queue are computed
      // in SIMD, and the rays whose closest hit lies beyond the exit cross into the next leaf.
      Hit dummy;
      for (uint32_t k = 0; k < cnt; ++k) {
        const uint32_t i = first + (v.index[k] & kIdMask);
        Hit* dst = v.rec[k].hit.prim != kNoHit ? &out[i] : &dummy;  // a select, not a branch
        *dst = v.rec[k].hit;
        if constexpr (P::enabled)
          if (dst != &dummy) probe.write(&out[i], sizeof(Hit));
      }
      const uint32_t moving = exit_stream(v, cnt, lnode, s.moving.data());
      for (uint32_t j = 0; j < moving; ++j) {
        const uint32_t k = s.moving[j];
        const uint32_t rec = v.index[k];
        const WalkRay w{{v.ox[k], v.oy[k], v.oz[k]}, {v.dx[k], v.dy[k], v.dz[k]}, {v.ix[k], v.iy[k], v.iz[k]},
                        v.tmin[k], v.rec[k].hit.t};
        uint32_t next = cross(w, lf.node, int(v.axis[k]), v.texit[k], probe);
        if (next == kNone) continue;  // left the scene
        if (!worth(w, next)) {
          c.skipped++;
          next = advance(w, next, c, probe);
          if (next == kNone) continue;
        }
        if (next == kFallback || (rec >> kIdBits) >= kMaxSteps) {
          c.fallbacks++;
          full_traversal<N, K>(s, w, out[first + (rec & kIdMask)], probe);
          continue;
        }
        push(s, oct.nodes[next].leaf, w, rec + (1u << kIdBits), c, probe);
      }
      s.empty.push_back(q);
    }
  }

  SchemeConfig cfg_;
  OctreeParams params_;
  int m_ = 768;
  uint32_t feed_ = kMaxChunk;  // rays fed per slice (default: all of them before processing, Alg. 5.1)
  mbvh_stream::Order order_ = mbvh_stream::Order::mean;  // the child order of the stream kernel
  uint32_t depth_ = 1;
  std::shared_ptr<const Octree> oct_;
  std::shared_ptr<const TriangleSet> tris_;
  ScratchPool<Scratch> pool_;  // one record per concurrent call
  mutable std::atomic<uint64_t> calls_{0}, rays_{0}, outside_{0}, queues_{0}, full_{0}, partial_{0}, queued_rays_{0},
      skipped_{0}, fallbacks_{0}, peak_queues_{0};
};

}  // namespace

std::optional<RayGridStats> raygrid_stats(const Traverser& t) {
  if (const auto* r = dynamic_cast<const RayGrid*>(&t)) return r->stats();
  return std::nullopt;
}
void raygrid_reset_stats(const Traverser& t) {
  if (const auto* r = dynamic_cast<const RayGrid*>(&t)) r->reset_stats();
}
const Octree* raygrid_octree(const Traverser& t) {
  if (const auto* r = dynamic_cast<const RayGrid*>(&t)) return r->octree();
  return nullptr;
}

std::unique_ptr<Traverser> make_raygrid(const SchemeConfig& cfg) { return std::make_unique<RayGrid>(cfg); }
ParamSpecs params_raygrid() {
  const OctreeParams o;
  return ParamSpecs{int_param("queue", 768, 1, 65535, "ray queue capacity M (thesis 5.3: 384 on its machine)"),
          int_param("feed", int(kMaxChunk), 1, 1 << 30, "rays fed per slice before queues are processed (default: all, Alg. 5.1)"),
          int_param("leaf_prims", o.leaf_prims, 1, 1 << 30, "subdivide octree nodes referencing more triangles than this"),
          int_param("max_depth", o.max_depth, 0, 20, "octree depth limit (root: 0)"),
          int_param("leaf_size", o.bvh.max_leaf, 1, 64, "most triangles in a binary SAH leaf of a mini-MBVH"),
          int_param("bins", o.bvh.bins, 2, 256, "binned-SAH bins per axis of the mini-MBVH builds"),
          // 8-wide mini-MBVHs by default (§5.3.2 uses the SIMD width of its machine, 4): on bounce:3
          // they made raygrid 5-25% faster than the thesis' 4-wide ones (docs/PERFORMANCE.md).
          int_choice_param("width", 8, {4, 8}, "mini-MBVH width: 4 (the thesis' SSE layout) or 8 (AVX2)"),
          int_param("merge", o.merge, 0, 64, "binary subtrees of at most this many triangles become one mini-MBVH leaf"),
          mbvh_stream::order_param()} +
         spatial_param_specs(false, "the octree leaf's geometry");
}

}  // namespace tb
