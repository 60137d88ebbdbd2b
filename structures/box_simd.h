// Boxes in SSE registers for the builders' per-reference loops (structures/bvh.cpp,
// structures/bvh_spatial.cpp): a box is a (lo, hi) pair of 4-float registers whose lane 3 is
// ignored. The operations give the same floats as the scalar AABB (vec3.h), so a builder that
// uses them makes the same tree.
#pragma once
#include <immintrin.h>

#include "structures/vec3.h"

namespace tb {

// Min/max with std::min/std::max semantics (vmin/vmax in vec3.h): minps returns its second
// operand unless the first is strictly smaller, so the accumulator goes second. Keeps ±0 and the
// boxes bit-identical to the scalar AABB::grow.
inline __m128 grow_lo(__m128 acc, __m128 x) { return _mm_min_ps(x, acc); }
inline __m128 grow_hi(__m128 acc, __m128 x) { return _mm_max_ps(x, acc); }

// AABB::area() of a non-empty box, same operation order: 2 * (ex*ey + ey*ez + ez*ex).
inline float area(__m128 lo, __m128 hi) {
  const __m128 e = _mm_sub_ps(hi, lo);
  const __m128 p = _mm_mul_ps(e, _mm_shuffle_ps(e, e, _MM_SHUFFLE(3, 0, 2, 1)));  // (ex*ey, ey*ez, ez*ex)
  alignas(16) float f[4];
  _mm_store_ps(f, p);
  return 2.f * (f[0] + f[1] + f[2]);
}

// An AABB's corners as registers (lane 3 zero) and back.
inline __m128 load_vec3(const Vec3& v) { return _mm_setr_ps(v.x, v.y, v.z, 0.f); }
inline AABB to_aabb(__m128 lo, __m128 hi) {
  alignas(16) float l[4], h[4];
  _mm_store_ps(l, lo);
  _mm_store_ps(h, hi);
  return {{l[0], l[1], l[2]}, {h[0], h[1], h[2]}};
}

}  // namespace tb
