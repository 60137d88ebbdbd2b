// The BVH packet schemes' packet (thesis §2.2.2, §3.3; Overbeck et al. 2008 naming: bvh_masked,
// bvh_ranged, bvh_partition): the packet's rays as SoA groups of 8 (AVX2), their hits and
// bounds, loading rays into it and storing hits out of it, and how a batch packet is split into
// the packets a scheme traces. The tests against boxes and triangles are packet_box.h and
// packet_tri.h, the bounds packet_bounds.h and packet_frustum.h.
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "traversal/bvh_common.h"
#include "traversal/packet_bounds.h"

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

// Rays [first, first + 8) of rays [0, n) into G, one per lane: origins, reciprocal directions,
// tmin and tfar (ray.tmax). Lanes past n repeat the last ray with an empty interval (tfar = -inf),
// so they never hit anything. v receives the transposed rows (org.x org.y org.z tmin dir.x dir.y
// dir.z tmax); returns the direction sign bits every lane shares (x: 1, y: 2, z: 4), or -1.
// load_packet's per-group step and mbvh8_packet's whole load.
[[gnu::always_inline]] inline int load_group(RayGroup& G, const Ray* rays, uint32_t first, uint32_t n, __m256 v[8]) {
  static_assert(sizeof(Ray) == 8 * sizeof(float));
  for (uint32_t l = 0; l < kW; ++l) v[l] = _mm256_loadu_ps(reinterpret_cast<const float*>(&rays[std::min(first + l, n - 1)]));
  transpose8(v);
  const __m256 one = _mm256_set1_ps(1.f);
  int gs = 0;
  for (int a = 0; a < 3; ++a) {
    G.o[a] = v[a];
    G.inv[a] = _mm256_div_ps(one, v[4 + a]);  // 1/(+-0) = +-inf, as in RayCtx
    const int sm = _mm256_movemask_ps(G.inv[a]);
    gs = gs < 0 || (sm != 0 && sm != 0xFF) ? -1 : gs | (sm ? 1 << a : 0);
  }
  const uint32_t real = first + kW <= n ? 0xFFu : (1u << (n - first)) - 1;
  G.tmin = v[3];
  G.tfar = _mm256_blendv_ps(_mm256_set1_ps(-INFINITY), v[7], lane_mask_ps(real));
  return gs;
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
    RayGroup& G = p.rg[g];
    TriGroup& T = p.tg[g];
    p.gsign[g] = int8_t(load_group(G, rays, g * kW, n, v));
    const __m256 o[3] = {v[0], v[1], v[2]}, d[3] = {v[4], v[5], v[6]};
    for (int a = 0; a < 3; ++a) {
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
    const uint32_t real = g * kW + kW <= n ? 0xFFu : (1u << (n - g * kW)) - 1;
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
