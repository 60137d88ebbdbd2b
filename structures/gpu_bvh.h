// The binary BVH in the GPU node layout of Aila & Laine 2009 ("Understanding the efficiency of ray
// traversal on GPUs", §3 and their published kernels): one 64-byte node per interior node of the
// binary BVH, holding the boxes of BOTH children and their references, so that one node fetch
// (half a 128-byte line, one aligned load per lane) gives a lane everything it needs to test and
// order the two children. Leaves are not nodes: a child reference with a non-zero count names a
// range of leaf-ordered triangles (the same TriangleSet slots as the binary BVH's leaves).
//
// Made only by conversion from the one binary builder's tree (structures/bvh.h). Node order: the
// root first; a node's interior children get their slots (adjacent) when it is converted, and the
// left subtree is converted before the right, so a parent always precedes its children.
#pragma once
#include <cstdint>
#include <string>

#include "structures/aligned.h"
#include "structures/bvh.h"

namespace tb {

// A child of a GPU node: an interior node (count == 0, index into GPUBVH::nodes) or a leaf
// (count > 0 triangles starting at slot `index` of the leaf-ordered triangle set).
struct GPUChild {
  uint32_t index = 0;
  uint32_t count = 0;
  bool is_leaf() const { return count != 0; }
};

struct alignas(64) GPUNode {
  Vec3 lo[2], hi[2];   // the children's boxes (48 bytes)
  GPUChild child[2];   // 16 bytes
};
static_assert(sizeof(GPUNode) == 64);

struct GPUBVH {
  aligned_vector<GPUNode, 128> nodes;  // nodes[0] = root; 128-byte aligned so a node never straddles a line
  uint32_t max_depth = 0;              // longest root-to-leaf path in nodes (stack bound)
  size_t bytes() const { return nodes.size() * sizeof(GPUNode); }
  std::string describe() const;

  // Converts the binary BVH (leaf prim slots unchanged). A BVH whose root is a leaf becomes one
  // node whose second child is an empty box (lo = +inf, hi = -inf): every slab test misses it.
  static GPUBVH from_bvh(const BVH& bvh);
};

}  // namespace tb
