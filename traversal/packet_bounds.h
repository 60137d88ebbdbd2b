// Packet bounds used for early misses by the BVH packet schemes (thesis §2.2.2, §3.3): interval
// arithmetic over origins and reciprocal directions (all packets), a frustum of four planes for
// packets with a common origin, and the eight planes a leaf's triangles are culled with. The
// types and their tests against one box or triangle; fitting the frustum to a packet is
// packet_frustum.h.
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "structures/bvh.h"
#include "structures/triangles.h"
#include "traversal/kernels.h"

namespace tb::packet {

// ---------------------------------------------------------------------------------------------
// Interval arithmetic over the packet (Wald et al. 2007; Boulos et al. 2006): per axis the range
// of origins and of reciprocal directions. An axis is usable only when every ray's reciprocal
// direction has the same sign bit and is finite; then the smallest entry distance and the largest
// (padded) exit distance any ray can compute for a box follow from the interval corners — the
// same rounded operations the per-ray test performs, and rounding is monotonic, so the bound
// holds for the computed per-ray values, not just the exact ones.
struct IABounds {
  __m128 omin, omax, rmin, rmax;
  __m128 neg;      // all-ones lanes where the axis' directions are negative
  __m128 usable;   // all-ones lanes (x, y, z) usable; lane 3 never
  float tmin_min = 0.f;
  float tfar_max = INFINITY;  // max over the packet's rays of the closest hit so far
};

inline float hmax3(__m128 v) {
  return std::max(std::max(_mm_cvtss_f32(v), _mm_cvtss_f32(_mm_shuffle_ps(v, v, 1))),
                  _mm_cvtss_f32(_mm_shuffle_ps(v, v, 2)));
}
inline float hmin3(__m128 v) {
  return std::min(std::min(_mm_cvtss_f32(v), _mm_cvtss_f32(_mm_shuffle_ps(v, v, 1))),
                  _mm_cvtss_f32(_mm_shuffle_ps(v, v, 2)));
}

// True when no ray of the packet can enter the node's box (early miss, Alg. 2.6 line 4). Forced
// inline: see group_box (packet_box.h).
[[gnu::always_inline]] inline bool ia_misses(const IABounds& b, const BVHNode& n) {
  const __m128 lo = _mm_loadu_ps(&n.lo.x), hi = _mm_loadu_ps(&n.hi.x);
  const __m128 pn = _mm_blendv_ps(lo, hi, b.neg), pf = _mm_blendv_ps(hi, lo, b.neg);
  const __m128 zero = _mm_setzero_ps();
  // Smallest entry: positive directions grow with the offset, so take the largest origin; the
  // reciprocal bound then depends on the offset's sign (see header comment).
  const __m128 xn = _mm_sub_ps(pn, _mm_blendv_ps(b.omax, b.omin, b.neg));
  const __m128 ln = _mm_mul_ps(xn, _mm_blendv_ps(b.rmax, b.rmin, _mm_cmpge_ps(xn, zero)));
  const __m128 xf = _mm_sub_ps(pf, _mm_blendv_ps(b.omin, b.omax, b.neg));
  const __m128 uf = _mm_mul_ps(_mm_mul_ps(xf, _mm_blendv_ps(b.rmin, b.rmax, _mm_cmpge_ps(xf, zero))),
                               _mm_set1_ps(kFarPad));
  // Unusable axes constrain nothing; NaN cannot occur on usable axes (finite reciprocals) but
  // would be ignored by the operand order anyway.
  const __m128 L = _mm_blendv_ps(_mm_set1_ps(-INFINITY), ln, b.usable);
  const __m128 U = _mm_blendv_ps(_mm_set1_ps(INFINITY), uf, b.usable);
  const float tn = std::max(hmax3(L), b.tmin_min);
  const float tf = std::min(hmin3(U), b.tfar_max);
  return tn > tf;
}

// ---------------------------------------------------------------------------------------------
// A frustum of four planes through the common origin, inward normals as SSE lanes (Reshetov et
// al. 2005; Wald et al. 2007 for BVHs). Every ray satisfies n.d > 0 (see fit_plane).
struct Frustum {
  bool valid = false;
  __m128 nx, ny, nz;
  __m128 ox, oy, oz;
};

// A box or triangle is culled when it lies entirely on the outer side of one plane, by more
// than the rounding of the float evaluation: f = n.(x - o) is within gamma(4) * sum|n_i a_i| of
// its exact value, and the margin 1e-6 * sum|n_i a_i| is several times that.
inline __m128 plane_outside(const Frustum& f, __m128 x, __m128 y, __m128 z) {
  const __m128 ax = _mm_sub_ps(x, f.ox), ay = _mm_sub_ps(y, f.oy), az = _mm_sub_ps(z, f.oz);
  const __m128 px = _mm_mul_ps(f.nx, ax), py = _mm_mul_ps(f.ny, ay), pz = _mm_mul_ps(f.nz, az);
  const __m128 s = _mm_add_ps(_mm_add_ps(px, py), pz);
  const __m128 absmask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
  const __m128 mag = _mm_add_ps(_mm_add_ps(_mm_and_ps(px, absmask), _mm_and_ps(py, absmask)),
                                _mm_and_ps(pz, absmask));
  return _mm_cmplt_ps(s, _mm_mul_ps(mag, _mm_set1_ps(-1e-6f)));
}

// Early miss: the node's box lies outside the packet frustum.
inline bool frustum_misses_box(const Frustum& f, const BVHNode& n) {
  // The corner that maximises n.x: hi where the normal component is positive, lo where negative.
  const __m128 x = _mm_blendv_ps(_mm_set1_ps(n.hi.x), _mm_set1_ps(n.lo.x), f.nx);
  const __m128 y = _mm_blendv_ps(_mm_set1_ps(n.hi.y), _mm_set1_ps(n.lo.y), f.ny);
  const __m128 z = _mm_blendv_ps(_mm_set1_ps(n.hi.z), _mm_set1_ps(n.lo.z), f.nz);
  return _mm_movemask_ps(plane_outside(f, x, y, z)) != 0;
}

// The planes a leaf's triangles are culled with, 8 lanes: 0-3 the packet frustum, 4-7 the two
// split planes of §3.3 as four half-spaces (left, right, top and bottom half of the 16x16
// packet). A zero normal never culls (its evaluation is exactly 0, never below the margin).
struct TriCull {
  __m256 nx, ny, nz, ox, oy, oz;
};
enum : uint32_t { kPlaneL = 1u << 4, kPlaneR = 1u << 5, kPlaneT = 1u << 6, kPlaneB = 1u << 7 };

// Bit j set when the triangle lies entirely outside plane j (same margin as plane_outside).
inline uint32_t tri_outside(const TriCull& c, const TriVerts& t) {
  const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF)), eps = _mm256_set1_ps(-1e-6f);
  __m256 out = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  for (const Vec3& v : {t.v0, t.v1, t.v2}) {
    const __m256 px = _mm256_mul_ps(c.nx, _mm256_sub_ps(_mm256_set1_ps(v.x), c.ox));
    const __m256 py = _mm256_mul_ps(c.ny, _mm256_sub_ps(_mm256_set1_ps(v.y), c.oy));
    const __m256 pz = _mm256_mul_ps(c.nz, _mm256_sub_ps(_mm256_set1_ps(v.z), c.oz));
    const __m256 s = _mm256_add_ps(_mm256_add_ps(px, py), pz);
    const __m256 mag = _mm256_add_ps(_mm256_add_ps(_mm256_and_ps(px, absmask), _mm256_and_ps(py, absmask)),
                                     _mm256_and_ps(pz, absmask));
    out = _mm256_and_ps(out, _mm256_cmp_ps(s, _mm256_mul_ps(mag, eps), _CMP_LT_OQ));
  }
  return uint32_t(_mm256_movemask_ps(out));
}

// The 64-ray quadrants (bits 0-3) a triangle may touch, from tri_outside's plane bits: quadrant
// 0 is the top-left 8x8 block of the Fig. 16 layout, 1 top-right, 2 bottom-left, 3 bottom-right.
inline uint32_t quadrants_touched(uint32_t out) {
  if (out & 0xFu) return 0;
  uint32_t q = 0xFu;
  if (out & kPlaneL) q &= ~0b0101u;
  if (out & kPlaneR) q &= ~0b1010u;
  if (out & kPlaneT) q &= ~0b0011u;
  if (out & kPlaneB) q &= ~0b1100u;
  return q;
}

}  // namespace tb::packet
