// Ray/box and ray/triangle kernels on the hard cases: +-0 directions, shared edges and
// vertices, degenerate triangles, empty intervals, huge offsets.
#include <bit>
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

// ---------------------------------------------------------------------------------------------
// The kernel library's templates give the same bits on every lane count: L = 4 and L = 8 lanes
// against L separate L = 1 calls (the single-ray schemes' kernels). Coordinates on a coarse grid
// make exact zeros (edge functions through vertices, rays on slab planes, axis-parallel rays)
// common, so the double fallbacks and the NaN-slab rule are exercised too.
template <int L>
struct Lanes {
  alignas(32) float v[L];
};
template <int L>
typename simd::V<L>::f load_lanes(const float* x) {
  return simd::V<L>::load(x);
}
uint32_t bits(float x) { return std::bit_cast<uint32_t>(x); }

struct KernelCase {
  std::vector<Ray> rays;
  std::vector<TriVerts> tris;
};
KernelCase grid_cases(uint32_t seed, int n) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> G(-4, 4), D(-2, 2);
  KernelCase c;
  for (int i = 0; i < n; ++i) {
    Vec3 d{float(D(rng)), float(D(rng)), float(D(rng))};
    if (d == Vec3{0, 0, 0}) d = {0, 0, 1};
    if (i % 3 == 0) d = d + Vec3{0.25f * G(rng), 0.125f * G(rng), 0.5f};  // not only grid directions
    c.rays.push_back({{float(G(rng)), float(G(rng)), float(G(rng))}, 0.f, d, INFINITY});
    c.tris.push_back({{float(G(rng)), float(G(rng)), float(G(rng))},
                      {float(G(rng)), float(G(rng)), float(G(rng))},
                      {float(G(rng)), float(G(rng)), float(G(rng))}});
  }
  return c;
}

template <int L>
void check_lanes(const KernelCase& c) {
  using S = simd::V<L>;
  using f = typename S::f;
  const int n = int(c.rays.size());
  int checked_hits = 0, zero_edges = 0;
  for (int base = 0; base + L <= n; base += L) {
    const TriVerts& tri = c.tris[base];
    const PlaneTri pt = make_plane_tri(tri);
    // Per-lane inputs from RayCtx, as the one-ray kernels see them.
    alignas(32) float o[3][L], d[3][L], inv[3][L], s[3][L], sh[6][L], xn[3][L], xf[3][L];
    for (int l = 0; l < L; ++l) {
      const RayCtx r(c.rays[base + l]);
      const Vec3 A = tri.v0 - r.org, B = tri.v1 - r.org, C = tri.v2 - r.org, sv = r.org - tri.v0;
      const Vec3 lo = tri.v0, hi = tri.v0 + Vec3{1, 2, 3};  // a box with a corner on the grid
      for (int a = 0; a < 3; ++a) {
        o[a][l] = r.org[a], d[a][l] = r.dir[a], inv[a][l] = r.inv[a], s[a][l] = sv[a];
        const bool neg = a == 0 ? r.near_x : a == 1 ? r.near_y : r.near_z;
        xn[a][l] = (neg ? hi[a] : lo[a]) - r.org[a];
        xf[a][l] = (neg ? lo[a] : hi[a]) - r.org[a];
      }
      const Vec3* P[3] = {&A, &B, &C};
      for (int v = 0; v < 3; ++v) {
        sh[2 * v][l] = shear<1>((*P[v])[r.kx], r.sx, (*P[v])[r.kz]);
        sh[2 * v + 1][l] = shear<1>((*P[v])[r.ky], r.sy, (*P[v])[r.kz]);
      }
    }
    auto V3 = [](float (&x)[3][L], f out[3]) {
      for (int a = 0; a < 3; ++a) out[a] = load_lanes<L>(x[a]);
    };
    f vo[3], vd[3], vinv[3], vs[3], vxn[3], vxf[3];
    V3(o, vo), V3(d, vd), V3(inv, vinv), V3(s, vs), V3(xn, vxn), V3(xf, vxf);
    // Slab test, both paddings.
    f tn4;
    const int box4 = S::mask(slab<L, false>(vxn, vxf, vinv, vinv, S::zero(), S::set1(INFINITY), tn4));
    alignas(32) float tnv[L];
    S::store(tnv, tn4);
    for (int l = 0; l < L; ++l) {
      const float xn1[3] = {xn[0][l], xn[1][l], xn[2][l]}, xf1[3] = {xf[0][l], xf[1][l], xf[2][l]};
      const float r1[3] = {inv[0][l], inv[1][l], inv[2][l]};
      float tn1;
      const bool box1 = slab<1, false>(xn1, xf1, r1, r1, 0.f, INFINITY, tn1);
      EXPECT_EQ(bool(box4 >> l & 1), box1);
      EXPECT_EQ(bits(tnv[l]), bits(tn1));
    }
    // Watertight inside test and edge functions.
    f U, V, W, det;
    const int in4 = S::mask(watertight_inside<L>(load_lanes<L>(sh[0]), load_lanes<L>(sh[1]), load_lanes<L>(sh[2]),
                                                 load_lanes<L>(sh[3]), load_lanes<L>(sh[4]), load_lanes<L>(sh[5]), U, V,
                                                 W, det));
    alignas(32) float uv[4][L];
    S::store(uv[0], U), S::store(uv[1], V), S::store(uv[2], W), S::store(uv[3], det);
    for (int l = 0; l < L; ++l) {
      float u1, v1, w1, d1 = 0.f;
      const bool in1 = watertight_inside<1>(sh[0][l], sh[1][l], sh[2][l], sh[3][l], sh[4][l], sh[5][l], u1, v1, w1, d1);
      EXPECT_EQ(bool(in4 >> l & 1), in1);
      EXPECT_EQ(bits(uv[0][l]), bits(u1));
      EXPECT_EQ(bits(uv[1][l]), bits(v1));
      EXPECT_EQ(bits(uv[2][l]), bits(w1));
      if (in1) {
        EXPECT_EQ(bits(uv[3][l]), bits(d1));  // det: defined where the test passes
      }
      zero_edges += u1 == 0.f || v1 == 0.f || w1 == 0.f;
    }
    // Moller and the plane kernels, against the one-ray wrappers.
    for (int k = 0; k < 3; ++k) {
      f t, u, v;
      int m4;
      if (k == 0) m4 = S::mask(moller<L>(vd, vs, tri, S::zero(), S::set1(INFINITY), S::all_true(), t, u, v));
      else if (k == 1) m4 = S::mask(plane<L, false>(vo, vd, plane_offset<L>(vo, pt.n), pt, S::zero(), S::set1(INFINITY), S::all_true(), t, u, v));
      else m4 = S::mask(plane<L, true>(vo, vd, plane_offset<L>(vo, pt.n), pt, S::zero(), S::set1(INFINITY), S::all_true(), t, u, v));
      alignas(32) float tv[3][L];
      S::store(tv[0], t), S::store(tv[1], u), S::store(tv[2], v);
      for (int l = 0; l < L; ++l) {
        const RayCtx r(c.rays[base + l]);
        Hit h{INFINITY, kNoHit, 0, 0};
        const bool h1 = k == 0 ? intersect_moller(r, tri, 0.f, h)
                        : k == 1 ? intersect_plane<false>(r, pt, 0.f, h)
                                 : intersect_plane<true>(r, pt, 0.f, h);
        ASSERT_EQ(bool(m4 >> l & 1), h1) << "kernel " << k << " lane " << l;
        if (h1) {
          ++checked_hits;
          EXPECT_EQ(bits(tv[0][l]), bits(h.t));
          EXPECT_EQ(bits(tv[1][l]), bits(h.u));
          EXPECT_EQ(bits(tv[2][l]), bits(h.v));
        }
      }
    }
  }
  EXPECT_GT(checked_hits, 50);  // the cases do reach the hit paths ...
  EXPECT_GT(zero_edges, 10);    // ... and the double fallback of the edge functions
}

// simd.h's contract, on which the slab tests' NaN rule rests: min(a, b) = a < b ? a : b and
// max(a, b) = a > b ? a : b bit for bit (the SECOND operand when either is NaN, and for +0 / -0) on
// every lane count; V<1> issues minss/maxss itself (session 40), the others minps/maxps.
template <int L>
void check_min_max(float a, float b) {
  using S = simd::V<L>;
  alignas(32) float x[L], y[L], lo[L], hi[L];
  for (int l = 0; l < L; ++l) x[l] = a, y[l] = b;
  S::store(lo, S::min(S::load(x), S::load(y)));
  S::store(hi, S::max(S::load(x), S::load(y)));
  for (int l = 0; l < L; ++l) {
    EXPECT_EQ(bits(lo[l]), bits(a < b ? a : b)) << L << " lanes: min(" << a << ", " << b << ")";
    EXPECT_EQ(bits(hi[l]), bits(a > b ? a : b)) << L << " lanes: max(" << a << ", " << b << ")";
  }
}
TEST(KernelLibrary, MinMaxTakeTheSecondOperandOnNaNAndZeros) {
  const float v[] = {1.f, -2.f, 0.f, -0.f, INFINITY, -INFINITY, NAN, -NAN, 1e-40f, 3.5f};
  for (float a : v)
    for (float b : v) {
      check_min_max<1>(a, b), check_min_max<4>(a, b), check_min_max<8>(a, b);
      // The structures' branch-free std::min/std::max (structures/vec3.h, the same instructions with
      // the operands swapped): std's NaN and signed-zero results, bit for bit.
      EXPECT_EQ(bits(min_of(a, b)), bits(std::min(a, b))) << "min_of(" << a << ", " << b << ")";
      EXPECT_EQ(bits(max_of(a, b)), bits(std::max(a, b))) << "max_of(" << a << ", " << b << ")";
    }
}

TEST(KernelLibrary, FourLanesMatchOneLaneBitForBit) { check_lanes<4>(grid_cases(5, 4000)); }
TEST(KernelLibrary, EightLanesMatchOneLaneBitForBit) { check_lanes<8>(grid_cases(6, 4000)); }

// exact_plane_distance's four-lane double form (the stream and packet kernels) gives the scalar
// function's bits.
TEST(KernelLibrary, PlaneDistanceFourLanesMatchesScalar) {
  const KernelCase c = grid_cases(7, 400);
  int finite = 0;
  for (size_t i = 0; i + 4 <= c.rays.size(); i += 4) {
    const TriVerts& tri = c.tris[i];
    using D = simd::D4v;
    const Vec3D<double> v0 = to_double(tri.v0);
    const Vec3D<double> nd = plane_normal(v0, to_double(tri.v1), to_double(tri.v2));
    alignas(32) float ox[4], oy[4], oz[4], dx[4], dy[4], dz[4], t4[4];
    for (int l = 0; l < 4; ++l) {
      const Ray& r = c.rays[i + l];
      ox[l] = r.org.x, oy[l] = r.org.y, oz[l] = r.org.z, dx[l] = r.dir.x, dy[l] = r.dir.y, dz[l] = r.dir.z;
    }
    D num, dn;
    plane_terms(Vec3D<D>{D(nd.x), D(nd.y), D(nd.z)}, Vec3D<D>{D(v0.x), D(v0.y), D(v0.z)},
                Vec3D<D>{D(_mm_load_ps(ox)), D(_mm_load_ps(oy)), D(_mm_load_ps(oz))},
                Vec3D<D>{D(_mm_load_ps(dx)), D(_mm_load_ps(dy)), D(_mm_load_ps(dz))}, num, dn);
    _mm_store_ps(t4, (num / dn).to_float());
    const int par = dn.zero_mask();
    for (int l = 0; l < 4; ++l) {
      const float t1 = exact_plane_distance(c.rays[i + l].org, c.rays[i + l].dir, tri);
      EXPECT_EQ(bool(par >> l & 1), std::isnan(t1));
      if (!std::isnan(t1)) {
        EXPECT_EQ(bits(t4[l]), bits(t1));
        ++finite;
      }
    }
  }
  EXPECT_GT(finite, 100);
}

// RayCtx's two ways of choosing the shear axes (branching for common-origin batches, branch-free
// for the others) give the same axes and constants for every direction: ties between components
// (the first of equal magnitudes wins in both), zeros, signed zeros, denormals and both signs.
TEST(KernelLibrary, BranchFreeShearAxesMatchBranching) {
  std::mt19937 rng(21);
  const float special[] = {0.f, -0.f, 1.f, -1.f, 0.5f, -0.5f, 1e-38f, -1e-38f, 1e-45f, 3e38f, -3e38f};
  std::vector<Vec3> dirs;
  for (float x : special)
    for (float y : special)
      for (float z : special) dirs.push_back({x, y, z});
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (int i = 0; i < 20000; ++i) dirs.push_back({u(rng), u(rng), u(rng)});
  int checked = 0;
  for (const Vec3& d : dirs) {
    if (d.x == 0.f && d.y == 0.f && d.z == 0.f) continue;  // not a direction
    const Ray ray{{0.25f, -3.f, 7.f}, 0.f, d, INFINITY};
    const RayCtx a(ray, RayCtx::ShearAxes::branching), b(ray, RayCtx::ShearAxes::branch_free);
    ASSERT_EQ(a.kx, b.kx) << d.x << " " << d.y << " " << d.z;
    ASSERT_EQ(a.ky, b.ky) << d.x << " " << d.y << " " << d.z;
    ASSERT_EQ(a.kz, b.kz) << d.x << " " << d.y << " " << d.z;
    ASSERT_EQ(std::bit_cast<uint32_t>(a.sx), std::bit_cast<uint32_t>(b.sx));
    ASSERT_EQ(std::bit_cast<uint32_t>(a.sy), std::bit_cast<uint32_t>(b.sy));
    ASSERT_EQ(std::bit_cast<uint32_t>(a.sz), std::bit_cast<uint32_t>(b.sz));
    ++checked;
  }
  EXPECT_GT(checked, 21000);
  EXPECT_EQ(RayCtx::axes_for(true), RayCtx::ShearAxes::branching);
  EXPECT_EQ(RayCtx::axes_for(false), RayCtx::ShearAxes::branch_free);
}

TEST(TriangleKernels, ParseKernelNames) {
  EXPECT_EQ(parse_kernel("moller"), TriKernel::moller);
  EXPECT_THROW(parse_kernel("fastest"), InputError);
}

}  // namespace
}  // namespace tb
