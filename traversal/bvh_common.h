// What every scheme over the binary BVH shares: the cached BVH and its triangles in leaf order
// (traversal/tree_scheme.h), and the BVH's declared build parameters.
#pragma once
#include "structures/bvh.h"
#include "traversal/tree_scheme.h"

namespace tb {

// The binary BVH's parameters, `bins`, `leaf_size` and the spatial-split ones, as a scheme
// declares them (its params_<name>() returns these plus its own), and the build parameters read
// from a config resolved against them.
// `default_spatial`: the scheme's default for `spatial` (the 8-wide MBVH schemes build spatial
// splits by default, docs/PERFORMANCE.md "Spatial splits by default"; the thesis' schemes do not).
ParamSpecs bvh_param_specs(int default_leaf = 4, bool default_spatial = false);
BVHBuildParams bvh_params(const SchemeConfig& cfg);
// The same for a scheme that declares `spatial` with auto_default (its default depends on another
// parameter, as mbvh_rs's on its width): `spatial` is the value when the user gave none.
BVHBuildParams bvh_params(const SchemeConfig& cfg, bool spatial);
// The spatial-split part of them (`spatial`, `split_*`) on their own, for a scheme whose binary
// builds take other parameters (RayGrid's mini-BVHs), and their reader, which refuses split_*
// without spatial=1. `extent`: what split_wall's fraction is of, in its description (the scene's
// extent for a whole-scene build).
ParamSpecs spatial_param_specs(bool default_spatial, const std::string& extent);
// `spatial`: the value of an auto_default `spatial` the user did not give.
void read_spatial_params(const SchemeConfig& cfg, BVHBuildParams& p, bool spatial = false);

using BVHData = TreeData<BVH>;
inline BVHData fetch_bvh(const Scene& scene, StructureCache& cache, const BVHBuildParams& params, TriKernel kernel) {
  return fetch_tree<BVH>(scene, cache, params, kernel);
}
// The base of the schemes over the binary BVH (bvh_single/masked/ranged/partition).
template <class Derived>
using BVHScheme = TreeScheme<Derived, BVH, BVHBuildParams, bvh_params>;

// One ray's closest-hit loop over a binary BVH (thesis Alg. 2.4): near child first, far children
// stacked with their entry distances, popped entries at or beyond the closest hit skipped.
// `leaf(n)` tests leaf n's primitives against `hit`; `stack` holds max_depth + 2 entries.
// bvh_single and both levels of the two-level BVH (traversal/two_level.cpp) run it.
struct BVHStackEntry {
  uint32_t node;
  float dist;
};
// box_entry (kernels.h) on a BVHNode, with each axis' near and far plane picked by address rather
// than by a branch: hi sits 4 floats after lo, so the plane of axis a is p[a + 4 * near_a].
// The same operations in the same order as box_entry, so the same distances.
[[gnu::always_inline]] inline float node_entry(const RayCtx& r, const BVHNode& n, float tmin, float tfar) {
  static_assert(offsetof(BVHNode, hi) == offsetof(BVHNode, lo) + 4 * sizeof(float));
  const float* p = &n.lo.x;
  const uint32_t nx = uint32_t(r.near_x) * 4, ny = uint32_t(r.near_y) * 4 + 1, nz = uint32_t(r.near_z) * 4 + 2;
  const float xn[3] = {p[nx] - r.org.x, p[ny] - r.org.y, p[nz] - r.org.z};
  const float xf[3] = {p[nx ^ 4] - r.org.x, p[ny ^ 4] - r.org.y, p[nz ^ 4] - r.org.z};
  const float rn[3] = {r.inv.x, r.inv.y, r.inv.z};
  float tn;
  return slab<1, false>(xn, xf, rn, rn, tmin, tfar, tn) ? tn : INFINITY;
}

template <class P, class Leaf>
[[gnu::always_inline]] inline void bvh_closest_hit(const BVHNode* nodes, const RayCtx& rc, float tmin, Hit& hit,
                                                   BVHStackEntry* stack, P& probe, Leaf&& leaf) {
  if (node_entry(rc, nodes[0], tmin, hit.t) == INFINITY) return;
  uint32_t sp = 0, node = 0;
  while (node != UINT32_MAX) {
    const BVHNode& n = nodes[node];
    if (n.is_leaf()) {
      probe.leaf(&n, sizeof(BVHNode));
      leaf(n);
    } else {
      probe.node(&n, sizeof(BVHNode));
      const BVHNode* c = &nodes[n.left_first];
      float d0 = node_entry(rc, c[0], tmin, hit.t);
      float d1 = node_entry(rc, c[1], tmin, hit.t);
      uint32_t near = n.left_first, far = n.left_first + 1;
      if (d1 < d0) { std::swap(d0, d1); std::swap(near, far); }
      if (d0 != INFINITY) {
        if (d1 != INFINITY) {
          stack[sp++] = {far, d1};
          probe.write(&stack[sp - 1], sizeof(BVHStackEntry));
        }
        node = near;
        continue;
      }
    }
    // Pop the nearest pending node that may still hold a closer hit.
    node = UINT32_MAX;
    while (sp > 0) {
      const BVHStackEntry e = stack[--sp];
      probe.read(&stack[sp], sizeof(BVHStackEntry));
      if (e.dist < hit.t) { node = e.node; break; }
    }
  }
}

}  // namespace tb
