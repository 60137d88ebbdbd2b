// What the three BVH packet schemes share (thesis §2.2.2, §3.3; Overbeck et al. 2008 naming:
// bvh_masked, bvh_ranged, bvh_partition): the packet's rays as SoA groups of 8 (AVX2), the 8-wide
// ray/box and ray/triangle tests, and the packet bounds used for early misses — a frustum of
// four planes for packets with a common origin, interval arithmetic (IA) over origins and
// reciprocal directions for all packets.
//
// Robustness contract (the same as the single-ray schemes): the box test is the conservative,
// NaN-aware slab test of kernels.h evaluated lane-wise; the IA bounds are built from exactly the
// quantities the per-ray slab test computes, so by monotonic rounding they never cull a node any
// ray of the packet would enter; frustum planes are fitted to the rays, proven to hold every ray
// by a float check whose margin exceeds its rounding error, and are evaluated against boxes and
// triangles with such a margin too. The box and triangle tests are the kernel library's
// (traversal/kernels.h: slab<8>, watertight_inside<8>, moller<8>, plane<8>), so every lane
// computes the very same values as the one-ray tests; the rare lanes whose ray is parallel to a
// triangle's plane go to the scalar kernel.
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "traversal/bvh_common.h"

namespace tb::packet {

inline constexpr uint32_t kW = 8;            // AVX2 lanes
inline constexpr uint32_t kMaxRays = 256;    // the thesis' 16x16 primary packet (§3.3)
inline constexpr uint32_t kMaxGroups = kMaxRays / kW;
inline constexpr uint32_t kQuadRays = 64;    // an 8x8 quadrant of the Fig. 16 layout
inline constexpr uint32_t kNone = 0xFFFFu;   // "no active ray" as a ray index

// What a ray/box test reads (256 bytes per group of 8 rays).
struct alignas(32) RayGroup {
  __m256 o[3], inv[3], tmin, tfar;  // tfar: the closest hit so far (initially ray.tmax)
};
// What a ray/triangle test reads besides the RayGroup.
struct alignas(32) TriGroup {
  __m256 d[3];
  __m256 sx, sy;      // watertight shear of Woop et al. for the lane's dominant axis kz
  __m256 cx[3], cy[3];  // the shear as coefficient vectors, for groups whose lanes differ in kz
  int kz;             // the group's common dominant axis, or -1 when its lanes differ
};
struct alignas(32) HitGroup {
  __m256i prim;
  __m256 u, v;
};

inline int popcount8(uint32_t m) { return std::popcount(m & 0xFFu); }

// All-ones lanes where bit l of m is set.
inline __m256 lane_mask_ps(uint32_t m) {
  const __m256i bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  const __m256i v = _mm256_and_si256(_mm256_set1_epi32(int(m)), bits);
  return _mm256_castsi256_ps(_mm256_cmpeq_epi32(v, bits));
}

// Lanes of group g whose ray index lies in [first, last].
inline uint32_t range_mask(uint32_t g, uint32_t first, uint32_t last) {
  const uint32_t base = g * kW;
  uint32_t m = 0xFFu;
  if (first > base) m &= 0xFFu << (first - base);
  if (last < base + kW - 1) m &= 0xFFu >> (kW - 1 - (last - base));
  return m & 0xFFu;
}

// ---------------------------------------------------------------------------------------------
// The kernel library's slab test (kernels.h slab, as box_entry: padded far distance), 8 rays
// against one box. Near/far planes are selected per lane by the sign bit of the reciprocal
// direction (blendv reads the sign bit, so -0 -> -inf selects like the scalar test). Returns the
// lane mask of hits.
inline uint32_t box_mask(const RayGroup& g, const BVHNode& n) {
  using S = simd::V<8>;
  const float* lo = &n.lo.x;
  const float* hi = &n.hi.x;
  __m256 xn[3], xf[3];
  for (int a = 0; a < 3; ++a) {
    const __m256 l = _mm256_sub_ps(_mm256_set1_ps(lo[a]), g.o[a]), h = _mm256_sub_ps(_mm256_set1_ps(hi[a]), g.o[a]);
    xn[a] = S::blendv(l, h, g.inv[a]);
    xf[a] = S::blendv(h, l, g.inv[a]);
  }
  __m256 tn;
  return uint32_t(S::mask(slab<8, false>(xn, xf, g.inv, g.inv, g.tmin, g.tfar, tn)));
}

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

// True when no ray of the packet can enter the node's box (early miss, Alg. 2.6 line 4).
inline bool ia_misses(const IABounds& b, const BVHNode& n) {
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

// ---------------------------------------------------------------------------------------------
// The packet: SoA copies of up to 256 rays, their hits, and the bounds above.
struct Packet {
  RayGroup rg[kMaxGroups];
  TriGroup tg[kMaxGroups];
  HitGroup hg[kMaxGroups];
  int8_t gsign[kMaxGroups];    // per group: direction sign bits (x: 1, y: 2, z: 4) when all its
                               // lanes agree on every axis, else -1
  const Ray* rays = nullptr;   // the batch's rays [0, n) of this packet
  uint32_t n = 0, groups = 0;
  bool common_origin = false;
  Vec3 org;                    // the common origin when common_origin
  Vec3 mean_dir;               // for the near-child choice
  IABounds ia;
  Frustum frustum;             // valid only for common-origin packets narrow enough to bound
  TriCull cull;                // valid with the frustum; split planes only with `split_planes`
  bool split_planes = false;   // §3.3 sub-frusta of a full 16x16 primary packet
  int8_t psign = -1;           // the direction sign bits every group shares (as gsign), else -1
  uint32_t sheared = 0;        // bit g: tg[g]'s watertight shear is computed (compute_shear)
  // Lazy frustum: build_frusta runs when the first node is not culled by the cheaper tests
  // (frustum_culls), so a packet that misses the scene after a root test or two (most packets
  // around a single object such as bunny) never pays for the plane fit (~50 instructions/ray).
  bool frustum_pending = false;
  bool frustum_split = false;  // build_frusta's `split` for the pending build

  void update_tfar_max() {
    __m256 m = rg[0].tfar;
    for (uint32_t g = 1; g < groups; ++g) m = _mm256_max_ps(m, rg[g].tfar);
    ia.tfar_max = hmax8(m);
  }
  static float hmax8(__m256 v) {
    __m128 m = _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
    m = _mm_max_ps(m, _mm_movehl_ps(m, m));
    m = _mm_max_ss(m, _mm_shuffle_ps(m, m, 1));
    return _mm_cvtss_f32(m);
  }
  static float hmin8(__m256 v) {
    __m128 m = _mm_min_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
    m = _mm_min_ps(m, _mm_movehl_ps(m, m));
    m = _mm_min_ss(m, _mm_shuffle_ps(m, m, 1));
    return _mm_cvtss_f32(m);
  }
  static float hsum8(__m256 v) {
    __m128 m = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
    m = _mm_add_ps(m, _mm_movehl_ps(m, m));
    m = _mm_add_ss(m, _mm_shuffle_ps(m, m, 1));
    return _mm_cvtss_f32(m);
  }
};

// box_mask for group g of a packet, cheaper when the group's lanes agree on every direction sign
// (the common case for coherent rays): the near and far planes are then chosen once for the
// group, and with a common origin the plane offsets are scalars. Every lane computes the very
// same values as in box_mask: (plane - o) * inv, padded far, NaN-first min/max.
template <bool kCommon>
inline uint32_t group_box(const Packet& p, uint32_t g, const BVHNode& n) {
  const int s = p.gsign[g];
  const RayGroup& G = p.rg[g];
  if (s < 0) return box_mask(G, n);
  const float* lo = &n.lo.x;
  const float* hi = &n.hi.x;
  __m256 xn[3], xf[3];
  for (int a = 0; a < 3; ++a) {
    const bool neg = (s >> a) & 1;
    const float pn = neg ? hi[a] : lo[a], pf = neg ? lo[a] : hi[a];
    if constexpr (kCommon) {
      xn[a] = _mm256_set1_ps(pn - p.org[a]);
      xf[a] = _mm256_set1_ps(pf - p.org[a]);
    } else {
      xn[a] = _mm256_sub_ps(_mm256_set1_ps(pn), G.o[a]);
      xf[a] = _mm256_sub_ps(_mm256_set1_ps(pf), G.o[a]);
    }
  }
  __m256 tn;
  return uint32_t(_mm256_movemask_ps(slab<8, false>(xn, xf, G.inv, G.inv, G.tmin, G.tfar, tn)));
}

// group_box with the node's work hoisted out of the per-group loop: when every group of a
// common-origin packet shares its direction signs (primary packets away from the axis planes),
// the near/far plane offsets (plane - org) are the same scalars for every group, so they are
// broadcast once per node and each group test is 6 multiplies, 6 min/max and a compare. The
// values are exactly group_box's (same scalar subtraction, same operation order).
template <bool kCommon>
struct NodeTester {
  const Packet& p;
  const BVHNode& n;
  bool pre = false;
  __m256 xn[3], xf[3];
  NodeTester(const Packet& pk, const BVHNode& nd) : p(pk), n(nd) {
    if constexpr (kCommon) {
      if (p.psign >= 0) {
        pre = true;
        const float* lo = &n.lo.x;
        const float* hi = &n.hi.x;
        for (int a = 0; a < 3; ++a) {
          const bool neg = (p.psign >> a) & 1;
          xn[a] = _mm256_set1_ps((neg ? hi[a] : lo[a]) - p.org[a]);
          xf[a] = _mm256_set1_ps((neg ? lo[a] : hi[a]) - p.org[a]);
        }
      }
    }
  }
  uint32_t operator()(uint32_t g) const {
    if (!pre) return group_box<kCommon>(p, g, n);
    const RayGroup& G = p.rg[g];
    __m256 tn;
    return uint32_t(_mm256_movemask_ps(slab<8, false>(xn, xf, G.inv, G.inv, G.tmin, G.tfar, tn)));
  }
};

// r[k][l] <- r[l][k]: eight 32-byte rays (org, tmin, dir, tmax) become eight SoA vectors.
inline void transpose8(__m256 r[8]) {
  const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
  const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
  const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
  const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
  const __m256 s0 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 s1 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
  const __m256 s2 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 s3 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2));
  const __m256 s4 = _mm256_shuffle_ps(t4, t6, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 s5 = _mm256_shuffle_ps(t4, t6, _MM_SHUFFLE(3, 2, 3, 2));
  const __m256 s6 = _mm256_shuffle_ps(t5, t7, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 s7 = _mm256_shuffle_ps(t5, t7, _MM_SHUFFLE(3, 2, 3, 2));
  r[0] = _mm256_permute2f128_ps(s0, s4, 0x20);
  r[1] = _mm256_permute2f128_ps(s1, s5, 0x20);
  r[2] = _mm256_permute2f128_ps(s2, s6, 0x20);
  r[3] = _mm256_permute2f128_ps(s3, s7, 0x20);
  r[4] = _mm256_permute2f128_ps(s0, s4, 0x31);
  r[5] = _mm256_permute2f128_ps(s1, s5, 0x31);
  r[6] = _mm256_permute2f128_ps(s2, s6, 0x31);
  r[7] = _mm256_permute2f128_ps(s3, s7, 0x31);
}

// Copies rays [0, n) (n <= kMaxRays) into p's groups and computes the per-lane data and the IA
// bounds, 8 rays at a time. Lanes past n repeat the last ray with an empty interval
// (tfar = -inf), so they never hit anything and leave every min/max bound unchanged.
template <class P>
void load_packet(Packet& p, const Ray* rays, uint32_t n, P& probe) {
  static_assert(sizeof(Ray) == 8 * sizeof(float));
  p.rays = rays;
  p.n = n;
  p.groups = (n + kW - 1) / kW;
  const __m256 inf = _mm256_set1_ps(INFINITY), one = _mm256_set1_ps(1.f), zero = _mm256_setzero_ps();
  const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  __m256 omin[3], omax[3], rmin[3], rmax[3], md[3];
  for (int a = 0; a < 3; ++a) omin[a] = rmin[a] = inf, omax[a] = rmax[a] = _mm256_sub_ps(zero, inf), md[a] = zero;
  __m256 tmin_min = inf;
  int anyneg[3] = {0, 0, 0}, allneg[3] = {0xFF, 0xFF, 0xFF}, nonfinite[3] = {0, 0, 0}, same_org = 0xFF;
  const __m256i org0[3] = {_mm256_set1_epi32(std::bit_cast<int>(rays[0].org.x)),
                           _mm256_set1_epi32(std::bit_cast<int>(rays[0].org.y)),
                           _mm256_set1_epi32(std::bit_cast<int>(rays[0].org.z))};
  if constexpr (P::enabled)
    for (uint32_t i = 0; i < n; ++i) probe.read(&rays[i], sizeof(Ray));
  for (uint32_t g = 0; g < p.groups; ++g) {
    __m256 v[8];
    for (uint32_t l = 0; l < kW; ++l)
      v[l] = _mm256_loadu_ps(reinterpret_cast<const float*>(&rays[std::min(g * kW + l, n - 1)]));
    transpose8(v);  // v: org.x org.y org.z tmin dir.x dir.y dir.z tmax
    const __m256 o[3] = {v[0], v[1], v[2]}, d[3] = {v[4], v[5], v[6]};
    RayGroup& G = p.rg[g];
    TriGroup& T = p.tg[g];
    int gs = 0;
    for (int a = 0; a < 3; ++a) {
      G.o[a] = o[a];
      G.inv[a] = _mm256_div_ps(one, d[a]);  // 1/(+-0) = +-inf, as in RayCtx
      const int sm = _mm256_movemask_ps(G.inv[a]);
      gs = gs < 0 || (sm != 0 && sm != 0xFF) ? -1 : gs | (sm ? 1 << a : 0);
      T.d[a] = d[a];
      omin[a] = _mm256_min_ps(omin[a], o[a]);
      omax[a] = _mm256_max_ps(omax[a], o[a]);
      rmin[a] = _mm256_min_ps(rmin[a], G.inv[a]);
      rmax[a] = _mm256_max_ps(rmax[a], G.inv[a]);
      const int sgn = _mm256_movemask_ps(G.inv[a]);
      anyneg[a] |= sgn, allneg[a] &= sgn;
      nonfinite[a] |= _mm256_movemask_ps(_mm256_cmp_ps(_mm256_and_ps(G.inv[a], absmask), inf, _CMP_EQ_OQ));
      same_org &= _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_castps_si256(o[a]), org0[a])));
    }
    p.gsign[g] = int8_t(gs);
    const uint32_t real = g * kW + kW <= n ? 0xFFu : (1u << (n - g * kW)) - 1;
    G.tmin = v[3];
    G.tfar = _mm256_blendv_ps(_mm256_sub_ps(zero, inf), v[7], lane_mask_ps(real));
    tmin_min = _mm256_min_ps(tmin_min, v[3]);
    p.hg[g].prim = _mm256_set1_epi32(int(kNoHit));
    p.hg[g].u = p.hg[g].v = zero;
    probe.write(&G, sizeof(RayGroup));
    probe.write(&T, sizeof(TriGroup));
    probe.write(&p.hg[g], sizeof(HitGroup));
    // Mean of the normalised directions (near-child order and frustum centre only).
    const __m256 rl = _mm256_div_ps(one, _mm256_sqrt_ps(_mm256_add_ps(
                                             _mm256_add_ps(_mm256_mul_ps(d[0], d[0]), _mm256_mul_ps(d[1], d[1])),
                                             _mm256_mul_ps(d[2], d[2]))));
    for (int a = 0; a < 3; ++a) md[a] = _mm256_add_ps(md[a], _mm256_and_ps(_mm256_mul_ps(d[a], rl), lane_mask_ps(real)));
  }
  p.common_origin = same_org == 0xFF;
  p.org = rays[0].org;
  p.sheared = 0;
  p.frustum_pending = false;
  p.psign = p.gsign[0];
  for (uint32_t g = 1; g < p.groups; ++g)
    if (p.gsign[g] != p.psign) p.psign = -1;
  alignas(16) float neg[4], usable[4], lo[4], hi[4], r0[4], r1[4];
  for (int a = 0; a < 3; ++a) {
    const bool all_neg = allneg[a] == 0xFF, all_pos = anyneg[a] == 0;
    neg[a] = all_neg ? -1.f : 1.f;  // only the sign bit matters to blendv
    usable[a] = (all_neg || all_pos) && !nonfinite[a] ? -1.f : 1.f;
    lo[a] = Packet::hmin8(omin[a]), hi[a] = Packet::hmax8(omax[a]);
    r0[a] = Packet::hmin8(rmin[a]), r1[a] = Packet::hmax8(rmax[a]);
  }
  neg[3] = usable[3] = 1.f, lo[3] = hi[3] = r0[3] = r1[3] = 0.f;
  p.ia.omin = _mm_load_ps(lo);
  p.ia.omax = _mm_load_ps(hi);
  p.ia.rmin = _mm_load_ps(r0);
  p.ia.rmax = _mm_load_ps(r1);
  p.ia.neg = _mm_load_ps(neg);
  p.ia.usable = _mm_load_ps(usable);
  p.ia.tmin_min = Packet::hmin8(tmin_min);
  p.update_tfar_max();
  const Vec3 m{Packet::hsum8(md[0]), Packet::hsum8(md[1]), Packet::hsum8(md[2])};
  p.mean_dir = length(m) > 0.f ? normalize(m) : rays[0].dir;
  p.frustum.valid = false;
  p.split_planes = false;
}

// Plane fitting for common-origin packets. Every plane passes through the origin with an inward
// normal n; it is valid for a set of rays when n.d > 0 for each of them, so every point of every
// ray (t >= 0) lies on its inner side. Candidate normals come from the packet's corner rays (a
// pinhole grid's side planes contain its edge rays) or from slope bounds; each candidate is then
// tilted towards the packet's centre direction c until the float evaluation, with a margin that
// exceeds its rounding error, proves n.d > 0 for every ray — so the planes are conservative for
// any ray order, not only for the Fig. 16 layout the corner indices assume.
struct FitCtx {
  Vec3 c;
  __m256 cd[kMaxGroups];   // c.d per lane
  __m256 rcd[kMaxGroups];  // 1 / c.d: the tilt estimate only needs to be close, a check verifies it
};

// The packet's centre direction; false when some ray is more than ~75 degrees from it (cos <
// 0.25): planes through the origin cannot usefully bound such packets (rnd, most hard cases).
inline bool fit_centre(const Packet& p, const uint32_t* corners, FitCtx& fc) {
  auto mul = [](__m256 a, __m256 b) { return _mm256_mul_ps(a, b); };
  auto add = [](__m256 a, __m256 b) { return _mm256_add_ps(a, b); };
  const __m256 zero = _mm256_setzero_ps();
  Vec3 c{0, 0, 0};
  if (corners) {
    for (int i = 0; i < 4; ++i) c += normalize(p.rays[corners[i]].dir);
  } else {
    c = p.mean_dir;
  }
  if (!(length(c) > 0.f)) return false;
  c = normalize(c);
  fc.c = c;
  const __m256 cx = _mm256_set1_ps(c.x), cy = _mm256_set1_ps(c.y), cz = _mm256_set1_ps(c.z);
  int ok = 0xFF;
  for (uint32_t g = 0; g < p.groups; ++g) {
    const __m256* d = p.tg[g].d;
    fc.cd[g] = add(add(mul(cx, d[0]), mul(cy, d[1])), mul(cz, d[2]));
    fc.rcd[g] = _mm256_div_ps(_mm256_set1_ps(1.f), fc.cd[g]);
    const __m256 dd = add(add(mul(d[0], d[0]), mul(d[1], d[1])), mul(d[2], d[2]));
    ok &= _mm256_movemask_ps(_mm256_and_ps(_mm256_cmp_ps(fc.cd[g], zero, _CMP_GT_OQ),
                                           _mm256_cmp_ps(mul(fc.cd[g], fc.cd[g]), mul(_mm256_set1_ps(0.0625f), dd),
                                                         _CMP_GT_OQ)));
  }
  return ok == 0xFF;
}

// Tilts candidate normal m until n.d > 0 is proven for the rays of the groups in `gmask`:
// s = n.d in float errs by at most gamma(3) * sum|n_i d_i| (~1.8e-7 of it), so s > 1e-6 *
// sum|n_i d_i| proves the exact n.d > 0. Returns false (and leaves `out` alone) on failure.
inline bool fit_plane(const Packet& p, uint32_t gmask, const FitCtx& fc, Vec3 m, Vec3& out) {
  auto mul = [](__m256 a, __m256 b) { return _mm256_mul_ps(a, b); };
  auto add = [](__m256 a, __m256 b) { return _mm256_add_ps(a, b); };
  const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF)), zero = _mm256_setzero_ps();
  if (!(length(m) > 0.f)) return false;
  m = normalize(m);
  auto check = [&](const Vec3& n, bool with_need, float& need_out) {
    const __m256 nx = _mm256_set1_ps(n.x), ny = _mm256_set1_ps(n.y), nz = _mm256_set1_ps(n.z);
    __m256 need = zero;
    int fail = 0;
    for (uint32_t gm = gmask; gm; gm &= gm - 1) {
      const uint32_t g = std::countr_zero(gm);
      const __m256* d = p.tg[g].d;
      const __m256 px = mul(nx, d[0]), py = mul(ny, d[1]), pz = mul(nz, d[2]);
      const __m256 sdot = add(add(px, py), pz);
      const __m256 mag = add(add(_mm256_and_ps(px, absmask), _mm256_and_ps(py, absmask)), _mm256_and_ps(pz, absmask));
      const __m256 bad = _mm256_cmp_ps(sdot, mul(_mm256_set1_ps(1e-6f), mag), _CMP_LE_OQ);
      fail |= _mm256_movemask_ps(bad);
      if (with_need)
        need = _mm256_max_ps(
            need, _mm256_and_ps(bad, mul(_mm256_sub_ps(mul(_mm256_set1_ps(4e-6f), mag), sdot), fc.rcd[g])));
    }
    need_out = Packet::hmax8(need);
    return fail == 0;
  };
  // The tilt each failing ray needs comes with the first check (one pass instead of two): a
  // corner-ray plane of a pinhole packet contains its edge rays, so it never verifies untilted.
  float need = 0.f;
  bool verified = check(m, true, need);
  for (int iter = 0; iter < 6 && !verified; ++iter) {
    m = m + fc.c * (need * 1.5f + 1e-7f);
    verified = check(m, true, need);
  }
  if (verified) out = m;
  return verified;
}

// Builds the packet frustum (common-origin packets only) and, with `split`, the two §3.3 split
// planes of a full 16x16 packet. A full packet is taken to be in the Fig. 16 layout for the
// choice of candidate rays; the fit keeps the planes conservative for any ray order.
inline void build_frusta(Packet& p, bool split) {
  p.frustum.valid = false;
  p.split_planes = false;
  if (!p.common_origin) return;
  const bool full = p.n == kMaxRays;
  // Corner rays (0,0), (15,0), (15,15), (0,15) of the Fig. 16 layout.
  static constexpr uint32_t corners[4] = {0, 77, 255, 178};
  FitCtx fc;
  if (!fit_centre(p, full ? corners : nullptr, fc)) return;
  const Vec3 c = fc.c;
  Vec3 N[4];
  bool have = full;
  for (int i = 0; i < 4 && have; ++i) {
    const Vec3 a = p.rays[corners[i]].dir, b = p.rays[corners[(i + 1) & 3]].dir;
    N[i] = cross(a, b);
    if (dot(N[i], c) < 0.f) N[i] = -N[i];
    have = length(N[i]) > 1e-6f * length(a) * length(b);
  }
  const uint32_t all = p.groups == 32 ? 0xFFFFFFFFu : (1u << p.groups) - 1;
  if (!have) {
    // Slope bounds in a basis (c, t, b), t from the world axis least aligned with c.
    const int ax = std::fabs(c.x) <= std::fabs(c.y) ? (std::fabs(c.x) <= std::fabs(c.z) ? 0 : 2)
                                                    : (std::fabs(c.y) <= std::fabs(c.z) ? 1 : 2);
    Vec3 e{0, 0, 0};
    e[ax] = 1.f;
    const Vec3 t = normalize(e - c * dot(e, c)), b = cross(c, t);
    auto bc = [](float x) { return _mm256_set1_ps(x); };
    __m256 st0 = bc(INFINITY), st1 = bc(-INFINITY), sb0 = bc(INFINITY), sb1 = bc(-INFINITY);
    for (uint32_t g = 0; g < p.groups; ++g) {
      const __m256* d = p.tg[g].d;
      const __m256 r = _mm256_div_ps(bc(1.f), fc.cd[g]);
      const __m256 st = _mm256_mul_ps(
          _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(bc(t.x), d[0]), _mm256_mul_ps(bc(t.y), d[1])), _mm256_mul_ps(bc(t.z), d[2])), r);
      const __m256 sb = _mm256_mul_ps(
          _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(bc(b.x), d[0]), _mm256_mul_ps(bc(b.y), d[1])), _mm256_mul_ps(bc(b.z), d[2])), r);
      st0 = _mm256_min_ps(st0, st), st1 = _mm256_max_ps(st1, st);
      sb0 = _mm256_min_ps(sb0, sb), sb1 = _mm256_max_ps(sb1, sb);
    }
    N[0] = t - c * Packet::hmin8(st0);
    N[1] = c * Packet::hmax8(st1) - t;
    N[2] = b - c * Packet::hmin8(sb0);
    N[3] = c * Packet::hmax8(sb1) - b;
  }
  alignas(32) float nf[3][8] = {};
  for (int i = 0; i < 4; ++i) {
    Vec3 n;
    if (!fit_plane(p, all, fc, N[i], n)) return;
    nf[0][i] = n.x, nf[1][i] = n.y, nf[2][i] = n.z;
  }
  if (split && full) {
    // Split planes between pixel columns 7|8 and rows 7|8, through the mean of the rays on either
    // side: (7,0)+(8,0) and (7,15)+(8,15); (0,7)+(0,8) and (15,7)+(15,8) in Fig. 16 indices.
    auto mid = [&](uint32_t i, uint32_t j) { return normalize(p.rays[i].dir) + normalize(p.rays[j].dir); };
    Vec3 nr = cross(mid(13, 64), mid(191, 242));
    if (dot(nr, p.rays[77].dir - p.rays[0].dir) < 0.f) nr = -nr;  // towards the right half
    Vec3 nb = cross(mid(50, 128), mid(127, 205));
    if (dot(nb, p.rays[178].dir - p.rays[0].dir) < 0.f) nb = -nb;  // towards the bottom half
    // Left half: quadrants 0 and 2 (groups 0-7, 16-23); top half: quadrants 0 and 1 (groups 0-15).
    const Vec3 cand[4] = {-nr, nr, -nb, nb};
    const uint32_t half[4] = {0x00FF00FFu, 0xFF00FF00u, 0x0000FFFFu, 0xFFFF0000u};
    for (int i = 0; i < 4; ++i) {
      Vec3 n;  // a plane that cannot be fitted keeps a zero normal: it never culls
      if (fit_plane(p, half[i], fc, cand[i], n)) {
        nf[0][4 + i] = n.x, nf[1][4 + i] = n.y, nf[2][4 + i] = n.z;
        p.split_planes = true;
      }
    }
  }
  Frustum& f = p.frustum;
  f.nx = _mm_load_ps(nf[0]);
  f.ny = _mm_load_ps(nf[1]);
  f.nz = _mm_load_ps(nf[2]);
  f.ox = _mm_set1_ps(p.org.x);
  f.oy = _mm_set1_ps(p.org.y);
  f.oz = _mm_set1_ps(p.org.z);
  f.valid = true;
  p.cull.nx = _mm256_load_ps(nf[0]);
  p.cull.ny = _mm256_load_ps(nf[1]);
  p.cull.nz = _mm256_load_ps(nf[2]);
  p.cull.ox = _mm256_set1_ps(p.org.x);
  p.cull.oy = _mm256_set1_ps(p.org.y);
  p.cull.oz = _mm256_set1_ps(p.org.z);
}

// Frustum early miss with the lazy build (Packet::frustum_pending): call only after the cheaper
// tests failed to decide the node.
inline bool frustum_culls(Packet& p, const BVHNode& n) {
  if (p.frustum_pending) {
    p.frustum_pending = false;
    build_frusta(p, p.frustum_split);
  }
  return p.frustum.valid && frustum_misses_box(p.frustum, n);
}

// Writes the packet's hits back to the batch's hit array (AoS Hit, finish_hit semantics).
template <class P>
void store_hits(const Packet& p, Hit* out, P& probe) {
  const __m256 inf = _mm256_set1_ps(INFINITY);
  const __m256i nohit = _mm256_set1_epi32(int(kNoHit));
  for (uint32_t g = 0; g < p.groups; ++g) {
    const HitGroup& H = p.hg[g];
    probe.read(&H, sizeof(HitGroup));
    // finish_hit: misses report t = +inf.
    const __m256 miss = _mm256_castsi256_ps(_mm256_cmpeq_epi32(H.prim, nohit));
    const __m256 t = _mm256_blendv_ps(p.rg[g].tfar, inf, miss), prim = _mm256_castsi256_ps(H.prim);
    // 4 x 8 -> 8 x 4 transpose: Hit is {t, prim, u, v}.
    const __m256 a0 = _mm256_unpacklo_ps(t, prim), a1 = _mm256_unpackhi_ps(t, prim);
    const __m256 b0 = _mm256_unpacklo_ps(H.u, H.v), b1 = _mm256_unpackhi_ps(H.u, H.v);
    const __m256 h01 = _mm256_shuffle_ps(a0, b0, _MM_SHUFFLE(1, 0, 1, 0));  // lanes 0 | 4
    const __m256 h23 = _mm256_shuffle_ps(a0, b0, _MM_SHUFFLE(3, 2, 3, 2));  // lanes 1 | 5
    const __m256 h45 = _mm256_shuffle_ps(a1, b1, _MM_SHUFFLE(1, 0, 1, 0));  // lanes 2 | 6
    const __m256 h67 = _mm256_shuffle_ps(a1, b1, _MM_SHUFFLE(3, 2, 3, 2));  // lanes 3 | 7
    alignas(32) float buf[kW * 4];
    const uint32_t cnt = std::min(kW, p.n - g * kW);
    float* dst = cnt == kW ? reinterpret_cast<float*>(out + g * kW) : buf;
    _mm256_storeu_ps(dst + 0, _mm256_permute2f128_ps(h01, h23, 0x20));
    _mm256_storeu_ps(dst + 8, _mm256_permute2f128_ps(h45, h67, 0x20));
    _mm256_storeu_ps(dst + 16, _mm256_permute2f128_ps(h01, h23, 0x31));
    _mm256_storeu_ps(dst + 24, _mm256_permute2f128_ps(h45, h67, 0x31));
    if (cnt < kW) std::memcpy(out + g * kW, buf, cnt * sizeof(Hit));
    if constexpr (P::enabled)
      for (uint32_t l = 0; l < cnt; ++l) probe.write(&out[g * kW + l], sizeof(Hit));
  }
}

// ---------------------------------------------------------------------------------------------
// 8-wide ray/triangle tests. Each updates the lanes of `mask` that find a closer hit and returns
// their mask. kCommon: every lane starts at p.org, so vertex offsets are computed once.


inline void commit_hits(Packet& p, uint32_t g, __m256 hit, __m256 t, __m256 u, __m256 v, uint32_t prim) {
  RayGroup& G = p.rg[g];
  HitGroup& H = p.hg[g];
  G.tfar = _mm256_blendv_ps(G.tfar, t, hit);
  H.u = _mm256_blendv_ps(H.u, u, hit);
  H.v = _mm256_blendv_ps(H.v, v, hit);
  H.prim = _mm256_castps_si256(
      _mm256_blendv_ps(_mm256_castsi256_ps(H.prim), _mm256_castsi256_ps(_mm256_set1_epi32(int(prim))), hit));
}

// The scalar kernel for single lanes (edge cases), on the lane's own hit record.
template <TriKernel K>
inline bool scalar_lane(Packet& p, uint32_t g, uint32_t l, const TriangleSet& ts, uint32_t k) {
  const uint32_t i = g * kW + l;
  const Ray& r = p.rays[i];
  alignas(32) float t[kW], u[kW], v[kW];
  alignas(32) uint32_t prim[kW];
  _mm256_store_ps(t, p.rg[g].tfar);
  _mm256_store_ps(u, p.hg[g].u);
  _mm256_store_ps(v, p.hg[g].v);
  _mm256_store_si256(reinterpret_cast<__m256i*>(prim), p.hg[g].prim);
  Hit h{t[l], prim[l], u[l], v[l]};
  if (!intersect_tri<K>(RayCtx(r), ts, k, r.tmin, h)) return false;
  t[l] = h.t, u[l] = h.u, v[l] = h.v, prim[l] = h.prim;
  p.rg[g].tfar = _mm256_load_ps(t);
  p.hg[g].u = _mm256_load_ps(u);
  p.hg[g].v = _mm256_load_ps(v);
  p.hg[g].prim = _mm256_load_si256(reinterpret_cast<const __m256i*>(prim));
  return true;
}

// The watertight shear of group g (Woop et al. 2013), computed on the group's first triangle test
// rather than in load_packet: primary packets around a single object (bunny, dragon) mostly miss
// the scene, and groups that never reach a leaf never need it (5 divisions per group saved).
// Dominant axis exactly as RayCtx chooses it; kx = kz+1, ky = kz+2 (mod 3) without RayCtx's
// winding swap: a swap only negates all three edge functions, which the sign test and
// u = V/det, v = W/det do not see.
inline void compute_shear(Packet& p, uint32_t g) {
  TriGroup& T = p.tg[g];
  const __m256* d = T.d;
  const __m256 one = _mm256_set1_ps(1.f), sign = _mm256_set1_ps(-0.f);
  const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  const __m256 ax = _mm256_and_ps(d[0], absmask), ay = _mm256_and_ps(d[1], absmask), az = _mm256_and_ps(d[2], absmask);
  const __m256 xy = _mm256_cmp_ps(ax, ay, _CMP_GE_OQ);
  const __m256 m0 = _mm256_and_ps(xy, _mm256_cmp_ps(ax, az, _CMP_GE_OQ));
  const __m256 m1 = _mm256_andnot_ps(xy, _mm256_cmp_ps(ay, az, _CMP_GE_OQ));
  const __m256 m2 = _mm256_andnot_ps(_mm256_or_ps(m0, m1), _mm256_castsi256_ps(_mm256_set1_epi32(-1)));
  const __m256 dkz = _mm256_blendv_ps(_mm256_blendv_ps(d[2], d[1], m1), d[0], m0);
  const __m256 dkx = _mm256_blendv_ps(_mm256_blendv_ps(d[0], d[2], m1), d[1], m0);
  const __m256 dky = _mm256_blendv_ps(_mm256_blendv_ps(d[1], d[0], m1), d[2], m0);
  T.sx = _mm256_div_ps(dkx, dkz);
  T.sy = _mm256_div_ps(dky, dkz);
  const int k0 = _mm256_movemask_ps(m0), k1 = _mm256_movemask_ps(m1), k2 = _mm256_movemask_ps(m2);
  T.kz = k0 == 0xFF ? 0 : k1 == 0xFF ? 1 : k2 == 0xFF ? 2 : -1;
  if (T.kz < 0) {  // the coefficient form, only for groups whose lanes differ in kz
    const __m256 nsx = _mm256_xor_ps(T.sx, sign), nsy = _mm256_xor_ps(T.sy, sign);
    T.cx[0] = _mm256_blendv_ps(_mm256_and_ps(m0, nsx), one, m2);
    T.cx[1] = _mm256_blendv_ps(_mm256_and_ps(m1, nsx), one, m0);
    T.cx[2] = _mm256_blendv_ps(_mm256_and_ps(m2, nsx), one, m1);
    T.cy[0] = _mm256_blendv_ps(_mm256_and_ps(m0, nsy), one, m1);
    T.cy[1] = _mm256_blendv_ps(_mm256_and_ps(m1, nsy), one, m2);
    T.cy[2] = _mm256_blendv_ps(_mm256_and_ps(m2, nsy), one, m0);
  }
  p.sheared |= 1u << g;
}

// Watertight (Woop et al. 2013) over 8 lanes. Edge functions as in intersect_watertight:
// X = A[kx] - sx * A[kz]; groups with mixed kz use the coefficient form cx.A, which evaluates
// to the identical float (the other terms are exact zeros), so every lane decides exactly as
// the scalar kernel does. Hit distance as in the scalar kernel (exact_plane_distance).
template <bool kCommon>
inline uint32_t tri_watertight(Packet& p, uint32_t g, uint32_t mask, const TriangleSet& ts, uint32_t k) {
  if (!((p.sheared >> g) & 1u)) [[unlikely]] compute_shear(p, g);
  const TriVerts& tri = ts.verts[k];
  const RayGroup& G = p.rg[g];
  const TriGroup& T = p.tg[g];
  __m256 A[3], B[3], C[3];
  float As[3], Bs[3], Cs[3];
  if constexpr (kCommon) {
    for (int a = 0; a < 3; ++a) {
      As[a] = tri.v0[a] - p.org[a], Bs[a] = tri.v1[a] - p.org[a], Cs[a] = tri.v2[a] - p.org[a];
      A[a] = _mm256_set1_ps(As[a]), B[a] = _mm256_set1_ps(Bs[a]), C[a] = _mm256_set1_ps(Cs[a]);
    }
  } else {
    for (int a = 0; a < 3; ++a) {
      A[a] = _mm256_sub_ps(_mm256_set1_ps(tri.v0[a]), G.o[a]);
      B[a] = _mm256_sub_ps(_mm256_set1_ps(tri.v1[a]), G.o[a]);
      C[a] = _mm256_sub_ps(_mm256_set1_ps(tri.v2[a]), G.o[a]);
    }
  }
  __m256 Ax, Ay, Bx, By, Cx, Cy;
  if (T.kz >= 0) {
    const int kz = T.kz, kx = kz == 2 ? 0 : kz + 1, ky = kx == 2 ? 0 : kx + 1;
    Ax = shear<8>(A[kx], T.sx, A[kz]);
    Ay = shear<8>(A[ky], T.sy, A[kz]);
    Bx = shear<8>(B[kx], T.sx, B[kz]);
    By = shear<8>(B[ky], T.sy, B[kz]);
    Cx = shear<8>(C[kx], T.sx, C[kz]);
    Cy = shear<8>(C[ky], T.sy, C[kz]);
  } else {
    auto sh = [](const __m256* c, const __m256* v) {
      return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(c[0], v[0]), _mm256_mul_ps(c[1], v[1])),
                           _mm256_mul_ps(c[2], v[2]));
    };
    Ax = sh(T.cx, A), Ay = sh(T.cy, A), Bx = sh(T.cx, B), By = sh(T.cy, B), Cx = sh(T.cx, C), Cy = sh(T.cy, C);
  }
  __m256 U, V, W, det;
  const uint32_t cand = uint32_t(_mm256_movemask_ps(watertight_inside<8>(Ax, Ay, Bx, By, Cx, Cy, U, V, W, det))) & mask;
  if (!cand) return 0;
  // The distance: exact_plane_distance's double plane equation (kernels.h), 4 lanes at a time,
  // the triangle's normal hoisted (the same operations in the same order, so the same t as the
  // scalar kernel). Lanes parallel in double take the scalar kernel's sheared fallback.
  using D = simd::D4v;
  const Vec3D<double> v0 = to_double(tri.v0);
  const Vec3D<double> nd = plane_normal(v0, to_double(tri.v1), to_double(tri.v2));
  const Vec3D<D> n{D(nd.x), D(nd.y), D(nd.z)};
  uint32_t parallel = 0;
  __m128 th[2];
  for (int h = 0; h < 2; ++h) {
    auto half = [h](__m256 v) { return D(h ? _mm256_extractf128_ps(v, 1) : _mm256_castps256_ps128(v)); };
    const D dn = plane_dot(n, Vec3D<D>{half(T.d[0]), half(T.d[1]), half(T.d[2])});
    D num;
    if constexpr (kCommon) {
      num = D(plane_dot(nd, Vec3D<double>{v0.x - double(p.org.x), v0.y - double(p.org.y), v0.z - double(p.org.z)}));
    } else {
      num = plane_dot(n, Vec3D<D>{D(v0.x) - half(G.o[0]), D(v0.y) - half(G.o[1]), D(v0.z) - half(G.o[2])});
    }
    parallel |= uint32_t(dn.zero_mask()) << (4 * h);
    th[h] = (num / dn).to_float();
  }
  parallel &= cand;
  const __m256 t = _mm256_set_m128(th[1], th[0]);
  uint32_t hits = cand & ~parallel & uint32_t(_mm256_movemask_ps(
      _mm256_and_ps(_mm256_cmp_ps(t, G.tmin, _CMP_GE_OQ), _mm256_cmp_ps(t, G.tfar, _CMP_LT_OQ))));
  if (hits) {
    const __m256 rdet = _mm256_div_ps(_mm256_set1_ps(1.f), det);
    commit_hits(p, g, lane_mask_ps(hits), t, _mm256_mul_ps(V, rdet), _mm256_mul_ps(W, rdet), ts.prim_id[k]);
  }
  for (uint32_t m = parallel; m; m &= m - 1)
    if (scalar_lane<TriKernel::watertight>(p, g, std::countr_zero(m), ts, k)) hits |= 1u << std::countr_zero(m);
  return hits;
}

// Moller-Trumbore over 8 lanes: the kernel library's moller<8>.
template <bool kCommon>
inline uint32_t tri_moller(Packet& p, uint32_t g, uint32_t mask, const TriangleSet& ts, uint32_t k) {
  const TriVerts& tri = ts.verts[k];
  const RayGroup& G = p.rg[g];
  __m256 s[3];
  if constexpr (kCommon) {
    const Vec3 sv = p.org - tri.v0;
    s[0] = _mm256_set1_ps(sv.x), s[1] = _mm256_set1_ps(sv.y), s[2] = _mm256_set1_ps(sv.z);
  } else {
    for (int a = 0; a < 3; ++a) s[a] = _mm256_sub_ps(G.o[a], _mm256_set1_ps(tri.v0[a]));
  }
  __m256 t, u, v;
  const __m256 ok = moller<8>(p.tg[g].d, s, tri, G.tmin, G.tfar, lane_mask_ps(mask), t, u, v);
  const uint32_t hits = uint32_t(_mm256_movemask_ps(ok));
  if (hits) commit_hits(p, g, ok, t, u, v, ts.prim_id[k]);
  return hits;
}

// Precomputed planes (Appendix C): the kernel library's plane<8>; kApprox: rcpps reciprocal.
template <bool kApprox, bool kCommon>
inline uint32_t tri_plane(Packet& p, uint32_t g, uint32_t mask, const TriangleSet& ts, uint32_t k) {
  const PlaneTri& tri = ts.planes[k];
  const RayGroup& G = p.rg[g];
  const __m256 on = kCommon ? _mm256_set1_ps(dot(p.org, tri.n)) : plane_offset<8>(G.o, tri.n);
  __m256 t, u, v;
  const __m256 ok = plane<8, kApprox>(G.o, p.tg[g].d, on, tri, G.tmin, G.tfar, lane_mask_ps(mask), t, u, v);
  const uint32_t hits = uint32_t(_mm256_movemask_ps(ok));
  if (hits) commit_hits(p, g, ok, t, u, v, ts.prim_id[k]);
  return hits;
}

// Tests triangle k against the lanes `mask` of group g with kernel K; returns the lanes that hit.
template <TriKernel K, bool kCommon>
inline uint32_t intersect_group(Packet& p, uint32_t g, uint32_t mask, const TriangleSet& ts, uint32_t k) {
  if constexpr (K == TriKernel::watertight) return tri_watertight<kCommon>(p, g, mask, ts, k);
  else if constexpr (K == TriKernel::moller) return tri_moller<kCommon>(p, g, mask, ts, k);
  else return tri_plane<K == TriKernel::plane_rcp, kCommon>(p, g, mask, ts, k);
}

// ---------------------------------------------------------------------------------------------
// Near child first: the child whose centre lies first along the packet's mean direction. BVH
// children may overlap, so this is a heuristic order (thesis §2.2.2), never a correctness issue.
inline bool right_first(const BVHNode* c, Vec3 dir) {
  const Vec3 d = (c[1].lo + c[1].hi) - (c[0].lo + c[0].hi);
  return dot(d, dir) < 0.f;
}

// Splits packet [b, e) of a batch into the sub-packets a scheme traces: at most kMaxRays each;
// with `split`, packets of rays after the first intersection (batch depth >= 1) continue as four
// parts, Arauna's 8x8 packets for secondary rays (thesis §3.3).
template <class F>
void for_each_subpacket(const RayBatch& batch, uint32_t b, uint32_t e, bool split, F&& f) {
  const uint32_t n = e - b;
  uint32_t chunk = kMaxRays;
  if (split && batch.depth >= 1 && n > kQuadRays / 2) chunk = std::min(kMaxRays, (n + 3) / 4);
  for (uint32_t s = b; s < e; s += chunk) f(s, std::min(e, s + chunk));
}

}  // namespace tb::packet
