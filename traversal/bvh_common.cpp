#include "traversal/bvh_common.h"

namespace tb {

ParamSpecs bvh_param_specs(int default_leaf) {
  return {int_param("bins", BVHBuildParams{}.bins, 2, 256, "binned-SAH bins per axis of the binary BVH build"),
          int_param("leaf_size", default_leaf, 1, 64, "most triangles in a leaf of the binary BVH")};
}

BVHBuildParams bvh_params(const SchemeConfig& cfg) {
  BVHBuildParams p;
  p.bins = cfg.get_int("bins");
  p.max_leaf = cfg.get_int("leaf_size");
  return p;
}

BVHData fetch_bvh(const Scene& scene, StructureCache& cache, const BVHBuildParams& params, TriKernel kernel) {
  BVHData d;
  d.bvh = cache.get<BVH>(params.key(), [&] { return BVH::build(scene, params); });
  d.tris = fetch_triangles(scene, cache, params.key(), kernel, [&] { return d.bvh->prim_index; });
  return d;
}

}  // namespace tb
