// The binary BVH of Embree 3's own builder (rtcBuildBVH), laid out as travbench's BVH: the tree
// Embree's SAH builder makes (binned SAH; with spatial splits, its fast spatial-split builder on
// split_triangle_bounds' clipped references), so that every travbench scheme can run on it and a
// comparison with the embree_* schemes can tell the tree from the kernel (structures/embree_bvh.h).
#include "structures/embree_bvh.h"

#include <embree3/rtcore.h>

#include <chrono>
#include <cstring>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <vector>

#include "structures/clip.h"

namespace tb {
namespace {

// The nodes the callbacks build (in memory of Embree's thread-local allocator, freed with the
// RTCBVH): a tag first, so that a child pointer tells its kind.
struct ENode {
  bool leaf;
};
struct EInner : ENode {
  ENode* child[2];
  AABB box[2];
};
struct ELeaf : ENode {
  uint32_t count;
  uint32_t ids[1];  // `count` of them (allocated to size)
};

AABB to_aabb(const RTCBounds& b) { return {{b.lower_x, b.lower_y, b.lower_z}, {b.upper_x, b.upper_y, b.upper_z}}; }
RTCBounds to_bounds(const AABB& b) {
  RTCBounds r{};
  r.lower_x = b.lo.x, r.lower_y = b.lo.y, r.lower_z = b.lo.z;
  r.upper_x = b.hi.x, r.upper_y = b.hi.y, r.upper_z = b.hi.z;
  return r;
}

void* create_node(RTCThreadLocalAllocator alloc, unsigned int child_count, void*) {
  if (child_count != 2) return nullptr;  // maxBranchingFactor is 2
  auto* n = static_cast<EInner*>(rtcThreadLocalAlloc(alloc, sizeof(EInner), 16));
  n->leaf = false;
  n->child[0] = n->child[1] = nullptr;
  return n;
}
void set_children(void* node, void** children, unsigned int count, void*) {
  auto* n = static_cast<EInner*>(node);
  for (unsigned i = 0; i < count && i < 2; ++i) n->child[i] = static_cast<ENode*>(children[i]);
}
void set_bounds(void* node, const RTCBounds** bounds, unsigned int count, void*) {
  auto* n = static_cast<EInner*>(node);
  for (unsigned i = 0; i < count && i < 2; ++i) n->box[i] = to_aabb(*bounds[i]);
}
void* create_leaf(RTCThreadLocalAllocator alloc, const RTCBuildPrimitive* prims, size_t count, void*) {
  auto* l = static_cast<ELeaf*>(rtcThreadLocalAlloc(alloc, sizeof(ELeaf) + sizeof(uint32_t) * count, 16));
  l->leaf = true;
  l->count = uint32_t(count);
  for (size_t i = 0; i < count; ++i) l->ids[i] = prims[i].primID;
  return l;
}
// Embree's reference split: the clipped triangle's parts (the same conservative clip as
// travbench's spatial builder), each kept inside the reference's own box.
void split_primitive(const RTCBuildPrimitive* prim, unsigned int dim, float pos, RTCBounds* left, RTCBounds* right,
                     void* user) {
  const Scene& scene = *static_cast<const Scene*>(user);
  const auto& t = scene.triangles[prim->primID];
  const Vec3 v[3] = {scene.positions[t[0]], scene.positions[t[1]], scene.positions[t[2]]};
  AABB l, r;
  split_triangle_bounds(v, int(dim), pos, l, r);
  const AABB box{{prim->lower_x, prim->lower_y, prim->lower_z}, {prim->upper_x, prim->upper_y, prim->upper_z}};
  const auto clamp = [&](AABB b) {
    b.lo = vmax(b.lo, box.lo), b.hi = vmin(b.hi, box.hi);
    return b;
  };
  l = clamp(l), r = clamp(r);
  // A side the clip leaves empty (a split at the reference's edge) keeps a degenerate box on the
  // plane: Embree's builder expects both sides to be valid boxes.
  if (l.empty()) l = box, l.hi[int(dim)] = l.lo[int(dim)] = pos;
  if (r.empty()) r = box, r.hi[int(dim)] = r.lo[int(dim)] = pos;
  *left = to_bounds(l), *right = to_bounds(r);
}

// A device of its own (one thread, as the embree_* schemes'): theirs (traversal/embree_common.cpp)
// carries the memory monitor that counts their structures' bytes, which a build here must not
// add to.
RTCDevice builder_device() {
  static std::once_flag once;
  static RTCDevice device = nullptr;
  std::call_once(once, [] { device = rtcNewDevice("threads=1,set_affinity=0"); });
  if (!device) throw std::runtime_error("embree: rtcNewDevice for rtcBuildBVH failed");
  return device;
}

}  // namespace

BVH build_embree_bvh(const Scene& scene, const BVHBuildParams& p) {
  if (p.max_leaf < 1 || p.max_leaf > int(RTC_BUILD_MAX_PRIMITIVES_PER_LEAF))
    throw std::invalid_argument("build_embree_bvh: Embree's leaves hold 1 to 32 primitives");
  const auto t0 = std::chrono::steady_clock::now();
  const size_t n = scene.num_triangles();
  BVH bvh;
  if (n == 0) {
    bvh.nodes.resize(2);  // as the binned builder leaves an empty scene: an empty root box
    bvh.nodes[0] = BVHNode{AABB{}.lo, 0, AABB{}.hi, 0};
    bvh.finish_stats(p, t0);
    return bvh;
  }
  // Spatial splits need room for the references they add: split_budget extra per triangle.
  const size_t capacity = p.spatial ? n + size_t(double(n) * p.split_budget) + 1 : n;
  std::vector<RTCBuildPrimitive> prims(capacity);
  AABB root_box;
  for (size_t i = 0; i < n; ++i) {
    const AABB b = scene.triangle_bounds(uint32_t(i));
    root_box.grow(b);
    RTCBuildPrimitive& r = prims[i];
    r.lower_x = b.lo.x, r.lower_y = b.lo.y, r.lower_z = b.lo.z, r.geomID = 0;
    r.upper_x = b.hi.x, r.upper_y = b.hi.y, r.upper_z = b.hi.z, r.primID = uint32_t(i);
  }
  // The nodes live in the RTCBVH's allocator until it is released, on every path out.
  const std::unique_ptr<RTCBVHTy, void (*)(RTCBVH)> handle(rtcNewBVH(builder_device()), rtcReleaseBVH);
  RTCBuildArguments a = rtcDefaultBuildArguments();
  a.byteSize = sizeof(a);
  a.buildQuality = RTC_BUILD_QUALITY_HIGH;
  a.maxBranchingFactor = 2;
  a.maxDepth = 1024;
  a.sahBlockSize = 1;
  a.minLeafSize = 1;
  a.maxLeafSize = uint32_t(p.max_leaf);
  a.traversalCost = p.cost_traversal;
  a.intersectionCost = p.cost_intersect;
  a.bvh = handle.get();
  a.primitives = prims.data();
  a.primitiveCount = n;
  a.primitiveArrayCapacity = capacity;
  a.createNode = create_node;
  a.setNodeChildren = set_children;
  a.setNodeBounds = set_bounds;
  a.createLeaf = create_leaf;
  a.splitPrimitive = p.spatial ? split_primitive : nullptr;
  a.userPtr = const_cast<Scene*>(&scene);
  auto* root = static_cast<const ENode*>(rtcBuildBVH(&a));
  if (!root) throw std::runtime_error("embree: rtcBuildBVH failed");
  // travbench's layout: nodes[0] the root, nodes[1] padding, a node's children side by side (a
  // binary tree over at most `capacity` references: at most 2 capacity - 1 nodes).
  bvh.nodes.reserve(2 * capacity + 2);
  bvh.nodes.resize(2);
  bvh.prim_index.reserve(capacity);
  uint32_t max_depth = 0;
  struct Task {
    const ENode* node;
    uint32_t index, depth;
  };
  std::vector<Task> stack{{root, 0, 0}};  // depth as the other builders count it: the root's is 0
  bvh.nodes[0] = BVHNode{root_box.lo, 0, root_box.hi, 0};
  while (!stack.empty()) {
    const Task t = stack.back();
    stack.pop_back();
    max_depth = std::max(max_depth, t.depth);
    if (t.node->leaf) {
      const auto* l = static_cast<const ELeaf*>(t.node);
      bvh.nodes[t.index].left_first = uint32_t(bvh.prim_index.size());
      bvh.nodes[t.index].count = l->count;
      for (uint32_t i = 0; i < l->count; ++i) bvh.prim_index.push_back(l->ids[i]);
      continue;
    }
    const auto* in = static_cast<const EInner*>(t.node);
    const uint32_t left = uint32_t(bvh.nodes.size());
    bvh.nodes[t.index].left_first = left;
    bvh.nodes[t.index].count = 0;
    for (int c = 0; c < 2; ++c) {
      bvh.nodes.push_back(BVHNode{in->box[c].lo, 0, in->box[c].hi, 0});
      stack.push_back({in->child[c], left + uint32_t(c), t.depth + 1});
    }
  }
  bvh.stats.max_depth = max_depth;
  bvh.finish_stats(p, t0);
  return bvh;
}

}  // namespace tb
