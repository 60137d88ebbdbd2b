// Closest-hit traversal of a two-level BVH (structures/two_level.h): the top level's leaves are
// instances; a ray entering one is transformed to the object's space (org' = M^-1 org,
// dir' = M^-1 dir, not renormalised, so t is the same parameter in both spaces and one closest
// distance bounds both levels) and descends the object's BVH (thesis §3.2-3.3: Arauna traverses
// the top-level BVH and the scene graph nodes' BVHs; CS348K lecture 18, "Two-level BVHs").
// Both levels use one loop (near child first, a stack of far children, thesis Alg. 2.4) and the
// suite's robust kernels (traversal/kernels.h: Ize's padded slab test, the watertight triangle
// test). Global prim ids are TwoLevelBVH::prim_offset(instance) + the object's triangle index,
// the order of TwoLevelBVH::flatten().
#pragma once
#include <span>

#include "structures/two_level.h"
#include "workloads/ray_batch.h"

namespace tb {

Hit trace_two_level(const TwoLevelBVH& tl, const Ray& ray);
// Every ray of the batch, on the calling thread.
void trace_two_level(const TwoLevelBVH& tl, const RayBatch& batch, std::span<Hit> hits);

}  // namespace tb
