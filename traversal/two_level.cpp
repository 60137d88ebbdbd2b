#include "traversal/two_level.h"

#include <algorithm>
#include <vector>

#include "traversal/bvh_common.h"
#include "traversal/kernels.h"
#include "traversal/probe.h"

namespace tb {

Hit trace_two_level(const TwoLevelBVH& tl, const Ray& ray) {
  Hit hit;
  hit.t = ray.tmax;
  if (tl.top().nodes.empty()) return Hit{};
  const RayCtx world(ray);
  NullProbe none;
  std::vector<BVHStackEntry> top_stack(tl.top().stats.max_depth + 2), obj_stack;
  bvh_closest_hit(tl.top().nodes.data(), world, ray.tmin, hit, top_stack.data(), none, [&](const BVHNode& tn) {
    for (uint32_t k = tn.left_first; k < tn.left_first + tn.count; ++k) {
      const uint32_t id = tl.top().prim_index[k];
      const Instance& in = tl.instances()[id];
      const Scene& mesh = tl.objects()[in.object];
      const BVH& bvh = tl.object_bvhs()[in.object];
      if (bvh.nodes.empty()) continue;
      const uint32_t offset = tl.prim_offset(id);
      Ray r = ray;
      r.org = in.to_object.point(ray.org);
      r.dir = in.to_object.vector(ray.dir);
      const RayCtx obj(r);
      obj_stack.resize(std::max(obj_stack.size(), size_t(bvh.stats.max_depth) + 2));
      bvh_closest_hit(bvh.nodes.data(), obj, ray.tmin, hit, obj_stack.data(), none, [&](const BVHNode& on) {
        for (uint32_t j = on.left_first; j < on.left_first + on.count; ++j) {
          const uint32_t tri = bvh.prim_index[j];
          if (intersect_watertight(obj, TriVerts{mesh.vertex(tri, 0), mesh.vertex(tri, 1), mesh.vertex(tri, 2)},
                                   ray.tmin, hit))
            hit.prim = offset + tri;
        }
      });
    }
  });
  if (!hit.hit()) hit = Hit{};
  return hit;
}

void trace_two_level(const TwoLevelBVH& tl, const RayBatch& batch, std::span<Hit> hits) {
  for (size_t i = 0; i < batch.size(); ++i) hits[i] = trace_two_level(tl, batch.rays[i]);
}

}  // namespace tb
