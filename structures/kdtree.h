// SAH kD-tree (thesis §2.2.1: axis-aligned BSP, SAH of Goldsmith/Salmon and MacDonald/Booth,
// empty-space bonus of Hurley et al.), built in O(N log N) with the event-sorting method of
// Wald & Havran 2006 ("On building fast kd-trees for ray tracing, and on doing that in
// O(N log N)"), with perfect splits: a triangle that straddles a split plane is clipped to each
// child cell (structures/clip.h) and classified further down by the bounds of the clipped
// polygon, so it is only referenced by cells it really overlaps.
//
// Watertightness contract with the traversal (traversal/kd_single.cpp, kd_packet.cpp): every
// point of every triangle lies in the closed cell of some leaf that references the triangle.
//  * a triangle is referenced by every leaf whose cell interior it overlaps with positive area;
//  * a triangle lying exactly in a split plane (both cells' closed boxes contain it) is
//    referenced on one side only, the side the SAH prefers, and a split on a cell face may peel
//    such triangles into a flat (zero-width) cell (Wald & Havran §4.1);
//  * a triangle that merely touches a cell along an edge or at a vertex is referenced only on
//    its own side;
//  * clipping is done in double and the clipped bounds are rounded outward to float wherever a
//    coordinate is not exact, so rounding can only add references, never drop one.
// That suffices because the traversal widens every cell's t-interval outward (kKdPad below): a
// ray that touches a cell's closed box at the hit point visits that cell, whichever of the
// cells sharing the point holds the reference, before the search can end.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "structures/aligned.h"
#include "structures/scene.h"
#include "structures/vec3.h"

namespace tb {

// 8-byte node (the compact layout of Wald's thesis and of the thesis' Alg. 2.2 implementation):
//  word a: bits 0-1 = axis (0, 1, 2) or 3 for a leaf; bits 2-31 = index of the left child
//          (the right child is at +1: siblings are adjacent) or, for a leaf, the triangle count;
//  word b: the split position (float bits), or for a leaf the offset of its first reference.
struct KDNode {
  uint32_t a = 3;
  uint32_t b = 0;

  bool is_leaf() const { return (a & 3u) == 3u; }
  int axis() const { return int(a & 3u); }
  uint32_t left() const { return a >> 2; }
  uint32_t count() const { return a >> 2; }
  uint32_t first() const { return b; }
  float split() const {
    float f;
    std::memcpy(&f, &b, sizeof f);
    return f;
  }
  static KDNode interior(int axis, float split, uint32_t left) {
    KDNode n;
    n.a = (left << 2) | uint32_t(axis);
    std::memcpy(&n.b, &split, sizeof split);
    return n;
  }
  static KDNode leaf(uint32_t first, uint32_t count) {
    KDNode n;
    n.a = (count << 2) | 3u;
    n.b = first;
    return n;
  }
};
static_assert(sizeof(KDNode) == 8);

struct KDBuildParams {
  // SAH costs. Wald & Havran 2006 use K_T = 15, K_I = 20; only the ratio matters.
  float cost_traversal = 15.f;
  float cost_intersect = 20.f;
  // Hurley et al. 2002: a split that cuts off empty space costs (1 - empty_bonus) times as much.
  float empty_bonus = 0.2f;
  // 0: automatic, KDTree::auto_depth: 8 + 1.3 log2(N) (Havran's / pbrt's rule), capped at kMaxDepth.
  int max_depth = 0;
  // Nodes with at most min_leaf triangles become leaves without evaluating splits.
  int min_leaf = 1;
  // Nodes with more than max_leaf triangles are split with the best SAH plane even when the SAH
  // says a leaf is cheaper (as long as the split separates something and depth and the
  // reference cap allow).
  int max_leaf = 64;
  // Triangles lying in a split plane: referenced only by the side the SAH prefers (false, Wald &
  // Havran 2006; also enables flat cells that peel such triangles off a cell face), or by both
  // children (true: the literal "every cell the triangle touches", kept to measure its cost).
  bool planar_both = false;
  std::string key() const;  // for the structure cache (a scheme's --param keys: traversal/kd_common.h)
};

struct KDStats {
  uint32_t nodes = 0, leaves = 0, empty_leaves = 0, max_depth = 0, depth_limit = 0;
  uint64_t references = 0;      // triangle references over all leaves
  uint32_t triangles = 0;
  uint32_t max_leaf_size = 0;
  uint32_t clipped = 0;         // straddling triangles clipped (perfect splits)
  uint32_t rebuilds = 0;        // builds abandoned at the reference cap (KDTree::reference_cap)
  float dup_cost = 0;           // the price per duplicated reference of the final build (0: plain SAH)
  double refs_per_triangle = 0; // references / triangles
  double sah_cost = 0, build_ms = 0;
  size_t bytes = 0;             // nodes + reference indices
  std::string describe() const;
};

struct KDTree {
  static constexpr int kMaxDepth = 64;

  aligned_vector<KDNode> nodes;     // nodes[0] = root; children of a node are adjacent
  std::vector<uint32_t> prim_index; // leaf reference slot -> scene triangle (duplicates allowed)
  AABB bounds;                      // the root cell (scene bounds)
  KDStats stats;

  static KDTree build(const Scene& scene, const KDBuildParams& params = {});
  // The automatic depth limit, 8 + 1.3 log2 N (Havran's / pbrt's rule), at most kMaxDepth.
  static int auto_depth(uint32_t n);
  // The most references a tree over n triangles holds, whatever the input and parameters:
  // n * auto_depth(n), O(N log N) (ordinary scenes use 2-6 per triangle). It bounds the build's
  // memory and, with the depth limit, its time.
  static uint64_t reference_cap(uint32_t n);
  // SAH cost of the built tree with the given cost parameters (expected cost per ray).
  double compute_sah_cost(const KDBuildParams& params) const;
  // Calls f(node_index, cell, depth) for every node, parents before children.
  template <class F>
  void for_each_node(F&& f) const;
};

// ---- What both kD traversals share (thesis Alg. 2.2/2.3, made robust) ----------------------
// Every split distance d = (split - org) / dir is rounded a few ulps (one rounding each for the
// subtraction, the reciprocal and the product: < 2e-7 relative). Cell intervals are widened by
// kKdPad relative at every split, so the computed interval of a cell always contains the true
// one: a ray that touches a cell's closed box (a hit exactly on a split plane, an origin on a
// plane, a corner) visits it. The price is at most a few extra cell visits per ray, and a hit
// reported up to 2 * kKdPad (relative) farther than a closer one just behind a boundary, far
// inside the 1e-5 accuracy bar.
inline constexpr float kKdPad = 1e-6f;
// x moved away from / towards zero by kKdPad relative; +-inf and NaN stay as they are (no
// inf - inf), so a direction component of +-0 (d = +-inf) still culls the far or near child.
inline float kd_pad_up(float x) { return x * (1.f + std::copysign(kKdPad, x)); }
inline float kd_pad_down(float x) { return x * (1.f - std::copysign(kKdPad, x)); }

// The ray's parameter interval inside the root cell, padded outward; false when it misses.
// A zero direction component (also -0) constrains nothing when the origin lies in the closed
// slab and rejects the ray otherwise (no 0 * inf = NaN).
inline bool kd_clip_ray(const AABB& box, Vec3 org, Vec3 dir, Vec3 inv, float tmin, float tmax, float& tn,
                        float& tf) {
  tn = tmin;
  tf = tmax;
  for (int k = 0; k < 3; ++k) {
    if (dir[k] == 0.f || std::isinf(inv[k])) {
      if (org[k] < box.lo[k] || org[k] > box.hi[k]) return false;
      continue;
    }
    float t0 = (box.lo[k] - org[k]) * inv[k], t1 = (box.hi[k] - org[k]) * inv[k];
    if (t0 > t1) std::swap(t0, t1);
    tn = std::max(tn, kd_pad_down(t0));
    tf = std::min(tf, kd_pad_up(t1));
  }
  return tn <= tf;
}

template <class F>
void KDTree::for_each_node(F&& f) const {
  if (nodes.empty()) return;
  struct Item {
    uint32_t node;
    AABB cell;
    uint32_t depth;
  };
  std::vector<Item> stack{{0, bounds, 0}};
  while (!stack.empty()) {
    Item it = stack.back();
    stack.pop_back();
    f(it.node, it.cell, it.depth);
    const KDNode& n = nodes[it.node];
    if (n.is_leaf()) continue;
    AABB l = it.cell, r = it.cell;
    l.hi[n.axis()] = n.split();
    r.lo[n.axis()] = n.split();
    stack.push_back({n.left() + 1, r, it.depth + 1});
    stack.push_back({n.left(), l, it.depth + 1});
  }
}

}  // namespace tb
