// What every scheme over the binary BVH shares: the cached BVH and its triangles in leaf order
// (traversal/tree_scheme.h), and the BVH's declared build parameters.
#pragma once
#include "structures/bvh.h"
#include "traversal/tree_scheme.h"

namespace tb {

// The binary BVH's parameters, `bins`, `leaf_size` and the spatial-split ones, as a scheme
// declares them (its params_<name>() returns these plus its own), and the build parameters read
// from a config resolved against them.
ParamSpecs bvh_param_specs(int default_leaf = 4);
BVHBuildParams bvh_params(const SchemeConfig& cfg);

using BVHData = TreeData<BVH>;
inline BVHData fetch_bvh(const Scene& scene, StructureCache& cache, const BVHBuildParams& params, TriKernel kernel) {
  return fetch_tree<BVH>(scene, cache, params, kernel);
}
// The base of the schemes over the binary BVH (bvh_single/masked/ranged/partition).
template <class Derived>
using BVHScheme = TreeScheme<Derived, BVH, BVHBuildParams, bvh_params>;

}  // namespace tb
