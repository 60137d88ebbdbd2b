#include "traversal/bvh_common.h"

namespace tb {

BVHBuildParams bvh_params(const SchemeConfig& cfg, int default_leaf) {
  BVHBuildParams p;
  p.bins = cfg.get_int("bins", p.bins);
  p.max_leaf = cfg.get_int("leaf_size", default_leaf);
  if (p.bins < 2 || p.bins > 256) throw InputError("parameter bins must be in [2, 256]");
  if (p.max_leaf < 1 || p.max_leaf > 64) throw InputError("parameter leaf_size must be in [1, 64]");
  return p;
}

BVHData fetch_bvh(const Scene& scene, StructureCache& cache, const BVHBuildParams& params, TriKernel kernel) {
  BVHData d;
  d.bvh = cache.get<BVH>(params.key(), [&] { return BVH::build(scene, params); });
  const bool planes = kernel == TriKernel::plane || kernel == TriKernel::plane_rcp;
  d.tris = cache.get<TriangleSet>(params.key() + (planes ? ":tris+planes" : ":tris"), [&] {
    TriangleSet t;
    t.build(scene, d.bvh->prim_index, kernel);
    return t;
  });
  return d;
}

}  // namespace tb
