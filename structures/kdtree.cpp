#include "structures/kdtree.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "structures/clip.h"

namespace tb {

std::string KDBuildParams::key() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "kd:ct=%g:ci=%g:eb=%g:depth=%d:minleaf=%d:maxleaf=%d:pb=%d", cost_traversal,
                cost_intersect, empty_bonus, max_depth, min_leaf, max_leaf, int(planar_both));
  return buf;
}

int KDTree::auto_depth(uint32_t n) {
  return std::min(kMaxDepth, int(8 + 1.3 * std::log2(std::max(1u, n))));
}

uint64_t KDTree::reference_cap(uint32_t n) { return uint64_t(std::max(1u, n)) * uint64_t(auto_depth(n)); }

std::string KDStats::describe() const {
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "nodes=%u leaves=%u empty_leaves=%u refs=%llu refs_per_tri=%.2f max_leaf=%u max_depth=%u/%u "
                "clipped=%u rebuilds=%u dup_cost=%g sah=%.2f build_ms=%.1f bytes=%zu",
                nodes, leaves, empty_leaves, (unsigned long long)references, refs_per_triangle, max_leaf_size,
                max_depth, depth_limit, clipped, rebuilds, dup_cost, sah_cost, build_ms, bytes);
  return buf;
}

// ---------------------------------------------------------------------------------------------
// Event-sorting builder (Wald & Havran 2006, §4.2-4.4).
// ---------------------------------------------------------------------------------------------
namespace {

// An event is one 64-bit key, so sorting and merging are plain integer operations and ties are
// broken deterministically: axis (2 bits) | position (32 bits, order-preserving) | type (2 bits)
// | triangle (28 bits). Types order end < planar < start at one position, as the sweep needs.
using Event = uint64_t;
enum : uint32_t { kEnd = 0, kPlanar = 1, kStart = 2 };
constexpr uint32_t kMaxTriangles = 1u << 28;

inline uint32_t ordered_bits(float f) {
  f += 0.f;  // -0 -> +0: one position, one group in the sweep
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}
inline float from_ordered(uint32_t u) {
  u = (u & 0x80000000u) ? (u & 0x7fffffffu) : ~u;
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}
inline Event make_event(int axis, float pos, uint32_t type, uint32_t tri) {
  return (uint64_t(axis) << 62) | (uint64_t(ordered_bits(pos)) << 30) | (uint64_t(type) << 28) | tri;
}
inline int ev_axis(Event e) { return int(e >> 62); }
inline uint32_t ev_posbits(Event e) { return uint32_t(e >> 30); }
inline float ev_pos(Event e) { return from_ordered(ev_posbits(e)); }
inline uint32_t ev_type(Event e) { return uint32_t(e >> 28) & 3u; }
inline uint32_t ev_tri(Event e) { return uint32_t(e) & (kMaxTriangles - 1); }

inline void push_events(std::vector<Event>& out, const AABB& b, uint32_t tri) {
  for (int k = 0; k < 3; ++k) {
    if (b.lo[k] == b.hi[k]) {
      out.push_back(make_event(k, b.lo[k], kPlanar, tri));
    } else {
      out.push_back(make_event(k, b.lo[k], kStart, tri));
      out.push_back(make_event(k, b.hi[k], kEnd, tri));
    }
  }
}

// Surface area of a box with extents e (flat boxes keep the area of their faces).
inline float half_area(Vec3 e) { return e.x * e.y + e.y * e.z + e.z * e.x; }

enum Side : uint8_t { kBoth = 0, kLeftOnly = 1, kRightOnly = 2 };

struct Split {
  int axis = -1;
  float pos = 0;
  float cost = INFINITY;
  uint32_t n_left = 0, n_right = 0;  // including the triangles in the plane that go there
  int planar_side = 0;                // 0: both, 1: left, 2: right
};

class Builder {
 public:
  Builder(const Scene& s, const KDBuildParams& p, KDTree& t) : scene_(s), p_(p), tree_(t), side_(s.num_triangles()) {}

  void run() {
    const uint32_t n = uint32_t(scene_.num_triangles());
    if (n >= kMaxTriangles) throw InputError("kD-tree: too many triangles (limit 2^28)");
    tree_.bounds = n ? scene_.bounds() : AABB{{0, 0, 0}, {0, 0, 0}};
    root_area_ = half_area(tree_.bounds.extent());
    depth_limit_ = p_.max_depth > 0 ? std::min(p_.max_depth, KDTree::kMaxDepth) : KDTree::auto_depth(n);
    tree_.stats.depth_limit = uint32_t(depth_limit_);
    ref_cap_ = KDTree::reference_cap(n);
    // The SAH alone does not bound duplication: on a plane of overlapping triangles it pays to cut
    // along every edge of their arrangement, with nearly all references on both sides, and
    // max_leaf forces such splits on down to the depth limit. So the reference count is capped
    // (KDTree::reference_cap). A build that would exceed the cap is abandoned and redone with a
    // price per duplicated reference, the Lagrange multiplier of "least SAH cost with at most cap
    // references": a split must lower the tree's SAH cost (area-weighted) by more than
    // dup_cost_ times the references it adds. Plain SAH first (ordinary scenes stay far below
    // the cap and build exactly once), then a price rising 4x per try, finally no duplication at
    // all, which always fits. Each try stops once the cap is exceeded, so it visits at most
    // depth_limit levels of at most cap references each: time and memory stay bounded.
    const float unit = p_.cost_intersect / float(KDTree::auto_depth(n));  // SAH gain per reference at the cap
    for (int attempt = 0;; ++attempt) {
      dup_cost_ = attempt == 0 ? 0.f : attempt > kPricedTries ? INFINITY : unit * std::ldexp(1.f, 2 * attempt - 12);
      tree_.nodes.clear();
      tree_.prim_index.clear();
      tree_.stats.max_depth = tree_.stats.clipped = 0;
      std::vector<Event> events;
      events.reserve(size_t(6) * n);
      for (uint32_t i = 0; i < n; ++i) push_events(events, scene_.triangle_bounds(i), i);
      std::sort(events.begin(), events.end());
      if (attempt == 0) tree_.nodes.reserve(size_t(4) * n + 1);
      tree_.nodes.push_back(KDNode::leaf(0, 0));
      frontier_ = n;
      over_ = false;
      recurse(0, tree_.bounds, events, n, 0);
      if (!over_) break;
      ++tree_.stats.rebuilds;
    }
    tree_.stats.dup_cost = dup_cost_;
  }

 private:
  // The SAH sweep over the sorted events of all three axes (Wald & Havran Alg. 3). Triangles in
  // the plane (N_P) go to whichever side is cheaper, or to both with planar_both. Per plane:
  // N_L = triangles starting before it, N_R = triangles ending after it.
  Split find_split(const AABB& cell, const std::vector<Event>& ev, uint32_t n) const {
    Split best;
    const Vec3 ext = cell.extent();
    const float inv_area = 1.f / half_area(ext);
    size_t i = 0;
    while (i < ev.size()) {
      const int k = ev_axis(ev[i]);
      const int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
      const float cross = ext[k1] * ext[k2], perim = ext[k1] + ext[k2];
      uint32_t nl = 0, nr = n;
      const bool splittable = ext[k] > 0.f;
      while (i < ev.size() && ev_axis(ev[i]) == k) {
        const uint32_t pb = ev_posbits(ev[i]);
        uint32_t pe = 0, pp = 0, ps = 0;
        const size_t j0 = i;
        while (i < ev.size() && ev_posbits(ev[i]) == pb && ev_axis(ev[i]) == k) {
          const uint32_t t = ev_type(ev[i]);
          pe += t == kEnd;
          pp += t == kPlanar;
          ps += t == kStart;
          ++i;
        }
        const float p = ev_pos(ev[j0]);
        nr -= pp + pe;
        const bool inside = p > cell.lo[k] && p < cell.hi[k];
        // A plane on the cell's own face is only a candidate with triangles lying in it: it
        // peels them off into a flat (zero-width) cell (Wald & Havran §4.1), so the big
        // axis-aligned faces of walls and floors are not tested in every cell along them.
        const bool face = !p_.planar_both && pp > 0 && (p == cell.lo[k] || p == cell.hi[k]);
        if (splittable && (inside || face)) {
          const float pl = (cross + (p - cell.lo[k]) * perim) * inv_area;
          const float pr = (cross + (cell.hi[k] - p) * perim) * inv_area;
          auto eval = [&](uint32_t L, uint32_t R, int side) {
            float c = p_.cost_traversal + p_.cost_intersect * (pl * float(L) + pr * float(R));
            if (L == 0 || R == 0) c *= 1.f - p_.empty_bonus;
            if (c < best.cost) best = {k, p, c, L, R, side};
          };
          if (p_.planar_both) eval(nl + pp, nr + pp, 0);
          else if (p == cell.lo[k]) eval(pp, nr, 1);  // the flat cell takes the planar ones
          else if (p == cell.hi[k]) eval(nl, pp, 2);
          else {
            eval(nl + pp, nr, 1);
            eval(nl, nr + pp, 2);
          }
        }
        nl += ps + pp;
      }
    }
    return best;
  }

  void make_leaf(uint32_t node, const std::vector<Event>& ev) {
    const uint32_t first = uint32_t(tree_.prim_index.size());
    // Each triangle of the node has exactly one start or planar event on every axis; take axis 0.
    for (Event e : ev) {
      if (ev_axis(e) != 0) break;
      if (ev_type(e) != kEnd) tree_.prim_index.push_back(ev_tri(e));
    }
    const uint32_t count = uint32_t(tree_.prim_index.size()) - first;
    tree_.nodes[node] = KDNode::leaf(first, count);
  }

  void recurse(uint32_t node, const AABB& cell, std::vector<Event>& ev, uint32_t n, int depth) {
    tree_.stats.max_depth = std::max(tree_.stats.max_depth, uint32_t(depth));
    Split s;
    if (n > uint32_t(std::max(0, p_.min_leaf)) && depth < depth_limit_ && half_area(cell.extent()) > 0.f)
      s = find_split(cell, ev, n);
    const float leaf_cost = p_.cost_intersect * float(n);
    const bool forced = n > uint32_t(std::max(1, p_.max_leaf));
    // A split must separate something: both children as full as the parent is pure overhead.
    const bool progress = s.axis >= 0 && (s.n_left < n || s.n_right < n);
    // The price of duplication (run()); n_left + n_right bound the children's counts from above.
    const uint32_t dup = s.n_left + s.n_right - std::min(n, s.n_left + s.n_right);
    const bool worth = dup_cost_ == 0.f || dup == 0 ||
                       half_area(cell.extent()) / root_area_ * (leaf_cost - s.cost) > dup_cost_ * float(dup);
    if (!progress || (s.cost >= leaf_cost && !forced) || !worth) {
      make_leaf(node, ev);
      return;
    }
    const int k = s.axis;
    const float p = s.pos;

    // Classification (Wald & Havran Alg. 4): every triangle starts as "both"; its events on the
    // split axis then say whether it lies entirely on one side. A triangle ending exactly at p is
    // left only, one starting at p right only (they touch the other cell in an edge or vertex
    // at most); one lying in the plane stays "both" and is referenced on either side.
    for (Event e : ev)
      if (ev_axis(e) == k && ev_type(e) != kEnd) side_[ev_tri(e)] = kBoth;
    for (Event e : ev) {
      if (ev_axis(e) != k) continue;
      const uint32_t t = ev_type(e);
      const float q = ev_pos(e);
      if (t == kEnd && q <= p) side_[ev_tri(e)] = kLeftOnly;
      else if (t == kStart && q >= p) side_[ev_tri(e)] = kRightOnly;
      else if (t == kPlanar)
        side_[ev_tri(e)] = q < p ? kLeftOnly : (q > p ? kRightOnly : (s.planar_side == 1 ? kLeftOnly : s.planar_side == 2 ? kRightOnly : kBoth));
    }
    std::vector<Event> el, er, bl, br;
    std::vector<uint32_t> both;
    el.reserve(ev.size() / 2 + 16);
    er.reserve(ev.size() / 2 + 16);
    uint32_t nl = 0, nr = 0;
    for (Event e : ev) {
      const uint32_t t = ev_tri(e);
      switch (side_[t]) {
        case kLeftOnly: el.push_back(e); break;
        case kRightOnly: er.push_back(e); break;
        default:
          if (ev_axis(e) == k && ev_type(e) != kEnd) both.push_back(t);
      }
      if (ev_axis(e) == k && ev_type(e) != kEnd) {
        nl += side_[t] == kLeftOnly;
        nr += side_[t] == kRightOnly;
      }
    }
    // Perfect splits: clip each straddling triangle to each child cell and generate new events
    // from the clipped bounds; a triangle whose clipped polygon is empty leaves that child.
    AABB cl = cell, cr = cell;
    cl.hi[k] = p;
    cr.lo[k] = p;
    for (uint32_t t : both) {
      const Vec3 a = scene_.vertex(t, 0), b = scene_.vertex(t, 1), c = scene_.vertex(t, 2);
      const AABB bl_box = clip_triangle_bounds(a, b, c, cl);
      const AABB br_box = clip_triangle_bounds(a, b, c, cr);
      if (!bl_box.empty()) push_events(bl, bl_box, t), ++nl;
      if (!br_box.empty()) push_events(br, br_box, t), ++nr;
    }
    tree_.stats.clipped += uint32_t(both.size());
    std::sort(bl.begin(), bl.end());
    std::sort(br.begin(), br.end());
    std::vector<Event>().swap(ev);  // the parent's events are no longer needed
    std::vector<Event> left, right;
    left.resize(el.size() + bl.size());
    std::merge(el.begin(), el.end(), bl.begin(), bl.end(), left.begin());
    std::vector<Event>().swap(el);
    std::vector<Event>().swap(bl);
    right.resize(er.size() + br.size());
    std::merge(er.begin(), er.end(), br.begin(), br.end(), right.begin());
    std::vector<Event>().swap(er);
    std::vector<Event>().swap(br);

    const uint32_t child = uint32_t(tree_.nodes.size());
    if (child >= (1u << 30) - 2) throw InputError("kD-tree: node index overflow");
    tree_.nodes.push_back(KDNode::leaf(0, 0));
    tree_.nodes.push_back(KDNode::leaf(0, 0));
    tree_.nodes[node] = KDNode::interior(k, p, child);
    // The leaves' references once every waiting node is a leaf: what this tree holds at least.
    frontier_ += int64_t(nl) + nr - n;
    if (frontier_ > int64_t(ref_cap_)) {
      over_ = true;
      return;
    }
    recurse(child, cl, left, nl, depth + 1);
    if (!over_) recurse(child + 1, cr, right, nr, depth + 1);
  }

  static constexpr int kPricedTries = 10;  // dup_cost_ from unit / 1024 to unit * 256

  const Scene& scene_;
  const KDBuildParams& p_;
  KDTree& tree_;
  std::vector<uint8_t> side_;
  int depth_limit_ = 0;
  float root_area_ = 0;
  uint64_t ref_cap_ = 0;
  int64_t frontier_ = 0;
  bool over_ = false;
  float dup_cost_ = 0;
};

}  // namespace

KDTree KDTree::build(const Scene& scene, const KDBuildParams& params) {
  const auto t0 = std::chrono::steady_clock::now();
  KDTree tree;
  Builder(scene, params, tree).run();
  tree.nodes.shrink_to_fit();
  tree.prim_index.shrink_to_fit();
  KDStats& st = tree.stats;
  st.nodes = uint32_t(tree.nodes.size());
  st.triangles = uint32_t(scene.num_triangles());
  for (const KDNode& n : tree.nodes) {
    if (!n.is_leaf()) continue;
    st.leaves++;
    st.empty_leaves += n.count() == 0;
    st.max_leaf_size = std::max(st.max_leaf_size, n.count());
  }
  st.references = tree.prim_index.size();
  st.refs_per_triangle = st.triangles ? double(st.references) / st.triangles : 0.0;
  st.bytes = tree.nodes.size() * sizeof(KDNode) + tree.prim_index.size() * sizeof(uint32_t);
  st.sah_cost = tree.compute_sah_cost(params);
  move_to_huge_pages(tree.nodes);
  st.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return tree;
}

double KDTree::compute_sah_cost(const KDBuildParams& p) const {
  const float root = half_area(bounds.extent());
  if (!(root > 0.f)) return 0.0;
  double cost = 0;
  for_each_node([&](uint32_t i, const AABB& cell, uint32_t) {
    const double a = double(half_area(cell.extent())) / root;
    const KDNode& n = nodes[i];
    cost += a * (n.is_leaf() ? p.cost_intersect * n.count() : p.cost_traversal);
  });
  return cost;
}

}  // namespace tb
