// Treelets: the MBVH cut into connected subtrees of at most a byte budget (Aila & Karras 2010,
// "Architecture considerations for tracing incoherent rays"; CS348K lecture 18, "partition BVH
// into treelets sized for L1 or L2 cache"). A treelet owns its interior nodes and the triangle
// blocks of the leaves those nodes reference (a leaf lives in its parent's slot, so it belongs to
// its parent's treelet): a ray that stays inside one treelet reads only that treelet's bytes.
//
// Formation is greedy by surface area, as Aila & Karras form theirs: a treelet starts at a root
// and repeatedly takes, among the interior children of its nodes, the one with the largest box
// (the most likely to be visited by random rays, the SAH's probability) while it fits the budget;
// the children left over become the roots of new treelets. A subtree that fits the budget whole
// is instead packed with the next such subtrees into one treelet (treelet.cpp says why). The MBVH itself
// is not rebuilt or reordered (traversal/treelet_queue.cpp runs mbvh8_single's loop on it).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "structures/mbvh.h"

namespace tb {

struct TreeletStats {
  uint32_t treelets = 0;
  size_t budget = 0, max_bytes = 0;
  double avg_bytes = 0, avg_nodes = 0;
  std::string describe() const;
};

struct Treelets {
  std::vector<uint32_t> node_treelet;   // per MBVH node
  std::vector<uint32_t> block_treelet;  // per W-wide block: its leaf's parent's treelet
  std::vector<uint32_t> small_treelet;  // per 4-wide small block (8-wide layouts with small leaves)
  std::vector<size_t> bytes;            // per treelet: node bytes + its leaves' block bytes
  uint32_t small_leaf = 0;              // the MBVH's small-leaf bound (which block array a leaf uses)
  TreeletStats stats;

  uint32_t count() const { return uint32_t(bytes.size()); }
  // The treelet of a child reference (interior node or leaf), as the entry a traversal reads.
  const uint32_t& entry(uint32_t ref) const {
    if (!mbvh_ref::is_leaf(ref)) return node_treelet[ref];
    const uint32_t first = mbvh_ref::first_block(ref);
    return mbvh_ref::num_tris(ref) <= small_leaf ? small_treelet[first] : block_treelet[first];
  }
  uint32_t of(uint32_t ref) const { return entry(ref); }
  size_t map_bytes() const {
    return (node_treelet.size() + block_treelet.size() + small_treelet.size()) * sizeof(uint32_t);
  }
  // A node's bytes always count, so a treelet holds at least its root (and that node's leaves)
  // even under a budget smaller than one node.
  template <int N, int W>
  static Treelets partition(const MBVH<N, W>& m, size_t budget);
};

}  // namespace tb
