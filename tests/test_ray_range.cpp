// Rays at the edges of the traceable range (structures/vec3.h, kCoordLimit: |origin|, |direction|
// <= 2^56, the largest direction component >= 2^-56, no denormals). Past those edges the schemes
// crashed (every node test entered every child slot, unused ones included) and the ray files are
// now refused (BadInput.RayFilesAreRejectedWithReason); inside them every scheme must trace without
// a fault, and where the float kernels can resolve the geometry, agree with the exact reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "test_util.h"

namespace tb {
namespace {

TEST(RayRange, RaysAtTheEdgesOfTheTraceableRangeTraceWithoutFault) {
  Bench& bench = test::bench_for("sphere");
  const float L = kCoordLimit, s = 1.f / kCoordLimit, tiny = std::numeric_limits<float>::min();
  const float inf = std::numeric_limits<float>::infinity();
  RayBatch b;
  // Resolvable in float: ordinary origins (the sphere is the unit sphere at the origin), extreme
  // direction lengths and tiny normal components. Each aims at the sphere or along an axis past it.
  const std::vector<Ray> resolvable = {
      {{0.1f, 0.1f, 5}, 0, {0, 0, -s}, inf},        // the shortest direction allowed
      {{0.1f, 0.1f, 5}, 0, {tiny, -tiny, -s}, inf},  // ... with the smallest normal components beside it
      {{0.1f, 0.1f, 5}, 0, {0, 0, -L}, inf},         // the longest
      {{0.1f, 0.1f, 5}, 0, {L, L, -L}, inf},         // longest on every axis (misses)
      {{0.1f, 0.1f, 5}, 0, {tiny, tiny, -1}, inf},
      {{0.1f, 0.1f, 5}, 0, {s, 0, -L}, inf},         // both extremes in one direction
      {{3, 0.2f, 0.1f}, 0, {-s, tiny, 0}, inf},
      {{0, 0, 0}, 0, {s, s, s}, inf},                // from inside
  };
  // Not resolvable in float (the sphere is far below the origin's spacing): only "no fault".
  const std::vector<Ray> far = {
      {{L, L, L}, 0, {-1, -1, -1}, inf},
      {{-L, 0.1f, 0.1f}, 0, {1, 0, 0}, inf},
      {{-L, 0.1f, 0.1f}, 0, {s, 0, 0}, inf},
      {{0.1f, L, -L}, 0, {0, -L, L}, inf},
  };
  b.rays = resolvable;
  b.rays.insert(b.rays.end(), far.begin(), far.end());
  b.group_uniform(4);
  ASSERT_NO_THROW(b.validate());
  auto ref = make_scheme("reference");
  ref->prepare(bench.scene(), bench.cache());
  std::vector<Hit> want(b.rays.size());
  trace_batch(*ref, b, want, 1);
  size_t hits = 0;
  for (size_t i = 0; i < resolvable.size(); ++i) hits += want[i].hit();
  EXPECT_GE(hits, 5u) << "the resolvable rays should mostly hit the sphere";
  const std::vector<std::string> ours = test::schemes_under_test(true);
  for (const auto& name : test::schemes_under_test()) {
    // Embree is a baseline: its faults are ours to prevent (its ray.valid() assertion), its
    // answers are reported, not required: it misses the rays of 2^-56 directions (t ~ 3.6e17).
    const bool baseline = std::find(ours.begin(), ours.end(), name) == ours.end();
    auto t = make_scheme(name);
    t->prepare(bench.scene(), bench.cache());
    std::vector<Hit> got(b.rays.size());
    trace_batch(*t, b, got, 1);
    for (size_t i = 0; i < b.rays.size(); ++i) {
      const Hit& h = got[i];
      if (h.hit()) {
        EXPECT_LT(h.prim, bench.scene().num_triangles()) << name << " ray " << i;
        EXPECT_TRUE(h.t >= b.rays[i].tmin && h.t < b.rays[i].tmax) << name << " ray " << i << " t " << h.t;
      }
      if (i < resolvable.size() && !baseline) {
        EXPECT_TRUE(hits_match(h, want[i])) << name << " ray " << i;
      }
    }
  }
}

}  // namespace
}  // namespace tb
