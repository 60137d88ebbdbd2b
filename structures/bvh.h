// Binary BVH with a binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding
// volume hierarchies"), 32-byte nodes, sibling pairs adjacent and 64-byte aligned.
#pragma once
#include <cstdint>
#include <string>
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

struct BVHBuildParams {
  int bins = 16;          // SAH bins per axis
  int max_leaf = 4;       // leaves never hold more prims than this
  float cost_traversal = 1.f;
  float cost_intersect = 1.f;
  int threads = 1;        // build threads (the tree is the same; node order may differ)
  std::string key() const;  // for the structure cache
};

struct BVHStats {
  uint32_t nodes = 0, leaves = 0, max_depth = 0;
  double sah_cost = 0, build_ms = 0;
  size_t bytes = 0;
  std::string describe() const;
};

struct BVH {
  aligned_vector<BVHNode> nodes;    // nodes[0] = root; nodes[1] unused so sibling pairs share a line
  std::vector<uint32_t> prim_index; // leaf prim slot -> scene triangle
  BVHStats stats;

  static BVH build(const Scene& scene, const BVHBuildParams& params = {});
  // Recomputes every box bottom-up for moved vertices, keeping the topology (thesis Table 1).
  void refit(const Scene& scene, int threads = 1);
  double compute_sah_cost(const BVHBuildParams& params) const;
};

}  // namespace tb
