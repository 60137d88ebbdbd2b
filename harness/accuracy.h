// Accuracy against the reference (DESIGN.md "Correctness and accuracy"): a hit matches when
// both miss, or both hit with |t - t_ref| <= 1e-5 * max(1, t_ref). A different primitive at the
// same distance (shared edge or vertex) still matches.
#pragma once
#include <cmath>
#include <cstdint>
#include <span>

#include "workloads/ray_batch.h"

namespace tb {

inline bool hits_match(const Hit& h, const Hit& ref) {
  if (!h.hit() || !ref.hit()) return h.hit() == ref.hit();
  return std::fabs(h.t - ref.t) <= 1e-5f * std::max(1.f, ref.t);
}

struct Accuracy {
  uint64_t rays = 0, mismatches = 0;
  uint64_t false_miss = 0;  // the reference hits, the scheme misses: a leak
  uint64_t false_hit = 0;   // the reference misses, the scheme hits
  double mismatch_rate() const { return rays ? double(mismatches) / double(rays) : 0.0; }
};

inline Accuracy compare_hits(std::span<const Hit> hits, std::span<const Hit> ref) {
  Accuracy a;
  a.rays = ref.size();
  for (size_t i = 0; i < ref.size(); ++i) {
    if (hits_match(hits[i], ref[i])) continue;
    a.mismatches++;
    if (ref[i].hit() && !hits[i].hit()) a.false_miss++;
    if (!ref[i].hit() && hits[i].hit()) a.false_hit++;
  }
  return a;
}

}  // namespace tb
