// The binary BVH built by Embree 3's own SAH builder (rtcBuildBVH), in travbench's BVH layout:
// BVHBuildParams::builder = BVHBuilder::embree (the `builder=embree` parameter of every BVH-based
// scheme). Embree's embree_* baselines trace Embree's tree with Embree's kernels; travbench's
// schemes on this tree separate the two: a scheme that is slower than embree_single on its own
// tree but not on Embree's has a tree to improve, not a kernel. Quality HIGH (Embree's binned SAH,
// BVHBuilderBinnedSAH); with spatial=1 its spatial-split builder (Stich et al. 2009, as Embree's
// HIGH fast scenes build them), splitting references with split_triangle_bounds and room for
// split_budget extra references per triangle. leaf_size, cost_traversal and cost_intersect are
// Embree's maxLeafSize (at most 32), traversalCost and intersectionCost; bins and the other
// split_* parameters are travbench's builder's own and mean nothing here.
#pragma once
#include "structures/bvh.h"
#include "structures/scene.h"

namespace tb {

BVH build_embree_bvh(const Scene& scene, const BVHBuildParams& params);

}  // namespace tb
