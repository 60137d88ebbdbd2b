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
//      distance, one-ray streams finishing with ordinary single-ray traversal); a leaf's rays are
//      tested two per AVX2 pass (pair_intersect);
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
// as mbvh4_single).
#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <mutex>

#include "structures/octree.h"
#include "traversal/raygrid_stats.h"

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

// The per-ray constants of the node and triangle tests, computed for a whole queue at once
// (SoA, eight rays per AVX2 instruction; the thesis' reason for SoA queues, §5.3.2). `meta`
// packs the direction's sign octant (bits 0-2: the reciprocal is negative on x, y, z), and the
// watertight test's axis permutation kx, ky, kz (bits 4-5, 6-7, 8-9).
enum Derived : uint32_t { kIX, kIY, kIZ, kFX, kFY, kFZ, kSX, kSY, kSZ, kTexit, kPX, kPY, kPZ, kDerived };

struct Task {
  uint32_t ref;    // mini-MBVH child reference (interior node or leaf)
  uint32_t lane;   // the active-ray stack holding its rays
  uint32_t count;  // how many (on top of that stack)
};

// What the octree walk needs of a ray.
struct WalkRay {
  Vec3 org, dir, inv;
  float tmin, tbest;
};

// box_entry of kernels.h for a WalkRay: the same operations with the same NaN semantics (a slab
// whose plane holds the origin of an axis-parallel ray constrains nothing) and Ize's padding.
inline float walk_entry(const WalkRay& w, const AABB& b) {
  const bool sx = std::signbit(w.inv.x), sy = std::signbit(w.inv.y), sz = std::signbit(w.inv.z);
  const float nx = ((sx ? b.hi.x : b.lo.x) - w.org.x) * w.inv.x;
  const float fx = ((sx ? b.lo.x : b.hi.x) - w.org.x) * w.inv.x;
  const float ny = ((sy ? b.hi.y : b.lo.y) - w.org.y) * w.inv.y;
  const float fy = ((sy ? b.lo.y : b.hi.y) - w.org.y) * w.inv.y;
  const float nz = ((sz ? b.hi.z : b.lo.z) - w.org.z) * w.inv.z;
  const float fz = ((sz ? b.lo.z : b.hi.z) - w.org.z) * w.inv.z;
  const float tn = std::max(std::max(std::max(w.tmin, nx), ny), nz);
  const float tf = std::min(std::min(std::min(w.tbest, fx * kFarPad), fy * kFarPad), fz * kFarPad);
  return tn <= tf ? tn : INFINITY;
}

// Pointers to the SoA arrays of the queue being processed.
struct Stream {
  const float *ox, *oy, *oz, *dx, *dy, *dz, *tmin;
  const uint32_t* rec;
  float *ix, *iy, *iz, *fx, *fy, *fz, *sx, *sy, *sz, *texit;
  float *px, *py, *pz;  // the origin permuted to (kx, ky, kz) for the watertight test
  uint32_t *meta, *axis;
  Hit* hits;
};

// Two rays against one block of four triangles in one AVX2 pass: ray A in the low 128-bit half,
// ray B in the high half, each half the watertight test of mbvh.h's block_intersect (Woop,
// Benthin and Wald 2013) with the same float operations in the same order per lane, so every
// lane decides exactly as the 4-wide test would — watertightness carries over — at half the
// instructions per ray. MBVH/RS leaf streams hold several rays (Table 10), so pairs are common.
struct PairRay {
  __m256 ox, oy, oz, sx, sy, sz;  // origin permuted to (kx, ky, kz) and the shear, per half
  uint32_t kx[2], ky[2], kz[2];
  const Stream* v;  // the rest of the two rays' records, read only for candidate hits
  uint32_t id[2];
};

inline __m256 pair_rows(const TriBlock<4>& b, int corner, uint32_t row_a, uint32_t row_b) {
  return _mm256_loadu2_m128(b.v[corner][row_b], b.v[corner][row_a]);
}

inline void pair_intersect(const PairRay& r, const TriBlock<4>& b, Hit* hit[2]) {
  using S = mbvh_simd::V<8>;
  using f = __m256;
  const f Az = S::sub(pair_rows(b, 0, r.kz[0], r.kz[1]), r.oz);
  const f Bz = S::sub(pair_rows(b, 1, r.kz[0], r.kz[1]), r.oz);
  const f Cz = S::sub(pair_rows(b, 2, r.kz[0], r.kz[1]), r.oz);
  const f Ax = S::sub(S::sub(pair_rows(b, 0, r.kx[0], r.kx[1]), r.ox), S::mul(r.sx, Az));
  const f Ay = S::sub(S::sub(pair_rows(b, 0, r.ky[0], r.ky[1]), r.oy), S::mul(r.sy, Az));
  const f Bx = S::sub(S::sub(pair_rows(b, 1, r.kx[0], r.kx[1]), r.ox), S::mul(r.sx, Bz));
  const f By = S::sub(S::sub(pair_rows(b, 1, r.ky[0], r.ky[1]), r.oy), S::mul(r.sy, Bz));
  const f Cx = S::sub(S::sub(pair_rows(b, 2, r.kx[0], r.kx[1]), r.ox), S::mul(r.sx, Cz));
  const f Cy = S::sub(S::sub(pair_rows(b, 2, r.ky[0], r.ky[1]), r.oy), S::mul(r.sy, Cz));
  f U = S::sub(S::mul(Cx, By), S::mul(Cy, Bx));
  f Vv = S::sub(S::mul(Ax, Cy), S::mul(Ay, Cx));
  f Ww = S::sub(S::mul(Bx, Ay), S::mul(By, Ax));
  const f z = S::zero();
  const int zmask = S::mask(S::or_(S::or_(S::eq(U, z), S::eq(Vv, z)), S::eq(Ww, z)));
  if (zmask) [[unlikely]] {
    // An edge passes (numerically) through the ray: decide those lanes in double (Woop et al. §4).
    alignas(32) float ax[8], ay[8], bx[8], by[8], cx[8], cy[8], u[8], v[8], w[8];
    S::store(ax, Ax), S::store(ay, Ay), S::store(bx, Bx), S::store(by, By), S::store(cx, Cx), S::store(cy, Cy);
    S::store(u, U), S::store(v, Vv), S::store(w, Ww);
    for (int m = zmask; m; m &= m - 1) {
      const int l = std::countr_zero(unsigned(m));
      u[l] = float(double(cx[l]) * by[l] - double(cy[l]) * bx[l]);
      v[l] = float(double(ax[l]) * cy[l] - double(ay[l]) * cx[l]);
      w[l] = float(double(bx[l]) * ay[l] - double(by[l]) * ax[l]);
    }
    U = S::load(u), Vv = S::load(v), Ww = S::load(w);
  }
  const f neg = S::lt(S::min(S::min(U, Vv), Ww), z);
  const f pos = S::gt(S::max(S::max(U, Vv), Ww), z);
  const f det = S::add(S::add(U, Vv), Ww);
  int m = S::mask(S::andnot(S::and_(neg, pos), S::neq(det, z)));  // det == 0: never a hit
  if (!m) return;
  // Candidates: the distance from the triangle's plane in double, as intersect_watertight
  // (exact_plane_distance: the same double operations in the same order), four lanes of a ray at
  // once — a ray's line passes through several triangles of a leaf, most of them out of range.
  alignas(32) float us[8], vs[8], ws[8], dets[8], ts[8];
  S::store(us, U), S::store(vs, Vv), S::store(ws, Ww), S::store(dets, det);
  for (int ray = 0; ray < 2; ++ray) {
    if (!((m >> (4 * ray)) & 15)) continue;
    const uint32_t id = r.id[ray];
    const Vec3 o{r.v->ox[id], r.v->oy[id], r.v->oz[id]}, d{r.v->dx[id], r.v->dy[id], r.v->dz[id]};
    const __m256d v0x = _mm256_cvtps_pd(_mm_load_ps(b.v[0][0])), v0y = _mm256_cvtps_pd(_mm_load_ps(b.v[0][1])),
                  v0z = _mm256_cvtps_pd(_mm_load_ps(b.v[0][2]));
    const __m256d ax = _mm256_sub_pd(v0x, _mm256_set1_pd(o.x)), ay = _mm256_sub_pd(v0y, _mm256_set1_pd(o.y)),
                  az = _mm256_sub_pd(v0z, _mm256_set1_pd(o.z));
    const __m256d e1x = _mm256_sub_pd(_mm256_cvtps_pd(_mm_load_ps(b.v[1][0])), v0x);
    const __m256d e1y = _mm256_sub_pd(_mm256_cvtps_pd(_mm_load_ps(b.v[1][1])), v0y);
    const __m256d e1z = _mm256_sub_pd(_mm256_cvtps_pd(_mm_load_ps(b.v[1][2])), v0z);
    const __m256d e2x = _mm256_sub_pd(_mm256_cvtps_pd(_mm_load_ps(b.v[2][0])), v0x);
    const __m256d e2y = _mm256_sub_pd(_mm256_cvtps_pd(_mm_load_ps(b.v[2][1])), v0y);
    const __m256d e2z = _mm256_sub_pd(_mm256_cvtps_pd(_mm_load_ps(b.v[2][2])), v0z);
    const __m256d nx = _mm256_sub_pd(_mm256_mul_pd(e1y, e2z), _mm256_mul_pd(e1z, e2y));
    const __m256d ny = _mm256_sub_pd(_mm256_mul_pd(e1z, e2x), _mm256_mul_pd(e1x, e2z));
    const __m256d nz = _mm256_sub_pd(_mm256_mul_pd(e1x, e2y), _mm256_mul_pd(e1y, e2x));
    const __m256d dn = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, _mm256_set1_pd(d.x)), _mm256_mul_pd(ny, _mm256_set1_pd(d.y))),
                                     _mm256_mul_pd(nz, _mm256_set1_pd(d.z)));
    const __m256d num = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, ax), _mm256_mul_pd(ny, ay)), _mm256_mul_pd(nz, az));
    _mm_store_ps(ts + 4 * ray, _mm256_cvtpd_ps(_mm256_div_pd(num, dn)));
    if (_mm256_movemask_pd(_mm256_cmp_pd(dn, _mm256_setzero_pd(), _CMP_EQ_OQ)) & (m >> (4 * ray)) & 15) [[unlikely]] {
      // Edge-on (the ray lies in the plane): the sheared distance, as intersect_watertight.
      alignas(32) float azs[8], bzs[8], czs[8];
      S::store(azs, Az), S::store(bzs, Bz), S::store(czs, Cz);
      alignas(32) double dns[4];
      _mm256_store_pd(dns, dn);
      for (int t4 = 0; t4 < 4; ++t4) {
        const int l = 4 * ray + t4;
        if (dns[t4] == 0.0) ts[l] = r.v->sz[r.id[ray]] * (us[l] * azs[l] + vs[l] * bzs[l] + ws[l] * czs[l]) * (1.f / dets[l]);
      }
    }
  }
  for (; m; m &= m - 1) {
    const int l = std::countr_zero(unsigned(m));
    const int ray = l >> 2, t4 = l & 3;
    Hit& h = *hit[ray];
    const float t = ts[l];
    if (!(t >= r.v->tmin[r.id[ray]] && t < h.t)) continue;
    const float inv_det = 1.f / dets[l];
    h.t = t;
    h.u = vs[l] * inv_det;
    h.v = ws[l] * inv_det;
    h.prim = b.prim[t4];
  }
}

// Per-call counters, added to the traverser's totals once per call.
struct Counters {
  uint64_t rays = 0, outside = 0, queues = 0, full = 0, partial = 0, queued_rays = 0, skipped = 0, fallbacks = 0;
  uint64_t peak_queues = 0;
};

// Scratch of one call: the queues and the stream buffers. Pooled by the traverser so repeated
// calls do not fault in fresh pages; one call owns one scratch, so concurrent calls on disjoint
// ranges never share.
struct Scratch {
  uint32_t mp = 0;                    // queue capacity rounded up to the SIMD width
  // Queues: data[q * kFields * mp + f * mp + slot], every field array 32-byte aligned.
  aligned_vector<float> data;
  std::vector<uint32_t> count, leaf, prev, next;
  std::vector<uint32_t> empty;        // stack of empty queues
  // Full queues: a chain per leaf (through `next`), and a stack of the leaves that have one, so
  // that a leaf's full queues are processed back to back while its geometry is in cache.
  std::vector<uint32_t> leaf_full, full_leaves;
  std::vector<uint8_t> leaf_listed;
  uint32_t partial_head = kNone, partial_tail = kNone;
  uint32_t allocated = 0;             // queues handed out so far (the rest are untouched)
  std::vector<uint32_t> leaf_partial; // per octree leaf: its partial queue or kNone
  // The queue being processed: derived per-ray constants (SoA), hits, and the MBVH/RS stacks.
  aligned_vector<float> derived;      // f * mp + slot
  aligned_vector<uint32_t> meta, axis;
  std::vector<uint32_t> moving;       // the rays of the queue that move on to another leaf
  std::vector<Hit> hits;
  std::vector<uint16_t> lanes[8];  // one per child slot (4 or 8 used)
  std::vector<uint8_t> masks;      // per ray of a task: the children it entered
  std::vector<Task> tasks;
  std::vector<MBVHStackEntry> single;
};

// Left-packing shuffles: for an 8-bit mask, the byte shuffle that moves the 16-bit elements whose
// bit is set to the front, in order.
struct PackLut {
  alignas(16) uint8_t s[256][16];
  constexpr PackLut() : s{} {
    for (int m = 0; m < 256; ++m) {
      int o = 0;
      for (int e = 0; e < 8; ++e)
        if (m >> e & 1) s[m][2 * o] = uint8_t(2 * e), s[m][2 * o + 1] = uint8_t(2 * e + 1), ++o;
      for (; o < 8; ++o) s[m][2 * o] = s[m][2 * o + 1] = 0x80;
    }
  }
};
inline constexpr PackLut kPackLut{};

class RayGrid final : public TraverserBase<RayGrid> {
 public:
  explicit RayGrid(const SchemeConfig& cfg) : cfg_(cfg) {
    m_ = cfg.get_int("queue", 768);
    const int feed = cfg.get_int("feed", int(kMaxChunk));
    params_.leaf_prims = cfg.get_int("leaf_prims", params_.leaf_prims);
    params_.max_depth = cfg.get_int("max_depth", params_.max_depth);
    params_.mbvh_leaf = cfg.get_int("leaf_size", params_.mbvh_leaf);
    params_.bins = cfg.get_int("bins", params_.bins);
    // 8-wide mini-MBVHs by default (§5.3.2 uses the SIMD width of its machine, 4): on bounce:3
    // they made raygrid 5-25% faster than the thesis' 4-wide ones (docs/PERFORMANCE.md).
    params_.width = cfg.get_int("width", 8);
    params_.merge = cfg.get_int("merge", params_.merge);
    if (params_.width != 4 && params_.width != 8) throw InputError("parameter width must be 4 or 8");
    if (m_ < 1 || m_ > 65535) throw InputError("parameter queue must be in [1, 65535]");
    if (feed < 1) throw InputError("parameter feed must be >= 1");
    feed_ = uint32_t(feed);
    if (params_.leaf_prims < 1) throw InputError("parameter leaf_prims must be >= 1");
    if (params_.max_depth < 0 || params_.max_depth > 20) throw InputError("parameter max_depth must be in [0, 20]");
    if (params_.mbvh_leaf < 1 || params_.mbvh_leaf > 64) throw InputError("parameter leaf_size must be in [1, 64]");
    if (params_.merge < 0 || params_.merge > 64) throw InputError("parameter merge must be in [0, 64]");
    if (params_.bins < 2 || params_.bins > 256) throw InputError("parameter bins must be in [2, 256]");
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
    std::lock_guard lock(pool_mutex_);
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
  size_t structure_bytes() const override {
    if (!oct_) return 0;
    return oct_->stats.bytes + (tris_ ? tris_->size() * (TriangleSet::bytes(cfg_.kernel) + sizeof(uint32_t)) : 0);
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
  // Scratch pool

  std::unique_ptr<Scratch> acquire() const {
    std::lock_guard lock(pool_mutex_);
    if (pool_.empty()) return std::make_unique<Scratch>();
    auto s = std::move(pool_.back());
    pool_.pop_back();
    return s;
  }
  void release(std::unique_ptr<Scratch> s) const {
    std::lock_guard lock(pool_mutex_);
    pool_.push_back(std::move(s));
  }

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
    const NodeRay<N> nr(rc, w.tmin);
    const TriRay<4> tr(rc, w.tmin);
    Hit h{w.tbest, kNoHit, 0.f, 0.f};
    WalkRay cur = w;
    for (const OctreeLeaf& lf : oct.leaves) {
      if (lf.empty()) continue;
      cur.tbest = h.t;
      if (walk_entry(cur, lf.cull) == INFINITY) continue;
      mbvh_traverse<N, 4, K>(mini<N>(), tris_.get(), nr, tr, &rc, lf.mbvh_root, h, s.single.data(), probe);
    }
    if (h.prim != kNoHit) out = h;
  }

  // ------------------------------------------------------------------------------------------
  // Per-queue SIMD passes over the SoA records

  // RayCtx's constants for rays [0, n) of the queue, eight at a time with the same float
  // operations (1/d, d[kx]/d[kz], ...), so the watertight test sees exactly RayCtx's values.
  static void prepare_stream(const Stream& v, uint32_t n) {
    const __m256 one = _mm256_set1_ps(1.f), pad = _mm256_set1_ps(kFarPad), zero = _mm256_setzero_ps();
    const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
    // (kz == 0, kz == 1, swap) -> kx | ky << 2 | kz << 4, as RayCtx chooses them.
    static constexpr uint32_t kPerm[2][2][2] = {
        {{0u | 1u << 2 | 2u << 4, 1u | 0u << 2 | 2u << 4}, {2u | 0u << 2 | 1u << 4, 0u | 2u << 2 | 1u << 4}},
        {{1u | 2u << 2 | 0u << 4, 2u | 1u << 2 | 0u << 4}, {1u | 2u << 2 | 0u << 4, 2u | 1u << 2 | 0u << 4}}};
    for (uint32_t k = 0; k < n; k += 8) {
      const __m256 dx = _mm256_load_ps(v.dx + k), dy = _mm256_load_ps(v.dy + k), dz = _mm256_load_ps(v.dz + k);
      const __m256 ix = _mm256_div_ps(one, dx), iy = _mm256_div_ps(one, dy), iz = _mm256_div_ps(one, dz);
      _mm256_store_ps(v.ix + k, ix), _mm256_store_ps(v.iy + k, iy), _mm256_store_ps(v.iz + k, iz);
      _mm256_store_ps(v.fx + k, _mm256_mul_ps(ix, pad));
      _mm256_store_ps(v.fy + k, _mm256_mul_ps(iy, pad));
      _mm256_store_ps(v.fz + k, _mm256_mul_ps(iz, pad));
      // kz = the dominant axis: a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2).
      const __m256 ax = _mm256_and_ps(dx, absmask), ay = _mm256_and_ps(dy, absmask), az = _mm256_and_ps(dz, absmask);
      const __m256 xy = _mm256_cmp_ps(ax, ay, _CMP_GE_OQ);
      const __m256 k0 = _mm256_and_ps(xy, _mm256_cmp_ps(ax, az, _CMP_GE_OQ));
      const __m256 k1 = _mm256_andnot_ps(xy, _mm256_cmp_ps(ay, az, _CMP_GE_OQ));
      // kx = kz + 1, ky = kx + 1 (mod 3), swapped when d[kz] < 0.
      const __m256 dkz = _mm256_blendv_ps(_mm256_blendv_ps(dz, dy, k1), dx, k0);
      const __m256 dkx = _mm256_blendv_ps(_mm256_blendv_ps(dx, dz, k1), dy, k0);
      const __m256 dky = _mm256_blendv_ps(_mm256_blendv_ps(dy, dx, k1), dz, k0);
      const __m256 swap = _mm256_cmp_ps(dkz, zero, _CMP_LT_OQ);
      {  // the origin in the same permutation (TriRay's ox, oy, oz)
        const __m256 ox = _mm256_load_ps(v.ox + k), oy = _mm256_load_ps(v.oy + k), oz = _mm256_load_ps(v.oz + k);
        const __m256 okz = _mm256_blendv_ps(_mm256_blendv_ps(oz, oy, k1), ox, k0);
        const __m256 okx = _mm256_blendv_ps(_mm256_blendv_ps(ox, oz, k1), oy, k0);
        const __m256 oky = _mm256_blendv_ps(_mm256_blendv_ps(oy, ox, k1), oz, k0);
        _mm256_store_ps(v.px + k, _mm256_blendv_ps(okx, oky, swap));
        _mm256_store_ps(v.py + k, _mm256_blendv_ps(oky, okx, swap));
        _mm256_store_ps(v.pz + k, okz);
      }
      _mm256_store_ps(v.sx + k, _mm256_div_ps(_mm256_blendv_ps(dkx, dky, swap), dkz));
      _mm256_store_ps(v.sy + k, _mm256_div_ps(_mm256_blendv_ps(dky, dkx, swap), dkz));
      _mm256_store_ps(v.sz + k, _mm256_div_ps(one, dkz));
      const int m0 = _mm256_movemask_ps(k0), m1 = _mm256_movemask_ps(k1), ms = _mm256_movemask_ps(swap);
      const int sx = _mm256_movemask_ps(ix), sy = _mm256_movemask_ps(iy), sz = _mm256_movemask_ps(iz);
      for (int j = 0; j < 8; ++j) {
        const uint32_t perm = kPerm[m0 >> j & 1][m1 >> j & 1][ms >> j & 1];
        v.meta[k + j] = uint32_t(sx >> j & 1) | uint32_t(sy >> j & 1) << 1 | uint32_t(sz >> j & 1) << 2 | perm << 4;
      }
    }
  }

  // Exit distance and axis (exit_of) of rays [0, n) leaving the leaf box, eight at a time, and
  // the rays that move on: those whose closest hit so far lies beyond the exit (listed in
  // `moving`, their number returned; compacted without a branch per ray).
  static uint32_t exit_stream(const Stream& v, uint32_t n, const OctreeNode& nd, uint32_t* moving) {
    const __m256 inf = _mm256_set1_ps(INFINITY);
    const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
    const __m256i one = _mm256_set1_epi32(1), two = _mm256_set1_epi32(2);
    const __m256i hit_t = _mm256_setr_epi32(0, 4, 8, 12, 16, 20, 24, 28);  // Hit::t of 8 hits (x 4 bytes)
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
      const __m256 tbest = _mm256_i32gather_ps(&v.hits[k].t, hit_t, 4);
      unsigned m = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(tbest, texit, _CMP_GT_OQ)));
      if (k + 8 > n) m &= (1u << (n - k)) - 1;
      for (; m; m &= m - 1) moving[count++] = k + uint32_t(std::countr_zero(m));
    }
    return count;
  }

  // ------------------------------------------------------------------------------------------
  // Mini-MBVH stream traversal: MBVH/RS (thesis Alg. 2.9, App. C.1) on rays [0, n) of a queue.

  static TriRay<4> tri_ray(const Stream& v, uint32_t id) {
    const uint32_t m = v.meta[id];
    return TriRay<4>(Vec3{v.ox[id], v.oy[id], v.oz[id]}, Vec3{v.dx[id], v.dy[id], v.dz[id]}, int(m >> 4 & 3),
                     int(m >> 6 & 3), int(m >> 8 & 3), v.sx[id], v.sy[id], v.sz[id], v.tmin[id]);
  }
  // The permuted origins come from prepare_stream, so a pair costs broadcasts only (a pair is
  // built per leaf visit: the component selection per ray was 137 instructions a pair).
  static PairRay pair_ray(const Stream& v, uint32_t a, uint32_t b) {
    PairRay p;
    const uint32_t ma = v.meta[a], mb = v.meta[b];
    p.kx[0] = ma >> 4 & 3, p.ky[0] = ma >> 6 & 3, p.kz[0] = ma >> 8 & 3;
    p.kx[1] = mb >> 4 & 3, p.ky[1] = mb >> 6 & 3, p.kz[1] = mb >> 8 & 3;
    p.v = &v, p.id[0] = a, p.id[1] = b;
    auto two = [](const float* x, uint32_t lo, uint32_t hi) {
      return _mm256_setr_m128(_mm_broadcast_ss(x + lo), _mm_broadcast_ss(x + hi));
    };
    p.ox = two(v.px, a, b), p.oy = two(v.py, a, b), p.oz = two(v.pz, a, b);
    p.sx = two(v.sx, a, b), p.sy = two(v.sy, a, b), p.sz = two(v.sz, a, b);
    return p;
  }
  static RayCtx ray_ctx(const Stream& v, uint32_t id) {
    return RayCtx(Ray{Vec3{v.ox[id], v.oy[id], v.oz[id]}, v.tmin[id], Vec3{v.dx[id], v.dy[id], v.dz[id]}, INFINITY});
  }

  template <int N, TriKernel K, class P>
  void single(Scratch& s, const Stream& v, uint32_t id, uint32_t ref, P& probe) const {
    const NodeRay<N> nr(Vec3{v.ox[id], v.oy[id], v.oz[id]}, Vec3{v.ix[id], v.iy[id], v.iz[id]}, v.tmin[id]);
    if constexpr (K == TriKernel::watertight) {
      mbvh_traverse<N, 4, K>(mini<N>(), nullptr, nr, tri_ray(v, id), nullptr, ref, v.hits[id], s.single.data(), probe);
    } else {
      const RayCtx rc = ray_ctx(v, id);
      mbvh_traverse<N, 4, K>(mini<N>(), tris_.get(), nr, tri_ray(v, id), &rc, ref, v.hits[id], s.single.data(), probe);
    }
  }

  template <class P>
  static void probe_ray(const Stream& v, uint32_t id, P& probe) {
    if constexpr (P::enabled) {
      for (const float* f : std::initializer_list<const float*>{v.ox, v.oy, v.oz, v.ix, v.iy, v.iz, v.fx, v.fy, v.fz, v.tmin})
        probe.read(f + id, 4);
      probe.read(v.meta + id, 4);
      probe.read(&v.hits[id], 4);
    }
  }

  // Writes the ids of list[0, n) whose mask has bit c to dst (which may be list itself), in
  // order; returns their number. Reads up to 15 entries past n and writes up to 7 past the
  // result: the lane arrays and the mask buffer carry that slack.
  static uint32_t pack_lane(const uint16_t* list, const uint8_t* masks, uint32_t n, unsigned c, uint16_t* dst) {
    const __m128i shift = _mm_cvtsi32_si128(int(7 - c));
    uint32_t o = 0;
    for (uint32_t i = 0; i < n; i += 16) {
      // Bit c of 16 mask bytes to bit 7 (a 16-bit shift moves each byte's bit c to its bit 7).
      uint32_t bits = uint32_t(_mm_movemask_epi8(
          _mm_sll_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(masks + i)), shift)));
      if (n - i < 16) bits &= (1u << (n - i)) - 1;
      for (uint32_t g = 0; g < 2 && i + 8 * g < n; ++g) {
        const uint32_t b8 = (bits >> (8 * g)) & 255u;
        const __m128i ids = _mm_loadu_si128(reinterpret_cast<const __m128i*>(list + i + 8 * g));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + o),
                         _mm_shuffle_epi8(ids, _mm_load_si128(reinterpret_cast<const __m128i*>(kPackLut.s[b8]))));
        o += uint32_t(std::popcount(b8));
      }
    }
    return o;
  }

  template <int N>
  const MBVH<N, 4>& mini() const {
    if constexpr (N == 8) return oct_->mini8;
    else return oct_->mini;
  }

  // N = 4: the thesis' SSE MBVH/RS. N = 8: the same with one AVX2 8-child box test per ray and
  // eight active-ray stacks (the natural SIMD width of AVX2, as mbvh8_single); with the SAH
  // collapse a ray visits far fewer nodes for about the same cost per test.
  template <int N, TriKernel K, class P>
  void stream(Scratch& s, const Stream& v, uint32_t n, uint32_t root, P& probe) const {
    using SN = mbvh_simd::V<N>;
    using f = typename SN::f;
    const MBVH<N, 4>& m = mini<N>();
    const MBVHNode<N>* nodes = m.nodes.data();
    const TriBlock<4>* blocks = m.blocks.data();
    if (n == 1) {
      single<N, K>(s, v, 0, root, probe);
      return;
    }
    uint16_t* lane[N];
    uint32_t head[N];
    for (int c = 0; c < N; ++c) lane[c] = s.lanes[c].data(), head[c] = 0;
    head[0] = n;
    for (uint32_t j = 0; j < n; ++j) lane[0][j] = uint16_t(j);
    Task* tasks = s.tasks.data();
    uint32_t ntasks = 0;
    tasks[ntasks++] = {root, 0, n};
    while (ntasks) {
      const Task t = tasks[--ntasks];
      probe.read(&tasks[ntasks], sizeof(Task));
      head[t.lane] -= t.count;
      uint16_t* list = lane[t.lane] + head[t.lane];
      if (t.count == 1) {  // a stream of one ray: ordinary single-ray traversal of the subtree
        probe.read(list, sizeof(uint16_t));
        probe_ray(v, list[0], probe);
        single<N, K>(s, v, list[0], t.ref, probe);
        continue;
      }
      if (mbvh_ref::is_leaf(t.ref)) {
        probe_leaf(m, t.ref, probe, t.count);
        uint32_t i = 0;
        if constexpr (K == TriKernel::watertight) {
          const uint32_t first = mbvh_ref::first_block(t.ref), nblocks = (mbvh_ref::num_tris(t.ref) + 3) / 4;
          for (; i + 1 < t.count; i += 2) {
            probe.read(&list[i], 2 * sizeof(uint16_t));
            probe_ray(v, list[i], probe);
            probe_ray(v, list[i + 1], probe);
            const PairRay pr = pair_ray(v, list[i], list[i + 1]);
            Hit* h[2] = {&v.hits[list[i]], &v.hits[list[i + 1]]};
            for (uint32_t k = 0; k < nblocks; ++k) pair_intersect(pr, blocks[first + k], h);
          }
        }
        for (; i < t.count; ++i) {
          probe.read(&list[i], sizeof(uint16_t));
          const uint32_t id = list[i];
          probe_ray(v, id, probe);
          if constexpr (K == TriKernel::watertight) {
            leaf_test<4, K>(blocks, nullptr, tri_ray(v, id), nullptr, t.ref, v.hits[id]);
          } else {
            const RayCtx rc = ray_ctx(v, id);
            leaf_test<4, K>(blocks, tris_.get(), tri_ray(v, id), &rc, t.ref, v.hits[id]);
          }
        }
        continue;
      }
      // Interior node: every ray of the task against the N child boxes (box_test of mbvh.h:
      // sign-selected slabs, NaN slabs ignored by operand order, Ize-padded far planes).
      const MBVHNode<N>& nd = nodes[t.ref];
      probe.node(&nd, sizeof(nd), t.count);
      const float* b = &nd.box[0][0];
      uint8_t* masks = s.masks.data();
      unsigned active = 0;
      f dsum = SN::zero();
      for (uint32_t i = 0; i < t.count; ++i) {
        probe.read(&list[i], sizeof(uint16_t));
        const uint16_t id = list[i];
        probe_ray(v, id, probe);
        // Rows of box[6][N]: near plane lo (row a) or hi (row 3 + a) by the direction's sign.
        const uint32_t oct = v.meta[id];
        const uint32_t nx = (oct & 1) * 3 * N, ny = (oct >> 1 & 1) * 3 * N, nz = (oct >> 2 & 1) * 3 * N;
        const f ox = SN::set1(v.ox[id]), oy = SN::set1(v.oy[id]), oz = SN::set1(v.oz[id]);
        const f tnx = SN::mul(SN::sub(SN::load(b + nx), ox), SN::set1(v.ix[id]));
        const f tny = SN::mul(SN::sub(SN::load(b + N + ny), oy), SN::set1(v.iy[id]));
        const f tnz = SN::mul(SN::sub(SN::load(b + 2 * N + nz), oz), SN::set1(v.iz[id]));
        const f tfx = SN::mul(SN::sub(SN::load(b + 3 * N - nx), ox), SN::set1(v.fx[id]));
        const f tfy = SN::mul(SN::sub(SN::load(b + 4 * N - ny), oy), SN::set1(v.fy[id]));
        const f tfz = SN::mul(SN::sub(SN::load(b + 5 * N - nz), oz), SN::set1(v.fz[id]));
        const f tn = SN::max(tnz, SN::max(tny, SN::max(tnx, SN::set1(v.tmin[id]))));
        const f tf = SN::min(tfz, SN::min(tfy, SN::min(tfx, SN::set1(v.hits[id].t))));
        const f enter = SN::le(tn, tf);
        dsum = SN::add(dsum, SN::and_(tn, enter));
        const unsigned mk = unsigned(SN::mask(enter));
        masks[i] = uint8_t(mk);
        active |= mk;
      }
      if (!active) continue;
      // Distribute the rays over the lanes of the children they entered (App. C.1's push, done
      // per child after the box tests instead of N branch-free stores per ray: a child's ids
      // are left-packed eight at a time with one byte shuffle). The task's own lane is packed
      // last and in place: its output never overtakes its input.
      uint32_t cnt[N] = {};
      const unsigned own = 1u << t.lane;
      for (unsigned todo = (active & ~own) | (active & own); todo;) {
        const unsigned c = (todo & ~own) ? unsigned(std::countr_zero(todo & ~own)) : t.lane;
        todo &= ~(1u << c);
        uint16_t* dst = lane[c] + head[c];
        cnt[c] = pack_lane(list, masks, t.count, c, dst);
        if constexpr (P::enabled)
          for (uint32_t j = 0; j < cnt[c]; ++j) probe.write(&dst[j], sizeof(uint16_t));
        head[c] += cnt[c];
      }
      if (!(active & (active - 1))) {
        const int c = std::countr_zero(unsigned(active));
        tasks[ntasks] = {nd.ref[c], uint32_t(c), cnt[c]};
        probe.write(&tasks[ntasks++], sizeof(Task));
        continue;
      }
      // Several children: the nearest (smallest summed entry distance) is popped first.
      alignas(32) int32_t keys[N];
      if constexpr (N == 4) {
        const __m128 act = _mm_castsi128_ps(_mm_cmpgt_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(cnt)),
                                                            _mm_setzero_si128()));
        _mm_store_si128(reinterpret_cast<__m128i*>(keys), mbvh_simd::sort4(mbvh_simd::sort_keys4(dsum, act)));
      } else {
        const __m256 act = _mm256_castsi256_ps(_mm256_cmpgt_epi32(
            _mm256_loadu_si256(reinterpret_cast<const __m256i*>(cnt)), _mm256_setzero_si256()));
        _mm256_store_si256(reinterpret_cast<__m256i*>(keys), mbvh_simd::sort8(mbvh_simd::sort_keys8(dsum, act)));
      }
      for (int j = std::popcount(unsigned(active)) - 1; j >= 0; --j) {
        const uint32_t c = uint32_t(keys[j]) & (N - 1);
        tasks[ntasks] = {nd.ref[c], c, cnt[c]};
        probe.write(&tasks[ntasks++], sizeof(Task));
        // The farther children wait on the stack: start fetching their node or first block.
        if (j > 0) {
          const uint32_t ref = nd.ref[c];
          const char* p = mbvh_ref::is_leaf(ref) ? reinterpret_cast<const char*>(blocks + mbvh_ref::first_block(ref))
                                                 : reinterpret_cast<const char*>(nodes + ref);
          _mm_prefetch(p, _MM_HINT_T0);
          _mm_prefetch(p + 64, _MM_HINT_T0);
        }
      }
    }
  }

  // ------------------------------------------------------------------------------------------
  // Algorithm 5.1

  template <TriKernel K, class P>
  void run_kernel(const RayBatch& batch, PacketRange range, std::span<Hit> out, P& probe) const {
    const uint32_t begin = batch.packet_begin[range.first], end = batch.packet_begin[range.last];
    if (begin >= end) return;
    std::unique_ptr<Scratch> sp = acquire();
    Scratch& s = *sp;
    Counters c;
    for (uint32_t first = begin; first < end; first += kMaxChunk)
      if (params_.width == 8) run_chunk<8, K>(s, batch, first, std::min(end, first + kMaxChunk), out, c, probe);
      else run_chunk<4, K>(s, batch, first, std::min(end, first + kMaxChunk), out, c, probe);
    release(std::move(sp));
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
    s.mp = (M + 7) & ~7u;
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
      s.meta.resize(mp);
      s.axis.resize(mp);
      s.moving.resize(mp);
      s.hits.resize(mp);
    }
    // Per lane at most one pending task per tree level, each with at most a queue; tasks: N - 1
    // siblings pending per level; the one-ray stack: mbvh_traverse's (N-1) * depth + N.
    for (int l = 0; l < N; ++l)
      if (s.lanes[l].size() < size_t(depth_ + 1) * M + 32) s.lanes[l].resize(size_t(depth_ + 1) * M + 32);
    if (s.masks.size() < mp + 16) s.masks.resize(mp + 16);
    if (s.tasks.size() < size_t(N - 1) * depth_ + 2) s.tasks.resize(size_t(N - 1) * depth_ + 2);
    if (s.single.size() < size_t(N - 1) * depth_ + N + 2) s.single.resize(size_t(N - 1) * depth_ + N + 2);
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
      const Stream v{b + kOX * mp, b + kOY * mp, b + kOZ * mp, b + kDX * mp, b + kDY * mp, b + kDZ * mp,
                     b + kTmin * mp, reinterpret_cast<const uint32_t*>(b + kId * mp),
                     d + kIX * mp, d + kIY * mp, d + kIZ * mp, d + kFX * mp, d + kFY * mp, d + kFZ * mp,
                     d + kSX * mp, d + kSY * mp, d + kSZ * mp, d + kTexit * mp,
                     d + kPX * mp, d + kPY * mp, d + kPZ * mp, s.meta.data(), s.axis.data(),
                     s.hits.data()};
      if constexpr (P::enabled)
        for (uint32_t k = 0; k < cnt; ++k)
          for (uint32_t f = 0; f < kFields; ++f) probe.read(&b[f * mp + k], 4);
      prepare_stream(v, cnt);
      for (uint32_t k = 0; k < cnt; ++k) v.hits[k] = Hit{b[kTbest * mp + k], kNoHit, 0.f, 0.f};

      stream<N, K>(s, v, cnt, lf.mbvh_root, probe);

      // Finish or move on (Alg. 5.1, second half of `process`): the hits found here go to the
      // output (a ray's best hit only ever improves), the exits of the whole queue are computed
      // in SIMD, and the rays whose closest hit lies beyond the exit cross into the next leaf.
      Hit dummy;
      for (uint32_t k = 0; k < cnt; ++k) {
        const uint32_t i = first + (v.rec[k] & kIdMask);
        Hit* dst = v.hits[k].prim != kNoHit ? &out[i] : &dummy;  // a select, not a branch
        *dst = v.hits[k];
        if constexpr (P::enabled)
          if (dst != &dummy) probe.write(&out[i], sizeof(Hit));
      }
      const uint32_t moving = exit_stream(v, cnt, lnode, s.moving.data());
      for (uint32_t j = 0; j < moving; ++j) {
        const uint32_t k = s.moving[j];
        const uint32_t rec = v.rec[k];
        const WalkRay w{{v.ox[k], v.oy[k], v.oz[k]}, {v.dx[k], v.dy[k], v.dz[k]}, {v.ix[k], v.iy[k], v.iz[k]},
                        v.tmin[k], v.hits[k].t};
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
  uint32_t depth_ = 1;
  std::shared_ptr<const Octree> oct_;
  std::shared_ptr<const TriangleSet> tris_;
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::unique_ptr<Scratch>> pool_;
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

}  // namespace tb
