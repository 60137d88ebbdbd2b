// Ray/box and ray/triangle kernels on the hard cases: +-0 directions, shared edges and
// vertices, degenerate triangles, empty intervals, huge offsets.
#include <random>

#include "test_util.h"
#include "traversal/kernels.h"

namespace tb {
namespace {

Hit test_tri(TriKernel k, const Ray& ray, const TriVerts& t) {
  TriangleSet ts;
  ts.verts = {t};
  ts.prim_id = {0};
  if (k == TriKernel::plane || k == TriKernel::plane_rcp) ts.planes = {make_plane_tri(t)};
  Hit h{ray.tmax, kNoHit, 0, 0};
  const RayCtx rc(ray);
  dispatch_kernel(k, [&](auto kk) { intersect_tri<decltype(kk)::value>(rc, ts, 0, ray.tmin, h); });
  return h;
}

TEST(BoxKernel, SignedZeroDirectionsOnSlabPlanes) {
  const Vec3 lo{0, 0, 0}, hi{1, 1, 1};
  for (float zx : {0.f, -0.f})
    for (float zy : {0.f, -0.f}) {
      // Rays along z lying exactly in the box's faces and edges are inside the closed box.
      for (Vec3 o : {Vec3{0, 0.5f, -1}, Vec3{1, 0.5f, -1}, Vec3{0.5f, 0, -1}, Vec3{0, 0, -1}, Vec3{1, 1, -1}}) {
        const RayCtx r(Ray{o, 0.f, {zx, zy, 1.f}, INFINITY});
        EXPECT_EQ(box_entry(r, lo, hi, 0.f, INFINITY), 1.f) << o.x << "," << o.y << " dir " << zx << "," << zy;
      }
      // Just outside: a miss, never NaN.
      const RayCtx r(Ray{{1.0001f, 0.5f, -1}, 0.f, {zx, zy, 1.f}, INFINITY});
      EXPECT_EQ(box_entry(r, lo, hi, 0.f, INFINITY), INFINITY);
    }
}

// Whatever the float rounding, a box the ray enters in exact arithmetic is never culled (Ize 2013).
TEST(BoxKernel, ConservativeAtHugeOffsets) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  const Vec3 off{1e6f, -3e5f, 7e5f};
  int entered = 0;
  for (int i = 0; i < 50000; ++i) {
    const Vec3 lo = off + Vec3{U(rng), U(rng), U(rng)}, hi = lo + Vec3{0.0625f, 0.125f, 0.0625f};
    const Vec3 o = off + Vec3{U(rng), U(rng), U(rng)} * 1000.f;
    const Vec3 d = normalize((lo + hi) * 0.5f + Vec3{U(rng), U(rng), U(rng)} * 0.05f - o);
    // Exact slab test in double on the same float inputs.
    double tn = 0, tf = INFINITY;
    for (int a = 0; a < 3; ++a) {
      double t0 = (double(lo[a]) - o[a]) / d[a], t1 = (double(hi[a]) - o[a]) / d[a];
      if (t0 > t1) std::swap(t0, t1);
      tn = std::max(tn, t0), tf = std::min(tf, t1);
    }
    if (tn > tf) continue;
    ++entered;
    const RayCtx r(Ray{o, 0.f, d, INFINITY});
    EXPECT_LT(box_entry(r, lo, hi, 0.f, INFINITY), INFINITY) << "box culled at iteration " << i;
  }
  EXPECT_GT(entered, 1000);
}

TEST(TriangleKernels, AllAgreeOnAnEasyHit) {
  const TriVerts t{{0, 0, 5}, {1, 0, 5}, {0, 1, 5}};
  const Ray r{{0.2f, 0.3f, 0}, 0.f, {0, 0, 1}, INFINITY};
  for (TriKernel k : kAllTriKernels) {
    const Hit h = test_tri(k, r, t);
    ASSERT_EQ(h.prim, 0u) << kernel_name(k);
    EXPECT_NEAR(h.t, 5.f, k == TriKernel::plane_rcp ? 5e-3f : 1e-5f) << kernel_name(k);
    EXPECT_NEAR(h.u, 0.2f, 1e-3f);
    EXPECT_NEAR(h.v, 0.3f, 1e-3f);
  }
}

TEST(TriangleKernels, DegenerateTrianglesAreNeverHit) {
  const Ray r{{0.f, 0.f, -1}, 0.f, {0, 0, 1}, INFINITY};
  for (TriKernel k : kAllTriKernels) {
    EXPECT_FALSE(test_tri(k, r, {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}}).hit()) << kernel_name(k);
    EXPECT_FALSE(test_tri(k, r, {{-1, 0, 0}, {0, 0, 0}, {1, 0, 0}}).hit()) << kernel_name(k);  // collinear
    EXPECT_FALSE(test_tri(k, r, {{-1, -1, 0}, {1, 1, 0}, {1, 1, 0}}).hit()) << kernel_name(k);
  }
}

TEST(TriangleKernels, EmptyIntervalNeverHits) {
  const TriVerts t{{-1, -1, 2}, {1, -1, 2}, {0, 1, 2}};
  for (TriKernel k : kAllTriKernels) {
    EXPECT_FALSE(test_tri(k, Ray{{0, 0, 0}, 2.f, {0, 0, 1}, 2.f}, t).hit()) << kernel_name(k);
    EXPECT_FALSE(test_tri(k, Ray{{0, 0, 0}, 3.f, {0, 0, 1}, INFINITY}, t).hit()) << kernel_name(k);
  }
}

// Rays through the shared edge and vertex of a closed fan must hit one of its triangles.
TEST(TriangleKernels, WatertightOnSharedEdgesAndVertices) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  const int n = 7;  // a fan of 7 triangles around a centre vertex, far from the origin
  const Vec3 off{148376.f, 1234.f, -223423.f};
  std::vector<TriVerts> fan;
  for (int i = 0; i < n; ++i) {
    const float a0 = 6.2831853f * i / n, a1 = 6.2831853f * (i + 1) / n;
    fan.push_back({off, off + Vec3{std::cos(a0), std::sin(a0), 0.1f * U(rng)}, off + Vec3{std::cos(a1), std::sin(a1), 0}});
  }
  fan.back().v2 = fan.front().v1;  // close the fan exactly
  for (int i = 0; i + 1 < n; ++i) fan[i].v2 = fan[i + 1].v1;
  int leaks = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    // Aim at the centre vertex or a point on a shared edge.
    const TriVerts& t = fan[trial % n];
    const float s = (trial / n) % 2 ? 0.f : 0.9f * std::fabs(U(rng));  // not the open rim
    const Vec3 target = t.v0 + (t.v1 - t.v0) * s;
    const Vec3 o = off + Vec3{U(rng) * 3, U(rng) * 3, 2.f + std::fabs(U(rng))};
    const Ray r{o, 0.f, normalize(target - o), INFINITY};
    bool any = false;
    for (const auto& f : fan) any |= test_tri(TriKernel::watertight, r, f).hit();
    leaks += !any;
  }
  EXPECT_EQ(leaks, 0);
}

TEST(TriangleKernels, ParseKernelNames) {
  EXPECT_EQ(parse_kernel("moller"), TriKernel::moller);
  EXPECT_THROW(parse_kernel("fastest"), InputError);
}

}  // namespace
}  // namespace tb
