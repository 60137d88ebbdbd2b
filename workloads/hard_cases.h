// Hard-case workloads: the numerically nasty rays every kernel is tested on (DESIGN.md
// "Correctness"). Rays that start inside a closed mesh must hit it; a leak is a false miss.
#pragma once
#include <string>
#include <vector>

#include "structures/scene.h"
#include "workloads/ray_batch.h"

namespace tb {

struct WorkloadSpec;

// hard:inside, hard:vertices, hard:edges, hard:axis, hard:grazing, hard:surface, hard:tmin_tmax.
std::vector<std::string> hard_case_names();
// Whether every ray of the workload must hit when its origin lies inside a closed mesh
// (the "must hit" set of the accuracy tests).
bool hard_case_must_hit(const std::string& name);
// The interior point the must-hit workloads start from: the centre of the scene's bounds.
Vec3 interior_point(const Scene& scene);
RayBatch hard_case_rays(const Scene& scene, const WorkloadSpec& spec);

}  // namespace tb
