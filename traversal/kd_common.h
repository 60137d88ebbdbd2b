// What kd_single and kd_packet share: the kD-tree's declared build parameters, read from a
// resolved SchemeConfig, and the cached tree with its triangles (one fetch, so both schemes share
// one tree and one triangle set).
#pragma once
#include <memory>

#include "structures/kdtree.h"
#include "traversal/traverser.h"

namespace tb {

struct KDData {
  std::shared_ptr<const KDTree> tree;
  std::shared_ptr<const TriangleSet> tris;  // one entry per leaf reference, in leaf order
  // Nodes and references plus the triangle set in the kernel's layout.
  size_t bytes() const {
    return tree->stats.bytes + tris->verts.size() * sizeof(TriVerts) + tris->planes.size() * sizeof(PlaneTri) +
           tris->prim_id.size() * sizeof(uint32_t);
  }
};

// kd_ct, kd_ci (SAH costs), kd_empty_bonus, kd_max_depth (0: automatic), kd_min_leaf,
// kd_max_leaf, kd_planar_both; defaults from KDBuildParams.
ParamSpecs kd_param_specs();
KDBuildParams kd_params(const SchemeConfig& cfg);
// The tree and its triangles in reference order (a triangle referenced by k leaves is stored k
// times, so a leaf reads one contiguous run; the same layout the BVH schemes use).
KDData fetch_kd(const Scene& scene, StructureCache& cache, const KDBuildParams& params, TriKernel kernel);

// kd_single's and kd_packet's common part, as BVHScheme is the BVH schemes': Derived provides
// `template <TriKernel K, class P> void run_kernel(batch, range, hits, probe) const`.
template <class Derived>
class KDScheme : public TraverserBase<Derived> {
 public:
  explicit KDScheme(const SchemeConfig& cfg) : cfg_(cfg), params_(kd_params(cfg)) {}
  void prepare(const Scene& scene, StructureCache& cache) override { data_ = fetch_kd(scene, cache, params_, cfg_.kernel); }
  std::string structure_info() const override { return data_.tree->stats.describe(); }
  size_t structure_bytes() const override { return data_.bytes(); }
  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      static_cast<const Derived&>(*this).template run_kernel<decltype(k)::value>(batch, range, hits, probe);
    });
  }

 protected:
  SchemeConfig cfg_;
  KDBuildParams params_;
  KDData data_;
};

}  // namespace tb
