#include "structures/bvh_spatial.h"

#include <algorithm>
#include <bit>
#include <limits>
#include <chrono>
#include <cmath>

#include "structures/clip.h"


namespace tb {
namespace {

struct Bin {
  AABB box;
  uint32_t count = 0;  // object bins: references; spatial bins: entries
  uint32_t exits = 0;  // spatial bins: references whose last bin this is
};

struct Split {
  enum Kind { none, object, spatial, walls } kind = none;  // walls: walls_apart's split
  int axis = -1;
  int pos = 0;  // object: first bin of the right side; spatial: plane index
  float cost = INFINITY;  // A_L * N_L + A_R * N_R
  AABB left, right;
};

struct Task {
  uint32_t node, depth;
  std::vector<SpatialRef> refs;
};

class SpatialBuilder {
 public:
  SpatialBuilder(const Scene& scene, const BVHBuildParams& p, const SpatialSplitParams& sp, size_t n)
      : scene_(scene), p_(p), sp_(sp), obins_(std::clamp(p.bins, 2, 256)),
        sbins_all_(std::clamp(sp.spatial_bins, 2, 256)), sbins_(sbins_all_),
        max_leaf_(uint32_t(std::max(1, p.max_leaf))),
        budget_(size_t(double(std::max(0.f, sp.budget)) * double(n))) {}

  BVH run(std::vector<SpatialRef> refs) {
    BVH bvh;
    AABB root;
    for (const auto& r : refs) root.grow(r.box);
    mark_walls(refs, root);
    root_area_ = std::max(root.area(), 1e-30f);
    bvh.nodes.resize(2);
    bvh.nodes[0] = {root.lo, 0, root.hi, uint32_t(refs.size())};
    bvh.nodes[1] = {{0, 0, 0}, 0, {0, 0, 0}, 0};
    bvh.prim_index.reserve(refs.size() + refs.size() / 4);
    std::vector<Task> stack;
    stack.push_back({0, 0, std::move(refs)});
    while (!stack.empty()) {
      Task t = std::move(stack.back());
      stack.pop_back();
      bvh.stats.max_depth = std::max(bvh.stats.max_depth, t.depth);
      const AABB box{bvh.nodes[t.node].lo, bvh.nodes[t.node].hi};
      if (t.refs.size() < size_t(std::max(sp_.min_refs, 2)) &&
          (t.refs.size() < size_t(sp_.large_min_refs) || !has_large_ref(t.refs, box))) {
        graft(bvh, t);
        continue;
      }
      std::vector<SpatialRef> left, right;
      if (!split(t.refs, box, left, right)) {
        BVHNode& n = bvh.nodes[t.node];
        n.left_first = uint32_t(bvh.prim_index.size());
        n.count = uint32_t(t.refs.size());
        for (const auto& r : t.refs) bvh.prim_index.push_back(r.prim);
        continue;
      }
      const uint32_t l = uint32_t(bvh.nodes.size());
      AABB lb, rb;
      for (const auto& r : left) lb.grow(r.box);
      for (const auto& r : right) rb.grow(r.box);
      bvh.nodes.push_back({lb.lo, 0, lb.hi, uint32_t(left.size())});
      bvh.nodes.push_back({rb.lo, 0, rb.hi, uint32_t(right.size())});
      bvh.nodes[t.node].left_first = l;
      bvh.nodes[t.node].count = 0;
      t.refs.clear();
      t.refs.shrink_to_fit();
      stack.push_back({l + 1, t.depth + 1, std::move(right)});
      stack.push_back({l, t.depth + 1, std::move(left)});
    }
    return bvh;
  }

 private:
  // Below min_refs references spatial splits gain little (Stich et al. §5: most of the SAH gain
  // is near the top), so the subtree comes from the project's fast binned builder over the same
  // references (BVH::build over a span), renumbered into this tree.
  void graft(BVH& bvh, Task& t) {
    std::vector<PrimRef> refs;
    refs.reserve(t.refs.size());
    for (const auto& r : t.refs) refs.emplace_back(r.box, r.prim);
    BVHBuildParams p = p_;
    p.threads = 1;
    const BVH sub = BVH::build(std::span<PrimRef>(refs), p);
    const uint32_t node_off = uint32_t(bvh.nodes.size()) - 2, prim_off = uint32_t(bvh.prim_index.size());
    auto renumber = [&](BVHNode n) {
      n.left_first += n.is_leaf() ? prim_off : node_off;
      return n;
    };
    const BVHNode root = renumber(sub.nodes[0]);
    bvh.nodes[t.node].left_first = root.left_first;
    bvh.nodes[t.node].count = root.count;
    for (size_t i = 2; i < sub.nodes.size(); ++i) bvh.nodes.push_back(renumber(sub.nodes[i]));
    bvh.prim_index.insert(bvh.prim_index.end(), sub.prim_index.begin(), sub.prim_index.end());
    bvh.stats.max_depth = std::max(bvh.stats.max_depth, t.depth + sub.stats.max_depth);
  }

  // A reference longer than half the node on some axis: where big triangles meet small ones (a
  // ground quad isolated with a few walls by the object splits above) spatial splits keep paying
  // far below min_refs, so such subtrees are not handed off, down to large_min_refs.
  static bool has_large_ref(const std::vector<SpatialRef>& refs, const AABB& box) {
    const Vec3 half = box.extent() * 0.5f;
    for (const auto& r : refs) {
      const Vec3 e = r.box.extent();
      if (e.x > half.x || e.y > half.y || e.z > half.z) return true;
    }
    return false;
  }

  // Splits refs into left/right, or returns false for a leaf.
  bool split(std::vector<SpatialRef>& refs, const AABB& box, std::vector<SpatialRef>& left,
             std::vector<SpatialRef>& right) {
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
    walls_apart(refs, best);
    const float parent_area = std::max(box.area(), 1e-30f);
    const float split_cost = p_.cost_traversal + p_.cost_intersect * best.cost / parent_area;
    const float leaf_cost = p_.cost_intersect * float(count);
    if (count <= max_leaf_ && (best.kind == Split::none || split_cost >= leaf_cost)) return false;
    // Each side holds at most every reference once: one allocation each instead of a doubling
    // series (allocation was a tenth of the build).
    left.reserve(count);
    right.reserve(count);
    if (best.kind == Split::spatial) {
      do_spatial(refs, box, best, left, right);
      // A split that could not separate anything (all references straddle and every one was
      // kept on both sides) would recurse forever: fall back to the object split.
      if (left.size() < count && right.size() < count && !left.empty() && !right.empty()) return true;
      used_ -= std::min(used_, left.size() + right.size() - count);
      left.clear();
      right.clear();
      best = object_split(refs);
    }
    if (best.kind == Split::walls) {
      for (auto& r : refs) (is_wall(r) ? left : right).push_back(r);
      return true;
    }
    if (best.kind == Split::object) {
      const int a = best.axis;
      const AABB cb = centroid_bounds(refs);
      const float scale = obins_ / (cb.hi[a] - cb.lo[a]);
      for (auto& r : refs)
        (obin(r.box.centre()[a], cb.lo[a], scale) < best.pos ? left : right).push_back(r);
      if (!left.empty() && !right.empty()) return true;
      left.clear();
      right.clear();
    }
    // No usable split (coincident centroids) but too many references for one leaf: halve.
    left.assign(refs.begin(), refs.begin() + count / 2);
    right.assign(refs.begin() + count / 2, refs.end());
    return true;
  }

  static AABB centroid_bounds(const std::vector<SpatialRef>& refs) {
    AABB cb;
    for (const auto& r : refs) cb.grow(r.box.centre());
    return cb;
  }
  int obin(float centre, float lo, float scale) const { return std::clamp(int((centre - lo) * scale), 0, obins_ - 1); }

  // Binned SAH over reference centroids (Wald 2007), as structures/bvh.cpp. The centroids are
  // computed once per node (they were recomputed per axis: a fifth of the build).
  Split object_split(const std::vector<SpatialRef>& refs) {
    Split best;
    cen_.resize(refs.size());
    AABB cb;
    for (size_t i = 0; i < refs.size(); ++i) cb.grow(cen_[i] = refs[i].box.centre());
    // The three axes' bins in one pass over the references (x, y, z named, not indexed: Vec3's
    // operator[] is a branch chain).
    const Vec3 ext = cb.extent();
    const bool on[3] = {ext.x > 0.f, ext.y > 0.f, ext.z > 0.f};
    const Vec3 scale{on[0] ? obins_ / ext.x : 0.f, on[1] ? obins_ / ext.y : 0.f, on[2] ? obins_ / ext.z : 0.f};
    for (auto& bins : obins3_) bins.assign(obins_, Bin{});
    for (size_t i = 0; i < refs.size(); ++i) {
      const Vec3 c = cen_[i];
      const AABB& box = refs[i].box;
      Bin& bx = obins3_[0][obin(c.x, cb.lo.x, scale.x)];
      Bin& by = obins3_[1][obin(c.y, cb.lo.y, scale.y)];
      Bin& bz = obins3_[2][obin(c.z, cb.lo.z, scale.z)];
      bx.box.grow(box), bx.count++;
      by.box.grow(box), by.count++;
      bz.box.grow(box), bz.count++;
    }
    for (int a = 0; a < 3; ++a)
      if (on[a])
        sweep(obins3_[a], a, Split::object, best, [](const Bin& b) { return b.count; },
              [](const Bin& b) { return b.count; });
    return best;
  }

  // Sweeps bins for the cheapest plane; `enter(b)` counts references on the left of a plane after
  // bin b, `leave(b)` those on the right before it.
  template <class Enter, class Leave>
  void sweep(const std::vector<Bin>& bins, int axis, Split::Kind kind, Split& best, Enter enter, Leave leave) {
    const int nb = int(bins.size());
    right_area_.resize(nb);
    right_count_.resize(nb);
    AABB acc;
    uint32_t c = 0;
    for (int i = nb - 1; i > 0; --i) {
      acc.grow(bins[i].box);
      c += leave(bins[i]);
      right_area_[i] = acc.area();
      right_count_[i] = c;
    }
    acc = AABB{};
    c = 0;
    for (int i = 0; i < nb - 1; ++i) {
      acc.grow(bins[i].box);
      c += enter(bins[i]);
      if (c == 0 || right_count_[i + 1] == 0) continue;
      const float cost = acc.area() * float(c) + right_area_[i + 1] * float(right_count_[i + 1]);
      if (cost < best.cost) {
        best.kind = kind;
        best.cost = cost;
        best.axis = axis;
        best.pos = i + 1;
        best.left = acc;
        // The right box is recomputed when needed (only the object split's is read, for overlap).
        AABB r;
        for (int k = i + 1; k < nb; ++k) r.grow(bins[k].box);
        best.right = r;
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
  void mark_walls(const std::vector<SpatialRef>& refs, const AABB& root) {
    if (!(sp_.wall > 0.f)) return;
    wall_.assign(scene_.num_triangles(), 0);
    const Vec3 n = root.extent() * sp_.wall;
    for (const auto& r : refs) {
      const Vec3 e = r.box.extent();
      if (int(e.x >= n.x) + int(e.y >= n.y) + int(e.z >= n.z) >= 2) wall_[r.prim] = 1;
    }
  }
  bool is_wall(const SpatialRef& r) const { return !wall_.empty() && wall_[r.prim]; }
  // SpatialSplitParams::walls_apart: the split "the node's walls | the rest" as a candidate of
  // the SAH beside the binned ones (which place a whole wall by its centroid, among its
  // neighbours); replaces `best` where it costs less.
  void walls_apart(const std::vector<SpatialRef>& refs, Split& best) const {
    if (wall_.empty() || !sp_.walls_apart) return;
    Split s;
    uint32_t nw = 0, no = 0;
    for (const auto& r : refs) {
      if (is_wall(r)) s.left.grow(r.box), ++nw;
      else s.right.grow(r.box), ++no;
    }
    if (nw == 0 || no == 0) return;
    s.kind = Split::walls;
    s.cost = s.left.area() * float(nw) + s.right.area() * float(no);
    if (s.cost < best.cost) best = s;
  }

  // Chopped binning (Stich et al. §4.1): a reference enters its first bin and exits its last;
  // in every bin it spans it adds the bounds of its part clipped to that bin.
  Split spatial_split(const std::vector<SpatialRef>& refs, const AABB& box) {
    Split best;
    for (int a = 0; a < 3; ++a) {
      if (!(box.hi[a] - box.lo[a] > 0.f)) continue;
      if (a == 0) spatial_bins<0>(refs, box);
      else if (a == 1) spatial_bins<1>(refs, box);
      else spatial_bins<2>(refs, box);
      sweep(bins_, a, Split::spatial, best, [](const Bin& b) { return b.count; }, [](const Bin& b) { return b.exits; });
    }
    return best;
  }
  // The bins of one axis A (a template: constant coordinate accesses in the per-reference loop).
  template <int A>
  void spatial_bins(const std::vector<SpatialRef>& refs, const AABB& box) {
    std::vector<Bin>& bins = bins_;
    bins.assign(sbins_, Bin{});
    const AxisBins ab(*this, box, A);
    // The chopped parts' boxes, apart from the bins (chop_triangle_bounds grows an AABB array).
    AABB* sbox = parts_;
    std::fill(sbox, sbox + sbins_, AABB{});
    for (const auto& r : refs) {
      if (is_wall(r)) {  // never clipped: whole, in the bin of its centroid
        Bin& b = bins[ab.bin(r.box.centre()[A])];
        b.count++, b.exits++;
        b.box.grow(r.box);
        continue;
      }
      const int b0 = ab.bin(r.box.lo[A]), b1 = ab.bin(r.box.hi[A]);
      bins[b0].count++;
      bins[b1].exits++;
      if (b0 == b1) {
        bins[b0].box.grow(r.box);
        continue;
      }
      // Chop the reference at each plane it crosses (Stich et al. §4.1; Embree splits the
      // same way): one float sweep of the triangle's edges through the planes (clip.h,
      // chop_triangle_bounds, padded outward so each part is conservative), each part cut to
      // the reference's box.
      const Vec3 v[3] = {scene_.vertex(r.prim, 0), scene_.vertex(r.prim, 1), scene_.vertex(r.prim, 2)};
      chop_triangle_bounds(v, A, ab.pl + b0, b1 - b0 + 1, r.box, sbox + b0);
    }
    for (int b = 0; b < sbins_; ++b) bins[b].box.grow(sbox[b]);
  }

  // Distributes references for a spatial split; a straddling reference is split, or kept whole on
  // one side when that is cheaper ("reference unsplitting", Stich et al. §4.2).
  void do_spatial(const std::vector<SpatialRef>& refs, const AABB& box, const Split& s, std::vector<SpatialRef>& left,
                  std::vector<SpatialRef>& right) {
    const int a = s.axis;
    const float x = plane(box, a, s.pos);
    AABB lb, rb;
    std::vector<const SpatialRef*> straddle;
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
    std::vector<AABB> lparts(straddle.size()), rparts(straddle.size());
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
  std::vector<Bin> bins_;
  std::vector<Bin> obins3_[3];  // object_split's bins per axis
  AABB parts_[kMaxChopSlabs];  // spatial_bins' boxes of the chopped parts (sbins_ <= 256)
  std::vector<Vec3> cen_;  // object_split's centroids
  std::vector<uint8_t> wall_;  // by triangle id: never clipped (empty: wall = 0)
  std::vector<float> right_area_;
  std::vector<uint32_t> right_count_;
};

}  // namespace

BVH build_spatial_bvh(const Scene& scene, std::vector<SpatialRef> refs, const BVHBuildParams& params,
                      const SpatialSplitParams& sp) {
  const auto t0 = std::chrono::steady_clock::now();
  const size_t n = refs.size();
  BVH bvh = SpatialBuilder(scene, params, sp, n).run(std::move(refs));
  move_to_huge_pages(bvh.nodes);
  bvh.finish_stats(params, t0);
  return bvh;
}

BVH build_spatial_bvh(const Scene& scene, const BVHBuildParams& params, const SpatialSplitParams& sp) {
  std::vector<SpatialRef> refs(scene.num_triangles());
  for (uint32_t i = 0; i < refs.size(); ++i) refs[i] = {scene.triangle_bounds(i), i};
  return build_spatial_bvh(scene, std::move(refs), params, sp);
}

}  // namespace tb
