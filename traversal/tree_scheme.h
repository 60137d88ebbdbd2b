// What every scheme over a cached tree with leaf-ordered triangles shares (the binary BVH schemes,
// traversal/bvh_common.h; the kD-tree schemes, traversal/kd_common.h): the fetch of the tree and
// its triangle set, their accounting, and the dispatch of --kernel to a template argument. A
// new tree type joins by providing `static Tree build(const Scene&, const Params&)`, `prim_index`
// (scene triangle of each stored reference, in leaf order) and `stats.bytes` / `stats.describe()`.
#pragma once
#include <memory>
#include <string>

#include "traversal/traverser.h"

namespace tb {

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

template <class Tree>
struct TreeData {
  std::shared_ptr<const Tree> tree;
  std::shared_ptr<const TriangleSet> tris;  // one entry per leaf reference, in leaf order
  // Bytes of the nodes plus the leaf-ordered triangles in kernel k's layout (what a traversal
  // reads; as MBVHChoice::bytes counts the MBVH schemes).
  StructureBytes bytes(TriKernel k) const {
    return {tree->stats.bytes, tris->size() * (TriangleSet::bytes(k) + sizeof(uint32_t))};
  }
};

// Fetches (building on first use) the tree and the triangle set the kernel `kernel` needs.
template <class Tree, class Params>
TreeData<Tree> fetch_tree(const Scene& scene, StructureCache& cache, const Params& params, TriKernel kernel) {
  TreeData<Tree> d;
  d.tree = cache.get<Tree>(params.key(), [&] { return Tree::build(scene, params); });
  d.tris = fetch_triangles(scene, cache, params.key(), kernel, [&] { return d.tree->prim_index; });
  return d;
}

// The scheme base: `read` turns the resolved config into the tree's build parameters. Derived
// provides name() and `template <TriKernel K, class P> void run_kernel(batch, range, hits, probe)
// const` (public).
template <class Derived, class Tree, class Params, Params (*read)(const SchemeConfig&)>
class TreeScheme : public TraverserBase<Derived> {
 public:
  explicit TreeScheme(const SchemeConfig& cfg) : cfg_(cfg), params_(read(cfg)) {}
  void prepare(const Scene& scene, StructureCache& cache) override {
    data_ = fetch_tree<Tree>(scene, cache, params_, cfg_.kernel);
  }
  std::string structure_info() const override { return data_.tree->stats.describe(); }
  StructureBytes memory() const override { return data_.bytes(cfg_.kernel); }
  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      static_cast<const Derived&>(*this).template run_kernel<decltype(k)::value>(batch, range, hits, probe);
    });
  }

 protected:
  SchemeConfig cfg_;
  Params params_;
  TreeData<Tree> data_;
};

}  // namespace tb
