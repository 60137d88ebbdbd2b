#include "structures/cwbvh.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

namespace tb {

namespace {

// volatile-free but opaque to constant folding across the MXCSR change: the decode, one fused
// multiply-add in float (one rounding, which the traversal's error bound in
// traversal/cwbvh_traverse.h assumes). It equals a multiply then add wherever q * s is finite
// (q * 2^e is exact then); where q * 2^e overflows (e >= 121, only for coordinates near the float
// range's end) the fused form stays finite, and the builder checks the fused one.
[[gnu::noinline]] float decode_f(float p, float s, float q) { return std::fma(q, s, p); }

}  // namespace

float cw_decode(float p, float s, uint8_t q) { return decode_f(p, s, float(q)); }

int8_t cw_exponent(float p, float hi_max) {
  auto ok = [&](int e) {
    const float top = cw_decode(p, cw_scale(int8_t(e)), 255);
    return top >= hi_max && top > p;  // > p: unused slots (lo = 255, hi = 0) stay inverted
  };
  const double ext = double(hi_max) - double(p);
  int e = ext > 0 ? int(std::ceil(std::log2(ext / 255.0))) : -126;
  e = std::clamp(e, -126, 127);
  while (e < 127 && !ok(e)) ++e;
  while (e > -126 && ok(e - 1)) --e;
  return int8_t(e);
}

namespace {
AABB decode_box(const CWNode& n, int slot) {
  AABB b;
  for (int a = 0; a < 3; ++a) {
    const float s = cw_scale(n.e[a]);
    b.lo[a] = cw_decode(n.p[a], s, n.qlo[a][slot]);
    b.hi[a] = cw_decode(n.p[a], s, n.qhi[a][slot]);
  }
  return b;
}
}  // namespace

uint8_t cw_quantize_lo(float p, float s, float lo) {
  int q = int(std::clamp(std::floor((double(lo) - p) / s), 0.0, 255.0));
  while (q > 0 && cw_decode(p, s, uint8_t(q)) > lo) --q;
  while (q < 255 && cw_decode(p, s, uint8_t(q + 1)) <= lo) ++q;
  return uint8_t(q);
}

uint8_t cw_quantize_hi(float p, float s, float hi) {
  int q = int(std::clamp(std::ceil((double(hi) - p) / s), 0.0, 255.0));
  while (q < 255 && cw_decode(p, s, uint8_t(q)) < hi) ++q;
  while (q > 0 && cw_decode(p, s, uint8_t(q - 1)) >= hi) --q;
  return uint8_t(q);
}

std::string CWBVHStats::describe() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "nodes=%u full_nodes=%u leaves=%u blocks=%u leaf_blocks=%s max_depth=%u avg_children=%.2f bytes_per_node=%zu "
                "node_bytes=%zu tri_bytes=%zu box_growth=%.4f compress_ms=%.1f",
                nodes, full_nodes, leaves, blocks, indexed_leaves ? "indexed" : "mbvh8", max_depth, avg_children,
                nodes ? node_bytes / nodes : size_t(0), node_bytes,
                tri_bytes, box_growth, compress_ms);
  return buf;
}

bool CWBVH::slot_used(uint32_t node, int slot) const {
  if (node & kCWFull) {
    const MBVHNode<8>& f = full[node & ~kCWFull];
    return f.box[0][slot] <= f.box[3][slot];
  }
  const CWNode& n = nodes[node];
  return n.qlo[0][slot] <= n.qhi[0][slot] || (n.imask >> slot & 1);
}

AABB CWBVH::child_box(uint32_t node, int slot) const {
  if (node & kCWFull) return full[node & ~kCWFull].child_box(slot);
  const FlushDenormals ftz;
  return decode_box(nodes[node], slot);
}

uint32_t CWBVH::child_ref(uint32_t node, int slot) const {
  if (!slot_used(node, slot)) return 0;
  if (node & kCWFull) {
    const uint32_t r = full[node & ~kCWFull].ref[slot];
    return mbvh_ref::is_leaf(r) && leaves == CWLeaves::blocks ? cw_leaf_to_mbvh(r) : r;
  }
  const CWNode& n = nodes[node];
  if (n.imask >> slot & 1) return n.child_base + n.meta[slot];
  const uint32_t r = n.leaf_base + n.meta[slot];
  return leaves == CWLeaves::blocks ? cw_leaf_to_mbvh(r) : r;
}

std::array<int8_t, 8> cw_octant_slots(const MBVHNode<8>& n) {
  std::array<int8_t, 8> child{-1, -1, -1, -1, -1, -1, -1, -1};
  const int nc = int(n.num_children);
  AABB u;
  for (int i = 0; i < nc; ++i) u.grow(n.child_box(i));
  double cost[8][8];
  for (int i = 0; i < nc; ++i) {
    const AABB b = n.child_box(i);
    for (int s = 0; s < 8; ++s) {
      cost[i][s] = 0;
      for (int a = 0; a < 3; ++a) {
        // Centroids relative to the node's (in double: no overflow at any coordinate).
        const double c = (double(b.lo[a]) + b.hi[a]) - (double(u.lo[a]) + u.hi[a]);
        cost[i][s] += (s >> a & 1) ? -c : c;
      }
    }
  }
  bool placed[8] = {};
  for (int k = 0; k < nc; ++k) {
    int bi = -1, bs = -1;
    for (int i = 0; i < nc; ++i) {
      if (placed[i]) continue;
      for (int s = 0; s < 8; ++s)
        if (child[s] < 0 && (bi < 0 || cost[i][s] < cost[bi][bs])) bi = i, bs = s;
    }
    placed[bi] = true;
    child[bs] = int8_t(bi);
  }
  return child;
}

namespace {

// The MBVH nodes kept uncompressed (structures/cwbvh.h, "Uncompressed top"): the `budget` nodes of
// largest box area, the root first and each node after its parent (a max-heap of the frontier;
// ties to the lower node index).
std::vector<uint8_t> full_top(const MBVH<8, 8>& m, size_t budget) {
  std::vector<uint8_t> full(m.nodes.size(), 0);
  std::vector<std::pair<float, uint32_t>> frontier;  // (area, node); the root's area is taken as +inf
  if (budget && !m.nodes.empty()) frontier.push_back({INFINITY, 0});
  const auto later = [](const auto& a, const auto& b) { return a.first < b.first || (a.first == b.first && a.second > b.second); };
  for (size_t taken = 0; taken < budget && !frontier.empty(); ++taken) {
    std::pop_heap(frontier.begin(), frontier.end(), later);
    const uint32_t n = frontier.back().second;
    frontier.pop_back();
    full[n] = 1;
    const MBVHNode<8>& nd = m.nodes[n];
    for (uint32_t i = 0; i < nd.num_children; ++i) {
      if (mbvh_ref::is_leaf(nd.ref[i])) continue;
      frontier.push_back({nd.child_box(int(i)).area(), nd.ref[i]});
      std::push_heap(frontier.begin(), frontier.end(), later);
    }
  }
  return full;
}

// Appends leaf `ref`'s triangles (its blocks' real lanes, in order) as indexed blocks and returns
// how many. Packing: a block starts with the first triangle left, then repeatedly takes the
// triangle left that adds the fewest vertices to its table (ties: the earliest), while the table
// holds at most 8 distinct vertices and the block 8 triangles. Vertices are told apart by their
// bits (-0 and +0 stay two vertices: the test must see the scene's floats).
uint32_t append_indexed_leaf(const MBVH<8, 8>& m, uint32_t ref, aligned_vector<CWTriBlock>& out) {
  struct Tri {
    uint32_t bits[3][3];  // corner, axis
    uint32_t prim;
  };
  // Fixed arrays, no allocation per leaf (compress runs this for every leaf of the tree).
  const uint32_t ntris = mbvh_ref::num_tris(ref), first = mbvh_ref::first_block(ref);
  std::array<Tri, kCWMaxLeafTris> left;  // compress refuses larger leaves
  uint32_t nleft = 0;
  for (uint32_t t = 0; t < ntris; ++t) {
    const TriBlock<8>& b = m.blocks[first + t / 8];
    Tri& tri = left[nleft++];
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) tri.bits[c][a] = std::bit_cast<uint32_t>(b.v[c][a][t % 8]);
    tri.prim = b.prim[t % 8];
  }
  const auto same = [](const uint32_t (&a)[3], const uint32_t (&b)[3]) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; };
  uint32_t made = 0;
  while (nleft) {
    CWTriBlock blk{};
    uint32_t table[8][3], nv = 0;
    const auto slot_of = [&](const uint32_t (&v)[3]) {
      for (uint32_t i = 0; i < nv; ++i)
        if (same(table[i], v)) return int(i);
      return -1;
    };
    const auto new_vertices = [&](const Tri& t) {
      uint32_t n = 0;
      for (int c = 0; c < 3; ++c) {
        bool dup = slot_of(t.bits[c]) >= 0;
        for (int d = 0; d < c && !dup; ++d) dup = same(t.bits[c], t.bits[d]);
        n += !dup;
      }
      return n;
    };
    uint32_t lanes = 0;
    while (lanes < 8) {
      int best = -1;
      uint32_t best_new = 4;
      for (uint32_t i = 0; i < nleft; ++i) {
        const uint32_t n = new_vertices(left[i]);
        if (nv + n <= 8 && n < best_new) best = int(i), best_new = n;
        if (lanes == 0) break;  // a block starts with the first triangle left
      }
      if (best < 0) break;
      const Tri t = left[size_t(best)];
      std::copy(left.begin() + best + 1, left.begin() + nleft, left.begin() + best);
      --nleft;
      for (int c = 0; c < 3; ++c) {
        int sl = slot_of(t.bits[c]);
        if (sl < 0) {
          sl = int(nv);
          std::copy(t.bits[c], t.bits[c] + 3, table[nv++]);
        }
        blk.idx[c][lanes] = uint8_t(sl);
      }
      blk.prim[lanes] = t.prim;
      ++lanes;
    }
    blk.lanes = uint8_t(lanes);
    for (uint32_t l = lanes; l < 8; ++l) {  // padding lanes repeat the last triangle
      for (int c = 0; c < 3; ++c) blk.idx[c][l] = blk.idx[c][lanes - 1];
      blk.prim[l] = blk.prim[lanes - 1];
    }
    for (int a = 0; a < 3; ++a)  // unused table slots repeat slot 0 (finite, never indexed)
      for (uint32_t i = 0; i < 8; ++i) blk.v[a][i] = std::bit_cast<float>(table[i < nv ? i : 0][a]);
    out.push_back(blk);
    ++made;
  }
  out.back().last = 1;
  return made;
}

}  // namespace

std::array<int8_t, 8> cw_slots(const MBVHNode<8>& n, CWSlots slots) {
  if (slots == CWSlots::octant) return cw_octant_slots(n);
  std::array<int8_t, 8> child;
  for (int i = 0; i < 8; ++i) child[size_t(i)] = i < int(n.num_children) ? int8_t(i) : int8_t(-1);
  return child;
}

CWBVH CWBVH::compress(const MBVH<8, 8>& m, double full_share, CWSlots slots, CWLeaves leaves) {
  const auto t0 = std::chrono::steady_clock::now();
  if (m.small_leaf != 0 || !m.small.empty())
    throw std::invalid_argument("cwbvh: needs an MBVH8 with 8-wide blocks only (small=0)");
  if (!(full_share >= 0 && full_share <= 1)) throw std::invalid_argument("cwbvh: full_share must be in [0, 1]");
  const FlushDenormals ftz;
  CWBVH out;
  const std::vector<uint8_t> is_full = full_top(m, size_t(std::floor(full_share * double(m.nodes.size()))));
  out.nodes.reserve(m.nodes.size());
  out.leaves = leaves;
  const bool indexed = leaves == CWLeaves::indexed;
  if (indexed) {
    out.iblocks.reserve(m.blocks.size() * 2);
  } else {
    out.blocks.reserve(m.blocks.size());
  }
  struct Item {
    uint32_t src, dst, depth;  // dst: index in out.full for a full node, in out.nodes otherwise
  };
  std::vector<Item> stack;
  if (!m.nodes.empty() && is_full[0]) {
    out.full.emplace_back();
    out.root = kCWFull;
  } else {
    out.nodes.emplace_back();
  }
  if (!m.nodes.empty()) stack.push_back({0, 0, 1});
  double growth = 0;
  uint64_t growth_n = 0, children = 0;
  double bound[3] = {0, 0, 0};
  int e_min = 127, e_max = -128;
  // Where the next leaf block goes (either kind).
  const auto next_block = [&] { return uint32_t(indexed ? out.iblocks.size() : out.blocks.size()); };
  // Appends a leaf's blocks; returns its triangle count (indexed: its block count).
  const auto copy_leaf = [&](uint32_t ref) {
    const uint32_t ntris = mbvh_ref::num_tris(ref), nblocks = (ntris + 7) / 8;
    if (ntris > kCWMaxLeafTris)
      throw std::invalid_argument("cwbvh: a leaf of " + std::to_string(ntris) + " triangles (at most " +
                                  std::to_string(kCWMaxLeafTris) + ": merge <= " + std::to_string(kCWMaxLeafTris) + ")");
    out.stats.leaves++;
    if (indexed) return append_indexed_leaf(m, ref, out.iblocks);
    for (uint32_t k = 0; k < nblocks; ++k) out.blocks.push_back(m.blocks[mbvh_ref::first_block(ref) + k]);
    return ntris;
  };
  const auto leaf_ref = [&](uint32_t first_block, uint32_t ntris) {
    return indexed ? cw_ileaf_ref(first_block) : cw_leaf_ref(first_block, ntris);
  };
  const uint32_t max_blocks = indexed ? kCWMaxIndexedBlocks : kCWMaxBlocks;
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    const MBVHNode<8>& src = m.nodes[it.src];
    out.stats.max_depth = std::max(out.stats.max_depth, it.depth);
    const uint32_t nc = src.num_children;
    children += nc;
    if (is_full[it.src]) {
      // Float boxes, slots as the compressed nodes' (the octant order reads both kinds alike);
      // children allocated one by one (a full node's references are explicit).
      MBVHNode<8> f{};
      f.num_children = nc;
      const std::array<int8_t, 8> slot_child = cw_slots(src, slots);
      const uint32_t first_block = next_block();
      std::vector<Item> kids;
      for (int i = 0; i < 8; ++i) {
        const int c = slot_child[size_t(i)];
        for (int a = 0; a < 3; ++a) f.box[a][i] = INFINITY, f.box[3 + a][i] = -INFINITY;
        if (c < 0) continue;
        const AABB b = src.child_box(c);
        for (int a = 0; a < 3; ++a) {
          f.box[a][i] = b.lo[a], f.box[3 + a][i] = b.hi[a];
          bound[a] = std::max({bound[a], std::fabs(double(b.lo[a])), std::fabs(double(b.hi[a]))});
        }
        const uint32_t ref = src.ref[c];
        if (mbvh_ref::is_leaf(ref)) {
          const uint32_t at = next_block();
          f.ref[i] = leaf_ref(at, copy_leaf(ref));
        } else if (is_full[ref]) {
          f.ref[i] = kCWFull | uint32_t(out.full.size());
          kids.push_back({ref, uint32_t(out.full.size()), it.depth + 1});
          out.full.emplace_back();
        } else {
          f.ref[i] = uint32_t(out.nodes.size());
          kids.push_back({ref, uint32_t(out.nodes.size()), it.depth + 1});
          out.nodes.emplace_back();
        }
      }
      if (next_block() >= max_blocks) throw std::invalid_argument("cwbvh: too many triangle blocks");
      // Unused slots (never entered: their planes are infinite) still reference a real triangle.
      for (int i = 0; i < 8; ++i)
        if (slot_child[size_t(i)] < 0) f.ref[i] = leaf_ref(next_block() > first_block ? first_block : 0, 1);
      out.full[it.dst] = f;
      for (auto k = kids.rbegin(); k != kids.rend(); ++k) stack.push_back(*k);
      continue;
    }
    // A compressed node; its children are compressed too (full_top takes a node only after its
    // parent).
    CWNode n{};
    // The grid: origin at the union's lo corner, cell size so that 255 cells reach its hi.
    AABB u;
    for (uint32_t i = 0; i < nc; ++i) u.grow(src.child_box(int(i)));
    for (int a = 0; a < 3; ++a) {
      n.p[a] = nc ? u.lo[a] : 0.f;
      n.e[a] = cw_exponent(n.p[a], nc ? u.hi[a] : 0.f);
    }
    // Interior children consecutively, then this node's leaf blocks consecutively, both in slot
    // order.
    n.child_base = uint32_t(out.nodes.size());
    const uint32_t first_block = next_block();
    uint32_t interior = 0, block_off = 0;
    std::vector<Item> kids;
    const std::array<int8_t, 8> slot_child = cw_slots(src, slots);
    for (int i = 0; i < 8; ++i) {
      const int c = slot_child[size_t(i)];
      if (c < 0) {  // unused: lo > hi on every axis
        for (int a = 0; a < 3; ++a) n.qlo[a][i] = 255, n.qhi[a][i] = 0;
        continue;
      }
      const AABB b = src.child_box(c);
      for (int a = 0; a < 3; ++a) {
        const float s = cw_scale(n.e[a]);
        n.qlo[a][i] = cw_quantize_lo(n.p[a], s, b.lo[a]);
        n.qhi[a][i] = cw_quantize_hi(n.p[a], s, b.hi[a]);
        // Where cells are below the origin's ulp several q decode alike: keep lo <= hi so that
        // only unused slots look inverted (a smaller q_lo still decodes at or below lo).
        n.qlo[a][i] = std::min(n.qlo[a][i], n.qhi[a][i]);
      }
      const uint32_t ref = src.ref[c];
      if (mbvh_ref::is_leaf(ref)) {
        if (indexed) {
          // At most 8 leaves of at most 8 blocks (a block holds any 2 triangles): offsets < 64.
          n.meta[i] = uint8_t(block_off);
          block_off += copy_leaf(ref);
        } else {
          const uint32_t ntris = copy_leaf(ref), nblocks = (ntris + 7) / 8;
          if (block_off + nblocks > 16) throw std::invalid_argument("cwbvh: more than 16 leaf blocks under one node");
          n.meta[i] = uint8_t(block_off << 4 | (ntris - 1));
          block_off += nblocks;
        }
      } else {
        n.imask |= uint8_t(1u << i);
        n.meta[i] = uint8_t(interior);
        kids.push_back({ref, n.child_base + interior, it.depth + 1});
        ++interior;
      }
      const float ta = b.area();
      if (ta > 0) growth += double(decode_box(n, i).area()) / ta - 1.0, growth_n++;
    }
    // Unused slots (meta 0) reference a real triangle: the node's first leaf block, or block 0.
    if (first_block + block_off >= max_blocks) throw std::invalid_argument("cwbvh: too many triangle blocks");
    n.leaf_base = leaf_ref(block_off ? first_block : 0, 1);
    for (int a = 0; a < 3; ++a) {
      bound[a] = std::max(bound[a], std::fabs(double(n.p[a])) + 255.0 * double(cw_scale(n.e[a])));
      e_min = std::min(e_min, int(n.e[a])), e_max = std::max(e_max, int(n.e[a]));
    }
    out.nodes.resize(out.nodes.size() + interior);
    out.nodes[it.dst] = n;
    for (auto k = kids.rbegin(); k != kids.rend(); ++k) stack.push_back(*k);
  }
  if (e_min <= e_max) out.e_min = e_min, out.e_max = e_max;
  for (int a = 0; a < 3; ++a) {  // rounded up to a float
    out.coord_bound[a] = float(bound[a]);
    if (double(out.coord_bound[a]) < bound[a]) out.coord_bound[a] = std::nextafter(out.coord_bound[a], INFINITY);
  }
  CWBVHStats& s = out.stats;
  s.nodes = uint32_t(out.nodes.size() + out.full.size());
  s.full_nodes = uint32_t(out.full.size());
  s.blocks = next_block();
  s.indexed_leaves = indexed;
  s.node_bytes = out.nodes.size() * sizeof(CWNode) + out.full.size() * sizeof(MBVHNode<8>);
  s.tri_bytes = out.blocks.size() * sizeof(TriBlock<8>) + out.iblocks.size() * sizeof(CWTriBlock);
  s.avg_children = s.nodes ? double(children) / s.nodes : 0;
  s.box_growth = growth_n ? growth / double(growth_n) : 0;
  move_to_huge_pages(out.nodes);
  move_to_huge_pages(out.full);
  move_to_huge_pages(out.blocks);
  move_to_huge_pages(out.iblocks);
  s.compress_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

}  // namespace tb
