// Fitting the packet frustum (common-origin packets) and the §3.3 split planes to a packet's rays,
// lazily on the first node the cheaper tests do not decide (frustum_culls).
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "traversal/packet.h"

namespace tb::packet {


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

}  // namespace tb::packet
