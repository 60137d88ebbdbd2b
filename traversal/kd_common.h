// What kd_single and kd_packet share: the kD-tree's declared build parameters, read from a
// resolved SchemeConfig, and the cached tree with its triangles (traversal/tree_scheme.h; one
// fetch, so both schemes share one tree and one triangle set). The triangles are stored in
// reference order: a triangle referenced by k leaves is stored k times, so a leaf reads one
// contiguous run (the layout the BVH schemes use).
#pragma once
#include "structures/kdtree.h"
#include "traversal/tree_scheme.h"

namespace tb {

// kd_ct, kd_ci (SAH costs), kd_empty_bonus, kd_max_depth (0: automatic), kd_min_leaf,
// kd_max_leaf, kd_planar_both; defaults from KDBuildParams.
ParamSpecs kd_param_specs();
KDBuildParams kd_params(const SchemeConfig& cfg);

// The base of kd_single and kd_packet.
template <class Derived>
using KDScheme = TreeScheme<Derived, KDTree, KDBuildParams, kd_params>;

}  // namespace tb
