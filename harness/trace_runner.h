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

// The median of v (the mean of the middle two for an even count; 0 for none).
double median_of(std::vector<double> v);

struct ThroughputStats {
  double mrays_median = 0, mrays_min = 0, mrays_max = 0;
  std::vector<double> seconds;  // one per repetition
};

// One untimed warm-up, then `reps` timed runs of the whole batch.
ThroughputStats measure(const Traverser& t, const RayBatch& batch, std::span<Hit> hits, int threads, int reps);

// Several schemes on one batch, interleaved: one warm-up trace each, then `rounds` rounds that each
// trace the batch once with every scheme, the order rotated by one per round, so a shared machine's
// slow phases (another tenant on the core's caches, a frequency change) fall on every scheme alike.
// Returns each scheme's seconds per round: sec[scheme][round]. `hits` receives the last trace's.
std::vector<std::vector<double>> measure_interleaved(std::span<const Traverser* const> schemes, const RayBatch& batch,
                                                     std::span<Hit> hits, int threads, int rounds);

}  // namespace tb
