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
                "nodes=%u leaves=%u blocks=%u max_depth=%u avg_children=%.2f bytes_per_node=%zu node_bytes=%zu "
                "tri_bytes=%zu box_growth=%.4f compress_ms=%.1f",
                nodes, leaves, blocks, max_depth, avg_children, nodes ? node_bytes / nodes : size_t(0), node_bytes,
                tri_bytes, box_growth, compress_ms);
  return buf;
}

bool CWBVH::slot_used(uint32_t node, int slot) const {
  const CWNode& n = nodes[node];
  return n.qlo[0][slot] <= n.qhi[0][slot] || (n.imask >> slot & 1);
}

AABB CWBVH::child_box(uint32_t node, int slot) const {
  const FlushDenormals ftz;
  return decode_box(nodes[node], slot);
}

uint32_t CWBVH::child_ref(uint32_t node, int slot) const {
  const CWNode& n = nodes[node];
  if (n.imask >> slot & 1) return n.child_base + n.meta[slot];
  if (!slot_used(node, slot)) return 0;
  return cw_leaf_to_mbvh(n.leaf_base + n.meta[slot]);
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

CWBVH CWBVH::compress(const MBVH<8, 8>& m) {
  const auto t0 = std::chrono::steady_clock::now();
  if (m.small_leaf != 0 || !m.small.empty())
    throw std::invalid_argument("cwbvh: needs an MBVH8 with 8-wide blocks only (small=0)");
  const FlushDenormals ftz;
  CWBVH out;
  out.nodes.reserve(m.nodes.size());
  out.blocks.reserve(m.blocks.size());
  struct Item {
    uint32_t src, dst, depth;
  };
  std::vector<Item> stack;
  out.nodes.emplace_back();
  if (!m.nodes.empty()) stack.push_back({0, 0, 1});
  double growth = 0;
  uint64_t growth_n = 0, children = 0;
  double bound[3] = {0, 0, 0};
  int e_min = 127, e_max = -128;
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    const MBVHNode<8>& src = m.nodes[it.src];
    CWNode n{};
    out.stats.max_depth = std::max(out.stats.max_depth, it.depth);
    const uint32_t nc = src.num_children;
    children += nc;
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
    const uint32_t first_block = uint32_t(out.blocks.size());
    uint32_t interior = 0, block_off = 0;
    std::vector<Item> kids;
    const std::array<int8_t, 8> slot_child = cw_octant_slots(src);
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
        const uint32_t ntris = mbvh_ref::num_tris(ref), nblocks = (ntris + 7) / 8;
        if (ntris > 16) throw std::invalid_argument("cwbvh: a leaf of " + std::to_string(ntris) + " triangles (at most 16: merge <= 16)");
        if (block_off + nblocks > 16) throw std::invalid_argument("cwbvh: more than 16 leaf blocks under one node");
        n.meta[i] = uint8_t(block_off << 4 | (ntris - 1));
        for (uint32_t k = 0; k < nblocks; ++k) out.blocks.push_back(m.blocks[mbvh_ref::first_block(ref) + k]);
        block_off += nblocks;
        out.stats.leaves++;
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
    if (first_block + block_off >= kCWMaxBlocks) throw std::invalid_argument("cwbvh: too many triangle blocks");
    n.leaf_base = cw_leaf_ref(block_off ? first_block : 0, 1);
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
  s.nodes = uint32_t(out.nodes.size());
  s.blocks = uint32_t(out.blocks.size());
  s.node_bytes = out.nodes.size() * sizeof(CWNode);
  s.tri_bytes = out.blocks.size() * sizeof(TriBlock<8>);
  s.avg_children = s.nodes ? double(children) / s.nodes : 0;
  s.box_growth = growth_n ? growth / double(growth_n) : 0;
  move_to_huge_pages(out.nodes);
  move_to_huge_pages(out.blocks);
  s.compress_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

}  // namespace tb
