// Multi-branching BVHs (MBVH, "QBVH"; thesis §2.2 "MBVH traversal" and ch. 5 baseline): N = 4 or 8
// children per node, collapsed from the binary binned-SAH BVH (Dammertz et al. 2008, Wald et al.
// 2008), with the N child boxes stored SoA so that one node test is one SIMD operation per slab.
//
// This header holds the layout and its builder (the collapse). What reads the layout — the N-wide
// node test, the triangle-block test and the ordered single-ray traversal shared by mbvh4_single,
// mbvh8_single, mbvh_rs and raygrid — is traversal/mbvh_traverse.h.
#pragma once
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "structures/aligned.h"
#include "structures/bvh.h"
#include "structures/scene.h"
#include "structures/structure_cache.h"
#include "structures/triangles.h"

namespace tb {

// ---------------------------------------------------------------------------------------------
// Layout

// A child reference is one 32-bit word: an interior child is its node index; a leaf has the top
// bit set, its first triangle block in bits 30..6 and its triangle count minus one in bits 5..0.
// Keeping the leaf inside the parent's slot saves a node fetch per leaf visit.
namespace mbvh_ref {
inline constexpr uint32_t kLeaf = 0x80000000u;
inline constexpr uint32_t kMaxLeafTris = 64;
inline constexpr uint32_t kMaxBlocks = 1u << 25;
constexpr bool is_leaf(uint32_t r) { return (r & kLeaf) != 0; }
constexpr uint32_t make_leaf(uint32_t first_block, uint32_t ntris) { return kLeaf | first_block << 6 | (ntris - 1); }
constexpr uint32_t first_block(uint32_t r) { return (r >> 6) & (kMaxBlocks - 1); }
constexpr uint32_t num_tris(uint32_t r) { return (r & 63u) + 1; }
}  // namespace mbvh_ref

// N child boxes SoA: box[0..2] = lo x,y,z, box[3..5] = hi x,y,z, N floats each. Valid children
// come first; unused slots hold an empty box (lo = +inf, hi = -inf) that no ray enters, so the
// traversal needs no validity mask. 128 bytes (N = 4) or 256 bytes (N = 8): whole cache lines.
template <int N>
struct alignas(64) MBVHNode {
  float box[6][N];
  uint32_t ref[N];
  uint32_t num_children;
  AABB child_box(int i) const { return {{box[0][i], box[1][i], box[2][i]}, {box[3][i], box[4][i], box[5][i]}}; }
};
static_assert(sizeof(MBVHNode<4>) == 128 && sizeof(MBVHNode<8>) == 256);

// W triangles SoA for the SIMD watertight test (v[corner][axis][lane]) and their scene indices:
// 40 bytes per triangle. Nothing else is precomputed: the watertight decision must come from
// the vertices themselves (shared edges give exactly negated edge functions), and the hit
// distance of the rare candidate that passes it is computed in double from the vertices (as in
// intersect_watertight). A leaf's last block is padded with copies of its last triangle, so
// every lane is a real triangle: no mask, and a duplicate can never report a different hit.
template <int W>
struct alignas(W * 4) TriBlock {
  float v[3][3][W];
  uint32_t prim[W];
};
static_assert(sizeof(TriBlock<4>) == 160 && sizeof(TriBlock<8>) == 320);

struct MBVHBuildParams {
  BVHBuildParams bvh;  // the binary BVH that is collapsed
  // Binary subtrees with at most `merge` triangles become one leaf (one or two SIMD blocks instead
  // of a node visit and several partly filled blocks); 0 disables merging. With the SAH collapse,
  // the largest leaf it may form.
  int merge = 0;
  // false: greedy collapse (open the largest child until N). true: the SAH-optimal collapse by
  // dynamic programming over the binary tree (Ylitie, Karras, Laine 2017, §3.2): every binary
  // subtree becomes a leaf, a node, or is dissolved into up to N slots, whichever minimises
  // sum(area * node cost) + sum(area * block tests * tri_cost / 100).
  bool sah_collapse = false;
  int tri_cost = 100;  // cost of one triangle-block test in percent of a node visit
  // SAH collapse: each triangle of a leaf adds this cost, in percent of a node visit, on top of its
  // blocks' tri_cost. A block tests its W triangles at once, so with blocks alone a leaf of 1 and
  // one of W triangles cost the same and every subtree of up to W triangles becomes one leaf, however
  // far apart its triangles lie; but each triangle a ray's line crosses is a candidate whose
  // distance is computed in double (traversal/mbvh_traverse.h), which a node visit could have culled.
  int prim_cost = 0;
  // Which triangles prim_cost charges: those whose box, clipped to the leaf's, has at least this
  // share of the leaf box's surface area (0: every triangle). A leaf of small neighbouring triangles
  // (a scanned mesh) is then charged little; one of triangles as large as the leaf (walls, floors,
  // steps), whose lines most rays that enter the leaf cross, fully. Neither parameter changes leaf
  // sizes monotonically (a node's cost holds its children's charges too): docs/PERFORMANCE.md,
  // session 16, measures them; both 0 by default.
  float prim_share = 0.f;
  // 8-wide blocks: leaves of up to `small` triangles (0 or 4) take a 4-wide block instead.
  int small = 4;
  std::string key(int width, int tri_width) const;
};

struct MBVHStats {
  uint32_t width = 0, tri_width = 0;
  uint32_t nodes = 0, leaves = 0, blocks = 0, triangles = 0, max_depth = 0;
  double avg_children = 0, avg_leaf_tris = 0, lane_fill = 0;  // lane_fill: real triangles / block lanes
  double sah_cost = 0, bvh_build_ms = 0, collapse_ms = 0;
  double avg_leaf_depth = 0;  // mean depth of the leaves (children of the root: 1)
  size_t node_bytes = 0, tri_bytes = 0;
  std::string describe() const;
};

template <int N, int W>
struct MBVH {
  static constexpr int kWidth = N, kTriWidth = W;
  using Node = MBVHNode<N>;
  using Block = TriBlock<W>;
  aligned_vector<Node> nodes;    // nodes[0] = root (always an interior node, possibly with 0 or 1 child)
  aligned_vector<Block> blocks;  // leaf triangles in depth-first leaf order
  // With 8-wide blocks, leaves of at most 4 triangles take one 4-wide block here instead (the
  // leaf's triangle count says which array): half the bytes of a mostly empty 8-wide block.
  aligned_vector<TriBlock<4>> small;
  uint32_t small_leaf = 0;  // leaves of at most this many triangles are small (0 or 4; 0 when W = 4)
  MBVHStats stats;
  // Per axis the largest |coordinate| of any finite child-box plane (set with the stats): the
  // traversal's fused node test bounds its rounding error by it (traversal/kernels.h,
  // FusedPlanes). +inf until set, which only makes that bound useless (every axis left out: no
  // box culled), never wrong.
  float coord_bound[3] = {INFINITY, INFINITY, INFINITY};

  // Collapses the binary BVH (whose subtrees hold contiguous ranges of prim_index). Greedy
  // (Dammertz et al. 2008, the thesis' construction): start from the binary node's two children
  // and repeatedly open the interior child with the largest surface area until there are N.
  // SAH (params.sah_collapse): the dynamic programme described at MBVHBuildParams.
  // The binary tree may be over any primitive references (BVH::build over a span): the blocks
  // take prim_index's ids as scene triangles.
  static MBVH collapse(const Scene& scene, const BVH& bvh, const MBVHBuildParams& params);
  // Where concat put one part: its root node and its first block (in `blocks`, or in `small`
  // for a part whose blocks are all small).
  struct Placement {
    uint32_t root = 0, first_block = 0, first_small = 0;
  };
  // Several wide trees collapsed on their own (in parallel, say) in one pair of arrays, part
  // after part, each part's nodes and blocks contiguous and in their own order, child references
  // rebased (RayGrid's per-leaf mini-MBVHs, structures/octree.h). The parts are consumed; `where`
  // receives each one's placement. Stats: sums and means over the parts (sah_cost 0: the parts
  // have different roots); a part with no nodes takes no space.
  static MBVH concat(std::vector<MBVH>&& parts, std::vector<Placement>* where = nullptr);
  // Scene triangle of every block lane (block * W + lane, then the small blocks' lanes): the
  // order of the TriangleSet the scalar kernels (--kernel moller/plane/plane_rcp) index.
  std::vector<uint32_t> lane_prims() const;
  uint32_t small_lane(uint32_t block, uint32_t lane) const { return uint32_t(blocks.size()) * W + block * 4 + lane; }
};
extern template struct MBVH<4, 4>;
extern template struct MBVH<8, 4>;
extern template struct MBVH<8, 8>;

// The structure and, for the scalar kernels, their triangle set in lane order.
template <int N, int W>
struct MBVHData {
  static constexpr int kN = N, kW = W;
  std::shared_ptr<const MBVH<N, W>> mbvh;
  std::shared_ptr<const TriangleSet> tris;  // null for the watertight kernel (it reads the blocks)
};
// The triangle bytes a traversal reads: blocks (+ the scalar kernels' triangle set when one is used).
template <int N, int W>
size_t mbvh_prim_bytes(const MBVHData<N, W>& d, TriKernel k) {
  return d.mbvh->stats.tri_bytes + (d.tris ? d.tris->size() * (TriangleSet::bytes(k) + sizeof(uint32_t)) : 0);
}

// mbvh_params and fetch_mbvh (a scheme's config -> MBVHBuildParams; the cached MBVH) live in
// traversal/mbvh_fetch.h.

}  // namespace tb
