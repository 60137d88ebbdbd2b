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

}  // namespace

template <int N, int W>
Treelets Treelets::partition(const MBVH<N, W>& m, size_t budget) {
  Treelets t;
  t.small_leaf = m.small_leaf;
  t.node_treelet.assign(m.nodes.size(), UINT32_MAX);
  t.block_treelet.assign(m.blocks.size(), UINT32_MAX);
  t.small_treelet.assign(m.small.size(), UINT32_MAX);
  // Bytes a node brings into its treelet: itself and the blocks of its leaf children.
  auto node_cost = [&](uint32_t n) {
    size_t b = sizeof(MBVHNode<N>);
    const auto& nd = m.nodes[n];
    for (uint32_t c = 0; c < nd.num_children; ++c) {
      const uint32_t r = nd.ref[c];
      if (!mbvh_ref::is_leaf(r)) continue;
      const uint32_t k = mbvh_ref::num_tris(r);
      b += k <= m.small_leaf ? sizeof(TriBlock<4>) : (k + W - 1) / W * sizeof(TriBlock<W>);
    }
    return b;
  };
  auto assign = [&](uint32_t n, uint32_t id) {
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
  };
  if (m.nodes.empty()) return t;
  // Subtree bytes, children before parents (a breadth-first order, reversed).
  std::vector<uint32_t> order{0};
  for (size_t i = 0; i < order.size(); ++i) {
    const auto& nd = m.nodes[order[i]];
    for (uint32_t k = 0; k < nd.num_children; ++k)
      if (!mbvh_ref::is_leaf(nd.ref[k])) order.push_back(nd.ref[k]);
  }
  std::vector<size_t> subtree(m.nodes.size(), 0);
  for (size_t i = order.size(); i-- > 0;) {
    const uint32_t n = order[i];
    subtree[n] += node_cost(n);
    const auto& nd = m.nodes[n];
    for (uint32_t k = 0; k < nd.num_children; ++k)
      if (!mbvh_ref::is_leaf(nd.ref[k])) subtree[n] += subtree[nd.ref[k]];
  }
  // With 8-wide nodes the frontier a full treelet leaves is wide and mostly small subtrees; each
  // of its own would make treelets of a node or two (measured: 895 treelets for 1334 nodes on
  // stadium at 256 KiB). So a subtree that fits the budget whole is packed with the next ones
  // (next-fit, in the breadth-first order the frontier comes in: siblings share a treelet), and
  // only a subtree larger than the budget grows a treelet greedily, skipping candidates that no
  // longer fit so the treelet fills up. Packed treelets are unions of whole sibling subtrees
  // (not connected); a ray still changes queue only where it crosses a treelet's edge.
  std::deque<uint32_t> roots{0};
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
        assign(n, pack);
        const auto& nd = m.nodes[n];
        for (uint32_t k = 0; k < nd.num_children; ++k)
          if (!mbvh_ref::is_leaf(nd.ref[k])) todo.push_back(nd.ref[k]);
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
      const size_t c = node_cost(n);
      if (nodes > 0 && bytes + c > budget) {
        roots.push_back(n);  // the root of a later treelet
        continue;
      }
      assign(n, id);
      bytes += c, ++nodes;
      const auto& nd = m.nodes[n];
      for (uint32_t k = 0; k < nd.num_children; ++k)
        if (!mbvh_ref::is_leaf(nd.ref[k])) cand.push({half_area(nd.child_box(int(k))), nd.ref[k]});
    }
    t.bytes.push_back(bytes);
  }
  t.stats.treelets = t.count();
  t.stats.budget = budget;
  t.stats.max_bytes = *std::max_element(t.bytes.begin(), t.bytes.end());
  size_t sum = 0;
  for (size_t b : t.bytes) sum += b;
  t.stats.avg_bytes = double(sum) / double(t.count());
  t.stats.avg_nodes = double(m.nodes.size()) / double(t.count());
  return t;
}

template Treelets Treelets::partition(const MBVH<8, 8>&, size_t);
template Treelets Treelets::partition(const MBVH<8, 4>&, size_t);

}  // namespace tb
