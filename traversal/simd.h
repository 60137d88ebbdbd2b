// The one SIMD wrapper of the suite: simd::V<L> for L = 1 (scalar float), 4 (SSE) and 8 (AVX2)
// lanes, with the same operations under the same names, so each kernel of traversal/kernels.h
// (ray/triangle tests, the conservative slab test) is written once as a template over the lane
// count and instantiated for single rays (L = 1), 4-wide nodes and blocks, and 8-wide
// nodes/blocks/packets. simd::D<L> is its double-precision counterpart (L = 1: double; L = 4:
// AVX2 __m256d), used by exact_plane_distance.
//
// NaN semantics are part of the contract, because the slab test relies on them (see box_entry):
// min(a, b) = a < b ? a : b and max(a, b) = a > b ? a : b, i.e. the SECOND operand when either is
// NaN — what minps/maxps do. V<1> issues minss/maxss itself: the expressions compile to them in a
// plain build, but the profile-guided build turned them into branches where the training's rays
// took one side (bvh_single's slab test: 2x slower on bounce rays; docs/PERFORMANCE.md, session 40). Compares
// are ordered (false on NaN) except neq, which is unordered (true on NaN), as C++'s != is.
// V<1>'s masks are bool, so scalar code keeps its branches; V<4>/V<8> masks are all-ones lanes.
#pragma once
#include <immintrin.h>

#include <cstdint>

#include "structures/vec3.h"

namespace tb::simd {

template <int L>
struct V;

template <>
struct V<1> {
  static constexpr int kLanes = 1;
  using f = float;
  using m = bool;
  static f load(const float* p) { return *p; }
  static f set1(float x) { return x; }
  static f add(f a, f b) { return a + b; }
  static f sub(f a, f b) { return a - b; }
  static f mul(f a, f b) { return a * b; }
  static f div(f a, f b) { return a / b; }
  // a < b ? a : b and a > b ? a : b as one vminss/vmaxss each (structures/vec3.h: not left to the
  // compiler's profile).
  static f min(f a, f b) { return minss(a, b); }
  static f max(f a, f b) { return maxss(a, b); }
  static m and_(m a, m b) { return a && b; }
  static m or_(m a, m b) { return a || b; }
  static m andnot(m a, m b) { return !a && b; }  // ~a & b
  static f blendv(f a, f b, m s) { return s ? b : a; }
  static m lt(f a, f b) { return a < b; }
  static m le(f a, f b) { return a <= b; }
  static m gt(f a, f b) { return a > b; }
  static m ge(f a, f b) { return a >= b; }
  static m eq(f a, f b) { return a == b; }
  static m neq(f a, f b) { return a != b; }
  static f zero() { return 0.f; }
  static f abs(f a) { return __builtin_fabsf(a); }
  static f rcp(f a) { return _mm_cvtss_f32(_mm_rcp_ss(_mm_set_ss(a))); }  // 12-bit approximation
  static f select(m s, f a) { return s ? a : 0.f; }  // a where s, else 0
  static int mask(m a) { return int(a); }
  static bool any(m a) { return a; }
  static m all_true() { return true; }
  static void store(float* p, f a) { *p = a; }
  static float lane(f a, uint32_t) { return a; }
};

// V<4> and V<8> are one definition: the same operations on the SSE (_mm_*) or AVX (_mm256_*)
// intrinsics. Compares use the VEX predicate form for both (ordered, non-signalling), so V<4>'s
// results are those of cmpltps & co.
#define TB_SIMD_FLOAT_OPS(P, F, L, FT, IT)                                                       \
  static constexpr int kLanes = L;                                                               \
  using f = FT;                                                                                  \
  using m = FT;                                                                                  \
  using i = IT;                                                                                  \
  static f load(const float* p) { return P##_load_ps(p); }                                      \
  static f set1(float x) { return P##_set1_ps(x); }                                              \
  static f add(f a, f b) { return P##_add_ps(a, b); }                                            \
  static f sub(f a, f b) { return P##_sub_ps(a, b); }                                            \
  static f mul(f a, f b) { return P##_mul_ps(a, b); }                                            \
  static f fma(f a, f b, f c) { return P##_fmadd_ps(a, b, c); } /* a * b + c, one rounding */    \
  static f div(f a, f b) { return P##_div_ps(a, b); }                                            \
  static f min(f a, f b) { return P##_min_ps(a, b); }                                            \
  static f max(f a, f b) { return P##_max_ps(a, b); }                                            \
  static f and_(f a, f b) { return P##_and_ps(a, b); }                                           \
  static f or_(f a, f b) { return P##_or_ps(a, b); }                                             \
  static f andnot(f a, f b) { return P##_andnot_ps(a, b); } /* ~a & b */                         \
  static f blendv(f a, f b, f s) { return P##_blendv_ps(a, b, s); }                              \
  static f lt(f a, f b) { return P##_cmp_ps(a, b, _CMP_LT_OQ); }                                 \
  static f le(f a, f b) { return P##_cmp_ps(a, b, _CMP_LE_OQ); }                                 \
  static f gt(f a, f b) { return P##_cmp_ps(a, b, _CMP_GT_OQ); }                                 \
  static f ge(f a, f b) { return P##_cmp_ps(a, b, _CMP_GE_OQ); }                                 \
  static f eq(f a, f b) { return P##_cmp_ps(a, b, _CMP_EQ_OQ); }                                 \
  static f neq(f a, f b) { return P##_cmp_ps(a, b, _CMP_NEQ_UQ); }                               \
  static f zero() { return P##_setzero_ps(); }                                                   \
  static f abs(f a) { return P##_andnot_ps(P##_set1_ps(-0.f), a); }                              \
  static f rcp(f a) { return P##_rcp_ps(a); }                                                    \
  static f select(m s, f a) { return P##_and_ps(s, a); }                                         \
  static int mask(f a) { return P##_movemask_ps(a); }                                            \
  static bool any(m a) { return P##_movemask_ps(a) != 0; }                                       \
  static m all_true() { return P##_castsi##F##_ps(P##_set1_epi32(-1)); }                         \
  static void store(float* p, f a) { P##_store_ps(p, a); }

template <>
struct V<4> {
  TB_SIMD_FLOAT_OPS(_mm, 128, 4, __m128, __m128i)
  static float hmin(f a) {
    a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
    a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2)));
    return _mm_cvtss_f32(a);
  }
  // Lane i, without a round trip through memory.
  static float lane(f a, uint32_t l) { return _mm_cvtss_f32(_mm_permutevar_ps(a, _mm_cvtsi32_si128(int(l)))); }
};

template <>
struct V<8> {
  TB_SIMD_FLOAT_OPS(_mm256, 256, 8, __m256, __m256i)
  static float hmin(f a) { return V<4>::hmin(_mm_min_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1))); }
  static float lane(f a, uint32_t l) {
    return _mm256_cvtss_f32(_mm256_permutevar8x32_ps(a, _mm256_castsi128_si256(_mm_cvtsi32_si128(int(l)))));
  }
};
#undef TB_SIMD_FLOAT_OPS

// Double lanes for exact_plane_distance: plain double, or four lanes of AVX2 with the arithmetic
// operators (so one expression serves both, with the same operations in the same order).
template <int L>
struct D;
template <>
struct D<1> {
  using d = double;
};
struct D4v {
  __m256d v;
  D4v() = default;
  D4v(__m256d x) : v(x) {}
  explicit D4v(double x) : v(_mm256_set1_pd(x)) {}
  explicit D4v(__m128 x) : v(_mm256_cvtps_pd(x)) {}  // four floats, widened exactly
  friend D4v operator+(D4v a, D4v b) { return _mm256_add_pd(a.v, b.v); }
  friend D4v operator-(D4v a, D4v b) { return _mm256_sub_pd(a.v, b.v); }
  friend D4v operator*(D4v a, D4v b) { return _mm256_mul_pd(a.v, b.v); }
  friend D4v operator/(D4v a, D4v b) { return _mm256_div_pd(a.v, b.v); }
  int zero_mask() const { return _mm256_movemask_pd(_mm256_cmp_pd(v, _mm256_setzero_pd(), _CMP_EQ_OQ)); }
  __m128 to_float() const { return _mm256_cvtpd_ps(v); }
};
template <>
struct D<4> {
  using d = D4v;
};

}  // namespace tb::simd
