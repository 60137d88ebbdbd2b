// Runs a traverser over a batch: threads, FTZ/DAZ, repetitions and their statistics.
#pragma once
#include <span>
#include <vector>

#include "traversal/traverser.h"

namespace tb {

// Sets flush-to-zero and denormals-are-zero for the calling thread (DESIGN.md: every thread
// that traces), so denormal slowdowns never pollute a timing.
void enable_ftz_daz();

// Traces the whole batch with `threads` threads pulling chunks of packets.
void trace_batch(const Traverser& t, const RayBatch& batch, std::span<Hit> hits, int threads);

struct ThroughputStats {
  double mrays_median = 0, mrays_min = 0, mrays_max = 0;
  std::vector<double> seconds;  // one per repetition
};

// One untimed warm-up, then `reps` timed runs of the whole batch.
ThroughputStats measure(const Traverser& t, const RayBatch& batch, std::span<Hit> hits, int threads, int reps);

}  // namespace tb
