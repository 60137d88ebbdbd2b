// Accuracy against the reference (docs/ACCURACY.md), which is the exact oracle
// (traversal/exact.h). A hit matches when both miss, or both hit with
// |t - t_ref| <= 1e-5 * max(1, t_ref): a different primitive at the same distance (shared edge or
// vertex) still matches. Every disagreement counts in mismatch_rate and in exactly one kind:
// ambiguous (each triangle decision the scheme made differently flips when the ray moves by a few
// float ulps: ExactOracle::ambiguous), else false_miss (a leak), false_hit, or wrong_t (both hit, at another
// distance: another surface or a wrong t).
#pragma once
#include <cmath>
#include <cstdint>
#include <functional>
#include <span>

#include "workloads/ray_batch.h"

namespace tb {

inline constexpr float kDistanceBar = 1e-5f;  // relative, on max(1, t_ref)

inline bool hits_match(const Hit& h, const Hit& ref) {
  if (!h.hit() || !ref.hit()) return h.hit() == ref.hit();
  return std::fabs(h.t - ref.t) <= kDistanceBar * std::max(1.f, ref.t);
}

struct Accuracy {
  uint64_t rays = 0, mismatches = 0;
  uint64_t false_miss = 0;  // the reference hits, the scheme misses: a leak
  uint64_t false_hit = 0;   // the reference misses, the scheme hits
  uint64_t wrong_t = 0;     // both hit, beyond the distance bar
  uint64_t ambiguous = 0;   // the exact answer flips within k ulps of the ray; not in the three above
  double mismatch_rate() const { return rays ? double(mismatches) / double(rays) : 0.0; }
  uint64_t non_ambiguous() const { return false_miss + false_hit + wrong_t; }
};

// `is_ambiguous(i)` is asked for disagreeing rays only; without it no disagreement is ambiguous.
inline Accuracy compare_hits(std::span<const Hit> hits, std::span<const Hit> ref,
                             const std::function<bool(size_t)>& is_ambiguous = {}) {
  Accuracy a;
  a.rays = ref.size();
  for (size_t i = 0; i < ref.size(); ++i) {
    if (hits_match(hits[i], ref[i])) continue;
    a.mismatches++;
    if (is_ambiguous && is_ambiguous(i)) a.ambiguous++;
    else if (ref[i].hit() && !hits[i].hit()) a.false_miss++;
    else if (!ref[i].hit() && hits[i].hit()) a.false_hit++;
    else a.wrong_t++;
  }
  return a;
}

}  // namespace tb
