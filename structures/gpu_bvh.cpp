#include "structures/gpu_bvh.h"

#include <cmath>
#include <utility>
#include <vector>

namespace tb {

std::string GPUBVH::describe() const {
  return "gpu_bvh nodes=" + std::to_string(nodes.size()) + " depth=" + std::to_string(max_depth) +
         " bytes=" + std::to_string(bytes());
}

GPUBVH GPUBVH::from_bvh(const BVH& bvh) {
  GPUBVH g;
  const BVHNode* src = bvh.nodes.data();
  if (bvh.nodes.empty()) return g;
  if (src[0].is_leaf()) {  // a one-leaf tree: the root's box and an empty sibling
    GPUNode n;
    n.lo[0] = src[0].lo, n.hi[0] = src[0].hi;
    n.child[0] = {src[0].left_first, src[0].count};
    n.lo[1] = Vec3{INFINITY, INFINITY, INFINITY}, n.hi[1] = Vec3{-INFINITY, -INFINITY, -INFINITY};
    n.child[1] = {0, 0};
    g.nodes.push_back(n);
    g.max_depth = 1;
    return g;
  }
  g.nodes.reserve(bvh.stats.nodes / 2 + 1);
  // Work list, left subtree first: (binary BVH interior node, GPU slot to fill, depth).
  struct Item { uint32_t src, dst, depth; };
  std::vector<Item> todo{{0, 0, 1}};
  g.nodes.emplace_back();
  while (!todo.empty()) {
    const Item it = todo.back();
    todo.pop_back();
    g.max_depth = std::max(g.max_depth, it.depth);
    const uint32_t first = src[it.src].left_first;
    GPUNode n;
    for (int c = 0; c < 2; ++c) {
      const BVHNode& ch = src[first + c];
      n.lo[c] = ch.lo, n.hi[c] = ch.hi;
      if (ch.is_leaf()) {
        n.child[c] = {ch.left_first, ch.count};
      } else {
        n.child[c] = {uint32_t(g.nodes.size()), 0};
        g.nodes.emplace_back();
      }
    }
    g.nodes[it.dst] = n;
    // Right pushed first so the left subtree is converted next.
    for (int c = 1; c >= 0; --c)
      if (!n.child[c].is_leaf()) todo.push_back({first + uint32_t(c), n.child[c].index, it.depth + 1});
  }
  return g;
}

}  // namespace tb
