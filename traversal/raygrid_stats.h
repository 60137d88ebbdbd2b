// What a `raygrid` traverser can tell beyond the Traverser interface: its octree and the queue
// statistics of the calls it has traced (thesis §5.3.4-5.3.5: queue fills, memory use, and the
// robustness fallback that should never fire). Used by the raygrid table and the tests.
#pragma once
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "traversal/traverser.h"

namespace tb {

struct Octree;

// Accumulated over every trace call since construction (or the last reset).
struct RayGridStats {
  uint64_t calls = 0;
  uint64_t rays = 0;              // rays traced
  uint64_t outside = 0;           // rays that missed the scene bounds (never queued)
  uint64_t queues = 0;            // ray queues processed
  uint64_t full_queues = 0;       // ... of them full (M rays)
  uint64_t partial_queues = 0;    // ... of them partially filled (the tail of §5.3.4)
  uint64_t queued_rays = 0;       // rays over all processed queues (= leaf visits with a mini-MBVH traversal)
  uint64_t skipped_leaves = 0;    // leaves a ray crossed without queueing (empty, or its geometry out of reach)
  uint64_t fallbacks = 0;         // rays finished by a full traversal after the step limit (should be 0)
  uint64_t peak_queues = 0;       // most queues in use at once in one call
  uint64_t peak_bytes = 0;        // their memory, M * 36 bytes each: (O*M + N) * 36 at most (§5.3.5)
  uint32_t queue_size = 0;        // M

  double avg_fill() const { return queues ? double(queued_rays) / double(queues) : 0.0; }
  double leaf_visits_per_ray() const { return rays ? double(queued_rays) / double(rays) : 0.0; }
  std::string describe() const;
};

// The statistics of a raygrid traverser; nullopt for any other scheme.
std::optional<RayGridStats> raygrid_stats(const Traverser& t);
void raygrid_reset_stats(const Traverser& t);
// The octree a prepared raygrid traverser uses (nullptr for other schemes or before prepare).
const Octree* raygrid_octree(const Traverser& t);

}  // namespace tb
