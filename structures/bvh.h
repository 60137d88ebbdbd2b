// Binary BVH with a binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding
// volume hierarchies"), 32-byte nodes, sibling pairs adjacent and 64-byte aligned.
//
// The project's one binary builder. It works on a span of primitive references (a box and an id
// each, PrimRef below) and never looks at triangles: BVH::build(scene) makes one reference per
// scene triangle and calls the same code, and a structure that needs a tree over something else
// hands its own references in. The RayGrid octree (structures/octree.h, thesis §5.3.2) does so
// for its mini-BVHs: an index subset of the scene (the triangles a leaf references), each box
// clipped to the leaf (structures/clip.h). Wide layouts come from the one collapse of such a tree
// (MBVH::collapse, structures/mbvh.h).
#pragma once
#include <chrono>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "structures/aligned.h"
#include "structures/scene.h"
#include "structures/vec3.h"

namespace tb {

struct BVHNode {
  Vec3 lo;
  uint32_t left_first;  // interior: index of the left child (right = left + 1); leaf: first prim
  Vec3 hi;
  uint32_t count;       // 0 for interior nodes, else number of prims in the leaf
  bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(BVHNode) == 32);

// Whose builder makes the binary tree: travbench's binned SAH (bvh.cpp; spatial splits:
// bvh_spatial.cpp) or Embree 3's rtcBuildBVH (structures/embree_bvh.h), to tell a tree from a kernel.
enum class BVHBuilder { travbench, embree };

struct BVHBuildParams {
  BVHBuilder builder = BVHBuilder::travbench;
  int bins = 16;          // SAH bins per axis
  int max_leaf = 4;       // leaves never hold more prims than this
  float cost_traversal = 1.f;
  float cost_intersect = 1.f;
  int threads = 1;        // build threads (the tree is the same; node order may differ)
  // Spatial splits (structures/bvh_spatial.h): the scene build clips straddling triangles
  // (references may repeat); split_alpha, split_budget, split_wall, split_overlap and
  // split_walls are SpatialSplitParams' alpha, budget, wall, overlap and walls_apart.
  bool spatial = false;
  float split_alpha = 1e-5f;
  float split_budget = 1.0f;
  float split_wall = 0.8f;
  float split_overlap = 0.f;  // SpatialSplitParams::overlap
  bool split_walls = true;     // SpatialSplitParams::walls_apart
  std::string key() const;  // for the structure cache
};

struct BVHStats {
  uint32_t nodes = 0, leaves = 0, max_depth = 0;
  double sah_cost = 0, build_ms = 0;
  size_t bytes = 0;
  std::string describe() const;
};

// One primitive as the builder sees it, a "primitive reference" (Wald 2007; Embree's PrimRef):
// its box and its id, so every pass of the builder streams one contiguous array, partitioned in
// place, instead of gathering boxes and centroids through an index. The centroid is the box's
// (lo + hi) / 2. 32 bytes, SSE-loadable: lo[3] carries the id's bits; hi[3] = 1 so that lane 3
// of lo + hi is a normal float (the id's bits are a denormal, which can cost a microcode assist
// on every add).
struct alignas(32) PrimRef {
  float lo[4];
  float hi[4];
  PrimRef() = default;  // uninitialised, like the arrays of them the builder fills
  PrimRef(const AABB& box, uint32_t id)
      : lo{box.lo.x, box.lo.y, box.lo.z, 0.f}, hi{box.hi.x, box.hi.y, box.hi.z, 1.f} {
    std::memcpy(&lo[3], &id, 4);
  }
  uint32_t id() const {
    uint32_t i;
    std::memcpy(&i, &lo[3], 4);
    return i;
  }
  AABB box() const { return {{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}}; }
};
static_assert(sizeof(PrimRef) == 32);

struct BVH {
  aligned_vector<BVHNode> nodes;    // nodes[0] = root; nodes[1] unused so sibling pairs share a line
  std::vector<uint32_t> prim_index; // leaf prim slot -> primitive id (scene triangle)
  BVHStats stats;

  // Over every scene triangle (its box as Scene::triangle_bounds; id = triangle index).
  static BVH build(const Scene& scene, const BVHBuildParams& params = {});
  // Over the references `refs` (any boxes, any ids: a subset of the scene, clipped boxes),
  // which the build reorders in place. Same builder, same tree as the scene build for the same
  // references; prim_index holds the ids.
  static BVH build(std::span<PrimRef> refs, const BVHBuildParams& params = {});
  // Recomputes every box bottom-up for moved vertices, keeping the topology (thesis Table 1).
  void refit(const Scene& scene, int threads = 1);
  // The same over any primitives: box_of(id) is primitive id's current box (the top level of a
  // two-level BVH refits over its instances' world boxes, structures/two_level.h). Post-order
  // over the tree; the top levels fork so `threads` subtrees refit at once.
  template <class BoxOf>
  void refit_boxes(const BoxOf& box_of, int threads = 1);
  double compute_sah_cost(const BVHBuildParams& params) const;
  // Fills `stats` from the finished tree, all but max_depth (which only the builder knows), the
  // build time counted from `start`: the last step of both builders (binned SAH, spatial splits).
  void finish_stats(const BVHBuildParams& params, std::chrono::steady_clock::time_point start);
};

// The same binned builder for many small subtrees of one tree under construction (the
// spatial-split builder hands it every subtree below its min_refs, structures/bvh_spatial.cpp):
// build() grows node `node` of `bvh` into the subtree of `refs` in place — its nodes appended to
// bvh.nodes, whose capacity must hold them (a binary tree: < 2 refs.size() nodes), its ids
// appended to bvh.prim_index — the same subtree, node for node, as BVH::build over the same
// references would make and renumber, without that tree's allocations, copy and statistics
// (which cost the spatial build of stadium ~10% of its instructions, 2.8 k subtrees of at
// most 64 references; docs/PERFORMANCE.md, session 29). `node`'s box must be the references'
// bounds. Single-threaded; the bins are kept from call to call. Returns the subtree's depth
// below `node`.
class BVHSubtreeBuilder {
 public:
  explicit BVHSubtreeBuilder(const BVHBuildParams& params);
  ~BVHSubtreeBuilder();
  BVHSubtreeBuilder(const BVHSubtreeBuilder&) = delete;
  BVHSubtreeBuilder& operator=(const BVHSubtreeBuilder&) = delete;
  uint32_t build(BVH& bvh, uint32_t node, std::span<PrimRef> refs);

 private:
  struct Scratch;
  BVHBuildParams params_;
  std::unique_ptr<Scratch> scratch_;
};

template <class BoxOf>
void BVH::refit_boxes(const BoxOf& box_of, int threads) {
  int fork_levels = 0;
  while ((1 << fork_levels) < threads) ++fork_levels;
  auto rec = [&](auto&& self, uint32_t i, int depth) -> void {
    BVHNode& nd = nodes[i];
    AABB b;
    if (nd.is_leaf()) {
      for (uint32_t k = nd.left_first; k < nd.left_first + nd.count; ++k) b.grow(box_of(prim_index[k]));
    } else {
      if (depth < fork_levels) {
        std::thread left([&] { self(self, nd.left_first, depth + 1); });
        self(self, nd.left_first + 1, depth + 1);
        left.join();
      } else {
        self(self, nd.left_first, depth + 1);
        self(self, nd.left_first + 1, depth + 1);
      }
      const BVHNode &l = nodes[nd.left_first], &r = nodes[nd.left_first + 1];
      b.grow(AABB{l.lo, l.hi});
      b.grow(AABB{r.lo, r.hi});
    }
    nd.lo = b.lo;
    nd.hi = b.hi;
  };
  if (!nodes.empty()) rec(rec, 0, 0);
}

}  // namespace tb
