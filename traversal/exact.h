// The exact oracle (docs/ACCURACY.md): the closest hit of a float32 ray against float32 triangles,
// decided without rounding error. Every sign and every comparison of two distances is first
// tried in double with a certified running error bound (Higham, "Accuracy and Stability of
// Numerical Algorithms", 2nd ed., §3.1, with exact TwoSum/TwoProduct error terms); when the bound
// cannot decide it, it is recomputed in GMP rationals (mpq_class), so the answer is the one of
// exact arithmetic on the stored floats. The `reference` scheme is this oracle.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "structures/bvh.h"
#include "structures/scene.h"
#include "workloads/ray_batch.h"

namespace tb {

class StructureCache;

// Exact hit rule (docs/ACCURACY.md "The hit rule"), for ray o + t d and triangle (A, B, C):
// two-sided; edges and vertices inclusive; a ray parallel to the plane (d . N = 0, including a
// ray lying in the plane) misses; a degenerate triangle (N = 0) never hits; accepted when
// tmin <= t < tmax with t the rational det(A-o, B-o, C-o) / (d . N). Among hits the smallest exact
// t wins; at equal exact t the lowest primitive id. Rays with a non-finite origin or direction
// component or a NaN tmin/tmax, and triangles with a non-finite vertex, never hit.

// Candidate test of one triangle, exposed for the tests: whether the triangle is hit under the
// rule within [tmin, tmax), and t rounded to nearest float.
bool exact_triangle_hit(const Ray& ray, Vec3 a, Vec3 b, Vec3 c, float* t_out = nullptr);

class ExactOracle {
 public:
  // Uses the default BVH of the structure cache as a conservative culling structure.
  ExactOracle(const Scene& scene, StructureCache& cache);
  ExactOracle(const Scene& scene, std::shared_ptr<const BVH> bvh);
  // Closest exact hit over the BVH.
  Hit closest(const Ray& ray, uint64_t* tri_tests = nullptr) const;
  // The same without any structure: every triangle, for cross-checks.
  Hit closest_brute_force(const Ray& ray) const;
  // Every hit the rule accepts in [tmin, tmax), t rounded to float, sorted by (t, prim).
  std::vector<Hit> all_hits(const Ray& ray) const;
  // Whether a disagreement of `scheme` with the exact answer is ambiguous (docs/ACCURACY.md
  // "Error kinds"): each triangle decision the scheme made differently flips within a few float
  // ulps of the ray. The moved rays: each origin and direction component alone by +-1 and +-k
  // ulps, and all six by +-k in every sign pattern. (1) every surface the exact ray hits before
  // the scheme's answer is escaped by some moved ray; (2) the scheme's own hit is made by the exact
  // ray at that distance or by some moved ray. `rel_bar`: the accuracy bar, |dt| <= rel_bar max(1, t).
  bool ambiguous(const Ray& ray, const Hit& scheme, float rel_bar, int k = kAmbiguityUlps) const;
  static constexpr int kAmbiguityUlps = 4;

  const Scene& scene() const { return *scene_; }
  const BVH& bvh() const { return *bvh_; }

 private:
  const Scene* scene_;
  std::shared_ptr<const BVH> bvh_;
};

}  // namespace tb
