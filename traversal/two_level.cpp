#include "traversal/two_level.h"

#include <vector>

#include "traversal/kernels.h"

namespace tb {
namespace {

// One closest-hit loop for both levels: near child first, far children stacked with their entry
// distances and skipped when popped beyond the closest hit (bvh_single's order, thesis Alg. 2.4).
// leaf(first, count) tests a leaf's prims against `hit`.
template <class Leaf>
void closest_in(const BVH& bvh, const RayCtx& rc, float tmin, Hit& hit, uint64_t& visits, Leaf&& leaf) {
  struct Entry {
    uint32_t node;
    float dist;
  };
  const BVHNode* nodes = bvh.nodes.data();
  if (bvh.nodes.empty() || box_entry(rc, nodes[0].lo, nodes[0].hi, tmin, hit.t) == INFINITY) return;
  std::vector<Entry> stack(bvh.stats.max_depth + 2);
  uint32_t sp = 0, node = 0;
  while (node != UINT32_MAX) {
    const BVHNode& n = nodes[node];
    ++visits;
    if (n.is_leaf()) {
      leaf(n.left_first, n.count);
    } else {
      const BVHNode* c = &nodes[n.left_first];
      float d0 = box_entry(rc, c[0].lo, c[0].hi, tmin, hit.t);
      float d1 = box_entry(rc, c[1].lo, c[1].hi, tmin, hit.t);
      uint32_t near = n.left_first, far = n.left_first + 1;
      if (d1 < d0) { std::swap(d0, d1); std::swap(near, far); }
      if (d0 != INFINITY) {
        if (d1 != INFINITY) stack[sp++] = {far, d1};
        node = near;
        continue;
      }
    }
    node = UINT32_MAX;
    while (sp > 0) {
      const Entry e = stack[--sp];
      if (e.dist < hit.t) { node = e.node; break; }
    }
  }
}

}  // namespace

Hit trace_two_level(const TwoLevelBVH& tl, const Ray& ray, TwoLevelStats* stats) {
  TwoLevelStats local;
  TwoLevelStats& st = stats ? *stats : local;
  Hit hit;
  hit.t = ray.tmax;
  const RayCtx world(ray);
  closest_in(tl.top(), world, ray.tmin, hit, st.top_nodes, [&](uint32_t first, uint32_t count) {
    for (uint32_t k = first; k < first + count; ++k) {
      const uint32_t id = tl.top().prim_index[k];
      const Instance& in = tl.instances()[id];
      const Scene& mesh = tl.objects()[in.object];
      const BVH& bvh = tl.object_bvhs()[in.object];
      const uint32_t offset = tl.prim_offset(id);
      Ray r = ray;
      r.org = in.to_object.point(ray.org);
      r.dir = in.to_object.vector(ray.dir);
      const RayCtx obj(r);
      ++st.instance_visits;
      closest_in(bvh, obj, ray.tmin, hit, st.object_nodes, [&](uint32_t f, uint32_t c) {
        for (uint32_t j = f; j < f + c; ++j) {
          const uint32_t tri = bvh.prim_index[j];
          ++st.tri_tests;
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

void trace_two_level(const TwoLevelBVH& tl, const RayBatch& batch, std::span<Hit> hits, TwoLevelStats* stats) {
  for (size_t i = 0; i < batch.size(); ++i) hits[i] = trace_two_level(tl, batch.rays[i], stats);
}

}  // namespace tb
