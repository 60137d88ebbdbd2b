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
    const BVHNode* nodes = bvh.nodes.data();
    std::vector<Entry> stack(bvh.stats.max_depth + 2);
    for_each_ray(batch, range, hits, probe, [&](const Ray& ray, Hit& hit) {
      const RayCtx rc(ray);
      uint32_t sp = 0;
      uint32_t node = 0;
      if (box_entry(rc, nodes[0].lo, nodes[0].hi, ray.tmin, hit.t) == INFINITY) node = UINT32_MAX;
      while (node != UINT32_MAX) {
        const BVHNode& n = nodes[node];
        if (n.is_leaf()) {
          probe.leaf(&n, sizeof(BVHNode));
          for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) {
            probe.tris(tris.data_at(k, K), TriangleSet::bytes(K));
            intersect_tri<K>(rc, tris, k, ray.tmin, hit);
          }
        } else {
          probe.node(&n, sizeof(BVHNode));
          const BVHNode* c = &nodes[n.left_first];
          float d0 = box_entry(rc, c[0].lo, c[0].hi, ray.tmin, hit.t);
          float d1 = box_entry(rc, c[1].lo, c[1].hi, ray.tmin, hit.t);
          uint32_t near = n.left_first, far = n.left_first + 1;
          if (d1 < d0) { std::swap(d0, d1); std::swap(near, far); }
          if (d0 != INFINITY) {
            if (d1 != INFINITY) {
              stack[sp++] = {far, d1};
              probe.write(&stack[sp - 1], sizeof(Entry));
            }
            node = near;
            continue;
          }
        }
        // Pop the nearest pending node that may still hold a closer hit.
        node = UINT32_MAX;
        while (sp > 0) {
          const Entry e = stack[--sp];
          probe.read(&stack[sp], sizeof(Entry));
          if (e.dist < hit.t) { node = e.node; break; }
        }
      }
    });
  }

 private:
  struct Entry {
    uint32_t node;
    float dist;
  };
};

}  // namespace

std::unique_ptr<Traverser> make_bvh_single(const SchemeConfig& cfg) { return std::make_unique<BVHSingle>(cfg); }
ParamSpecs params_bvh_single() { return bvh_param_specs(); }

}  // namespace tb
