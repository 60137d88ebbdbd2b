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

// What the schemes over the binary BVH have in common besides their loop: the config, the build
// parameters, the cached structure and its accounting, and the dispatch of --kernel to a template
// argument. Derived provides `template <TriKernel K, class P> void run_kernel(batch, range, hits,
// probe) const` (public) and name().
template <class Derived>
class BVHScheme : public TraverserBase<Derived> {
 public:
  explicit BVHScheme(const SchemeConfig& cfg) : cfg_(cfg), params_(bvh_params(cfg)) {}
  void prepare(const Scene& scene, StructureCache& cache) override {
    data_ = fetch_bvh(scene, cache, params_, cfg_.kernel);
  }
  std::string structure_info() const override { return data_.bvh->stats.describe(); }
  size_t structure_bytes() const override { return data_.bytes(cfg_.kernel); }
  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      static_cast<const Derived&>(*this).template run_kernel<decltype(k)::value>(batch, range, hits, probe);
    });
  }

 protected:
  SchemeConfig cfg_;
  BVHBuildParams params_;
  BVHData data_;
};

// Seeds a hit record: the search interval is [ray.tmin, ray.tmax).
inline Hit initial_hit(const Ray& r) { return Hit{r.tmax, kNoHit, 0.f, 0.f}; }
// Turns a search record into the reported hit: misses carry t = +inf.
inline Hit finish_hit(Hit h) {
  if (h.prim == kNoHit) h.t = INFINITY;
  return h;
}

}  // namespace tb
