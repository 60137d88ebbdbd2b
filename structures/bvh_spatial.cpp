#include "structures/bvh_spatial.h"

#include <algorithm>
#include <bit>
#include <cassert>
#include <limits>
#include <chrono>
#include <cmath>
#include <span>

#include "structures/box_simd.h"
#include "structures/clip.h"


namespace tb {
namespace {

struct Split {
  enum Kind { none, object, spatial, walls } kind = none;  // walls: walls_apart's split
  int axis = -1;
  int pos = 0;  // object: first bin of the right side; spatial: plane index
  float cost = INFINITY;  // A_L * N_L + A_R * N_R
  AABB left, right;
};

// A node still to split: its references are arena_[off, off + count) (SpatialBuilder::run).
struct Task {
  uint32_t node, depth;
  size_t off, count;
};
using Refs = std::span<const SpatialRef>;
using RefArray = aligned_vector<SpatialRef>;

// A SpatialRef's box as SSE registers (box_simd.h): unaligned loads inside the 28-byte record.
// Lane 3 of lo is box.hi.x, which no result reads; lane 3 of hi would be the bits of `prim` (a
// denormal as a float, slow in some arithmetic), so it is zeroed.
inline __m128 ref_lo(const SpatialRef& r) { return _mm_loadu_ps(&r.box.lo.x); }
inline __m128 ref_hi(const SpatialRef& r) { return _mm_blend_ps(_mm_loadu_ps(&r.box.hi.x), _mm_setzero_ps(), 8); }

struct BinBox {
  __m128 lo, hi;
};
struct alignas(16) Float4 {
  float v[4];
};

class SpatialBuilder {
 public:
  SpatialBuilder(const Scene& scene, const BVHBuildParams& p, const SpatialSplitParams& sp, size_t n)
      : scene_(scene), p_(p), sp_(sp), obins_(std::clamp(p.bins, 2, 256)),
        sbins_all_(std::clamp(sp.spatial_bins, 2, 256)), sbins_(sbins_all_),
        max_leaf_(uint32_t(std::max(1, p.max_leaf))),
        budget_(size_t(double(std::max(0.f, sp.budget)) * double(n))), sub_(p) {}

  // The references of the nodes still to split live in one array, arena_, as a stack: the task
  // on top of the task stack owns the top of the arena. A split writes the two children into the
  // scratch arrays left_ and right_ and then over the parent's place, right below left (left is
  // split next, right once left's subtree is done). Each node used to get two fresh arrays and
  // free its parent's: every level of the tree faulted its references' pages in again (perf: ~15%
  // of a crytek_sponza_partial build's samples in the page-fault path of this paravirtualised VM,
  // whose cost per fault moves with the host; Embree's builders partition one array in place;
  // docs/PERFORMANCE.md, session 28). The arena holds at most the references not yet placed in a
  // leaf, so every reference once plus the duplicates, which the budget bounds (a vector that
  // outgrows its reservation still works: tasks hold offsets); the same references in the same
  // order as before, so the same tree. Peak memory: the arena and, at the root's split, two scratch
  // arrays of up to n references each (28 bytes per reference).
  // fill(arena_) appends the n starting references to the arena (reserved for them and the
  // duplicates), so the scene's references are written there once, not first into an array of
  // their own (session 29: that array was a tenth of a cold conference build's page faults).
  template <class Fill>
  BVH run(size_t n, const Fill& fill) {
    // The arena and the scratch arrays are written over and over: on huge pages (structures/aligned.h)
    // they fault in 2 MiB at a time, unlike a builder's short-lived temporaries (session 15):
    // crytek, conference and sibenik_lucy 2.2-3.5 k fewer faults and 2-6% less process time
    // (3 interleaved runs each; docs/PERFORMANCE.md, session 28); so do object_split's centroids (session 29).
    reserve_on_huge_pages(arena_, n + budget_ + 2);
    fill(arena_);
    assert(arena_.size() == n);
    BVH bvh;
    AABB root;
    for (const auto& r : arena_) root.grow(r.box);
    mark_walls(arena_, root);
    root_area_ = std::max(root.area(), 1e-30f);
    // A leaf holds at least one reference, and a binary tree has 2 leaves - 1 nodes (+ node 1,
    // unused): reserved once (untouched pages cost nothing) instead of a doubling series, and on
    // huge pages where that is 2 MiB or more, so the tree is written where it stays (the nodes
    // used to be written on 4 KiB pages and then copied onto huge pages: a third of a cold
    // conference build's faults; session 29). The reservation stays with the tree: untouched, it
    // costs address space only.
    const size_t max_nodes = 2 * (n + budget_) + 2;
    nodes_on_huge_pages_ = reserve_to_keep(bvh.nodes, max_nodes);
    bvh.nodes.resize(2);
    bvh.nodes[0] = {root.lo, 0, root.hi, uint32_t(n)};
    bvh.nodes[1] = {{0, 0, 0}, 0, {0, 0, 0}, 0};
    bvh.prim_index.reserve(n + n / 4);
    reserve_on_huge_pages(left_, n);
    reserve_on_huge_pages(right_, n);
    reserve_on_huge_pages(cen_, n);
    std::vector<Task> stack;
    stack.push_back({0, 0, 0, n});
    while (!stack.empty()) {
      const Task t = stack.back();
      stack.pop_back();
      assert(arena_.size() == t.off + t.count);  // the task owns the top of the arena
      const Refs refs_t(arena_.data() + t.off, t.count);
      bvh.stats.max_depth = std::max(bvh.stats.max_depth, t.depth);
      const AABB box{bvh.nodes[t.node].lo, bvh.nodes[t.node].hi};
      if (t.count < size_t(std::max(sp_.min_refs, 2)) &&
          (t.count < size_t(sp_.large_min_refs) || !has_large_ref(refs_t, box))) {
        graft(bvh, t, refs_t);
        arena_.resize(t.off);
        continue;
      }
      left_.clear(), right_.clear();
      AABB lb, rb;
      if (!split(refs_t, box, left_, right_, lb, rb)) {
        BVHNode& nd = bvh.nodes[t.node];
        nd.left_first = uint32_t(bvh.prim_index.size());
        nd.count = uint32_t(t.count);
        for (const auto& r : refs_t) bvh.prim_index.push_back(r.prim);
        arena_.resize(t.off);
        continue;
      }
      const uint32_t l = uint32_t(bvh.nodes.size());
      bvh.nodes.push_back({lb.lo, 0, lb.hi, uint32_t(left_.size())});
      bvh.nodes.push_back({rb.lo, 0, rb.hi, uint32_t(right_.size())});
      bvh.nodes[t.node].left_first = l;
      bvh.nodes[t.node].count = 0;
      arena_.resize(t.off);  // the parent's references are no longer read
      arena_.insert(arena_.end(), right_.begin(), right_.end());
      arena_.insert(arena_.end(), left_.begin(), left_.end());
      stack.push_back({l + 1, t.depth + 1, t.off, right_.size()});
      stack.push_back({l, t.depth + 1, t.off + right_.size(), left_.size()});
    }
    return bvh;
  }
  bool nodes_on_huge_pages() const { return nodes_on_huge_pages_; }

 private:
  // Below min_refs references spatial splits gain little (Stich et al. §5: most of the SAH gain
  // is near the top), so the subtree comes from the project's fast binned builder over the same
  // references, built in place under the task's node (BVHSubtreeBuilder: the tree BVH::build
  // over them would give, renumbered).
  void graft(BVH& bvh, const Task& t, Refs refs_t) {
    graft_refs_.clear();
    for (const auto& r : refs_t) graft_refs_.emplace_back(r.box, r.prim);
    const uint32_t depth = sub_.build(bvh, t.node, graft_refs_);
    bvh.stats.max_depth = std::max(bvh.stats.max_depth, t.depth + depth);
  }

  // A reference longer than half the node on some axis: where big triangles meet small ones (a
  // ground quad isolated with a few walls by the object splits above) spatial splits keep paying
  // far below min_refs, so such subtrees are not handed off, down to large_min_refs.
  static bool has_large_ref(Refs refs, const AABB& box) {
    const __m128 half = _mm_mul_ps(_mm_sub_ps(load_vec3(box.hi), load_vec3(box.lo)), _mm_set1_ps(0.5f));
    for (const auto& r : refs)
      if (_mm_movemask_ps(_mm_cmpgt_ps(_mm_sub_ps(ref_hi(r), ref_lo(r)), half)) & 7) return true;
    return false;
  }

  // Splits refs into left/right with their boxes, or returns false for a leaf.
  bool split(Refs refs, const AABB& box, RefArray& left, RefArray& right, AABB& lbox,
             AABB& rbox) {
    const uint32_t count = uint32_t(refs.size());
    if (count <= 1) return false;
    Split best = object_split(refs);
    // Small nodes (those kept from the hand-off for a large reference) bin spatially with fewer
    // bins: the chopping of that reference over every bin is most of their cost.
    sbins_ = count < uint32_t(sp_.min_refs) ? std::clamp(sp_.small_spatial_bins, 2, sbins_all_) : sbins_all_;
    // Spatial splits only where the object split's children overlap noticeably (Stich §4.3) and
    // the duplication budget is not spent.
    const float overlap = best.kind == Split::none ? INFINITY : intersect(best.left, best.right).area();
    if (used_ < budget_ && overlap > sp_.alpha * root_area_ && overlap > sp_.overlap * box.area()) {
      const Split s = spatial_split(refs, box);
      if (s.cost < best.cost) best = s;
    }
    if (walls_.cost < best.cost) best = walls_;  // walls_apart's candidate, from object_split's pass
    const float parent_area = std::max(box.area(), 1e-30f);
    const float split_cost = p_.cost_traversal + p_.cost_intersect * best.cost / parent_area;
    const float leaf_cost = p_.cost_intersect * float(count);
    if (count <= max_leaf_ && (best.kind == Split::none || split_cost >= leaf_cost)) return false;
    // Each side holds at most every reference once: no doubling series (the scratch arrays keep
    // their capacity from node to node, so this allocates only while it grows).
    left.reserve(count);
    right.reserve(count);
    if (best.kind == Split::spatial) {
      do_spatial(refs, box, best, left, right);
      // A split that could not separate anything (all references straddle and every one was
      // kept on both sides) would recurse forever: fall back to the object split.
      if (left.size() < count && right.size() < count && !left.empty() && !right.empty()) {
        lbox = bounds(left), rbox = bounds(right);
        return true;
      }
      used_ -= std::min(used_, left.size() + right.size() - count);
      left.clear();
      right.clear();
      best = object_split(refs);
    }
    // The other kinds' child boxes are the unions their sweep or pass already formed.
    if (best.kind == Split::walls) {
      for (auto& r : refs) (is_wall(r) ? left : right).push_back(r);
      lbox = best.left, rbox = best.right;
      return true;
    }
    if (best.kind == Split::object) {
      // The bins object_split gave the centroids (kept in cen_, same floats).
      const int a = best.axis;
      const float lo = ocl_.v[a], scale = osc_.v[a];
      for (uint32_t i = 0; i < count; ++i) (obin(cen_[i].v[a], lo, scale) < best.pos ? left : right).push_back(refs[i]);
      if (!left.empty() && !right.empty()) {
        lbox = best.left, rbox = best.right;
        return true;
      }
      left.clear();
      right.clear();
    }
    // No usable split (coincident centroids) but too many references for one leaf: halve.
    left.assign(refs.begin(), refs.begin() + count / 2);
    right.assign(refs.begin() + count / 2, refs.end());
    lbox = bounds(left), rbox = bounds(right);
    return true;
  }

  static AABB bounds(std::span<const SpatialRef> refs) {
    __m128 lo = _mm_set1_ps(INFINITY), hi = _mm_set1_ps(-INFINITY);
    for (const auto& r : refs) lo = grow_lo(lo, ref_lo(r)), hi = grow_hi(hi, ref_hi(r));
    return to_aabb(lo, hi);
  }
  int obin(float centre, float lo, float scale) const { return std::clamp(int((centre - lo) * scale), 0, obins_ - 1); }

  // Binned SAH over reference centroids (Wald 2007), as structures/bvh.cpp, in SSE: one pass
  // forms the centroids (kept for the partition) and their bounds, a second bins all three axes.
  // The same float operations as the scalar AABB code, so the same tree. With walls
  // (SpatialSplitParams::walls_apart), the first pass also forms the candidate "the node's
  // walls | the rest" (walls_), which the binned splits place by centroid among the rest.
  Split object_split(Refs refs) {
    Split best;
    const size_t n = refs.size();
    const __m128 inf = _mm_set1_ps(INFINITY), ninf = _mm_set1_ps(-INFINITY), half = _mm_set1_ps(0.5f);
    cen_.resize(n);
    __m128 cl = inf, ch = ninf;
    walls_ = Split{};
    if (wall_.empty() || !sp_.walls_apart) {
      for (size_t i = 0; i < n; ++i) {
        const __m128 c = _mm_mul_ps(_mm_add_ps(ref_lo(refs[i]), ref_hi(refs[i])), half);
        _mm_store_ps(cen_[i].v, c);
        cl = grow_lo(cl, c), ch = grow_hi(ch, c);
      }
    } else {
      __m128 wl = inf, wh = ninf, xl = inf, xh = ninf;
      uint32_t nw = 0;
      for (size_t i = 0; i < n; ++i) {
        const __m128 lo = ref_lo(refs[i]), hi = ref_hi(refs[i]);
        const __m128 c = _mm_mul_ps(_mm_add_ps(lo, hi), half);
        _mm_store_ps(cen_[i].v, c);
        cl = grow_lo(cl, c), ch = grow_hi(ch, c);
        if (is_wall(refs[i])) wl = grow_lo(wl, lo), wh = grow_hi(wh, hi), ++nw;
        else xl = grow_lo(xl, lo), xh = grow_hi(xh, hi);
      }
      if (nw != 0 && nw != n) {
        walls_.kind = Split::walls;
        walls_.left = to_aabb(wl, wh), walls_.right = to_aabb(xl, xh);
        walls_.cost = walls_.left.area() * float(nw) + walls_.right.area() * float(n - nw);
      }
    }
    // The three axes' bins in one pass over the centroids; an axis whose centroids coincide gets
    // scale 0 (every reference in bin 0) and no sweep.
    _mm_store_ps(ocl_.v, cl);
    Float4 ext;
    _mm_store_ps(ext.v, _mm_sub_ps(ch, cl));
    bool on[3];
    for (int a = 0; a < 3; ++a) on[a] = ext.v[a] > 0.f, osc_.v[a] = on[a] ? float(obins_) / ext.v[a] : 0.f;
    osc_.v[3] = 0.f;
    const __m128 vlo = _mm_load_ps(ocl_.v), vscale = _mm_load_ps(osc_.v);
    const __m128i maxbin = _mm_set1_epi32(obins_ - 1), zero = _mm_setzero_si128();
    obox_.assign(size_t(3) * obins_, BinBox{inf, ninf});
    ocount_.assign(size_t(3) * obins_, 0u);
    BinBox* bb = obox_.data();
    uint32_t* bc = ocount_.data();
    for (size_t i = 0; i < n; ++i) {
      const __m128i k = _mm_max_epi32(
          _mm_min_epi32(_mm_cvttps_epi32(_mm_mul_ps(_mm_sub_ps(_mm_load_ps(cen_[i].v), vlo), vscale)), maxbin), zero);
      const int k0 = _mm_cvtsi128_si32(k), k1 = _mm_extract_epi32(k, 1) + obins_,
                k2 = _mm_extract_epi32(k, 2) + 2 * obins_;
      const __m128 lo = ref_lo(refs[i]), hi = ref_hi(refs[i]);
      bb[k0].lo = grow_lo(bb[k0].lo, lo), bb[k0].hi = grow_hi(bb[k0].hi, hi), bc[k0]++;
      bb[k1].lo = grow_lo(bb[k1].lo, lo), bb[k1].hi = grow_hi(bb[k1].hi, hi), bc[k1]++;
      bb[k2].lo = grow_lo(bb[k2].lo, lo), bb[k2].hi = grow_hi(bb[k2].hi, hi), bc[k2]++;
    }
    for (int a = 0; a < 3; ++a)
      if (on[a]) sweep(bb + size_t(a) * obins_, bc + size_t(a) * obins_, bc + size_t(a) * obins_, obins_, a, Split::object, best);
    return best;
  }

  // Sweeps nb bins (boxes b) for the cheapest plane (SAH, Wald 2007): enter[k] references lie on
  // the left of every plane after bin k, leave[k] on the right of every plane before it (object
  // bins: both their count; spatial bins: entries and exits). A side without references offers
  // no split. Areas as AABB::area() (0 for an empty box), so the scalar sweep's choice.
  void sweep(const BinBox* b, const uint32_t* enter, const uint32_t* leave, int nb, int axis, Split::Kind kind,
             Split& best) {
    auto box_area = [](__m128 lo, __m128 hi) {
      return (_mm_movemask_ps(_mm_cmple_ps(lo, hi)) & 7) == 7 ? area(lo, hi) : 0.f;
    };
    right_area_.resize(nb);
    right_count_.resize(nb);
    right_box_.resize(nb);
    __m128 lo = _mm_set1_ps(INFINITY), hi = _mm_set1_ps(-INFINITY);
    uint32_t c = 0;
    for (int i = nb - 1; i > 0; --i) {
      lo = grow_lo(lo, b[i].lo), hi = grow_hi(hi, b[i].hi);
      c += leave[i];
      right_area_[i] = box_area(lo, hi);
      right_count_[i] = c;
      right_box_[i] = {lo, hi};
    }
    lo = _mm_set1_ps(INFINITY), hi = _mm_set1_ps(-INFINITY);
    c = 0;
    for (int i = 0; i < nb - 1; ++i) {
      lo = grow_lo(lo, b[i].lo), hi = grow_hi(hi, b[i].hi);
      c += enter[i];
      if (c == 0 || right_count_[i + 1] == 0) continue;
      const float cost = box_area(lo, hi) * float(c) + right_area_[i + 1] * float(right_count_[i + 1]);
      if (cost < best.cost) {
        best.kind = kind;
        best.cost = cost;
        best.axis = axis;
        best.pos = i + 1;
        best.left = to_aabb(lo, hi);
        best.right = to_aabb(right_box_[i + 1].lo, right_box_[i + 1].hi);
      }
    }
  }

  // Plane k of the spatial bins of `box` on `axis`: the same float for binning and splitting.
  float plane(const AABB& box, int axis, int k) const {
    if (k >= sbins_) return box.hi[axis];
    return box.lo[axis] + (box.hi[axis] - box.lo[axis]) * (float(k) / float(sbins_));
  }
  // The planes of one axis computed once (plane(box, axis, k) for k = 0..sbins), and the bin of a
  // coordinate: a multiply for the guess, then the planes decide (x belongs to bin k when
  // plane(k) <= x < plane(k + 1)), so binning and splitting agree whatever the guess's rounding.
  struct AxisBins {
    float pl[257];
    float lo, scale;
    int n;
    AxisBins(const SpatialBuilder& b, const AABB& box, int axis) : lo(box.lo[axis]), n(b.sbins_) {
      for (int k = 0; k <= n; ++k) pl[k] = b.plane(box, axis, k);
      scale = float(n) / (box.hi[axis] - box.lo[axis]);
    }
    int bin(float x) const {
      int k = std::clamp(int((x - lo) * scale), 0, n - 1);
      while (k > 0 && x < pl[k]) --k;
      while (k < n - 1 && x >= pl[k + 1]) ++k;
      return k;
    }
  };
  // Bounds of the parts of r's triangle below and above x[axis] = pos, within r's box.
  void split_ref(const SpatialRef& r, int axis, float pos, AABB& left, AABB& right) const {
    const Vec3 v[3] = {scene_.vertex(r.prim, 0), scene_.vertex(r.prim, 1), scene_.vertex(r.prim, 2)};
    split_ref(v, r.box, axis, pos, left, right);
  }
  static void split_ref(const Vec3 v[3], const AABB& box, int axis, float pos, AABB& left, AABB& right) {
    split_triangle_bounds(v, axis, pos, left, right);
    left = intersect(left, box);
    right = intersect(right, box);
  }

  // SpatialSplitParams::wall: the triangles whose (starting) box spans `wall` of the root's
  // extent on two axes, flagged by triangle id.
  void mark_walls(Refs refs, const AABB& root) {
    if (!(sp_.wall > 0.f)) return;
    wall_.assign(scene_.num_triangles(), 0);
    const Vec3 n = root.extent() * sp_.wall;
    for (const auto& r : refs) {
      const Vec3 e = r.box.extent();
      if (int(e.x >= n.x) + int(e.y >= n.y) + int(e.z >= n.z) >= 2) wall_[r.prim] = 1;
    }
  }
  bool is_wall(const SpatialRef& r) const { return !wall_.empty() && wall_[r.prim]; }
  // Chopped binning (Stich et al. §4.1): a reference enters its first bin and exits its last;
  // in every bin it spans it adds the bounds of its part clipped to that bin.
  Split spatial_split(Refs refs, const AABB& box) {
    Split best;
    for (int a = 0; a < 3; ++a) {
      if (!(box.hi[a] - box.lo[a] > 0.f)) continue;
      if (a == 0) spatial_bins<0>(refs, box);
      else if (a == 1) spatial_bins<1>(refs, box);
      else spatial_bins<2>(refs, box);
      sweep(sbox_, scount_, sexit_, sbins_, a, Split::spatial, best);
    }
    return best;
  }
  // The bins of one axis A (a template: constant coordinate accesses in the per-reference loop).
  // The boxes of references inside one bin grow the SSE bin boxes; the chopped parts grow parts_
  // (chop_triangle_bounds grows an AABB array), joined to the bins at the end.
  template <int A>
  void spatial_bins(Refs refs, const AABB& box) {
    const __m128 inf = _mm_set1_ps(INFINITY), ninf = _mm_set1_ps(-INFINITY);
    uint32_t *count = scount_, *exits = sexit_;
    std::fill(count, count + sbins_, 0u);
    std::fill(exits, exits + sbins_, 0u);
    BinBox* bb = sbox_;
    std::fill(bb, bb + sbins_, BinBox{inf, ninf});
    const AxisBins ab(*this, box, A);
    AABB* parts = parts_;
    std::fill(parts, parts + sbins_, AABB{});
    for (const auto& r : refs) {
      if (is_wall(r)) {  // never clipped: whole, in the bin of its centroid
        const int k = ab.bin(r.box.centre()[A]);
        count[k]++, exits[k]++;
        bb[k].lo = grow_lo(bb[k].lo, ref_lo(r)), bb[k].hi = grow_hi(bb[k].hi, ref_hi(r));
        continue;
      }
      const int b0 = ab.bin(r.box.lo[A]), b1 = ab.bin(r.box.hi[A]);
      count[b0]++;
      exits[b1]++;
      if (b0 == b1) {
        bb[b0].lo = grow_lo(bb[b0].lo, ref_lo(r)), bb[b0].hi = grow_hi(bb[b0].hi, ref_hi(r));
        continue;
      }
      // Chop the reference at each plane it crosses (Stich et al. §4.1; Embree splits the
      // same way): one float sweep of the triangle's edges through the planes (clip.h,
      // chop_triangle_bounds, padded outward so each part is conservative), each part cut to
      // the reference's box.
      const Vec3 v[3] = {scene_.vertex(r.prim, 0), scene_.vertex(r.prim, 1), scene_.vertex(r.prim, 2)};
      chop_triangle_bounds(v, A, ab.pl + b0, b1 - b0 + 1, r.box, parts + b0);
    }
    for (int k = 0; k < sbins_; ++k)
      bb[k].lo = grow_lo(bb[k].lo, load_vec3(parts[k].lo)), bb[k].hi = grow_hi(bb[k].hi, load_vec3(parts[k].hi));
  }

  // Distributes references for a spatial split; a straddling reference is split, or kept whole on
  // one side when that is cheaper ("reference unsplitting", Stich et al. §4.2).
  void do_spatial(Refs refs, const AABB& box, const Split& s, RefArray& left, RefArray& right) {
    const int a = s.axis;
    const float x = plane(box, a, s.pos);
    AABB lb, rb;
    std::vector<const SpatialRef*>& straddle = straddle_;  // kept from node to node, as run's arrays
    straddle.clear();
    const AxisBins ab(*this, box, a);
    for (const auto& r : refs) {
      if (is_wall(r)) {  // the side of its centroid's bin, as binned
        if (ab.bin(r.box.centre()[a]) < s.pos) left.push_back(r), lb.grow(r.box);
        else right.push_back(r), rb.grow(r.box);
        continue;
      }
      const int b0 = ab.bin(r.box.lo[a]), b1 = ab.bin(r.box.hi[a]);
      if (b1 < s.pos) {
        left.push_back(r);
        lb.grow(r.box);
      } else if (b0 >= s.pos) {
        right.push_back(r);
        rb.grow(r.box);
      } else {
        straddle.push_back(&r);
      }
    }
    // Counts and boxes as if every straddler were split, then each straddler decides.
    float nl = float(left.size() + straddle.size()), nr = float(right.size() + straddle.size());
    std::vector<AABB>&lparts = lparts_, &rparts = rparts_;
    lparts.resize(straddle.size()), rparts.resize(straddle.size());
    for (size_t i = 0; i < straddle.size(); ++i) {
      split_ref(*straddle[i], a, x, lparts[i], rparts[i]);
      lb.grow(lparts[i]);
      rb.grow(rparts[i]);
    }
    for (size_t i = 0; i < straddle.size(); ++i) {
      const SpatialRef& r = *straddle[i];
      const bool lempty = lparts[i].empty(), rempty = rparts[i].empty();
      if (lempty || rempty) {  // the clipper found no part on one side: the reference is one-sided
        if (!lempty) left.push_back({lparts[i], r.prim}), nr -= 1;
        else if (!rempty) right.push_back({rparts[i], r.prim}), nl -= 1;
        else left.push_back(r), nr -= 1;  // cannot happen for a reference inside the node's box
        continue;
      }
      const float c_split = lb.area() * nl + rb.area() * nr;
      AABB l1 = lb, r2 = rb;
      l1.grow(r.box);
      r2.grow(r.box);
      const float c_left = l1.area() * nl + rb.area() * (nr - 1);
      const float c_right = lb.area() * (nl - 1) + r2.area() * nr;
      if (c_left < c_split && c_left <= c_right) {
        left.push_back(r);
        lb = l1;
        nr -= 1;
      } else if (c_right < c_split) {
        right.push_back(r);
        rb = r2;
        nl -= 1;
      } else {
        left.push_back({lparts[i], r.prim});
        right.push_back({rparts[i], r.prim});
        used_++;
      }
    }
  }

  const Scene& scene_;
  const BVHBuildParams& p_;
  const SpatialSplitParams& sp_;
  const int obins_, sbins_all_;
  int sbins_;  // the node's spatial bins: sbins_all_, or small_spatial_bins below min_refs
  const uint32_t max_leaf_;
  const size_t budget_;
  size_t used_ = 0;
  float root_area_ = 1.f;
  std::vector<BinBox> obox_;  // object_split's bin boxes, [axis * obins_ + bin]
  std::vector<uint32_t> ocount_;  // ... and counts
  Float4 ocl_, osc_;  // object_split's centroid minimum and bin scale per axis
  Split walls_;  // object_split's walls_apart candidate (kind none: not offered)
  aligned_vector<Float4> cen_;  // object_split's centroids, in the order of the references
  BinBox sbox_[kMaxChopSlabs];  // spatial_bins' bin boxes (references inside one bin, then parts)
  uint32_t scount_[kMaxChopSlabs], sexit_[kMaxChopSlabs];  // ... entries and exits per bin
  AABB parts_[kMaxChopSlabs];  // spatial_bins' boxes of the chopped parts (sbins_ <= 256)
  std::vector<uint8_t> wall_;  // by triangle id: never clipped (empty: wall = 0)
  std::vector<float> right_area_;
  std::vector<uint32_t> right_count_;
  std::vector<BinBox> right_box_;
  RefArray arena_;         // run: the references of the nodes still to split
  RefArray left_, right_;  // run: a split's children, before they go to the arena
  BVHSubtreeBuilder sub_;               // graft: the binned builder of the small subtrees
  std::vector<PrimRef> graft_refs_;     // ... and their references
  std::vector<const SpatialRef*> straddle_;  // do_spatial: the references across the plane
  std::vector<AABB> lparts_, rparts_;        // ... and their parts on either side
  bool nodes_on_huge_pages_ = false;         // run: the tree's nodes were reserved on huge pages
};

}  // namespace

namespace {

template <class Fill>
BVH build_spatial(const Scene& scene, size_t n, const Fill& fill, const BVHBuildParams& params,
                  const SpatialSplitParams& sp, std::chrono::steady_clock::time_point t0) {
  SpatialBuilder builder(scene, params, sp, n);
  BVH bvh = builder.run(n, fill);
  if (!builder.nodes_on_huge_pages()) bvh.nodes.shrink_to_fit();  // a small tree: drop run's reserve
  bvh.finish_stats(params, t0);
  return bvh;
}

}  // namespace

SpatialSplitParams spatial_split_params(const BVHBuildParams& p) {
  SpatialSplitParams sp;
  sp.alpha = p.split_alpha;
  sp.budget = p.split_budget;
  sp.wall = p.split_wall;
  sp.overlap = p.split_overlap;
  sp.walls_apart = p.split_walls;
  return sp;
}

BVH build_spatial_bvh(const Scene& scene, std::vector<SpatialRef> refs, const BVHBuildParams& params,
                      const SpatialSplitParams& sp) {
  const auto t0 = std::chrono::steady_clock::now();
  return build_spatial(
      scene, refs.size(), [&](RefArray& arena) { arena.assign(refs.begin(), refs.end()), refs = {}; }, params, sp, t0);
}

BVH build_spatial_bvh(const Scene& scene, const BVHBuildParams& params, const SpatialSplitParams& sp) {
  const auto t0 = std::chrono::steady_clock::now();
  const uint32_t n = uint32_t(scene.num_triangles());
  return build_spatial(
      scene, n,
      [&](RefArray& arena) {
        for (uint32_t i = 0; i < n; ++i) arena.push_back({scene.triangle_bounds(i), i});
      },
      params, sp, t0);
}

}  // namespace tb
