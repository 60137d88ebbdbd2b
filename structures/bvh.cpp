#include "structures/bvh.h"
#include "structures/bvh_spatial.h"
#include "structures/embree_bvh.h"
#include "structures/box_simd.h"

#include <immintrin.h>

#include <algorithm>
#include <cassert>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <thread>

namespace tb {

std::string BVHBuildParams::key() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "bvh:bins=%d:leaf=%d:ct=%g:ci=%g", bins, max_leaf, cost_traversal, cost_intersect);  // threads do not change the tree
  std::string k = buf;
  if (builder == BVHBuilder::embree) k += ":embree";
  if (spatial) {
    std::snprintf(buf, sizeof buf, ":spatial:alpha=%g:budget=%g:wall=%g:overlap=%g:walls=%d", split_alpha, split_budget,
                  split_wall, split_overlap, int(split_walls));
    k += buf;
  }
  return k;
}

std::string BVHStats::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf, "nodes=%u leaves=%u max_depth=%u sah=%.2f build_ms=%.1f bytes=%zu", nodes, leaves,
                max_depth, sah_cost, build_ms, bytes);
  return buf;
}

namespace {

// PrimRef (bvh.h) as SSE registers.
inline __m128 vlo(const PrimRef& r) { return _mm_load_ps(r.lo); }
inline __m128 vhi(const PrimRef& r) { return _mm_load_ps(r.hi); }

// The box (bl, bh) and doubled-centroid bounds (cl, ch) of references: a build's root.
struct RefBounds {
  __m128 bl, bh, cl, ch;
};
RefBounds ref_bounds(std::span<const PrimRef> refs) {
  RefBounds b{_mm_set1_ps(INFINITY), _mm_set1_ps(-INFINITY), _mm_set1_ps(INFINITY), _mm_set1_ps(-INFINITY)};
  for (const PrimRef& r : refs) {
    const __m128 lo = vlo(r), hi = vhi(r), cen = _mm_add_ps(lo, hi);
    b.bl = grow_lo(b.bl, lo); b.bh = grow_hi(b.bh, hi);
    b.cl = grow_lo(b.cl, cen); b.ch = grow_hi(b.ch, cen);
  }
  return b;
}

// Centroid bounds travel with a task: the parent's partition pass computes them for free, so a
// node never needs a bounds pass of its own. Centroids are kept doubled (lo + hi): the factor 2
// cancels in the bin mapping, bit for bit (scaling by 2 commutes with rounding).
struct BuildTask {
  __m128 cmin, cmax;
  uint32_t node, depth;
};

// Nodes up to this many references take the sparse binning path.
constexpr uint32_t kSparseMax = 32;

// Per-thread bin storage, allocated once per run() rather than per node.
struct BinBox {
  __m128 lo, hi;
};
struct BinSet {
  std::vector<BinBox> box;  // [axis * nbins + bin]
  std::vector<uint32_t> count;
  std::vector<float> right_area;
  std::vector<uint32_t> right_count;
  std::vector<uint8_t> occupied;  // [axis * nbins + i]: the i-th occupied bin
  explicit BinSet(int nbins)
      : box(size_t(3) * nbins), count(size_t(3) * nbins), right_area(nbins), right_count(nbins),
        occupied(size_t(3) * nbins) {}
};

// The binned SAH sweep over one subtree at a time. Threads share the node array (pairs are
// claimed with an atomic counter) and work on disjoint ranges of the reference array.
struct Builder {
  const BVHBuildParams& p;
  BVH& bvh;
  PrimRef* refs;
  std::atomic<uint32_t> next_node{2};
  std::atomic<uint32_t> max_depth{0};
  uint32_t defer_below = 0;  // subtrees smaller than this are left for the thread pool
  bool grow_nodes = false;   // single thread: the node array grows as pairs are claimed
  std::vector<BuildTask> deferred;

  Builder(const BVHBuildParams& p_, BVH& bvh_, PrimRef* refs_) : p(p_), bvh(bvh_), refs(refs_) {}

  static int bins(const BVHBuildParams& p) { return std::clamp(p.bins, 2, 256); }
  void run(std::vector<BuildTask> stack, bool may_defer) {
    BinSet bs(bins(p));
    run(stack, may_defer, bs);
  }
  // The same with the caller's bins (BinSet(bins(p))), emptying the caller's stack.
  void run(std::vector<BuildTask>& stack, bool may_defer, BinSet& bs) {
    const int nbins = bins(p);
    const uint32_t max_leaf = uint32_t(std::max(1, p.max_leaf));
    const __m128 inf = _mm_set1_ps(INFINITY), ninf = _mm_set1_ps(-INFINITY);
    const __m128i maxbin = _mm_set1_epi32(nbins - 1), zero = _mm_setzero_si128();
    uint32_t local_depth = 0;
    while (!stack.empty()) {
      const BuildTask task = stack.back();
      stack.pop_back();
      BVHNode& node = bvh.nodes[task.node];
      const uint32_t first = node.left_first, count = node.count;
      if (may_defer && count < defer_below) {
        deferred.push_back(task);
        continue;
      }
      local_depth = std::max(local_depth, task.depth);
      if (count <= 1) continue;

      // Bin all three axes in one pass over the references, by centroid (Wald 2007). An axis
      // whose centroids coincide gets scale 0: everything lands in bin 0, and the sweep finds no
      // split on it.
      alignas(16) float cmin[4], cext[4], scale[4];
      _mm_store_ps(cmin, task.cmin);
      _mm_store_ps(cext, _mm_sub_ps(task.cmax, task.cmin));
      for (int a = 0; a < 3; ++a) scale[a] = cext[a] > 0.f ? nbins / cext[a] : 0.f;
      scale[3] = 0.f;
      cmin[3] = 0.f;
      const __m128 vcmin = _mm_load_ps(cmin), vscale = _mm_load_ps(scale);
      BinBox* bb = bs.box.data();
      uint32_t* bcnt = bs.count.data();
      auto bin_of = [&](__m128 lo, __m128 hi) {
        const __m128i k = _mm_cvttps_epi32(_mm_mul_ps(_mm_sub_ps(_mm_add_ps(lo, hi), vcmin), vscale));
        return _mm_max_epi32(_mm_min_epi32(k, maxbin), zero);
      };
      // The sweep visits only occupied bins, listed per axis in increasing order.
      uint8_t* occ = bs.occupied.data();  // [axis * nbins + i]
      int nocc[3] = {0, 0, 0};
      int best_axis = -1, best_split = 0;
      float best_cost = INFINITY;
      if (count == 2) {
        // Two references (about 40% of the nodes binned on Sponza): on an axis where their
        // centroids differ they are the two ends of the centroid bounds, so they land in bins 0
        // and nbins - 1; every such axis offers the same split at the same cost, and the first
        // wins the strict comparison. This is the binned result without touching the bins.
        int a = 0;
        while (a < 3 && !(cext[a] > 0.f)) ++a;
        if (a < 3) {
          best_axis = a;
          best_split = 1;
          best_cost = area(vlo(refs[first]), vhi(refs[first])) * 1.f +
                      area(vlo(refs[first + 1]), vhi(refs[first + 1])) * 1.f;
        }
      } else if (count <= kSparseMax && nbins <= 64) {
        // Small node: most bins stay empty, so rather than clearing and sweeping all 3 x nbins
        // bins, only the bins the references fall into are cleared, recorded in a bit mask per
        // axis, and swept. Two passes (clear, then accumulate) rather than an "already touched?"
        // test per reference and axis, which mispredicts often: with the branch this path was
        // ~4% slower on Sponza.
        uint64_t mask[3] = {0, 0, 0};
        alignas(16) int ks[kSparseMax][4];
        for (uint32_t i = 0; i < count; ++i) {
          _mm_store_si128(reinterpret_cast<__m128i*>(ks[i]), bin_of(vlo(refs[first + i]), vhi(refs[first + i])));
          for (int a = 0; a < 3; ++a) {
            const int j = a * nbins + ks[i][a];
            mask[a] |= uint64_t(1) << ks[i][a];
            bb[j] = BinBox{inf, ninf};
            bcnt[j] = 0;
          }
        }
        for (uint32_t i = 0; i < count; ++i) {
          const __m128 lo = vlo(refs[first + i]), hi = vhi(refs[first + i]);
          for (int a = 0; a < 3; ++a) {
            const int j = a * nbins + ks[i][a];
            bb[j].lo = grow_lo(bb[j].lo, lo); bb[j].hi = grow_hi(bb[j].hi, hi); bcnt[j]++;
          }
        }
        for (int a = 0; a < 3; ++a)
          for (uint64_t m = mask[a]; m; m &= m - 1) occ[a * nbins + nocc[a]++] = uint8_t(__builtin_ctzll(m));
      } else {
        std::fill(bs.box.begin(), bs.box.end(), BinBox{inf, ninf});
        std::fill(bs.count.begin(), bs.count.end(), 0u);
        for (uint32_t i = first; i < first + count; ++i) {
          const __m128 lo = vlo(refs[i]), hi = vhi(refs[i]);
          const __m128i k = bin_of(lo, hi);
          const int k0 = _mm_cvtsi128_si32(k), k1 = _mm_extract_epi32(k, 1) + nbins,
                    k2 = _mm_extract_epi32(k, 2) + 2 * nbins;
          bb[k0].lo = grow_lo(bb[k0].lo, lo); bb[k0].hi = grow_hi(bb[k0].hi, hi); bcnt[k0]++;
          bb[k1].lo = grow_lo(bb[k1].lo, lo); bb[k1].hi = grow_hi(bb[k1].hi, hi); bcnt[k1]++;
          bb[k2].lo = grow_lo(bb[k2].lo, lo); bb[k2].hi = grow_hi(bb[k2].hi, hi); bcnt[k2]++;
        }
        for (int a = 0; a < 3; ++a)
          for (int k = 0; k < nbins; ++k)
            if (bcnt[a * nbins + k]) occ[a * nbins + nocc[a]++] = uint8_t(k);
      }

      // SAH sweep (Wald 2007) over the occupied bins only: a split after an empty bin costs
      // exactly what the split before it costs, and only a strictly smaller cost wins, so the
      // chosen split is the one the full sweep over all bins picks.
      for (int a = 0; a < 3; ++a) {
        const int no = nocc[a];
        if (no < 2) continue;  // one occupied bin (or coincident centroids): no split on this axis
        const BinBox* b = bb + size_t(a) * nbins;
        const uint32_t* cnt = bcnt + size_t(a) * nbins;
        const uint8_t* o = occ + size_t(a) * nbins;
        // Right-to-left: area and count of the occupied bins o[i..no).
        __m128 alo = inf, ahi = ninf;
        uint32_t c = 0;
        for (int i = no - 1; i > 0; --i) {
          alo = grow_lo(alo, b[o[i]].lo);
          ahi = grow_hi(ahi, b[o[i]].hi);
          c += cnt[o[i]];
          bs.right_area[i] = area(alo, ahi);
          bs.right_count[i] = c;
        }
        alo = inf;
        ahi = ninf;
        c = 0;
        for (int i = 0; i < no - 1; ++i) {
          alo = grow_lo(alo, b[o[i]].lo);
          ahi = grow_hi(ahi, b[o[i]].hi);
          c += cnt[o[i]];
          const float cost = area(alo, ahi) * c + bs.right_area[i + 1] * bs.right_count[i + 1];
          if (cost < best_cost) { best_cost = cost; best_axis = a; best_split = o[i] + 1; }
        }
      }
      const float parent_area = AABB{node.lo, node.hi}.area();
      const float split_cost = p.cost_traversal + p.cost_intersect * best_cost / std::max(parent_area, 1e-30f);
      const float leaf_cost = p.cost_intersect * count;
      if (count <= max_leaf && (best_axis < 0 || split_cost >= leaf_cost)) continue;

      uint32_t mid;
      __m128 lbl = inf, lbh = ninf, rbl = inf, rbh = ninf;  // child boxes
      __m128 lcl = inf, lch = ninf, rcl = inf, rch = ninf;  // child centroid bounds
      if (best_axis >= 0) {
        // The child boxes are the unions of their bins; the partition only has to collect the
        // children's centroid bounds, which become the children's binning ranges.
        const BinBox* b = bb + size_t(best_axis) * nbins;
        const uint8_t* o = occ + size_t(best_axis) * nbins;
        for (int i = 0; i < nocc[best_axis]; ++i) {
          const BinBox& x = b[o[i]];
          if (o[i] < best_split) {
            lbl = grow_lo(lbl, x.lo); lbh = grow_hi(lbh, x.hi);
          } else {
            rbl = grow_lo(rbl, x.lo); rbh = grow_hi(rbh, x.hi);
          }
        }
        const int ax = best_axis;
        const float cm = cmin[ax], sc = scale[ax];
        auto is_left = [&](const PrimRef& r) {
          return std::min(nbins - 1, int((r.lo[ax] + r.hi[ax] - cm) * sc)) < best_split;
        };
        // Branch-free Lomuto partition, in place: which side a reference goes to is a coin flip
        // the branch predictor loses about half the time, so every reference is swapped
        // unconditionally and the left end advances by the comparison (6% of the build on Sponza
        // against std::partition). The order inside each side is not std::partition's; only the
        // count/2 fallback below depends on it, and serial and parallel builds share this code.
        PrimRef* l = refs + first;
        for (PrimRef *it = l, *end = refs + first + count; it < end; ++it) {
          const bool left = is_left(*it);
          const __m128 c = _mm_add_ps(vlo(*it), vhi(*it));
          const __m128 m = _mm_castsi128_ps(_mm_set1_epi32(-int(left)));
          lcl = grow_lo(lcl, _mm_blendv_ps(inf, c, m)); lch = grow_hi(lch, _mm_blendv_ps(ninf, c, m));
          rcl = grow_lo(rcl, _mm_blendv_ps(c, inf, m)); rch = grow_hi(rch, _mm_blendv_ps(c, ninf, m));
          const PrimRef x = *it;
          *it = *l;
          *l = x;
          l += left;
        }
        mid = uint32_t(l - refs);
        if (count == 2) {  // no bins were filled: the child boxes are the two references' boxes
          lbl = vlo(refs[first]); lbh = vhi(refs[first]);
          rbl = vlo(refs[first + 1]); rbh = vhi(refs[first + 1]);
        }
      } else {
        // All centroids coincide: split the list to respect max_leaf.
        mid = first + count / 2;
        for (uint32_t i = first; i < first + count; ++i) {
          const __m128 lo = vlo(refs[i]), hi = vhi(refs[i]), c = _mm_add_ps(lo, hi);
          if (i < mid) {
            lbl = grow_lo(lbl, lo); lbh = grow_hi(lbh, hi); lcl = grow_lo(lcl, c); lch = grow_hi(lch, c);
          } else {
            rbl = grow_lo(rbl, lo); rbh = grow_hi(rbh, hi); rcl = grow_lo(rcl, c); rch = grow_hi(rch, c);
          }
        }
      }
      const uint32_t left = next_node.fetch_add(2);
      if (grow_nodes) bvh.nodes.resize(left + 2);  // within the reserved capacity: no reallocation
      alignas(16) float f[4][4];
      _mm_store_ps(f[0], lbl); _mm_store_ps(f[1], lbh); _mm_store_ps(f[2], rbl); _mm_store_ps(f[3], rbh);
      bvh.nodes[left] = {{f[0][0], f[0][1], f[0][2]}, first, {f[1][0], f[1][1], f[1][2]}, mid - first};
      bvh.nodes[left + 1] = {{f[2][0], f[2][1], f[2][2]}, mid, {f[3][0], f[3][1], f[3][2]}, first + count - mid};
      node.left_first = left;
      node.count = 0;
      stack.push_back({rcl, rch, left + 1, task.depth + 1});
      stack.push_back({lcl, lch, left, task.depth + 1});
    }
    for (uint32_t d = max_depth.load(); local_depth > d && !max_depth.compare_exchange_weak(d, local_depth);) {
    }
  }
};

}  // namespace

namespace {

// The build proper, shared by both entry points: the references with their box (bl, bh) and
// doubled-centroid bounds (cl, ch), gathered by the caller in its one pass over them.
BVH build_refs(PrimRef* refs, uint32_t n, __m128 bl, __m128 bh, __m128 cl, __m128 ch, const BVHBuildParams& p,
               std::chrono::steady_clock::time_point t0) {
  BVH bvh;
  bvh.prim_index.resize(n);
  // A binary tree over n leaves has < 2n nodes. A single-threaded build only reserves them and
  // grows the array pair by pair: value-initialising all 2n nodes up front touched (page-faulted
  // and zeroed) twice the memory the tree uses, ~10% of the build time on Sponza. Parallel
  // builds claim pairs from several threads, so they need the whole array in place (and copy
  // the used part onto huge pages at the end, freeing the rest). A single thread's reservation
  // is on huge pages where it spans 2 MiB or more, so the tree is written where it stays instead
  // of on 4 KiB pages and then copied: bvh_single's build 0.70-0.82x on 4 scenes, cold and warm
  // (docs/PERFORMANCE.md, session 29); untouched, the rest of the reservation is address space.
  const int threads = std::max(1, p.threads);
  const size_t max_nodes = size_t(2) * std::max(n, 1u) + 2;
  const bool in_place = threads == 1 && reserve_to_keep(bvh.nodes, max_nodes);
  bvh.nodes.resize(threads == 1 ? 2 : max_nodes);
  alignas(16) float flo[4], fhi[4];
  _mm_store_ps(flo, bl);
  _mm_store_ps(fhi, bh);
  bvh.nodes[0] = {{flo[0], flo[1], flo[2]}, 0, {fhi[0], fhi[1], fhi[2]}, n};
  bvh.nodes[1] = {{0, 0, 0}, 0, {0, 0, 0}, 0};

  Builder b{p, bvh, refs};
  const BuildTask root{cl, ch, 0, 0};
  if (threads == 1) {
    b.grow_nodes = true;
    b.run({root}, false);
  } else {
    // Top levels on this thread until the subtrees are small enough to balance across threads,
    // then the deferred subtrees in parallel, each thread pulling the next from a shared index.
    b.defer_below = std::max(n / (8 * uint32_t(threads)), 1024u);
    b.run({root}, true);
    std::atomic<size_t> next{0};
    auto worker = [&] {
      for (size_t i; (i = next.fetch_add(1)) < b.deferred.size();) b.run({b.deferred[i]}, false);
    };
    std::vector<std::thread> pool;
    for (int i = 1; i < threads; ++i) pool.emplace_back(worker);
    worker();
    for (auto& t : pool) t.join();
  }
  for (uint32_t i = 0; i < n; ++i) bvh.prim_index[i] = refs[i].id();
  bvh.nodes.resize(b.next_node.load());
  bvh.stats.max_depth = b.max_depth.load();
  if (!in_place) move_to_huge_pages(bvh.nodes);
  bvh.finish_stats(p, t0);
  return bvh;
}

}  // namespace

struct BVHSubtreeBuilder::Scratch {
  BinSet bins;
  std::vector<BuildTask> stack;
  explicit Scratch(const BVHBuildParams& p) : bins(Builder::bins(p)) {}
};

BVHSubtreeBuilder::BVHSubtreeBuilder(const BVHBuildParams& params) : params_(params) {
  params_.threads = 1;
  scratch_ = std::make_unique<Scratch>(params_);
}
BVHSubtreeBuilder::~BVHSubtreeBuilder() = default;

uint32_t BVHSubtreeBuilder::build(BVH& bvh, uint32_t node, std::span<PrimRef> refs) {
  const uint32_t n = uint32_t(refs.size()), prim_off = uint32_t(bvh.prim_index.size()),
                 node_off = uint32_t(bvh.nodes.size());
  // The root task's centroid bounds, as BVH::build(span) forms them; the node's box is the
  // references' bounds (the builder's leaf decision at the root reads its area).
  const RefBounds rb = ref_bounds(refs);
  assert((_mm_movemask_ps(_mm_and_ps(_mm_cmpeq_ps(rb.bl, load_vec3(bvh.nodes[node].lo)),
                                     _mm_cmpeq_ps(rb.bh, load_vec3(bvh.nodes[node].hi)))) & 7) == 7);
  // The builder reads a node's references at left_first, an index into `refs`: the subtree's
  // leaves are moved to prim_index's numbering once it is built.
  bvh.nodes[node].left_first = 0;
  bvh.nodes[node].count = n;
  Builder b{params_, bvh, refs.data()};
  b.grow_nodes = true;
  b.next_node = node_off;
  scratch_->stack.assign(1, BuildTask{rb.cl, rb.ch, node, 0});
  b.run(scratch_->stack, false, scratch_->bins);
  if (bvh.nodes[node].is_leaf()) bvh.nodes[node].left_first += prim_off;
  for (size_t i = node_off; i < bvh.nodes.size(); ++i)
    if (bvh.nodes[i].is_leaf()) bvh.nodes[i].left_first += prim_off;
  for (const PrimRef& r : refs) bvh.prim_index.push_back(r.id());
  return b.max_depth.load();
}

BVH BVH::build(const Scene& scene, const BVHBuildParams& p) {
  if (p.builder == BVHBuilder::embree) return build_embree_bvh(scene, p);
  if (p.spatial) return build_spatial_bvh(scene, p, spatial_split_params(p));
  const auto t0 = std::chrono::steady_clock::now();
  const uint32_t n = uint32_t(scene.num_triangles());
  // Uninitialised: the loop below writes every reference once.
  std::unique_ptr<PrimRef[]> refs(new PrimRef[n]);
  // One pass: every triangle's box (as Scene::triangle_bounds, vertex order kept), the root box
  // and the root's centroid bounds.
  __m128 bl = _mm_set1_ps(INFINITY), bh = _mm_set1_ps(-INFINITY), cl = bl, ch = bh;
  const Vec3* pos = scene.positions.data();
  for (uint32_t i = 0; i < n; ++i) {
    const auto& t = scene.triangles[i];
    const Vec3 a = pos[t[0]], b = pos[t[1]], c = pos[t[2]];
    const __m128 va = _mm_setr_ps(a.x, a.y, a.z, 0.f), vb = _mm_setr_ps(b.x, b.y, b.z, 0.f),
                 vc = _mm_setr_ps(c.x, c.y, c.z, 0.f);
    __m128 lo = grow_lo(grow_lo(_mm_set1_ps(INFINITY), va), vb);
    lo = grow_lo(lo, vc);
    __m128 hi = grow_hi(grow_hi(_mm_set1_ps(-INFINITY), va), vb);
    hi = grow_hi(hi, vc);
    lo = _mm_castsi128_ps(_mm_insert_epi32(_mm_castps_si128(lo), int(i), 3));
    hi = _mm_insert_ps(hi, _mm_set_ss(1.f), 0x30);
    _mm_store_ps(refs[i].lo, lo);
    _mm_store_ps(refs[i].hi, hi);
    const __m128 cen = _mm_add_ps(lo, hi);
    bl = grow_lo(bl, lo); bh = grow_hi(bh, hi);
    cl = grow_lo(cl, cen); ch = grow_hi(ch, cen);
  }
  return build_refs(refs.get(), n, bl, bh, cl, ch, p, t0);
}

BVH BVH::build(std::span<PrimRef> refs, const BVHBuildParams& p) {
  const auto t0 = std::chrono::steady_clock::now();
  const RefBounds b = ref_bounds(refs);
  return build_refs(refs.data(), uint32_t(refs.size()), b.bl, b.bh, b.cl, b.ch, p, t0);
}

void BVH::refit(const Scene& scene, int threads) {
  refit_boxes([&](uint32_t id) { return scene.triangle_bounds(id); }, threads);
}

void BVH::finish_stats(const BVHBuildParams& params, std::chrono::steady_clock::time_point start) {
  stats.nodes = uint32_t(nodes.size() - 1);  // nodes[1] is padding
  stats.leaves = 0;
  for (size_t i = 0; i < nodes.size(); ++i)
    if (i != 1 && nodes[i].is_leaf()) stats.leaves++;
  stats.bytes = nodes.size() * sizeof(BVHNode) + prim_index.size() * sizeof(uint32_t);
  stats.sah_cost = compute_sah_cost(params);
  stats.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

double BVH::compute_sah_cost(const BVHBuildParams& p) const {
  if (nodes.empty()) return 0;
  const double root = std::max(AABB{nodes[0].lo, nodes[0].hi}.area(), 1e-30f);
  double cost = 0;
  for (size_t i = 0; i < nodes.size(); ++i) {
    if (i == 1) continue;
    const double a = AABB{nodes[i].lo, nodes[i].hi}.area() / root;
    cost += nodes[i].is_leaf() ? a * p.cost_intersect * nodes[i].count : a * p.cost_traversal;
  }
  return cost;
}

}  // namespace tb
