// Compressed 8-wide BVH (CS348K lecture 18 "compression"; Ylitie, Karras and Laine 2017,
// "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", §3.1): the child
// boxes of a node are stored as 8-bit offsets in the node's local grid — an fp32 origin p and a
// power-of-two cell size 2^e per axis — instead of 6 floats each. 80 bytes per node where the
// MBVH8 layout (structures/mbvh.h) takes 256: 10 bytes per child, the lecture's "amortized 10
// bytes per child, 3.2x compression". Optionally a small top of the tree stays uncompressed
// ("Uncompressed top" below; cwbvh_single keeps 4% of its nodes so by default).
//
// Layout (Ylitie et al.'s, adapted to the CPU leaf blocks): interior children of a node are stored
// consecutively from `child_base` (slot i's node is child_base + meta[i]), the triangle blocks of
// its leaf children consecutively from its first leaf block b. A leaf slot's reference is
// leaf_base + meta[i], leaf_base = kLeaf | b << 4 and meta[i] = block offset << 4 | (triangles - 1):
// the compressed leaf reference (cw_leaf_*), so that the traversal forms all 8 references with one
// select and one add. A leaf holds at most 16 triangles and a node's leaves at most 16 blocks.
// Unused slots have meta 0 and no imask bit: their reference is a real one-triangle leaf (the
// node's first block, block 0 where it has none), so a ray that a padded box test lets into an
// unused slot only tests a triangle of the scene.
//
// Child slots (CWSlots): the MBVH8 node's child order (`mbvh`, for traversals that order the
// entered children by distance), or octant-ordered (`octant`; Ylitie et al. 2017 §3.2, ordering
// the children for the octant-aware fixed-order traversal of §4): the builder places the children
// so that, for a ray whose direction has octant o (bit a set: component a negative, as kernels.h's
// plane rows), the slots taken in the order k ^ o, k = 0..7, come approximately near to far
// (cw_octant_slots). A traversal then gets a near-to-far order of the entered children from the
// octant alone, without sorting their distances. Only that traversal gets octant slots: the
// sorted and branching orders break ties of entry distance (keys equal but for their low 3 bits,
// which hold the slot) by slot, and on the MBVH8's order they test fewer leaves: crytek_sponza_partial
// 1.72 -> 1.56 leaves per primary ray, 3.20 -> 2.88 on bounce:2; sponza, conference and bunny
// unchanged (128x128, every node compressed; docs/PERFORMANCE.md, session 23). Children are interior nodes
// and leaf blocks in slot order. Leaves are the MBVH8's TriBlock<8> SoA blocks, tested by the same
// watertight SIMD kernel, or (`leaves=indexed`, cwbvh_single's default) indexed blocks over a
// table of distinct vertices (CWTriBlock below).
//
// Uncompressed top (`full_share`, Benthin, Wald, Woop and Afra 2018, "Compressed-Leaf Bounding
// Volume Hierarchies": compress where most of the memory is, keep full-precision nodes where most
// of the visits are): the nodes of largest box area — the most likely to be entered, by the SAH's
// geometric probability — may be kept as MBVH8 nodes (`full`, 256 bytes, float boxes) up to a
// share of the node count, the rest compressed. The full nodes form a top of the tree (the root
// first; a node's box contains its children's, so its area is at least theirs, and a node is taken
// only after its parent). Their references: a full child is kCWFull | its index in `full`, a
// compressed child its index in `nodes`, a leaf the compressed leaf reference (any block, no
// 16-block limit), an unused slot an empty box (lo = +inf, hi = -inf) with a one-triangle leaf
// reference. Children of compressed nodes are compressed. With 4% of the nodes full, node bytes
// are 0.3125 + 0.04 * 0.6875 = 0.340 of the MBVH8's, and 69-83% of node visits take the
// uncompressed test on crytek_sponza_partial, sponza and spheres:2M (primary and bounce:2;
// docs/PERFORMANCE.md, session 23).
//
// Conservative quantization: a child's box decodes as lo = p + q_lo * 2^e, hi = p + q_hi * 2^e in
// float, one fused multiply-add each in flush-to-zero mode (cw_decode); the builder picks q_lo as
// the largest and q_hi as the smallest 8-bit value for which the decoded box still contains the
// true child box, checking the decoded floats themselves rather than trusting an error bound. The
// decoded box therefore always contains the true box, at any offset and for flat children. The
// traversal (traversal/cwbvh_traverse.h) never forms these floats: its fused plane distances are
// bounded against them, a bound that takes the decode's one rounding into account. Unused slots
// decode to boxes with lo > hi on every axis.
#pragma once
#include <xmmintrin.h>

#include <array>
#include <bit>
#include <cstdint>
#include <string>

#include "structures/aligned.h"
#include "structures/mbvh.h"

namespace tb {

struct alignas(16) CWNode {
  float p[3];          // grid origin (the node's box corner)
  int8_t e[3];         // cell size 2^e per axis
  uint8_t imask;       // bit i: slot i is an interior node
  uint32_t child_base;  // first interior child node
  uint32_t leaf_base;   // kLeaf | first leaf block << 4 (cw_leaf_ref)
  uint8_t meta[8];     // interior: rank among the interior children; leaf: offset << 4 | (tris - 1)
  uint8_t qlo[3][8];   // quantized child boxes, per axis and slot
  uint8_t qhi[3][8];
};
static_assert(sizeof(CWNode) == 80);

// An indexed leaf block (`leaves=indexed`; the "compressed leaves" of Benthin, Wald, Woop and Afra
// 2018 in the simplest lossless form): up to 8 triangles over a table of up to 8 distinct vertices,
// each corner a byte index into the table: 160 bytes where the MBVH8's TriBlock<8> takes 320 and
// repeats a vertex once per triangle that uses it (and once per padding lane). The vertices are the
// scene's floats, bit for bit, so the watertight test computes exactly what it computes on a
// TriBlock<8>: the per-corner operations (origin subtraction, shear) run once per table vertex and
// a lane's corner is a permute of the results, the same values. A leaf takes as many blocks as its
// triangles need for 8 distinct vertices each (compress packs them greedily); `last` ends the leaf.
struct alignas(32) CWTriBlock {
  float v[3][8];      // vertex table: axis, slot
  uint8_t idx[3][8];  // corner c of lane l is vertex slot idx[c][l]
  uint8_t lanes;      // real triangles: lanes 0..lanes-1 (the others repeat lane lanes-1)
  uint8_t last;       // 1 on the last block of its leaf
  uint8_t pad[6];
  uint32_t prim[8];   // scene triangles
};
static_assert(sizeof(CWTriBlock) == 160);

// How a CWBVH stores its leaves: the MBVH8's TriBlock<8> (`blocks`) or indexed (CWTriBlock,
// `iblocks`).
enum class CWLeaves { blocks, indexed };

struct CWBVHStats {
  uint32_t nodes = 0, full_nodes = 0, leaves = 0, blocks = 0, max_depth = 0;  // nodes: compressed and full
  size_t node_bytes = 0, tri_bytes = 0;
  double avg_children = 0;
  double box_growth = 0;  // mean (decoded child area / true child area) - 1, over children with area
  double compress_ms = 0;
  bool indexed_leaves = false;  // CWLeaves::indexed: `blocks` counts CWTriBlocks
  std::string describe() const;
};

enum class CWSlots { mbvh, octant };

// An interior reference to a full (uncompressed) node: kCWFull | index in CWBVH::full. Without
// the bit an interior reference indexes CWBVH::nodes; leaves have mbvh_ref::kLeaf (bit 31).
inline constexpr uint32_t kCWFull = 0x40000000u;

struct CWBVH {
  aligned_vector<CWNode> nodes;          // compressed nodes (nodes[0] = root where `full` is empty)
  aligned_vector<MBVHNode<8>> full;      // the uncompressed top (full[0] = root where not empty)
  uint32_t root = 0;                     // reference of the root: 0 or kCWFull
  aligned_vector<TriBlock<8>> blocks;    // leaf triangles, each node's leaves contiguous (CWLeaves::blocks)
  aligned_vector<CWTriBlock> iblocks;    // the same, indexed (CWLeaves::indexed)
  CWLeaves leaves = CWLeaves::blocks;
  CWBVHStats stats;
  // Per axis an upper bound of |p| + 255 * 2^e over the compressed nodes (so of every coordinate a
  // node's grid can express) and of every finite plane of a full node, rounded up: the traversal's per-ray error bound of its fused plane
  // distances is proportional to it (traversal/cwbvh_traverse.h).
  float coord_bound[3] = {0, 0, 0};
  // The least and the largest cell exponent e of any node and axis: the traversal forms
  // A = 2^e * r by adding e to r's exponent field when every r_exp + e of a ray stays a normal
  // float's exponent (traversal/cwbvh_traverse.h, CWRay::exp_add).
  int e_min = 0, e_max = 0;

  // Re-lays out and quantizes an 8-wide MBVH with 8-wide blocks only (small_leaf = 0) and leaves
  // of at most 16 triangles; throws std::invalid_argument otherwise. full_share (0..1): the share
  // of the nodes kept uncompressed (floor(full_share * nodes) of largest area, see above); slots:
  // the child slot order of every node (see above).
  static CWBVH compress(const MBVH<8, 8>& m, double full_share = 0, CWSlots slots = CWSlots::octant,
                        CWLeaves leaves = CWLeaves::blocks);
  // Of a node given by its CWBVH reference: slot i's box — decoded (conservative; cw_decode per
  // coordinate) for a compressed node, the stored float box for a full one.
  AABB child_box(uint32_t node, int slot) const;
  // Slot i's child in the MBVH reference format (mbvh_ref: leaf = first block and triangle count;
  // with indexed leaves the indexed leaf reference, cw_ileaf_ref),
  // interior children as CWBVH references (index in `nodes`, or kCWFull | index in `full`), 0 for
  // an unused slot of a node with no such child. `node` is a CWBVH reference (either kind).
  uint32_t child_ref(uint32_t node, int slot) const;
  bool slot_used(uint32_t node, int slot) const;  // either kind of reference
};

// The slot assignment of one node (slot -> child index of the MBVH node, -1: unused), exposed for
// tests. Slot s is meant to be entered first by rays of octant s: the cost of child i in slot s is
// its centroid, relative to the node's centroid, projected on the diagonal direction of octant s
// ((-1)^(s>>a&1) per axis a); the assignment of least total cost is approximated greedily: the
// pair (child, free slot) of least cost first, ties to the lower child and slot index.
std::array<int8_t, 8> cw_octant_slots(const MBVHNode<8>& n);
// The slot assignment compress uses: cw_octant_slots, or the MBVH node's own order.
std::array<int8_t, 8> cw_slots(const MBVHNode<8>& n, CWSlots slots);

// The compressed leaf reference: kLeaf | first block << 4 | (triangles - 1), at most 16 triangles
// (kCWMaxLeafTris: the count's 4 bits; indexed leaves keep the limit, so one tree serves both) and
// 2^27 blocks. cw_leaf_to_mbvh gives the MBVH reference the leaf kernels take.
inline constexpr uint32_t kCWMaxLeafTris = 16;
inline constexpr uint32_t kCWMaxBlocks = 1u << 27;
constexpr uint32_t cw_leaf_ref(uint32_t first_block, uint32_t ntris) { return mbvh_ref::kLeaf | first_block << 4 | (ntris - 1); }
// With indexed leaves (CWLeaves::indexed) a leaf reference is kLeaf | its first CWTriBlock (the
// blocks say where the leaf ends), and a compressed node's meta[i] the offset of leaf i's first
// block from the node's first (at most 255).
inline constexpr uint32_t kCWMaxIndexedBlocks = 1u << 30;
constexpr uint32_t cw_ileaf_ref(uint32_t first_block) { return mbvh_ref::kLeaf | first_block; }
constexpr uint32_t cw_ileaf_block(uint32_t r) { return r & ~mbvh_ref::kLeaf; }
constexpr uint32_t cw_leaf_to_mbvh(uint32_t r) {
  return mbvh_ref::make_leaf((r >> 4) & (kCWMaxBlocks - 1), (r & 15u) + 1);
}

// One axis of a node's grid: the cell size 2^e for origin p and largest coordinate hi, and the
// 8-bit offsets of [lo, hi] (exposed for tests).
inline float cw_scale(int8_t e) { return std::bit_cast<float>(uint32_t(int(e) + 127) << 23); }
int8_t cw_exponent(float p, float hi_max);
uint8_t cw_quantize_lo(float p, float s, float lo);
uint8_t cw_quantize_hi(float p, float s, float hi);
float cw_decode(float p, float s, uint8_t q);

// Flush-to-zero and denormals-are-zero for the calling thread while in scope. Every tracing thread
// runs with FTZ/DAZ (harness/trace_runner); the builder's decode checks, child_box and the tests
// of the cw_* functions run in the same mode, the mode the traversal's error bound assumes.
struct FlushDenormals {
  unsigned saved = _mm_getcsr();
  FlushDenormals() { _mm_setcsr(saved | 0x8040); }  // FTZ (bit 15) | DAZ (bit 6)
  ~FlushDenormals() { _mm_setcsr(saved); }
  FlushDenormals(const FlushDenormals&) = delete;
  FlushDenormals& operator=(const FlushDenormals&) = delete;
};

}  // namespace tb
