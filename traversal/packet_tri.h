// Packet groups against one triangle: the kernel library's triangle tests (traversal/kernels.h:
// watertight_inside<8>, exact_plane_distance's plane_terms, moller<8>, plane<8>) on 8 rays, and
// the bookkeeping of the packet's hits.
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "traversal/packet.h"

namespace tb::packet {

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

}  // namespace tb::packet
