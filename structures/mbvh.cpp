#include "structures/mbvh.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace tb {

std::string MBVHBuildParams::key(int width, int tri_width) const {
  char share[32];
  std::snprintf(share, sizeof share, "%g", prim_share);
  const std::string collapse = sah_collapse ? ":sah:tc=" + std::to_string(tri_cost) + ":pc=" +
                                                 std::to_string(prim_cost) + ":ps=" + share
                                           : ":greedy";
  return "mbvh:N=" + std::to_string(width) + ":W=" + std::to_string(tri_width) + ":merge=" + std::to_string(merge) +
         collapse + ":small=" + std::to_string(small) + ":" + bvh.key();
}

std::string MBVHStats::describe() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "width=%u tri_width=%u nodes=%u leaves=%u blocks=%u max_depth=%u avg_children=%.2f "
                "avg_leaf_tris=%.2f lane_fill=%.2f sah=%.2f bytes_per_node=%zu bytes_per_tri=%.1f node_bytes=%zu "
                "tri_bytes=%zu bvh_build_ms=%.1f collapse_ms=%.1f",
                width, tri_width, nodes, leaves, blocks, max_depth, avg_children, avg_leaf_tris, lane_fill, sah_cost,
                nodes ? node_bytes / nodes : size_t(0), triangles ? double(tri_bytes) / triangles : 0.0, node_bytes,
                tri_bytes, bvh_build_ms, collapse_ms);
  return buf;
}

namespace {

template <int N, int W>
class Collapser {
 public:
  Collapser(const Scene& scene, const BVH& bvh, const MBVHBuildParams& p, MBVH<N, W>& out)
      : scene_(scene), bvh_(bvh), p_(p), out_(out) {
    out_.small_leaf = W == 8 ? uint32_t(p.small) : 0;
    // The triangle range of every binary subtree: the binned builder partitions prim_index in
    // place, so a subtree's triangles are contiguous.
    first_.assign(bvh.nodes.size(), 0);
    count_.assign(bvh.nodes.size(), 0);
    range();
    if (p.sah_collapse) optimise();
  }

  double leaf_depth_sum() const { return leaf_depth_sum_; }
  // Whether the nodes and blocks still sit in the blocks reserved on huge pages by run().
  bool nodes_in_place() const { return out_.nodes.data() == reserved_[0]; }
  bool blocks_in_place() const { return out_.blocks.data() == reserved_[1]; }

  void run() {
    const uint32_t tris = uint32_t(bvh_.prim_index.size());
    // The finished arrays are written in place on huge pages (structures/aligned.h), reserved for
    // as many nodes and blocks as the tree can need in practice (untouched pages of the reservation
    // are never backed). Writing the blocks into fresh 4 KiB pages and then copying them onto huge
    // pages was most of the collapse's time on sponza in a paravirtualised VM (37 -> ~7 ms,
    // docs/PERFORMANCE.md session 16); the copy remains for a vector that outgrew its reservation.
    reserve_on_huge_pages(out_.nodes, std::max<size_t>(1, 2 * tris / N + 1));
    reserve_on_huge_pages(out_.blocks, (tris + W - 1) / W + tris / 2 + 1);
    reserved_[0] = out_.nodes.data(), reserved_[1] = out_.blocks.data();
    std::vector<uint32_t> top;
    if (tris > 0) {
      if (as_leaf(0)) top.push_back(0);
      else top = kids_of(0);
    }
    out_.nodes.emplace_back();
    fill(0, std::move(top), 1);
  }

 private:
  void range() {
    // Pre-order from the root, then reverse pre-order: every child after its parent, whatever
    // the node numbering (the parallel builder does not number children after parents).
    if (bvh_.nodes.empty()) return;
    std::vector<uint32_t>& order = order_;
    std::vector<uint32_t> stack{0};
    while (!stack.empty()) {
      const uint32_t i = stack.back();
      stack.pop_back();
      order.push_back(i);
      const BVHNode& n = bvh_.nodes[i];
      if (!n.is_leaf() && n.left_first != 0) stack.push_back(n.left_first), stack.push_back(n.left_first + 1);
    }
    for (size_t k = order.size(); k-- > 0;) {
      const uint32_t i = order[k];
      const BVHNode& n = bvh_.nodes[i];
      if (n.is_leaf()) {
        first_[i] = n.left_first, count_[i] = n.count;
      } else if (n.left_first != 0) {
        first_[i] = std::min(first_[n.left_first], first_[n.left_first + 1]);
        count_[i] = count_[n.left_first] + count_[n.left_first + 1];
      }
    }
  }
  bool as_leaf(uint32_t b) const {
    if (p_.sah_collapse) return leaf_[b] != 0;
    return bvh_.nodes[b].is_leaf() || (p_.merge > 0 && count_[b] <= uint32_t(p_.merge));
  }

  // The SAH collapse. F(n, j): the least cost of binary subtree n as a forest of at most j roots
  // in the wide tree; F(n, 1) = min(leaf cost, node cost); a node costs its area plus the best
  // split of its N slots between its two binary children (D(n, N)); F(n, j > 1) may dissolve n
  // into its children's forests (D(n, j)). Children before parents: reverse pre-order, in which
  // a node's F is read only by its parent, right after the parent's other child's subtree, so the F
  // of the nodes whose parent is still to come form a stack (the last two on it are a parent's
  // children): a tree's depth of entries instead of one per binary node (72 bytes each, pages the
  // build faulted in: docs/PERFORMANCE.md, session 28). The same values, so the same tree.
  void optimise() {
    const size_t nb = bvh_.nodes.size();
    std::vector<std::array<double, N + 1>>& fs = fstack_;
    fs.clear();
    split_.assign(nb, {});
    leaf_.assign(nb, 0);
    node_split_.assign(nb, 1);
    const double ci = p_.tri_cost / 100.0, cp = p_.prim_cost / 100.0;
    const uint32_t max_leaf = std::min<uint32_t>(mbvh_ref::kMaxLeafTris, uint32_t(std::max(p_.merge, W)));
    for (size_t k = order_.size(); k-- > 0;) {
      const uint32_t n = order_[k];
      const BVHNode& bn = bvh_.nodes[n];
      const double area = box_of(n).area();
      // Blocks tested; a small leaf's 4-wide block counts half (half the bytes and lanes).
      const double blocks = count_[n] <= out_.small_leaf ? 0.5 : double((count_[n] + W - 1) / W);
      const double leaf_cost =
          count_[n] <= max_leaf || bn.is_leaf() ? area * (ci * blocks + cp * charged_tris(n, area)) : INFINITY;
      std::array<double, N + 1> F{};
      if (bn.is_leaf()) {
        leaf_[n] = 1;
        for (int j = 1; j <= N; ++j) F[j] = leaf_cost;
        fs.push_back(F);
        continue;
      }
      // The children's F: range()'s pre-order visits the right child's subtree first, so in
      // reverse the left child's F is pushed first and the right child's is on top. A node without
      // children (the root of an empty tree) reads zeros, as the per-node table it replaced did.
      std::array<double, N + 1> Fl{}, Fr{};
      if (bn.left_first != 0) {
        Fr = fs.back(), fs.pop_back();
        Fl = fs.back(), fs.pop_back();
      }
      double D[N + 1];
      for (int j = 2; j <= N; ++j) {
        D[j] = INFINITY;
        for (int kk = 1; kk < j; ++kk) {
          const double c = Fl[kk] + Fr[j - kk];
          if (c < D[j]) D[j] = c, split_[n][j] = uint8_t(kk);
        }
      }
      const double node_cost = area + D[N];
      node_split_[n] = split_[n][N];  // how n's N slots divide if n becomes a node
      leaf_[n] = leaf_cost <= node_cost;
      F[1] = std::min(leaf_cost, node_cost);
      for (int j = 2; j <= N; ++j) {
        if (D[j] < F[j - 1]) {
          F[j] = D[j];
        } else {
          F[j] = F[j - 1];
          split_[n][j] = 0;  // keep n as one root
        }
      }
      fs.push_back(F);
    }
  }
  // The triangles of subtree n that prim_cost charges as one leaf of surface area `area`: all of
  // them, or with prim_share those whose box clipped to the subtree's box (a spatial-split reference
  // is clipped to its leaf) has at least that share of `area`.
  double charged_tris(uint32_t n, double area) const {
    if (p_.prim_cost == 0 || p_.prim_share <= 0.f) return double(count_[n]);
    const AABB nb = box_of(n);
    uint32_t big = 0;
    for (uint32_t k = first_[n]; k < first_[n] + count_[n]; ++k)
      big += double(intersect(scene_.triangle_bounds(bvh_.prim_index[k]), nb).area()) >= double(p_.prim_share) * area;
    return double(big);
  }

  // The roots of binary subtree n as a forest of at most j wide-tree slots.
  void roots(uint32_t n, int j, std::vector<uint32_t>& out) const {
    while (j > 1 && split_[n][j] == 0) --j;
    if (j <= 1) {
      out.push_back(n);
      return;
    }
    const int k = split_[n][j];
    roots(bvh_.nodes[n].left_first, k, out);
    roots(bvh_.nodes[n].left_first + 1, j - k, out);
  }
  // The children of binary node b when it becomes a wide node.
  std::vector<uint32_t> kids_of(uint32_t b) const {
    std::vector<uint32_t> kids;
    if (p_.sah_collapse) {
      const int k = node_split_[b];
      roots(bvh_.nodes[b].left_first, k, kids);
      roots(bvh_.nodes[b].left_first + 1, N - k, kids);
    } else {
      kids = {bvh_.nodes[b].left_first, bvh_.nodes[b].left_first + 1};
    }
    return kids;
  }
  AABB box_of(uint32_t b) const { return {bvh_.nodes[b].lo, bvh_.nodes[b].hi}; }

  // Fills node `idx` with the binary subtrees `kids` (greedy: after opening the largest ones).
  void fill(uint32_t idx, std::vector<uint32_t> kids, uint32_t depth) {
    out_.stats.max_depth = std::max(out_.stats.max_depth, depth);
    while (!p_.sah_collapse && kids.size() < size_t(N)) {
      int best = -1;
      float best_area = -1.f;
      for (size_t i = 0; i < kids.size(); ++i) {
        if (as_leaf(kids[i])) continue;
        const float a = box_of(kids[i]).area();
        if (a > best_area) best_area = a, best = int(i);
      }
      if (best < 0) break;
      const uint32_t open = kids[size_t(best)];
      kids[size_t(best)] = bvh_.nodes[open].left_first;
      kids.insert(kids.begin() + best + 1, bvh_.nodes[open].left_first + 1);
    }
    if (kids.size() > size_t(N)) throw std::logic_error("mbvh: collapse produced more than N children");
    MBVHNode<N> node;
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < N; ++i) node.box[a][i] = INFINITY, node.box[3 + a][i] = -INFINITY;
    for (int i = 0; i < N; ++i) node.ref[i] = 0;
    node.num_children = uint32_t(kids.size());
    for (size_t i = 0; i < kids.size(); ++i) {
      const AABB b = box_of(kids[i]);
      for (int a = 0; a < 3; ++a) node.box[a][i] = b.lo[a], node.box[3 + a][i] = b.hi[a];
    }
    // Leaves first (they need no recursion), then the interior children in depth-first order,
    // so a node's first interior child sits right after it in memory.
    for (size_t i = 0; i < kids.size(); ++i)
      if (as_leaf(kids[i])) {
        node.ref[i] = make_leaf(first_[kids[i]], count_[kids[i]]);
        leaf_depth_sum_ += depth;
      }
    std::vector<std::pair<size_t, uint32_t>> interior;
    for (size_t i = 0; i < kids.size(); ++i)
      if (!as_leaf(kids[i])) {
        node.ref[i] = uint32_t(out_.nodes.size());
        interior.push_back({i, node.ref[i]});
        out_.nodes.emplace_back();
      }
    out_.nodes[idx] = node;
    for (const auto& [slot, child] : interior) fill(child, kids_of(kids[slot]), depth + 1);
  }

  uint32_t make_leaf(uint32_t first, uint32_t count) {
    // A spatial-split BVH (structures/bvh_spatial.h) references a triangle from every leaf it
    // was split into, and a merged leaf can hold several of those references: one lane each would
    // test the same triangle twice. Keep the first occurrence (a tree without repeats packs
    // exactly as before).
    leaf_tris_.clear();
    for (uint32_t k = first; k < first + count; ++k)
      if (std::find(leaf_tris_.begin(), leaf_tris_.end(), bvh_.prim_index[k]) == leaf_tris_.end())
        leaf_tris_.push_back(bvh_.prim_index[k]);
    count = uint32_t(leaf_tris_.size());
    if (count == 0 || count > mbvh_ref::kMaxLeafTris)
      throw std::runtime_error("mbvh: leaf of " + std::to_string(count) + " triangles (merge/leaf_size must be <= 64)");
    out_.stats.leaves++;
    if (count <= out_.small_leaf) {
      const uint32_t block = uint32_t(out_.small.size());
      if (block >= mbvh_ref::kMaxBlocks) throw std::runtime_error("mbvh: too many triangle blocks");
      out_.small.push_back(block_of<4>(first, count, 0));
      return mbvh_ref::make_leaf(block, count);
    }
    const uint32_t block0 = uint32_t(out_.blocks.size());
    const uint32_t nblocks = (count + W - 1) / W;
    if (size_t(block0) + nblocks > mbvh_ref::kMaxBlocks) throw std::runtime_error("mbvh: too many triangle blocks");
    for (uint32_t k = 0; k < nblocks; ++k) out_.blocks.push_back(block_of<W>(first, count, k));
    return mbvh_ref::make_leaf(block0, count);
  }
  // Block k of the current leaf (leaf_tris_), padded with its last triangle.
  template <int B>
  TriBlock<B> block_of(uint32_t /*first*/, uint32_t count, uint32_t k) const {
    TriBlock<B> blk;
    for (uint32_t l = 0; l < uint32_t(B); ++l) {
      const uint32_t slot = std::min(k * B + l, count - 1);
      const uint32_t tri = leaf_tris_[slot];
      for (int c = 0; c < 3; ++c) {
        const Vec3 v = scene_.vertex(tri, c);
        blk.v[c][0][l] = v.x, blk.v[c][1][l] = v.y, blk.v[c][2][l] = v.z;
      }
      blk.prim[l] = tri;
    }
    return blk;
  }

  const void* reserved_[2] = {nullptr, nullptr};
  const Scene& scene_;
  const BVH& bvh_;
  const MBVHBuildParams& p_;
  MBVH<N, W>& out_;
  std::vector<uint32_t> first_, count_, order_;
  std::vector<uint32_t> leaf_tris_;  // the distinct triangles of the leaf being packed
  std::vector<std::array<double, N + 1>> fstack_;  // optimise: F of the nodes whose parent is to come
  std::vector<std::array<uint8_t, N + 1>> split_;
  std::vector<uint8_t> leaf_, node_split_;
  double leaf_depth_sum_ = 0;
};

// The statistics that follow from the arrays alone (collapse and concat).
template <int N, int W>
void count_arrays(MBVH<N, W>& m) {
  MBVHStats& s = m.stats;
  s.width = N, s.tri_width = W;
  s.nodes = uint32_t(m.nodes.size());
  s.blocks = uint32_t(m.blocks.size() + m.small.size());
  s.node_bytes = m.nodes.size() * sizeof(MBVHNode<N>);
  s.tri_bytes = m.blocks.size() * sizeof(TriBlock<W>) + m.small.size() * sizeof(TriBlock<4>);
  uint64_t children = 0;
  for (const MBVHNode<N>& n : m.nodes) children += n.num_children;
  s.avg_children = s.nodes ? double(children) / s.nodes : 0.0;
  s.avg_leaf_tris = s.leaves ? double(s.triangles) / s.leaves : 0.0;
  const double lanes = double(m.blocks.size()) * W + double(m.small.size()) * 4;
  s.lane_fill = lanes > 0 ? double(s.triangles) / lanes : 0.0;
  for (int a = 0; a < 3; ++a) {
    float k = 0.f;
    for (const MBVHNode<N>& n : m.nodes)
      for (int i = 0; i < N; ++i)
        for (const float x : {n.box[a][i], n.box[3 + a][i]})
          if (std::isfinite(x)) k = std::max(k, std::fabs(x));
    m.coord_bound[a] = k;
  }
}

}  // namespace

template <int N, int W>
MBVH<N, W> MBVH<N, W>::collapse(const Scene& scene, const BVH& bvh, const MBVHBuildParams& params) {
  const auto t0 = std::chrono::steady_clock::now();
  MBVH m;
  Collapser<N, W> c(scene, bvh, params, m);
  c.run();
  MBVHStats& s = m.stats;
  s.triangles = uint32_t(bvh.prim_index.size());
  s.bvh_build_ms = bvh.stats.build_ms;
  s.avg_leaf_depth = s.leaves ? c.leaf_depth_sum() / s.leaves : 0.0;
  count_arrays(m);
  double cost = 0;
  AABB root;
  for (const Node& n : m.nodes)
    for (uint32_t i = 0; i < n.num_children; ++i) root.grow(n.child_box(int(i)));
  const double root_area = std::max(1e-30f, root.area());
  // SAH cost with the thesis' unit costs: one per node visit, one per SIMD block test.
  for (const Node& n : m.nodes) {
    for (uint32_t i = 0; i < n.num_children; ++i) {
      const double a = n.child_box(int(i)).area() / root_area;
      const uint32_t nt = mbvh_ref::num_tris(n.ref[i]);
      cost += !mbvh_ref::is_leaf(n.ref[i]) ? a : nt <= m.small_leaf ? 0.5 * a : a * double((nt + W - 1) / W);
    }
  }
  s.sah_cost = cost + (m.nodes[0].num_children ? 1.0 : 0.0);
  if (!c.nodes_in_place()) move_to_huge_pages(m.nodes);
  if (!c.blocks_in_place()) move_to_huge_pages(m.blocks);
  move_to_huge_pages(m.small);
  s.collapse_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return m;
}

template <int N, int W>
MBVH<N, W> MBVH<N, W>::concat(std::vector<MBVH>&& parts, std::vector<Placement>* where) {
  MBVH m;
  size_t nodes = 0, blocks = 0, small = 0;
  for (const MBVH& p : parts) {
    nodes += p.nodes.size(), blocks += p.blocks.size(), small += p.small.size();
    if (!p.nodes.empty()) m.small_leaf = p.small_leaf;
  }
  if (blocks > mbvh_ref::kMaxBlocks || small > mbvh_ref::kMaxBlocks)
    throw std::runtime_error("mbvh: too many triangle blocks");
  // Exact sizes, so the arrays fill these blocks in place: on huge pages without a final copy.
  reserve_on_huge_pages(m.nodes, nodes);
  reserve_on_huge_pages(m.blocks, blocks);
  reserve_on_huge_pages(m.small, small);
  if (where) where->assign(parts.size(), {});
  double leaf_depth_sum = 0;
  for (size_t k = 0; k < parts.size(); ++k) {
    MBVH& p = parts[k];
    const uint32_t nb = uint32_t(m.nodes.size()), bb = uint32_t(m.blocks.size()), sb = uint32_t(m.small.size());
    if (where) (*where)[k] = {nb, bb, sb};
    if (p.nodes.empty()) continue;
    if (p.small_leaf != m.small_leaf) throw std::logic_error("mbvh: concat of parts with different small leaves");
    for (Node n : p.nodes) {
      for (uint32_t i = 0; i < n.num_children; ++i) {
        const uint32_t r = n.ref[i], nt = mbvh_ref::num_tris(r);
        n.ref[i] = !mbvh_ref::is_leaf(r) ? r + nb
                                         : mbvh_ref::make_leaf(mbvh_ref::first_block(r) + (nt <= m.small_leaf ? sb : bb), nt);
      }
      m.nodes.push_back(n);
    }
    m.blocks.insert(m.blocks.end(), p.blocks.begin(), p.blocks.end());
    m.small.insert(m.small.end(), p.small.begin(), p.small.end());
    m.stats.leaves += p.stats.leaves;
    m.stats.triangles += p.stats.triangles;
    m.stats.max_depth = std::max(m.stats.max_depth, p.stats.max_depth);
    m.stats.bvh_build_ms += p.stats.bvh_build_ms;
    m.stats.collapse_ms += p.stats.collapse_ms;
    leaf_depth_sum += p.stats.avg_leaf_depth * p.stats.leaves;
    p = MBVH{};  // frees the part as soon as it is copied
  }
  m.stats.avg_leaf_depth = m.stats.leaves ? leaf_depth_sum / m.stats.leaves : 0.0;
  count_arrays(m);
  return m;
}

template <int N, int W>
std::vector<uint32_t> MBVH<N, W>::lane_prims() const {
  std::vector<uint32_t> out;
  out.reserve(blocks.size() * W + small.size() * 4);
  for (const Block& b : blocks)
    for (int l = 0; l < W; ++l) out.push_back(b.prim[l]);
  for (const TriBlock<4>& b : small)
    for (int l = 0; l < 4; ++l) out.push_back(b.prim[l]);
  return out;
}

template struct MBVH<4, 4>;
template struct MBVH<8, 4>;
template struct MBVH<8, 8>;


}  // namespace tb
