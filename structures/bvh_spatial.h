// Spatial-split BVH ("SBVH", Stich, Friedrich and Dietrich 2009, "Spatial Splits in Bounding
// Volume Hierarchies"): the binned SAH builder of structures/bvh.cpp extended by splits that cut
// space instead of the primitive list. A triangle straddling the chosen plane is clipped to each
// side and referenced by both children, so large or long triangles stop inflating the boxes of
// everything near them (Sponza's floor and walls, a scanned model on a huge ground quad).
//
// The output is an ordinary BVH (same nodes, same sibling-pair layout): leaves index
// `prim_index`, whose entries are the scene's triangle ids and may repeat — a triangle is stored
// once per leaf that references it. Every traversal that reads a BVH (binary, packets, MBVH
// collapse, stream kernels) works on it unchanged; a closest-hit query may test a duplicated
// triangle twice, which gives the same answer.
//
// Watertightness: a child reference's box is the bounds of the triangle clipped to the parent
// reference's box and the half-space of its side, computed by the shared clipper
// (clip_triangle_bounds: double-precision Sutherland-Hodgman rounded outward), so the union of
// the two parts' boxes contains the whole part of the triangle inside the parent's box. Node boxes
// are the unions of their references' boxes. Every point of a triangle therefore lies in the box
// of some leaf that references it and in all of that leaf's ancestors. The binning's chopped parts
// (clip.h chop_triangle_bounds, float, padded outward) only choose the plane.
#pragma once
#include <span>
#include <vector>

#include "structures/bvh.h"
#include "structures/scene.h"

namespace tb {

struct SpatialSplitParams {
  // Spatial splits are tried only in nodes whose best object split leaves the children
  // overlapping by more than alpha * (root surface area) (Stich et al. §4.3: 1e-5 keeps the
  // build fast and loses almost nothing).
  float alpha = 1e-5f;
  // ... and, where > 0, by more than this fraction of the node's own surface area (Embree's
  // SPATIAL_ASPLIT_OVERLAP_THRESHOLD: 0.1 in 3.13, 0.2 in a disabled older setting): fewer nodes
  // bin spatially, so a faster build, at whatever quality that costs (0: alpha alone, as published).
  float overlap = 0.f;
  // At most budget * (triangles) extra references in the whole tree (Embree caps growth the same
  // way); once spent, only object splits are made.
  float budget = 1.0f;
  // A triangle whose box spans at least this fraction of the build's root box on two axes (a
  // floor, ceiling or wall of the whole scene: an enclosure) is never clipped; a spatial split
  // bins and places it whole by its centroid, as an object split would. Chopping an enclosure
  // gives every box near it a piece of it, so the boxes around a ray that starts inside (a camera,
  // a bounce) all span the enclosure and are all entered; kept whole it sits in one subtree that
  // is entered once and ends the ray early. Measured (mbvh8_single / embree_single, 512x512,
  // docs/PERFORMANCE.md "Spatial splits by default"): conference primary 0.96 with every triangle
  // clipped (0) vs 1.36 at 0.8, stadium 0.92 vs 1.11; 0.8 keeps every other scene's gain from the
  // splits (sponza bounce:2 1.20 -> 1.22). 0 clips every triangle (Stich et al. as published).
  float wall = 0.8f;
  // Whether the SAH also weighs, at every node holding walls and other references, the split
  // "walls | the rest" (the walls to a child of their own). The binned splits place a whole wall
  // by its centroid, among its neighbours, so every node on its path spans the enclosure and is
  // entered by every ray that crosses it; set apart, the walls sit in one shallow subtree.
  // Measured (session 17, docs/PERFORMANCE.md): node visits per ray -17 to -27% on
  // crytek_sponza_partial, conference and stadium (-9% on the held-out-shaped scene), mbvh8_single
  // +2 to +18% against embree_single; trees without walls are unchanged.
  bool walls_apart = true;
  int spatial_bins = 16;  // spatial bins per axis (object splits use BVHBuildParams::bins)
  // Subtrees of fewer references are built by the plain binned builder (BVH::build over their
  // references): spatial splits deep in the tree gain little SAH (sponza: 0.823 of the plain
  // SAH with 16, 0.825 with 64, 0.833 with 256) and cost the most build time.
  int min_refs = 64;
  // ... unless it holds a reference longer than half the node on some axis (a large triangle
  // among small ones, where spatial splits keep paying), down to this many references. Keeping
  // every such subtree (0, before) built almost the whole tree with spatial binning (sponza: the
  // builder's split() ran on 82.6 k of its 88 k nodes); 8 keeps the trace work of conference's
  // primary rays (16 or 32 visit 5% more nodes there) at 0.72x the instructions of 0
  // (docs/PERFORMANCE.md, spatial splits).
  int large_min_refs = 8;
  // Spatial bins per axis in such kept nodes (below min_refs): chopping their large reference
  // over every bin is most of their cost; 8 gives the same SAH within 0.1% as 16.
  int small_spatial_bins = 8;
};

// One reference: a (possibly clipped) box around part of triangle `prim`.
struct SpatialRef {
  AABB box;
  uint32_t prim;
};

// The spatial-split parameters a BVHBuildParams carries (split_alpha, split_budget, ...), the
// rest at their defaults: what BVH::build and RayGrid's mini-BVH builds pass.
SpatialSplitParams spatial_split_params(const BVHBuildParams& params);

// Spatial-split build over the whole scene.
BVH build_spatial_bvh(const Scene& scene, const BVHBuildParams& params, const SpatialSplitParams& sp = {});
// Over given references (e.g. triangles already clipped to an octree cell): the boxes are the
// starting bounds; clipping uses the scene's triangles.
BVH build_spatial_bvh(const Scene& scene, std::vector<SpatialRef> refs, const BVHBuildParams& params,
                      const SpatialSplitParams& sp = {});

}  // namespace tb
