// Small float vector and axis-aligned box: the only math every module shares.
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace tb {

struct Vec3 {
  float x = 0, y = 0, z = 0;
  constexpr Vec3() = default;
  constexpr Vec3(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
  constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};

constexpr Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
constexpr Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
constexpr Vec3 operator*(float s, Vec3 a) { return a * s; }
constexpr Vec3 operator*(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
constexpr Vec3 operator/(Vec3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
constexpr bool operator==(Vec3 a, Vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
inline Vec3& operator+=(Vec3& a, Vec3 b) { a = a + b; return a; }
constexpr float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float length(Vec3 a) { return std::sqrt(dot(a, a)); }
inline Vec3 normalize(Vec3 a) { return a / length(a); }
// minss(a, b) = a < b ? a : b and maxss(a, b) = a > b ? a : b, the SECOND operand when either is
// NaN or both are zeros: one vminss/vmaxss each, whatever the compiler's profile says. The
// profile-guided build (scripts/build.sh) had turned the ternaries into compares and branches laid
// out for the training's data: in Scene::triangle_bounds, mispredicting on a mesh's vertices (thesis
// Table 1's refits 2.2-3.6x slower, docs/PERFORMANCE.md, session 34), and in the single-ray slab
// test (simd::V<1>::min/max, which are these; bvh_single 2x slower on bounce rays, session 40).
// Inline asm rather than _mm_min_ss(_mm_set_ss(a), _mm_set_ss(b)): the intrinsics add a move that
// zeroes the upper lanes, on the slab test's dependency chain.
inline float minss(float a, float b) {
  float r;
  __asm__("vminss %2, %1, %0" : "=x"(r) : "x"(a), "x"(b));
  return r;
}
inline float maxss(float a, float b) {
  float r;
  __asm__("vmaxss %2, %1, %0" : "=x"(r) : "x"(a), "x"(b));
  return r;
}
// std::min(a, b) and std::max(a, b) exactly ((b < a) ? b : a and (a < b) ? b : a, so NaNs and
// signed zeros come out the same), branch-free.
inline float min_of(float a, float b) { return minss(b, a); }
inline float max_of(float a, float b) { return maxss(b, a); }
inline Vec3 vmin(Vec3 a, Vec3 b) { return {min_of(a.x, b.x), min_of(a.y, b.y), min_of(a.z, b.z)}; }
inline Vec3 vmax(Vec3 a, Vec3 b) { return {max_of(a.x, b.x), max_of(a.y, b.y), max_of(a.z, b.z)}; }
inline bool is_finite(Vec3 a) { return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z); }
inline float max_abs(Vec3 a) { return std::max({std::fabs(a.x), std::fabs(a.y), std::fabs(a.z)}); }

// The coordinates travbench traces: scene vertices and ray origins and directions with |x| <= 2^56
// (7.2e16), directions whose largest component is >= 2^-56, and no denormal component. Why: the
// node tests carry a per-ray error bound proportional to (|scene| + |origin|) / |direction| and
// leave an axis out where it would exceed 2^100 (kernels.h, FusedPlanes; the compressed BVH's decode
// needs 8 ulps of it); inside these limits the dominant axis of every ray is always kept, so no
// node test degenerates into "every child entered" (which took the unused child slots of an MBVH
// node with it: a crash). Every thread that traces reads denormals as 0 (DAZ, trace_runner.h), so a
// denormal would be traced as a different ray or scene than the exact reference sees. Embree's own
// valid range is |x| <= 1.844e18 (its FLT_LARGE), so a valid ray is valid for the baselines too.
inline constexpr float kCoordLimit = 0x1p56f;
// The smallest scene travbench traces: a bounding box at least 2^-51 (4.4e-16) wide on its widest
// axis. The float kernels multiply coordinate differences (the watertight edge functions, U = Cx
// By - Cy Bx on vertices relative to the origin): for a scene of extent s seen from a distance d
// near s they are ~s^2, and they keep 24 significant bits only while s^2 >= 2^24 FLT_MIN = 2^-102.
// Below that every thread's flush-to-zero arithmetic loses them: a scene 1e-18 across gave every
// non-Embree scheme false hits and misses (4-16% of its rays) against the exact reference, which
// loses nothing (a bad-input audit, session 37; 1e-16 across was still clean).
inline constexpr float kMinSceneExtent = 0x1p-51f;
inline bool is_denormal(float x) { return x != 0.f && std::fabs(x) < std::numeric_limits<float>::min(); }
inline bool in_coord_range(float x) { return std::fabs(x) <= kCoordLimit && !is_denormal(x); }
inline bool in_coord_range(Vec3 a) { return in_coord_range(a.x) && in_coord_range(a.y) && in_coord_range(a.z); }

struct AABB {
  Vec3 lo{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
          std::numeric_limits<float>::infinity()};
  Vec3 hi{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
          -std::numeric_limits<float>::infinity()};
  void grow(Vec3 p) { lo = vmin(lo, p); hi = vmax(hi, p); }
  void grow(const AABB& b) { lo = vmin(lo, b.lo); hi = vmax(hi, b.hi); }
  bool empty() const { return !(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z); }
  Vec3 extent() const { return hi - lo; }
  Vec3 centre() const { return (lo + hi) * 0.5f; }
  float area() const {
    if (empty()) return 0.f;
    Vec3 e = extent();
    return 2.f * (e.x * e.y + e.y * e.z + e.z * e.x);
  }
  bool contains(const AABB& b) const {
    return lo.x <= b.lo.x && lo.y <= b.lo.y && lo.z <= b.lo.z && hi.x >= b.hi.x && hi.y >= b.hi.y &&
           hi.z >= b.hi.z;
  }
  int longest_axis() const {
    Vec3 e = extent();
    return e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
  }
};
// The common part of two boxes (empty when they do not overlap).
inline AABB intersect(const AABB& a, const AABB& b) { return {vmax(a.lo, b.lo), vmin(a.hi, b.hi)}; }

}  // namespace tb
