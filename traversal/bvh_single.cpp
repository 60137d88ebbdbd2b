// bvh_single: one ray at a time through the binary BVH, near child first with a stack of far
// children and their entry distances (thesis Alg. 2.4); stacked nodes beyond the closest hit
// found so far are skipped when popped.
#include "traversal/bvh_common.h"

namespace tb {
namespace {

class BVHSingle final : public BVHScheme<BVHSingle> {
 public:
  using TreeScheme::TreeScheme;
  std::string_view name() const override { return "bvh_single"; }

  template <TriKernel K, class P>
  void run_kernel(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const BVH& bvh = *data_.tree;
    const TriangleSet& tris = *data_.tris;
    std::vector<BVHStackEntry> stack(bvh.stats.max_depth + 2);
    const RayCtx::ShearAxes axes = RayCtx::axes_for(batch.common_origin);
    for_each_ray(batch, range, hits, probe, [&](const Ray& ray, Hit& hit) {
      const RayCtx rc(ray, axes);
      bvh_closest_hit(bvh.nodes.data(), rc, ray.tmin, hit, stack.data(), probe, [&](const BVHNode& n) {
        for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) {
          probe.tris(tris.data_at(k, K), TriangleSet::bytes(K));
          intersect_tri<K>(rc, tris, k, ray.tmin, hit);
        }
      });
    });
  }
};

}  // namespace

std::unique_ptr<Traverser> make_bvh_single(const SchemeConfig& cfg) { return std::make_unique<BVHSingle>(cfg); }
ParamSpecs params_bvh_single() { return bvh_param_specs(); }

}  // namespace tb
