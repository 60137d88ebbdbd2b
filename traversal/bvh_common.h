// What every scheme over the binary BVH shares: the cached BVH and its triangles in leaf order.
#pragma once
#include <memory>

#include "structures/bvh.h"
#include "traversal/traverser.h"

namespace tb {

struct BVHData {
  std::shared_ptr<const BVH> bvh;
  std::shared_ptr<const TriangleSet> tris;
  // Bytes of the nodes plus the leaf-ordered triangles in kernel k's layout (what a traversal
  // reads; as mbvh_bytes counts the MBVH schemes).
  size_t bytes(TriKernel k) const {
    return bvh->stats.bytes + tris->size() * (TriangleSet::bytes(k) + sizeof(uint32_t));
  }
};

// The binary BVH's parameters, `bins` and `leaf_size`, as a scheme declares them (its
// params_<name>() returns these plus its own), and the build parameters read from a config
// resolved against them.
ParamSpecs bvh_param_specs(int default_leaf = 4);
BVHBuildParams bvh_params(const SchemeConfig& cfg);
// The triangle set kernel `kernel` reads for the structure cached under `structure_key`, its
// triangles in the order `order()` returns (called only when it is built): planes precomputed for
// the plane kernels, so the two layouts are cached apart.
template <class Order>
std::shared_ptr<const TriangleSet> fetch_triangles(const Scene& scene, StructureCache& cache,
                                                   const std::string& structure_key, TriKernel kernel, Order&& order) {
  const bool planes = kernel == TriKernel::plane || kernel == TriKernel::plane_rcp;
  return cache.get<TriangleSet>(structure_key + (planes ? ":tris+planes" : ":tris"), [&] {
    TriangleSet t;
    t.build(scene, order(), kernel);
    return t;
  });
}
// Fetches (building on first use) the BVH and the triangle set the kernel `cfg.kernel` needs.
BVHData fetch_bvh(const Scene& scene, StructureCache& cache, const BVHBuildParams& params, TriKernel kernel);

// Seeds a hit record: the search interval is [ray.tmin, ray.tmax).
inline Hit initial_hit(const Ray& r) { return Hit{r.tmax, kNoHit, 0.f, 0.f}; }
// Turns a search record into the reported hit: misses carry t = +inf.
inline Hit finish_hit(Hit h) {
  if (h.prim == kNoHit) h.t = INFINITY;
  return h;
}

}  // namespace tb
