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
// is instead packed with the next such subtrees into one treelet (treelet.cpp says why). The tree
// itself is not rebuilt or reordered (traversal/treelet_queue.cpp runs mbvh8_single's loop on the
// MBVH8, or cwbvh_single's on the compressed BVH of structures/cwbvh.h, which is cut the same way
// by its own bytes: 80-byte nodes and indexed leaf blocks fill a budget with more of the tree).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "structures/cwbvh.h"
#include "structures/mbvh.h"

namespace tb {

struct TreeletStats {
  uint32_t treelets = 0;
  size_t budget = 0, max_bytes = 0;
  double avg_bytes = 0, avg_nodes = 0;
  std::string describe() const;
};

struct Treelets {
  // Per interior node: an MBVH's node index; a CWBVH's compressed node index, then its full
  // nodes from `full_offset` on (the number of compressed nodes).
  std::vector<uint32_t> node_treelet;
  std::vector<uint32_t> block_treelet;  // per leaf block (W-wide, or the CWBVH's): its leaf's parent's treelet
  std::vector<uint32_t> small_treelet;  // per 4-wide small block (8-wide layouts with small leaves)
  std::vector<size_t> bytes;            // per treelet: node bytes + its leaves' block bytes
  uint32_t small_leaf = 0;              // the MBVH's small-leaf bound (which block array a leaf uses)
  uint32_t full_offset = 0;             // CWBVH: where its full nodes start in node_treelet
  bool cw_indexed = false;              // CWBVH: leaf references name indexed blocks (CWLeaves::indexed)
  TreeletStats stats;

  uint32_t count() const { return uint32_t(bytes.size()); }
  // The treelet of a child reference (interior node or leaf), as the entry a traversal reads.
  const uint32_t& entry(uint32_t ref) const {
    if (!mbvh_ref::is_leaf(ref)) return node_treelet[ref];
    const uint32_t first = mbvh_ref::first_block(ref);
    return mbvh_ref::num_tris(ref) <= small_leaf ? small_treelet[first] : block_treelet[first];
  }
  uint32_t of(uint32_t ref) const { return entry(ref); }
  // The same for a CWBVH reference (structures/cwbvh.h: a compressed node, kCWFull | a full node,
  // or a leaf reference of either leaf kind).
  const uint32_t& cw_entry(uint32_t ref) const {
    if (!mbvh_ref::is_leaf(ref)) return node_treelet[(ref & kCWFull) ? full_offset + (ref & ~kCWFull) : ref];
    return block_treelet[cw_indexed ? cw_ileaf_block(ref) : mbvh_ref::first_block(cw_leaf_to_mbvh(ref))];
  }
  // The part of the map a traversal reads: the node entries (treelet_queue tests a leaf where the
  // ray is, so the block entries only describe the partition).
  size_t map_bytes() const { return node_treelet.size() * sizeof(uint32_t); }
  // A node's bytes always count, so a treelet holds at least its root (and that node's leaves)
  // even under a budget smaller than one node.
  template <int N, int W>
  static Treelets partition(const MBVH<N, W>& m, size_t budget);
  static Treelets partition(const CWBVH& c, size_t budget);
};

}  // namespace tb
