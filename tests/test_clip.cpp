// The one triangle/box clipper (structures/clip.h), used by the kD-tree's perfect splits and by
// the RayGrid octree: the overlap decision against an independent separating-axis test, the
// clipped bounds against points sampled on the triangle, and the hard cases — degenerate
// triangles (a point, a segment, slivers), triangles that touch the box only along an edge or at
// a vertex, and all of it 1e5 and 3e5 away from the origin, where a float ulp is 1/128 or 1/32.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "structures/clip.h"
#include "test_geometry.h"

namespace tb {
namespace {

using test::sat_overlap;

// Points of triangle (a, b, c) on a barycentric grid, in double (edges and vertices included;
// a vertex, and a point of a degenerate triangle's repeated vertex, exactly).
template <class F>
void for_each_sample(Vec3 a, Vec3 b, Vec3 c, int steps, F&& f) {
  for (int i = 0; i <= steps; ++i)
    for (int j = 0; j <= steps - i; ++j) {
      const double u = double(i) / steps, v = double(j) / steps;
      double p[3];
      for (int k = 0; k < 3; ++k) p[k] = a[k] + u * (double(b[k]) - a[k]) + v * (double(c[k]) - a[k]);
      f(p);
    }
}

// Inside the closed box grown by `tol`.
bool in_box(const double p[3], const AABB& box, double tol = 0) {
  for (int k = 0; k < 3; ++k)
    if (p[k] < double(box.lo[k]) - tol || p[k] > double(box.hi[k]) + tol) return false;
  return true;
}

// What every clip must satisfy: the bounds lie in the box and in the triangle's bounds, and hold
// every sampled point of the triangle that lies in the box.
void check_clip(Vec3 a, Vec3 b, Vec3 c, const AABB& box, const AABB& got) {
  if (got.empty()) return;
  AABB tri;
  tri.grow(a), tri.grow(b), tri.grow(c);
  EXPECT_TRUE(box.contains(got)) << "clipped bounds leave the box";
  EXPECT_TRUE(tri.contains(got)) << "clipped bounds leave the triangle's bounds";
  // Sampled points are computed in double from the float vertices, a few double ulps off the
  // triangle: allowed that much, far below a float ulp, a point the float bounds do not hold is
  // a real miss.
  double scale = 0;
  for (int k = 0; k < 3; ++k) scale = std::max({scale, std::fabs(double(box.lo[k])), std::fabs(double(box.hi[k]))});
  const double tol = 8 * 0x1p-52 * scale;
  int missed = 0;
  for_each_sample(a, b, c, 24, [&](const double p[3]) {
    if (in_box(p, box) && !in_box(p, got, tol)) ++missed;
  });
  EXPECT_EQ(missed, 0) << "sampled points of the clipped triangle outside its bounds";
}

AABB clip_checked(Vec3 a, Vec3 b, Vec3 c, const AABB& box) {
  const AABB got = clip_triangle_bounds(a, b, c, box);
  check_clip(a, b, c, box, got);
  return got;
}

TEST(Clip, TriangleBounds) {
  const AABB box{{0, 0, 0}, {1, 1, 1}};
  // A triangle through the box: clipped bounds lie in the box and in the triangle's bounds.
  AABB b = clip_triangle_bounds({-1, 0.5f, 0.5f}, {2, 0.5f, 0.5f}, {0.5f, 3, 0.5f}, box);
  ASSERT_FALSE(b.empty());
  EXPECT_EQ(b.lo.x, 0.f);
  EXPECT_EQ(b.hi.x, 1.f);
  EXPECT_EQ(b.lo.y, 0.5f);
  EXPECT_EQ(b.hi.y, 1.f);
  EXPECT_EQ(b.lo.z, 0.5f);
  EXPECT_EQ(b.hi.z, 0.5f);
  // Lying in a face: kept whole (closed box).
  b = clip_triangle_bounds({0.1f, 0.1f, 1}, {0.9f, 0.1f, 1}, {0.1f, 0.9f, 1}, box);
  ASSERT_FALSE(b.empty());
  EXPECT_EQ(b.lo.z, 1.f);
  EXPECT_EQ(b.hi.z, 1.f);
  // Bounding boxes overlap, the triangle does not (it lies in x + y = 2.5): a perfect split
  // drops it, and so does a box it misses entirely.
  EXPECT_TRUE(clip_triangle_bounds({2.5f, 0, 0.5f}, {0, 2.5f, 0.5f}, {2.5f, 0, 0.6f}, box).empty());
  EXPECT_TRUE(clip_triangle_bounds({2, 2, 2}, {3, 2, 2}, {2, 3, 2}, box).empty());
  // Interpolated coordinates are rounded outward: the clipped bounds stay in the box and the
  // clipped area inside a box that holds the whole triangle is its area.
  const Vec3 a{-0.3f, 0.1f, 0.7f}, c1{1.7f, 0.9f, 0.2f}, c2{0.4f, 1.3f, -0.6f};
  b = clip_checked(a, c1, c2, box);
  ASSERT_FALSE(b.empty());
  const Vec3 n = cross(c1 - a, c2 - a);
  EXPECT_NEAR(clipped_triangle_area(a, c1, c2, AABB{{-10, -10, -10}, {10, 10, 10}}), 0.5 * length(n), 1e-5);
  EXPECT_LT(clipped_triangle_area(a, c1, c2, box), 0.5 * length(n));
}

// The cases below on a lattice of step `u` around `o` (every lattice point exactly a float at
// these offsets), so that "on the face" and "at the corner" are exact.
struct Lattice {
  float o, u;
  Vec3 p(float x, float y, float z) const { return {o + u * x, o + u * y, o + u * z}; }
  AABB box(Vec3 lo, Vec3 hi) const { return {p(lo.x, lo.y, lo.z), p(hi.x, hi.y, hi.z)}; }
};
const Lattice kLattices[] = {{0.f, 0.125f}, {1e5f, 0.125f}, {-3e5f, 0.5f}, {1e5f, 1.f / 128}};

// A triangle and the clipped bounds it must give exactly, in lattice coordinates.
struct Exact {
  const char* what;
  Vec3 a, b, c, lo, hi;
};

void expect_exact(const Lattice& L, const AABB& box, const Exact& e) {
  SCOPED_TRACE(e.what);
  auto at = [&](Vec3 v) { return L.p(v.x, v.y, v.z); };
  const AABB got = clip_checked(at(e.a), at(e.b), at(e.c), box);
  ASSERT_FALSE(got.empty());
  EXPECT_EQ(got.lo, at(e.lo));
  EXPECT_EQ(got.hi, at(e.hi));
}

TEST(Clip, TouchingOnlyAtAnEdgeOrAVertex) {
  const Exact cases[] = {
      {"a vertex at a corner of the box, the rest outside", {8, 8, 8}, {16, 12, 9}, {12, 16, 14}, {8, 8, 8}, {8, 8, 8}},
      {"a vertex inside a face", {3, 5, 8}, {1, 2, 20}, {6, 7, 12}, {3, 5, 8}, {3, 5, 8}},
      {"an edge lying in a face", {2, 3, 8}, {6, 5, 8}, {4, 4, 16}, {2, 3, 8}, {6, 5, 8}},
      {"an edge along an edge of the box", {8, 8, 1}, {8, 8, 7}, {16, 24, 4}, {8, 8, 1}, {8, 8, 7}},
  };
  for (const Lattice& L : kLattices) {
    SCOPED_TRACE(::testing::Message() << "offset " << L.o << " step " << L.u);
    const AABB box = L.box({0, 0, 0}, {8, 8, 8});
    for (const Exact& e : cases) expect_exact(L, box, e);
    // Touching at a point that is no vertex: the triangle lies in z = 4 beyond x + y = 16 and
    // meets the box only at (8, 8, 4), where its edge crosses the box's vertical edge.
    const Vec3 touch = L.p(8, 8, 4);
    const AABB b = clip_checked(L.p(16, 0, 4), L.p(0, 16, 4), L.p(16, 16, 4), box);
    ASSERT_FALSE(b.empty());
    EXPECT_TRUE(b.lo.x <= touch.x && b.hi.x >= touch.x && b.lo.y <= touch.y && b.hi.y >= touch.y);
    EXPECT_TRUE(b.lo.z == touch.z && b.hi.z == touch.z);
    // The vertex and the edge in the face one float step outside the box do not touch it.
    const float out = std::nextafter(box.hi.z, INFINITY);
    Vec3 v0 = L.p(3, 5, 8), w0 = L.p(2, 3, 8), w1 = L.p(6, 5, 8);
    v0.z = w0.z = w1.z = out;
    EXPECT_TRUE(clip_triangle_bounds(v0, L.p(1, 2, 20), L.p(6, 7, 12), box).empty());
    EXPECT_TRUE(clip_triangle_bounds(w0, w1, L.p(4, 4, 16), box).empty());
  }
}

TEST(Clip, DegenerateTriangles) {
  const Exact cases[] = {
      {"a point inside", {3, 4, 5}, {3, 4, 5}, {3, 4, 5}, {3, 4, 5}, {3, 4, 5}},
      {"a point on a corner", {0, 8, 0}, {0, 8, 0}, {0, 8, 0}, {0, 8, 0}, {0, 8, 0}},
      // Collinear vertices, one repeated or one between the others, along the box's diagonal.
      {"a segment, repeated end", {-8, -8, -8}, {16, 16, 16}, {-8, -8, -8}, {0, 0, 0}, {8, 8, 8}},
      {"a segment, middle vertex", {-8, -8, -8}, {16, 16, 16}, {4, 4, 4}, {0, 0, 0}, {8, 8, 8}},
  };
  for (const Lattice& L : kLattices) {
    SCOPED_TRACE(::testing::Message() << "offset " << L.o << " step " << L.u);
    const AABB box = L.box({0, 0, 0}, {8, 8, 8});
    for (const Exact& e : cases) expect_exact(L, box, e);
    EXPECT_TRUE(clip_triangle_bounds(L.p(9, 4, 5), L.p(9, 4, 5), L.p(9, 4, 5), box).empty());
    // A segment through the box off the diagonal: it enters at x = 0 and leaves at x = 8.
    const AABB b = clip_checked(L.p(-4, 1, 2), L.p(12, 5, 6), L.p(4, 3, 4), box);
    ASSERT_FALSE(b.empty());
    EXPECT_EQ(b.lo.x, box.lo.x);
    EXPECT_EQ(b.hi.x, box.hi.x);
    // A segment passing beside the box.
    EXPECT_TRUE(clip_triangle_bounds(L.p(-4, 9, 2), L.p(12, 9, 6), L.p(4, 9, 4), box).empty());
  }
}

// Random triangles and boxes around the origin and far from it: the overlap decision agrees with
// the separating axis test, and the bounds hold every sampled point. Slivers (nearly collinear
// vertices) crossing faces and corners are the hard part: their interpolated vertices carry
// rounding that can make the clipped polygon non-convex, so clipping may add more than one
// vertex per plane (the vertex budget of structures/clip.cpp).
TEST(Clip, RandomTrianglesSliversAndOffsets) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  for (const float offset : {0.f, 1e5f, -3e5f}) {
    SCOPED_TRACE(::testing::Message() << "offset " << offset);
    const float scale = offset == 0.f ? 1.f : 64.f;  // well above the ulp at the offset
    int disagree = 0, overlapping = 0;
    for (int i = 0; i < 3000; ++i) {
      const Vec3 o{offset, offset, offset};
      const Vec3 c = o + Vec3{U(rng), U(rng), U(rng)} * scale;
      const Vec3 h = Vec3{std::fabs(U(rng)), std::fabs(U(rng)), std::fabs(U(rng))} * (0.5f * scale);
      const AABB box{c - h, c + h};
      Vec3 a = o + Vec3{U(rng), U(rng), U(rng)} * (1.5f * scale);
      Vec3 b = o + Vec3{U(rng), U(rng), U(rng)} * (1.5f * scale);
      Vec3 d;
      switch (i % 3) {
        case 0: d = o + Vec3{U(rng), U(rng), U(rng)} * (1.5f * scale); break;
        case 1: {  // sliver: the third vertex a tiny step off the segment a-b
          const float t = 0.5f + 0.5f * U(rng);
          d = a + (b - a) * t + Vec3{U(rng), U(rng), U(rng)} * (1e-6f * scale);
          break;
        }
        default: {  // sliver through a corner of the box
          a = box.lo - (box.hi - box.lo) * 0.5f;
          b = box.lo + (box.hi - box.lo) * 0.5f;
          d = box.lo + Vec3{U(rng), U(rng), U(rng)} * (1e-5f * scale);
        }
      }
      const AABB got = clip_checked(a, b, d, box);
      overlapping += !got.empty();
      // Slivers may graze the box within rounding; the separating axis test decides in double
      // too, so the two may only differ there.
      if (!got.empty() != sat_overlap(a, b, d, box) && i % 3 == 0) ++disagree;
    }
    EXPECT_EQ(disagree, 0) << "overlap decision differs from the separating axis test";
    EXPECT_GT(overlapping, 300);
  }
}

// The spatial-split builder's float sweep (chop_triangle_bounds) against the exact clipper, slab
// by slab: each part holds the exact clip of its slab (and every sampled point of it), stays
// within the slab, the clamp box and the triangle's bounds, and, unclamped, is empty exactly when
// the slab misses the triangle and at most the proven pad (2^-19 of the coordinates' magnitude)
// looser than the exact clip.
TEST(Clip, ChopMatchesSlabClips) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  std::uniform_int_distribution<int> N(1, 16);
  for (const float offset : {0.f, 1e5f, -3e5f}) {
    SCOPED_TRACE(::testing::Message() << "offset " << offset);
    const float scale = offset == 0.f ? 1.f : 64.f;
    int nonempty = 0, on_plane = 0;
    for (int i = 0; i < 2000; ++i) {
      const Vec3 o{offset, offset, offset};
      Vec3 v[3];
      for (auto& p : v) p = o + Vec3{U(rng), U(rng), U(rng)} * scale;
      const int axis = i % 3;
      if (i % 5 == 1) v[2] = v[0] + (v[1] - v[0]) * 0.37f + Vec3{U(rng), U(rng), U(rng)} * (1e-6f * scale);  // sliver
      if (i % 5 == 2) v[1][(axis + 1) % 3] = v[0][(axis + 1) % 3];  // an edge parallel to a box plane
      if (i % 5 == 3) v[2][axis] = v[1][axis];  // an edge in a plane of the sweep axis
      AABB tri;
      for (const auto& p : v) tri.grow(p);
      const int n = N(rng);
      // Planes over a range a little wider than the triangle's, some moved onto a vertex.
      std::vector<float> pl(n + 1);
      const float lo = tri.lo[axis] - 0.1f * scale, hi = tri.hi[axis] + 0.1f * scale;
      for (int k = 0; k <= n; ++k) pl[k] = lo + (hi - lo) * (float(k) / float(n));
      if (n > 2 && i % 4 == 0) pl[1 + i / 4 % (n - 1)] = v[i % 3][axis], ++on_plane;
      std::sort(pl.begin(), pl.end());
      if (std::adjacent_find(pl.begin(), pl.end()) != pl.end()) continue;
      // Clamped to the triangle's bounds (a no-op) or, every other time, to a box that cuts it.
      AABB clampbox = tri;
      if (i % 2) clampbox.hi[(axis + 1) % 3] = 0.5f * (tri.lo[(axis + 1) % 3] + tri.hi[(axis + 1) % 3]);
      std::vector<AABB> out(n);
      chop_triangle_bounds(v, axis, pl.data(), n, clampbox, out.data());
      for (int k = 0; k < n; ++k) {
        AABB slab = clampbox;
        if (k > 0) slab.lo[axis] = pl[k];
        if (k < n - 1) slab.hi[axis] = pl[k + 1];
        const AABB exact = clip_triangle_bounds(v[0], v[1], v[2], slab);
        SCOPED_TRACE(::testing::Message() << "triangle " << i << " slab " << k << " of " << n);
        // Clamped, the part's bounds cut to the box may hold points of no part: only one way.
        if (i % 2 == 0) {
          ASSERT_EQ(out[k].empty(), exact.empty());
        }
        if (exact.empty()) continue;
        ASSERT_FALSE(out[k].empty());
        ++nonempty;
        EXPECT_TRUE(out[k].contains(exact)) << "part tighter than the exact clip";
        check_clip(v[0], v[1], v[2], slab, out[k]);
        for (int c = 0; c < 3 && i % 2 == 0; ++c) {
          const float m = std::max(std::fabs(tri.lo[c]), std::fabs(tri.hi[c]));
          const float tol = 2 * 0x1p-19f * m + 2 * std::numeric_limits<float>::min();
          EXPECT_GE(out[k].lo[c], exact.lo[c] - tol) << "axis " << c;
          EXPECT_LE(out[k].hi[c], exact.hi[c] + tol) << "axis " << c;
        }
      }
    }
    EXPECT_GT(nonempty, 4000);
    EXPECT_GT(on_plane, 200);
  }
}

}  // namespace
}  // namespace tb
