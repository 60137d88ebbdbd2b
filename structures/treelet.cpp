#include "structures/treelet.h"

#include <algorithm>
#include <cstdio>
#include <deque>
#include <queue>

namespace tb {

std::string TreeletStats::describe() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, "treelets=%u budget=%zu avg_bytes=%.0f max_bytes=%zu avg_nodes=%.1f", treelets,
                budget, avg_bytes, max_bytes, avg_nodes);
  return buf;
}

namespace {

float half_area(const AABB& b) {
  const Vec3 d = b.hi - b.lo;
  return d.x * d.y + d.y * d.z + d.z * d.x;
}

// The tree as the partition reads it: interior nodes by a dense index (0..nodes()-1), the root's
// root(); children(n, f) calls f(dense index, box half-area) for each interior child of n; cost(n)
// is n's bytes plus its leaf children's blocks; assign(t, n, id) puts n and those blocks in
// treelet id.
template <int N, int W>
struct MBVHTree {
  const MBVH<N, W>& m;
  size_t nodes() const { return m.nodes.size(); }
  uint32_t root() const { return 0; }
  template <class F>
  void children(uint32_t n, F&& f) const {
    const auto& nd = m.nodes[n];
    for (uint32_t k = 0; k < nd.num_children; ++k)
      if (!mbvh_ref::is_leaf(nd.ref[k])) f(nd.ref[k], half_area(nd.child_box(int(k))));
  }
  size_t cost(uint32_t n) const {
    size_t b = sizeof(MBVHNode<N>);
    const auto& nd = m.nodes[n];
    for (uint32_t c = 0; c < nd.num_children; ++c) {
      const uint32_t r = nd.ref[c];
      if (!mbvh_ref::is_leaf(r)) continue;
      const uint32_t k = mbvh_ref::num_tris(r);
      b += k <= m.small_leaf ? sizeof(TriBlock<4>) : (k + W - 1) / W * sizeof(TriBlock<W>);
    }
    return b;
  }
  void assign(Treelets& t, uint32_t n, uint32_t id) const {
    t.node_treelet[n] = id;
    const auto& nd = m.nodes[n];
    for (uint32_t c = 0; c < nd.num_children; ++c) {
      const uint32_t r = nd.ref[c];
      if (!mbvh_ref::is_leaf(r)) continue;
      const uint32_t first = mbvh_ref::first_block(r), k = mbvh_ref::num_tris(r);
      if (k <= m.small_leaf) t.small_treelet[first] = id;
      else
        for (uint32_t j = 0; j < (k + W - 1) / W; ++j) t.block_treelet[first + j] = id;
    }
  }
};

// A CWBVH: compressed nodes 0..nodes.size()-1, then its full nodes; children and leaves through
// CWBVH's reference getters (child_ref gives block leaves in the MBVH's encoding).
struct CWTree {
  const CWBVH& c;
  size_t nodes() const { return c.nodes.size() + c.full.size(); }
  uint32_t ref_of(uint32_t n) const { return n < c.nodes.size() ? n : kCWFull | uint32_t(n - c.nodes.size()); }
  uint32_t dense(uint32_t ref) const { return (ref & kCWFull) ? uint32_t(c.nodes.size()) + (ref & ~kCWFull) : ref; }
  uint32_t root() const { return dense(c.root); }
  // Calls f(slot, child reference) for each used slot of n.
  template <class F>
  void slots(uint32_t n, F&& f) const {
    const uint32_t ref = ref_of(n);
    for (int s = 0; s < 8; ++s)
      if (c.slot_used(ref, s)) f(s, c.child_ref(ref, s));
  }
  // Calls f(first block, block count) for each leaf child of n.
  template <class F>
  void leaves(uint32_t n, F&& f) const {
    slots(n, [&](int, uint32_t r) {
      if (!mbvh_ref::is_leaf(r)) return;
      if (c.leaves == CWLeaves::indexed) {
        uint32_t k = cw_ileaf_block(r), first = k;
        while (!c.iblocks[k].last) ++k;
        f(first, k - first + 1);
      } else {
        f(mbvh_ref::first_block(r), (mbvh_ref::num_tris(r) + 7) / 8);
      }
    });
  }
  template <class F>
  void children(uint32_t n, F&& f) const {
    slots(n, [&](int s, uint32_t r) {
      if (!mbvh_ref::is_leaf(r)) f(dense(r), half_area(c.child_box(ref_of(n), s)));
    });
  }
  size_t cost(uint32_t n) const {
    size_t b = n < c.nodes.size() ? sizeof(CWNode) : sizeof(MBVHNode<8>);
    const size_t block = c.leaves == CWLeaves::indexed ? sizeof(CWTriBlock) : sizeof(TriBlock<8>);
    leaves(n, [&](uint32_t, uint32_t count) { b += count * block; });
    return b;
  }
  void assign(Treelets& t, uint32_t n, uint32_t id) const {
    t.node_treelet[n] = id;
    leaves(n, [&](uint32_t first, uint32_t count) {
      for (uint32_t j = 0; j < count; ++j) t.block_treelet[first + j] = id;
    });
  }
};

template <class Tree>
void partition_tree(const Tree& tree, size_t budget, Treelets& t) {
  t.node_treelet.assign(tree.nodes(), UINT32_MAX);
  if (tree.nodes() == 0) return;
  // Subtree bytes, children before parents (a breadth-first order, reversed).
  std::vector<uint32_t> order{tree.root()};
  for (size_t i = 0; i < order.size(); ++i) tree.children(order[i], [&](uint32_t k, float) { order.push_back(k); });
  std::vector<size_t> subtree(tree.nodes(), 0);
  for (size_t i = order.size(); i-- > 0;) {
    const uint32_t n = order[i];
    subtree[n] += tree.cost(n);
    tree.children(n, [&](uint32_t k, float) { subtree[n] += subtree[k]; });
  }
  // With 8-wide nodes the frontier a full treelet leaves is wide and mostly small subtrees; each
  // of its own would make treelets of a node or two (measured: 895 treelets for 1334 nodes on
  // stadium at 256 KiB). So a subtree that fits the budget whole is packed with the next ones
  // (next-fit, in the breadth-first order the frontier comes in: siblings share a treelet), and
  // only a subtree larger than the budget grows a treelet greedily, skipping candidates that no
  // longer fit so the treelet fills up. Packed treelets are unions of whole sibling subtrees
  // (not connected); a ray still changes queue only where it crosses a treelet's edge.
  std::deque<uint32_t> roots{tree.root()};
  uint32_t pack = UINT32_MAX;
  while (!roots.empty()) {
    const uint32_t root = roots.front();
    roots.pop_front();
    if (subtree[root] <= budget) {
      if (pack == UINT32_MAX || t.bytes[pack] + subtree[root] > budget) pack = t.count(), t.bytes.push_back(0);
      std::vector<uint32_t> todo{root};
      while (!todo.empty()) {
        const uint32_t n = todo.back();
        todo.pop_back();
        tree.assign(t, n, pack);
        tree.children(n, [&](uint32_t k, float) { todo.push_back(k); });
      }
      t.bytes[pack] += subtree[root];
      continue;
    }
    const uint32_t id = t.count();
    size_t bytes = 0, nodes = 0;
    // Candidates: interior children of the treelet's nodes, largest box first.
    using Cand = std::pair<float, uint32_t>;
    std::priority_queue<Cand> cand;
    cand.push({0.f, root});
    while (!cand.empty()) {
      const uint32_t n = cand.top().second;
      cand.pop();
      const size_t c = tree.cost(n);
      if (nodes > 0 && bytes + c > budget) {
        roots.push_back(n);  // the root of a later treelet
        continue;
      }
      tree.assign(t, n, id);
      bytes += c, ++nodes;
      tree.children(n, [&](uint32_t k, float area) { cand.push({area, k}); });
    }
    t.bytes.push_back(bytes);
  }
  t.stats.treelets = t.count();
  t.stats.budget = budget;
  t.stats.max_bytes = *std::max_element(t.bytes.begin(), t.bytes.end());
  size_t sum = 0;
  for (size_t b : t.bytes) sum += b;
  t.stats.avg_bytes = double(sum) / double(t.count());
  t.stats.avg_nodes = double(tree.nodes()) / double(t.count());
}

}  // namespace

template <int N, int W>
Treelets Treelets::partition(const MBVH<N, W>& m, size_t budget) {
  Treelets t;
  t.small_leaf = m.small_leaf;
  t.block_treelet.assign(m.blocks.size(), UINT32_MAX);
  t.small_treelet.assign(m.small.size(), UINT32_MAX);
  partition_tree(MBVHTree<N, W>{m}, budget, t);
  return t;
}

Treelets Treelets::partition(const CWBVH& c, size_t budget) {
  Treelets t;
  t.full_offset = uint32_t(c.nodes.size());
  t.cw_indexed = c.leaves == CWLeaves::indexed;
  t.block_treelet.assign(t.cw_indexed ? c.iblocks.size() : c.blocks.size(), UINT32_MAX);
  partition_tree(CWTree{c}, budget, t);
  return t;
}

template Treelets Treelets::partition(const MBVH<8, 8>&, size_t);
template Treelets Treelets::partition(const MBVH<8, 4>&, size_t);

}  // namespace tb
