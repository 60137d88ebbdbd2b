// The RayGrid structure (thesis §5.3.2): a shallow octree that adapts to local scene complexity,
// with spatial bounds and six neighbour links per node for stack-less leaf-to-leaf ray
// propagation, and per non-empty leaf a 4-wide "mini-MBVH" over the triangles it references.
//
// Octree. A node is subdivided at its centre while it references more than `leaf_prims` triangles
// and is shallower than `max_depth` (§5.4.1: 4096 triangles per leaf is near-optimal for every
// scene of the thesis). As in Toro (Pharr et al. 1997, footnote 6 of §5.3.1) a triangle is
// referenced by every leaf it overlaps. Watertightness needs more than the closed box: a ray's
// position along its walk is computed in float, so a leaf references every triangle that
// overlaps its box grown by `pad` (a few ulps of the scene's coordinates, see Octree::build).
// Then a hit point that float rounding places just across a face is still found, and the
// traversal (traversal/raygrid.cpp) needs no epsilon of its own.
//
// Neighbour links (Samet's "same size or larger" face neighbours): nbr[2*axis + side] is the
// node across that face (side 0 = lo, 1 = hi) with the same size, or the larger leaf that covers
// the whole face when the same-size node does not exist, or kNoNode at the scene boundary. A ray
// leaving a leaf through a face goes to that node and, if it is interior, descends to the leaf
// that contains its exit point (Octree::locate).
//
// Which leaves reference a triangle, and the part of it a leaf sees, come from the project's one
// triangle/box clipper (structures/clip.h, shared with the kD-tree's perfect splits): a triangle
// whose box crosses a padded leaf box is referenced when its clipped polygon is not empty.
//
// Mini-MBVHs (§5.3.2 "MBVH"): per leaf a wide BVH in the layout of structures/mbvh.h (MBVHNode<4>
// or <8>; TriBlock<4> leaves), so the SIMD node and triangle tests of the MBVH schemes apply
// unchanged. Built by the project's one builder path, as the whole-scene MBVHs are: the binary
// binned-SAH BVH over a span of references (BVH::build, structures/bvh.h) — an index subset of the
// scene, each triangle's box clipped to the padded leaf, so a large triangle that crosses many
// leaves only costs box area where it actually is, and the root box is the leaf's geometry bounds
// (OctreeLeaf::cull) that let a ray skip a leaf whose geometry it cannot reach — then the one
// collapse (MBVH::collapse: greedy to 4 wide as Dammertz et al. 2008 and the thesis, or the
// SAH-optimal programme of Ylitie et al. 2017 to 8 wide). The leaves build in parallel, each into
// arrays of its own; MBVH::concat lays them out in one node array and one block array, leaf after
// leaf, so a leaf's nodes and triangles are contiguous in memory (spatial coherence = memory
// coherence).
#pragma once
#include <immintrin.h>

#include <cstdint>
#include <string>
#include <vector>

#include "structures/mbvh.h"
#include "structures/scene.h"
#include "structures/vec3.h"

namespace tb {

struct OctreeParams {
  int leaf_prims = 4096;  // subdivide while a node references more triangles than this ...
  int max_depth = 10;     // ... and is shallower than this (root depth 0)
  // The binary build of each mini-MBVH: bvh.max_leaf (at most this many triangles per binary
  // leaf), bvh.bins (SAH bins per axis) and the spatial splits (bvh.spatial, bvh.split_*: the
  // leaf's references, already clipped to its padded box, are clipped again by the spatial-split
  // builder, structures/bvh_spatial.h; the enclosure rule `split_wall` is relative to the leaf's
  // geometry). Off by default, as the thesis built them. bvh.builder must be travbench's.
  BVHBuildParams bvh;
  int merge = 4;          // binary subtrees of at most this many triangles become one leaf
  // Mini-MBVH width. 4: the thesis' SSE mini-MBVHs, collapsed greedily (`merge` = subtrees of at
  // most that many triangles become one leaf). 8: AVX2 nodes (MBVHNode<8>, one 8-lane box test
  // per ray), collapsed SAH-optimally by structures/mbvh.cpp's dynamic programme (Ylitie et al.
  // 2017; `merge` = the largest leaf it may form), triangles still in 4-wide blocks (Octree::mini8).
  int width = 4;
  int threads = 2;        // mini-MBVH build threads (the structure does not depend on it)
  std::string key() const;
};

inline constexpr uint32_t kNoNode = 0xFFFFFFFFu;

// Face index: 2 * axis + side, side 0 = the lo face, 1 = the hi face.
inline constexpr int face_of(int axis, int side) { return 2 * axis + side; }

struct OctreeNode {
  Vec3 lo, hi;         // closed spatial bounds; children split at mid, sharing the exact float
  Vec3 mid;            // split point (interior nodes)
  uint32_t child = kNoNode;  // interior: first of 8 consecutive children, octant bit a = upper half on axis a
  uint32_t leaf = kNoNode;   // leaf: index into Octree::leaves
  uint32_t parent = kNoNode;
  uint32_t depth = 0;
  uint32_t nbr[6] = {kNoNode, kNoNode, kNoNode, kNoNode, kNoNode, kNoNode};
  bool is_leaf() const { return child == kNoNode; }
};

struct OctreeLeaf {
  uint32_t node = kNoNode;       // its OctreeNode
  uint32_t mbvh_root = kNoNode;  // root of its mini-MBVH in Octree::mini.nodes; kNoNode: no triangles
  uint32_t first_node = 0, num_nodes = 0;    // its mini-MBVH nodes (contiguous)
  uint32_t first_block = 0, num_blocks = 0;  // its triangle blocks (contiguous)
  uint32_t refs = 0;             // triangles referenced
  uint32_t mbvh_depth = 0;       // depth of its deepest mini-MBVH leaf (root = 1)
  double mbvh_leaf_depth = 0;    // average depth of its mini-MBVH leaves
  AABB cull;                     // bounds of its clipped triangles (inside the padded leaf box)
  bool cull_tight = false;       // cull leaves out at least half the leaf's volume: worth a test
  bool empty() const { return mbvh_root == kNoNode; }
};

struct OctreeStats {
  uint32_t nodes = 0, leaves = 0, empty_leaves = 0, max_depth = 0, mbvh_max_depth = 0;
  uint64_t refs = 0, triangles = 0;  // triangle references over all leaves; scene triangles
  double avg_leaf_depth = 0;         // over all leaves
  double avg_prims_per_leaf = 0;     // over non-empty leaves
  double avg_mbvh_nodes = 0;         // mini-MBVH nodes per non-empty leaf
  double avg_mbvh_leaf_depth = 0;    // depth of mini-MBVH leaves (root = 1), over all of them
  double build_ms = 0;
  size_t bytes = 0;                  // octree nodes + leaves + mini-MBVH nodes + triangle blocks
  size_t tri_bytes = 0;              // of which the mini-MBVHs' triangle blocks
  std::string describe() const;
};

struct Octree {
  std::vector<OctreeNode> nodes;  // nodes[0] = root
  std::vector<OctreeLeaf> leaves;
  MBVH<4, 4> mini;                // every leaf's mini-MBVH: nodes and triangle blocks (width 4)
  MBVH<8, 4> mini8;               // the same with 8-wide nodes (width 8); the other one is empty
  float pad = 0.f;                // leaves reference triangles within this distance of their box
  OctreeParams params;
  OctreeStats stats;

  static Octree build(const Scene& scene, const OctreeParams& params = {});

  // The leaf node below `node` containing point p; a coordinate exactly on a split plane goes to
  // the side the direction d points to (+0 counts as positive), so a ray that starts or enters
  // on a face continues in the leaf it runs into. Branch-free per level (SSE compares and one
  // movemask give the octant): the walk calls this for every leaf a ray enters.
  uint32_t locate(uint32_t node, Vec3 p, Vec3 d) const {
    const __m128 pp = _mm_setr_ps(p.x, p.y, p.z, 0.f);
    // Ties go up where the direction's sign bit is clear.
    const __m128 up = _mm_castsi128_ps(
        _mm_cmpeq_epi32(_mm_srai_epi32(_mm_castps_si128(_mm_setr_ps(d.x, d.y, d.z, 0.f)), 31), _mm_setzero_si128()));
    while (!nodes[node].is_leaf()) {
      const OctreeNode& n = nodes[node];
      const __m128 mid = _mm_loadu_ps(&n.mid.x);  // mid.x, mid.y, mid.z, (child)
      const __m128 go = _mm_or_ps(_mm_cmpgt_ps(pp, mid), _mm_and_ps(_mm_cmpeq_ps(pp, mid), up));
      node = n.child + uint32_t(_mm_movemask_ps(go) & 7);
    }
    return node;
  }
  // Whether p lies strictly inside node's box (then it lies in no other leaf).
  bool strictly_inside(uint32_t node, Vec3 p) const {
    const OctreeNode& n = nodes[node];
    const __m128 pp = _mm_setr_ps(p.x, p.y, p.z, 0.f);
    const __m128 in = _mm_and_ps(_mm_cmpgt_ps(pp, _mm_loadu_ps(&n.lo.x)), _mm_cmplt_ps(pp, _mm_loadu_ps(&n.hi.x)));
    return (_mm_movemask_ps(in) & 7) == 7;
  }
  // The triangle blocks of whichever mini-MBVH array is in use (4-wide blocks either way).
  const aligned_vector<TriBlock<4>>& mini_blocks() const { return params.width == 8 ? mini8.blocks : mini.blocks; }
  // Scene triangles referenced by a leaf (each once), for tests and statistics.
  std::vector<uint32_t> leaf_triangles(uint32_t leaf) const;
};

}  // namespace tb
