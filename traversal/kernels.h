// The kernel library: every ray/box and ray/triangle test of the suite, each written ONCE as a
// template over the lane count L of simd::V<L> (traversal/simd.h: 1 = one ray, 4 = SSE, 8 = AVX2)
// and instantiated by every scheme: the single-ray schemes call the L = 1 wrappers at the end of
// this file (box_entry, intersect_watertight, intersect_moller, intersect_plane), the MBVH node
// and block tests, the packet and stream kernels call the templates with L = 4 or 8, so that the
// same float operations run in the same order in every scheme (-ffp-contract=off) and the SIMD
// schemes return bit-identical hits to the scalar ones (tests/test_kernels.cpp, test_mbvh.cpp,
// test_packets.cpp, test_kdtree.cpp check it).
//
// Defaults are robust: the watertight triangle test of Woop, Benthin and Wald (JCGT 2013) and the
// conservative slab test of Ize (JCGT 2013, "Robust BVH Ray Traversal": the far distance is
// padded by 1 + 2*gamma(3) so rounding can never cull a box the ray really enters). The fast
// non-robust variants stay available as named alternatives so the suite can measure what
// robustness costs (issue "Accuracy"): Moller-Trumbore (1997), and the precomputed-plane test the
// thesis' MBVH/RS kernel uses (Appendix C; Havel & Herout 2010), with an exact or an
// approximate (rcpps, 12-bit) reciprocal.
//
// What stays with the callers is only where the lanes come from (which rays, which triangles,
// which axis permutation): e.g. one ray against a TriBlock's W triangles (block_intersect), eight
// rays against one triangle (the packet kernels), two rays against four triangles (the stream's
// pair kernel). The arithmetic is here.
#pragma once
#include <immintrin.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "structures/triangles.h"
#include "structures/vec3.h"
#include "traversal/simd.h"
#include "workloads/ray_batch.h"

namespace tb {

// gamma(n) of Pharr/Jakob/Humphreys: bound on the relative error of n float operations.
inline constexpr float kUlp = 0x1p-24f;
inline constexpr float gamma_f(int n) { return (n * kUlp) / (1 - n * kUlp); }
// Ize 2013: pad the far slab distance by 1 + 2*gamma(3).
inline constexpr float kFarPad = 1.f + 2.f * gamma_f(3);

// Per-ray data the kernels precompute once.
struct RayCtx {
  Vec3 org, dir, inv;
  int near_x, near_y, near_z;  // 1 where the direction's sign bit is set: enter through hi
  // The ray octant of the octant-row tables (octant_plane_rows): bit a set = axis a entered through hi.
  uint32_t octant() const { return uint32_t(near_x) | uint32_t(near_y) << 1 | uint32_t(near_z) << 2; }
  // Watertight shear (Woop et al. 2013, §3): permute so z is the dominant direction axis.
  int kx, ky, kz;
  float sx, sy, sz;
  // How the shear axes are chosen: ShearAxes::branching compares and branches (the default),
  // branch_free computes them with integer arithmetic on the comparisons. Rays of a
  // common-origin batch share their dominant axis with their neighbours, so the branches predict
  // and are the shorter path to the divisions below; a batch of random directions (bounce rays)
  // mispredicts them about once per ray (0.86 per bunny bounce:2 ray in callgrind's model) and
  // takes branch_free: mbvh8_single / Embree HIGH fast on bounce:2 +0.8 to +7.6% (dragon_100k,
  // bunny, sibenik, sponza, lucy_100k), while branch_free on primary rays loses 0.4 to 3.4%
  // (znver3 build, 3 interleaved rounds; docs/PERFORMANCE.md, session 21). Session 8 had tried two
  // small tables for every batch: primary rays paid for it (dragon_100k, bvh_ranged 0.924,
  // mbvh4_single 0.943, bvh_single 0.956); reverted then. Both give the same axes and constants.
  enum class ShearAxes { branching, branch_free };
  explicit RayCtx(const Ray& r, ShearAxes axes = ShearAxes::branching) : org(r.org), dir(r.dir) {
    // 1/(+-0) = +-inf (also for denormals under DAZ): the slab test below is NaN-aware.
    inv = {1.f / r.dir.x, 1.f / r.dir.y, 1.f / r.dir.z};
    near_x = std::signbit(inv.x), near_y = std::signbit(inv.y), near_z = std::signbit(inv.z);
    const Vec3 a{std::fabs(dir.x), std::fabs(dir.y), std::fabs(dir.z)};
    if (axes == ShearAxes::branch_free) {
      static_assert(sizeof(Vec3) == 3 * sizeof(float));
      const float* d = &dir.x;  // indexed loads, not Vec3's branching operator[]
      const int gxy = a.x >= a.y, gxz = a.x >= a.z, gyz = a.y >= a.z;
      kz = 2 - 2 * (gxy & gxz) - ((gxy ^ 1) & gyz);
      kx = (kz + 1) * (kz != 2);
      ky = (kx + 1) * (kx != 2);
      const int swap = (kx ^ ky) & -int(d[kz] < 0.f);  // keep the winding so backfaces are not culled
      kx ^= swap, ky ^= swap;
      sx = d[kx] / d[kz];
      sy = d[ky] / d[kz];
      sz = 1.f / d[kz];
      return;
    }
    kz = a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (dir[kz] < 0.f) std::swap(kx, ky);  // keep the winding so backfaces are not culled
    sx = dir[kx] / dir[kz];
    sy = dir[ky] / dir[kz];
    sz = 1.f / dir[kz];
  }
  // branch_free for batches without a common origin (the criterion of mbvh8_single's order=auto).
  static ShearAxes axes_for(bool common_origin) { return common_origin ? ShearAxes::branching : ShearAxes::branch_free; }
};

// Where a node layout keeps the near (0..2) and far (3..5) plane row of each axis, by ray octant
// (bit a set: direction a negative, entered through hi; Williams et al. 2005 sign-selected slabs):
// the rows of axis a sit at lo + a * step and hi + a * step, in whatever unit the layout indexes
// by (floats of an MBVH node, bytes of a CWBVH node).
constexpr std::array<std::array<uint32_t, 6>, 8> octant_plane_rows(uint32_t lo, uint32_t hi, uint32_t step) {
  std::array<std::array<uint32_t, 6>, 8> t{};
  for (uint32_t o = 0; o < 8; ++o)
    for (uint32_t a = 0; a < 3; ++a) {
      const bool neg = (o >> a) & 1;
      t[o][a] = (neg ? hi : lo) + a * step;
      t[o][3 + a] = (neg ? lo : hi) + a * step;
    }
  return t;
}

// =============================================================================================
// Conservative slab test (Williams et al. 2005 sign-selected slabs, Ize 2013 padding), L lanes.
// xn/xf: per axis the near and far plane minus the origin (the caller selects the planes by the
// sign of the reciprocal direction); rn: the reciprocal direction; rf: the far reciprocal.
// kPadRcp = false pads the far distance, (xf * rn) * kFarPad (box_entry's order; rf unused);
// kPadRcp = true takes rf = rn * kFarPad precomputed per ray, xf * rf (the MBVH layouts' order,
// one multiply fewer per box: the same rounding count — subtract, reciprocal, pad, multiply — so
// the same bound holds). Returns the lanes whose box is entered before `tfar`, the entry
// distance in tn.
// A zero direction component gives rn = +-inf, and (plane - org) * inf is NaN exactly when the
// origin lies on that slab plane, where the ray runs inside the closed slab for every t.
// simd::V's min/max return their SECOND operand when either is NaN, so the new slab value goes
// first and the running bound second: such a slab constrains nothing — the right answer, with no
// branch.
template <int L, bool kPadRcp>
[[gnu::always_inline]] inline typename simd::V<L>::m slab(const typename simd::V<L>::f xn[3],
                                                          const typename simd::V<L>::f xf[3],
                                                          const typename simd::V<L>::f rn[3],
                                                          const typename simd::V<L>::f rf[3],
                                                          typename simd::V<L>::f tmin, typename simd::V<L>::f tfar,
                                                          typename simd::V<L>::f& tn) {
  using S = simd::V<L>;
  typename S::f n = tmin, f = tfar;
  for (int a = 0; a < 3; ++a) {
    n = S::max(S::mul(xn[a], rn[a]), n);
    if constexpr (kPadRcp) f = S::min(S::mul(xf[a], rf[a]), f);
    else f = S::min(S::mul(S::mul(xf[a], rn[a]), S::set1(kFarPad)), f);
  }
  tn = n;
  return S::le(n, f);
}

// Per-ray constants of a fused slab test: the distance to an axis-a plane P is one fused
// multiply-add, t = fl(P * r + c), instead of Ize's subtract and multiply (Embree's fast mode and
// Ylitie, Karras and Laine 2017 §3.1 compute it so; their form has no bound). Here c carries a
// per-ray absolute error bound E: c_near = fl(-o r - E), c_far = fl(-o r + E), so every near
// distance is a LOWER and every far distance an UPPER bound of the exact T = (P - o) / d, and the
// test never culls a box the ray enters. The bound, per axis (PBR 3rd ed. §3.9 notation,
// u = 2^-24; o the origin, r = fl(1/d), R = |r|, K >= |P| for every plane the test will see):
//   1/|d| <= R / (1 - u), so |T| <= (K + |o|) R / (1 - u), and (P - o) r = T (1 + rho), |rho| <= u;
//   c = (-o r -+ E)(1 + d1) (one fma), t = (P r + c)(1 + d2), |d1|, |d2| <= u;
//   |t - (T -+ E)| <= u |T| + u (|o| R + E) + u |P r + c|, and |P r + c| <= |T| (1 + u) + E + u (|o| R + E),
//   so |t - (T -+ E)| <= u (2 K + 3 |o|) R (1 + 3u) + 2.01 u E,
// plus flush-to-zero (< 2^-126 per rounding) and denormal inputs read as 0 under DAZ (< 2^-126 R
// per operand): < 2^-110 (1 + R). E = 1.01 u (2 K + 3 |o|) R + 2^-110 (1 + R), evaluated in float
// (four roundings down at most: still >= 1.005 u (2 K + 3 |o|) R, and the 0.005 covers the
// second-order terms), bounds it. A caller with roundings of its own (the compressed BVH's decode)
// passes larger factors kK, ko for K and |o|. An axis is left out (r = NaN, c = 0: every t of that
// axis is NaN, which the NaN-skipping max/min of the node tests ignore — conservative) where R = 0
// (|d| > 2^126), R or o is NaN, or E > 2^100 (so |P r|, |c| <= 2^123 stay finite), and where R = inf
// (d = 0) has no stand-in (below). What it costs: along an axis the box grows by E / R ~ u (2 K +
// 3 |o|), a few float ulps of the scene's coordinates, where Ize's pad grows the far distance by
// 6 u t; and a box with a face in the plane of the closest hit (coplanar walls, spatial-split
// pieces of one floor) is entered, where Ize's unpadded near distance ties with the hit and
// usually culls it: 2.6% more leaves on stadium bounce:2 (docs/PERFORMANCE.md, session 13, also for
// a form with a relative pad instead of K: fewer extra leaves, three more per-ray vectors, slower).
//
// An axis the ray does not move along (d = +-0, so R = inf) is not left out (session 41: it was,
// and then only the other axes culled: an axis-parallel ray entered every box its one moving axis
// overlaps, and the MBVH schemes traced hard:axis 200-3000x slower than bvh_single). The ray's
// coordinate there is o for every t, so the box is entered only if lo <= o <= hi; the test keeps
// its form with a finite stand-in r0 = copysign(R0, inv) and bound E0, chosen from
//   W >= K + |o| (so |P - o| <= W),  Tm >= every |T| on the axes the ray moves along
//   (plane_distance_bound: (K + |o|) R (1 + 2^-20)),  E0 = 4 Tm,  R0 = Tm / (4 u W) = E0 / (16 u W):
// the two fmas err by at most 2 u (W R0 + E0)(1 + u) < E0 / 7 (the compressed node test's bound,
// 6.04 u Z + 4.02 u E with Z <= W R0, by < 0.38 E0), so
//   lo <= o: every near distance is < 0 <= tmin (no constraint);
//   hi >= o: every far distance is > 2 Tm, beyond every distance at which the box is entered (at
//            most the largest distance on a moving axis, <= Tm), so no box the ray enters is culled;
//   lo - o > 24 u W (27 u W for the compressed test): the near distance is > Tm >= any hit
//            distance (a hit point lies within K on every axis), so once the ray has a hit the box is
//            culled (before one, with tfar = inf, it is entered, as in exact arithmetic);
//   hi - o < -24 u W (27 u W): the far distance is < 0: culled.
// |P r0| <= W R0 = Tm / (4 u) and |c| stay finite for Tm <= 2^100; outside 2^-100 <= Tm <= 2^100,
// for W = 0 and for R0 = inf the axis is left out as before (r = NaN). A denormal d also reads as
// 0 here (DAZ); traced rays have none (structures/vec3.h).
//
// One axis of L rays (or the three axes of one ray in lanes 0..2 of L = 4: then lane 3 must
// have inv = 0, which leaves it out): r, c_near and c_far from the origin o, the reciprocal
// direction inv and the coordinate bound K; lanes with R = inf are then left out until still_axes
// gives them their stand-ins (the one-ray form below does both).
template <int L>
struct FusedPlanes {
  typename simd::V<L>::f r, cn, cf;
};
template <int L>
[[gnu::always_inline]] inline FusedPlanes<L> fused_planes(typename simd::V<L>::f o, typename simd::V<L>::f inv,
                                                         typename simd::V<L>::f K, float kK = 2.02f * kUlp,
                                                         float ko = 3.03f * kUlp) {
  using S = simd::V<L>;
  const typename S::f R = S::abs(inv);
  const typename S::f Z = S::mul(S::fma(K, S::set1(kK), S::mul(S::abs(o), S::set1(ko))), R);
  const typename S::f E = S::fma(S::add(R, S::set1(1.f)), S::set1(0x1p-110f), Z);
  // Used: 0 < R and E <= 2^100 (false for R = inf or NaN, o NaN, and the overflow case).
  const typename S::m use = S::and_(S::gt(R, S::zero()), S::le(E, S::set1(0x1p100f)));
  const typename S::f no = S::sub(S::zero(), o);
  return {S::blendv(S::set1(NAN), inv, use), S::select(use, S::fma(no, inv, S::sub(S::zero(), E))),
          S::select(use, S::fma(no, inv, E))};
}
// The lanes whose axis the ray does not move along (R = inf): rare (hard:axis, or a camera ray through
// the image centre), so the callers test for them first and take still_axes' stand-ins only then —
// computed for every ray, the stand-ins' division slowed mbvh8_single's primary rays by 5-7%.
template <int L>
[[gnu::always_inline]] inline typename simd::V<L>::m still_lanes(typename simd::V<L>::f inv) {
  using S = simd::V<L>;
  return S::eq(S::abs(inv), S::set1(INFINITY));
}
// (K + |o|) R (1 + 2^-20) >= |(P - o) / d| for every plane |P| <= K, on lanes whose axis the ray moves
// along (0 < R < inf); 0 on the others.
template <int L>
[[gnu::always_inline]] inline typename simd::V<L>::f plane_distance_bound(typename simd::V<L>::f o, typename simd::V<L>::f inv,
                                                                          typename simd::V<L>::f K) {
  using S = simd::V<L>;
  const typename S::f R = S::abs(inv);
  const typename S::m moves = S::and_(S::gt(R, S::zero()), S::lt(R, S::set1(INFINITY)));
  return S::select(moves, S::mul(S::mul(S::add(K, S::abs(o)), R), S::set1(1.f + 0x1p-20f)));
}
// The stand-ins above on the lanes with R = inf of p (fused_planes' result for o, inv, K), given
// each lane's Tm (plane_distance_bound, the max over the ray's three axes); the other lanes unchanged.
template <int L>
inline void still_axes(FusedPlanes<L>& p, typename simd::V<L>::f o, typename simd::V<L>::f inv, typename simd::V<L>::f K,
                       typename simd::V<L>::f Tm) {
  using S = simd::V<L>;
  const typename S::f W = S::mul(S::add(K, S::abs(o)), S::set1(1.f + 0x1p-20f));
  const typename S::f E0 = S::mul(Tm, S::set1(4.f));
  const typename S::f R0 = S::div(Tm, S::mul(W, S::set1(4.f * kUlp)));
  const typename S::m fixed =
      S::and_(S::and_(still_lanes<L>(inv), S::and_(S::ge(Tm, S::set1(0x1p-100f)), S::le(Tm, S::set1(0x1p100f)))),
              S::and_(S::gt(W, S::zero()), S::lt(R0, S::set1(INFINITY))));
  const typename S::f r0 = S::or_(S::and_(inv, S::set1(-0.f)), R0);  // copysign(R0, inv): the octant's sign
  const typename S::f no = S::sub(S::zero(), o);
  p.r = S::blendv(p.r, r0, fixed);
  p.cn = S::blendv(p.cn, S::fma(no, r0, S::sub(S::zero(), E0)), fixed);
  p.cf = S::blendv(p.cf, S::fma(no, r0, E0), fixed);
}
// The three axes of one ray, in lanes 0..2.
inline FusedPlanes<4> fused_planes(Vec3 org, Vec3 inv, const float bound[3], float kK = 2.02f * kUlp,
                                   float ko = 3.03f * kUlp) {
  using S = simd::V<4>;
  const __m128 o = _mm_setr_ps(org.x, org.y, org.z, 0.f), in = _mm_setr_ps(inv.x, inv.y, inv.z, 0.f);
  const __m128 K = _mm_setr_ps(bound[0], bound[1], bound[2], 0.f);
  FusedPlanes<4> p = fused_planes<4>(o, in, K, kK, ko);
  if (S::any(still_lanes<4>(in))) [[unlikely]] {
    const __m128 Tm = S::set1(-S::hmin(S::sub(S::zero(), plane_distance_bound<4>(o, in, K))));  // the lanes' max
    still_axes<4>(p, o, in, K, Tm);
  }
  return p;
}

// The slab test for one ray: the entry distance or +inf on a miss. tfar is the current closest
// hit (or ray tmax).
inline float box_entry(const RayCtx& r, const Vec3& lo, const Vec3& hi, float tmin, float tfar) {
  // An axis' near and far plane side by side: g++ 12 then tests each sign once (selecting all
  // near planes first, then all far ones, compiled to two tests per axis: +8% instructions in
  // bvh_single, callgrind, sponza primary).
  float xn[3], xf[3];
  xn[0] = (r.near_x ? hi.x : lo.x) - r.org.x;
  xf[0] = (r.near_x ? lo.x : hi.x) - r.org.x;
  xn[1] = (r.near_y ? hi.y : lo.y) - r.org.y;
  xf[1] = (r.near_y ? lo.y : hi.y) - r.org.y;
  xn[2] = (r.near_z ? hi.z : lo.z) - r.org.z;
  xf[2] = (r.near_z ? lo.z : hi.z) - r.org.z;
  const float rn[3] = {r.inv.x, r.inv.y, r.inv.z};
  float tn;
  return slab<1, false>(xn, xf, rn, rn, tmin, tfar, tn) ? tn : INFINITY;
}

// =============================================================================================
// Watertight test (Woop, Benthin and Wald 2013), in three parts that every scheme composes the
// same way: (1) the caller forms the sheared vertex coordinates X = P[kx] - sx * P[kz],
// Y = P[ky] - sy * P[kz] of the vertices relative to the origin (shear<L>); (2) watertight_inside
// computes the edge functions and decides inside/outside; (3) the hit distance of the few lanes
// that pass comes from exact_plane_distance (double), the sheared distance only where the ray
// lies in the plane (sheared_distance). u = V / det, v = W / det.

template <int L>
[[gnu::always_inline]] inline typename simd::V<L>::f shear(typename simd::V<L>::f p, typename simd::V<L>::f s,
                                                           typename simd::V<L>::f pz) {
  using S = simd::V<L>;
  return S::sub(p, S::mul(s, pz));
}

// The sheared edge functions on L lanes; lanes where an edge passes (numerically) through the
// ray are decided in double, so that the two triangles sharing the edge agree (Woop et al. 2013
// §4): all three functions of such a lane are recomputed, as the scalar test always did.
template <int L>
[[gnu::always_inline]] inline void edge_functions(typename simd::V<L>::f Ax, typename simd::V<L>::f Ay,
                                                  typename simd::V<L>::f Bx, typename simd::V<L>::f By,
                                                  typename simd::V<L>::f Cx, typename simd::V<L>::f Cy,
                                                  typename simd::V<L>::f& U, typename simd::V<L>::f& V,
                                                  typename simd::V<L>::f& W) {
  using S = simd::V<L>;
  U = S::sub(S::mul(Cx, By), S::mul(Cy, Bx));
  V = S::sub(S::mul(Ax, Cy), S::mul(Ay, Cx));
  W = S::sub(S::mul(Bx, Ay), S::mul(By, Ax));
  if constexpr (L == 1) {
    if (U == 0.f || V == 0.f || W == 0.f) [[unlikely]] {
      U = float(double(Cx) * By - double(Cy) * Bx);
      V = float(double(Ax) * Cy - double(Ay) * Cx);
      W = float(double(Bx) * Ay - double(By) * Ax);
    }
  } else {
    const typename S::f z = S::zero();
    const int zmask = S::mask(S::or_(S::or_(S::eq(U, z), S::eq(V, z)), S::eq(W, z)));
    if (zmask) [[unlikely]] {
      alignas(32) float ax[L], ay[L], bx[L], by[L], cx[L], cy[L], u[L], v[L], w[L];
      S::store(ax, Ax), S::store(ay, Ay), S::store(bx, Bx), S::store(by, By), S::store(cx, Cx), S::store(cy, Cy);
      S::store(u, U), S::store(v, V), S::store(w, W);
      for (int m = zmask; m; m &= m - 1) {
        const int l = std::countr_zero(unsigned(m));
        edge_functions<1>(ax[l], ay[l], bx[l], by[l], cx[l], cy[l], u[l], v[l], w[l]);
      }
      U = S::load(u), V = S::load(v), W = S::load(w);
    }
  }
}

// Parts (2): the lanes where the ray passes inside the triangle (all edge functions of one sign;
// no NaN can occur: vertices and origin are finite) and the triangle is not degenerate or
// edge-on (det == 0: never a hit). Also returns U, V, W and det = U + V + W (for L = 1 only
// where the test passes: one ray exits early, as most tests miss).
template <int L>
[[gnu::always_inline]] inline typename simd::V<L>::m watertight_inside(
    typename simd::V<L>::f Ax, typename simd::V<L>::f Ay, typename simd::V<L>::f Bx, typename simd::V<L>::f By,
    typename simd::V<L>::f Cx, typename simd::V<L>::f Cy, typename simd::V<L>::f& U, typename simd::V<L>::f& V,
    typename simd::V<L>::f& W, typename simd::V<L>::f& det) {
  using S = simd::V<L>;
  edge_functions<L>(Ax, Ay, Bx, By, Cx, Cy, U, V, W);
  if constexpr (L == 1) {  // one ray: the same decision with early exits (most tests miss)
    if ((U < 0.f || V < 0.f || W < 0.f) && (U > 0.f || V > 0.f || W > 0.f)) return false;
    det = U + V + W;
    return det != 0.f;
  }
  const typename S::f z = S::zero();
  // (U < 0 || V < 0 || W < 0) && (U > 0 || V > 0 || W > 0), as min < 0 and max > 0.
  const auto neg = S::lt(S::min(S::min(U, V), W), z);
  const auto pos = S::gt(S::max(S::max(U, V), W), z);
  det = S::add(S::add(U, V), W);
  return S::andnot(S::and_(neg, pos), S::neq(det, z));
}

// The fallback distance of part (3), for a ray lying in the triangle's plane: sz * (U Az + V Bz +
// W Cz) / det (Woop et al. 2013), with inv_det = 1 / det.
template <int L>
[[gnu::always_inline]] inline typename simd::V<L>::f sheared_distance(
    typename simd::V<L>::f sz, typename simd::V<L>::f U, typename simd::V<L>::f V, typename simd::V<L>::f W,
    typename simd::V<L>::f Az, typename simd::V<L>::f Bz, typename simd::V<L>::f Cz, typename simd::V<L>::f inv_det) {
  using S = simd::V<L>;
  return S::mul(S::mul(sz, S::add(S::add(S::mul(U, Az), S::mul(V, Bz)), S::mul(W, Cz))), inv_det);
}

// Part (3): the distance along the ray to the triangle's plane in double, for candidates that
// already passed the inside test (one or two per ray), as num / dn; dn == 0 when the ray is
// parallel to the plane. Why not T/det: the sheared distance loses up to ~1e-3 relative on long,
// thin triangles (the edge functions cancel), and even the float plane equation loses
// eps * |edge| / cos(angle) on grazing hits — both beyond the suite's 1e-5 accuracy bar on real
// scenes (measured on lucy, conference). Differences of floats are exact in double, so this is
// accurate to the last bit of the float result. D: double, or simd::D4v (four lanes); the
// normal may be computed once per triangle (plane_normal) and reused over several rays.
template <class D>
struct Vec3D {
  D x, y, z;
};
template <class D>
[[gnu::always_inline]] inline Vec3D<D> plane_normal(const Vec3D<D>& v0, const Vec3D<D>& v1, const Vec3D<D>& v2) {
  const D e1x = v1.x - v0.x, e1y = v1.y - v0.y, e1z = v1.z - v0.z;
  const D e2x = v2.x - v0.x, e2y = v2.y - v0.y, e2z = v2.z - v0.z;
  return {e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x};
}
template <class D>
[[gnu::always_inline]] inline D plane_dot(const Vec3D<D>& n, const Vec3D<D>& a) {
  return n.x * a.x + n.y * a.y + n.z * a.z;
}
// num = n . (v0 - org), dn = n . dir.
template <class D>
[[gnu::always_inline]] inline void plane_terms(const Vec3D<D>& n, const Vec3D<D>& v0, const Vec3D<D>& org,
                                               const Vec3D<D>& dir, D& num, D& dn) {
  num = plane_dot(n, Vec3D<D>{v0.x - org.x, v0.y - org.y, v0.z - org.z});
  dn = plane_dot(n, dir);
}
inline Vec3D<double> to_double(const Vec3& v) { return {v.x, v.y, v.z}; }
// One ray, one triangle: NaN when the ray is parallel to the plane.
[[gnu::always_inline]] inline float exact_plane_distance(const Vec3& org, const Vec3& dir, const TriVerts& tri) {
  const Vec3D<double> v0 = to_double(tri.v0);
  double num, dn;
  plane_terms(plane_normal(v0, to_double(tri.v1), to_double(tri.v2)), v0, to_double(org), to_double(dir), num, dn);
  return dn != 0.0 ? float(num / dn) : NAN;
}

// The watertight test for one ray. On a hit with tmin <= t < hit.t, updates hit (t, u, v) and
// returns true.
inline bool intersect_watertight(const RayCtx& r, const TriVerts& tri, float tmin, Hit& hit) {
  // The permuted coordinates by indexed loads (Vec3 is three packed floats), not by Vec3's
  // branching operator[]: nine selects per triangle on the ray's axes.
  static_assert(sizeof(Vec3) == 3 * sizeof(float));
  const float *o = &r.org.x, *a = &tri.v0.x, *b = &tri.v1.x, *c = &tri.v2.x;
  const float Az = a[r.kz] - o[r.kz], Bz = b[r.kz] - o[r.kz], Cz = c[r.kz] - o[r.kz];
  float U, V, W, det;
  if (!watertight_inside<1>(shear<1>(a[r.kx] - o[r.kx], r.sx, Az), shear<1>(a[r.ky] - o[r.ky], r.sy, Az),
                            shear<1>(b[r.kx] - o[r.kx], r.sx, Bz), shear<1>(b[r.ky] - o[r.ky], r.sy, Bz),
                            shear<1>(c[r.kx] - o[r.kx], r.sx, Cz), shear<1>(c[r.ky] - o[r.ky], r.sy, Cz), U, V, W, det))
    return false;
  const float inv_det = 1.f / det;
  float t = exact_plane_distance(r.org, r.dir, tri);
  if (std::isnan(t)) t = sheared_distance<1>(r.sz, U, V, W, Az, Bz, Cz, inv_det);
  if (!(t >= tmin && t < hit.t)) return false;
  hit.t = t;
  hit.u = V * inv_det;
  hit.v = W * inv_det;
  return true;
}

// =============================================================================================
// Moller-Trumbore (1997): fast, not watertight (rays through shared edges can leak). L rays
// against one triangle: d = direction, s = origin - v0, per lane. Returns the lanes of `ok`
// that hit with tmin <= t < tfar, and their t, u, v.
template <int L>
[[gnu::always_inline]] inline typename simd::V<L>::m moller(const typename simd::V<L>::f d[3],
                                                            const typename simd::V<L>::f s[3], const TriVerts& tri,
                                                            typename simd::V<L>::f tmin, typename simd::V<L>::f tfar,
                                                            typename simd::V<L>::m ok, typename simd::V<L>::f& t,
                                                            typename simd::V<L>::f& u, typename simd::V<L>::f& v) {
  using S = simd::V<L>;
  using f = typename S::f;
  const Vec3 e1 = tri.v1 - tri.v0, e2 = tri.v2 - tri.v0;
  const f e1x = S::set1(e1.x), e1y = S::set1(e1.y), e1z = S::set1(e1.z);
  const f e2x = S::set1(e2.x), e2y = S::set1(e2.y), e2z = S::set1(e2.z);
  const f zero = S::zero(), one = S::set1(1.f);
  t = u = v = zero;  // defined on every lane, also when no lane hits
  // p = cross(d, e2), det = dot(e1, p)
  const f px = S::sub(S::mul(d[1], e2z), S::mul(d[2], e2y));
  const f py = S::sub(S::mul(d[2], e2x), S::mul(d[0], e2z));
  const f pz = S::sub(S::mul(d[0], e2y), S::mul(d[1], e2x));
  const f det = S::add(S::add(S::mul(e1x, px), S::mul(e1y, py)), S::mul(e1z, pz));
  ok = S::andnot(S::lt(S::abs(det), S::set1(1e-20f)), ok);
  if (!S::any(ok)) return ok;
  const f inv_det = S::div(one, det);
  u = S::mul(S::add(S::add(S::mul(s[0], px), S::mul(s[1], py)), S::mul(s[2], pz)), inv_det);
  ok = S::andnot(S::or_(S::lt(u, zero), S::gt(u, one)), ok);
  if (!S::any(ok)) return ok;
  // q = cross(s, e1)
  const f qx = S::sub(S::mul(s[1], e1z), S::mul(s[2], e1y));
  const f qy = S::sub(S::mul(s[2], e1x), S::mul(s[0], e1z));
  const f qz = S::sub(S::mul(s[0], e1y), S::mul(s[1], e1x));
  v = S::mul(S::add(S::add(S::mul(d[0], qx), S::mul(d[1], qy)), S::mul(d[2], qz)), inv_det);
  ok = S::andnot(S::or_(S::lt(v, zero), S::gt(S::add(u, v), one)), ok);
  if (!S::any(ok)) return ok;
  t = S::mul(S::add(S::add(S::mul(e2x, qx), S::mul(e2y, qy)), S::mul(e2z, qz)), inv_det);
  return S::and_(ok, S::and_(S::ge(t, tmin), S::lt(t, tfar)));
}

inline bool intersect_moller(const RayCtx& r, const TriVerts& tri, float tmin, Hit& hit) {
  const float d[3] = {r.dir.x, r.dir.y, r.dir.z};
  const Vec3 sv = r.org - tri.v0;
  const float s[3] = {sv.x, sv.y, sv.z};
  float t, u, v;
  if (!moller<1>(d, s, tri, tmin, hit.t, true, t, u, v)) return false;
  hit.t = t, hit.u = u, hit.v = v;
  return true;
}

// =============================================================================================
// Precomputed-plane test (Appendix C): t from the plane, barycentrics from two edge planes
// evaluated at the hit point. kApproxRcp uses rcpps (12 bits) for 1/(n.d) as the thesis does.
// L rays against one triangle: o = origin, d = direction, on = dot(o, n) (plane_offset; a
// common-origin packet computes it once); same result convention as moller.
template <int L>
[[gnu::always_inline]] inline typename simd::V<L>::f plane_offset(const typename simd::V<L>::f o[3], const Vec3& n) {
  using S = simd::V<L>;
  return S::add(S::add(S::mul(o[0], S::set1(n.x)), S::mul(o[1], S::set1(n.y))), S::mul(o[2], S::set1(n.z)));
}
template <int L, bool kApproxRcp>
[[gnu::always_inline]] inline typename simd::V<L>::m plane(const typename simd::V<L>::f o[3],
                                                           const typename simd::V<L>::f d[3], typename simd::V<L>::f on,
                                                           const PlaneTri& tri, typename simd::V<L>::f tmin,
                                                           typename simd::V<L>::f tfar, typename simd::V<L>::m ok,
                                                           typename simd::V<L>::f& t, typename simd::V<L>::f& u,
                                                           typename simd::V<L>::f& v) {
  using S = simd::V<L>;
  using f = typename S::f;
  const f zero = S::zero(), one = S::set1(1.f);
  t = u = v = zero;  // defined on every lane, also when no lane hits
  const f dn = plane_offset<L>(d, tri.n);
  ok = S::and_(ok, S::neq(dn, zero));
  if (!S::any(ok)) return ok;
  const f rcp = kApproxRcp ? S::rcp(dn) : S::div(one, dn);
  t = S::mul(S::sub(S::set1(tri.nd), on), rcp);
  ok = S::and_(ok, S::and_(S::ge(t, tmin), S::lt(t, tfar)));
  if (!S::any(ok)) return ok;
  const f p[3] = {S::add(o[0], S::mul(d[0], t)), S::add(o[1], S::mul(d[1], t)), S::add(o[2], S::mul(d[2], t))};
  u = S::add(plane_offset<L>(p, tri.u), S::set1(tri.ud));
  ok = S::andnot(S::or_(S::lt(u, zero), S::gt(u, one)), ok);
  if (!S::any(ok)) return ok;
  v = S::add(plane_offset<L>(p, tri.v), S::set1(tri.vd));
  return S::andnot(S::or_(S::lt(v, zero), S::gt(S::add(u, v), one)), ok);
}

template <bool kApproxRcp>
inline bool intersect_plane(const RayCtx& r, const PlaneTri& tri, float tmin, Hit& hit) {
  const float o[3] = {r.org.x, r.org.y, r.org.z}, d[3] = {r.dir.x, r.dir.y, r.dir.z};
  float t, u, v;
  if (!plane<1, kApproxRcp>(o, d, dot(r.org, tri.n), tri, tmin, hit.t, true, t, u, v)) return false;
  hit.t = t, hit.u = u, hit.v = v;
  return true;
}

// =============================================================================================
// Tests stored triangle i with kernel K; on a closer hit records it (prim = scene index).
template <TriKernel K>
inline bool intersect_tri(const RayCtx& r, const TriangleSet& ts, uint32_t i, float tmin,
                                                 Hit& hit) {
  bool h;
  if constexpr (K == TriKernel::watertight) h = intersect_watertight(r, ts.verts[i], tmin, hit);
  else if constexpr (K == TriKernel::moller) h = intersect_moller(r, ts.verts[i], tmin, hit);
  else h = intersect_plane<K == TriKernel::plane_rcp>(r, ts.planes[i], tmin, hit);
  if (h) hit.prim = ts.prim_id[i];
  return h;
}

// Calls f(std::integral_constant<TriKernel, K>{}) for the runtime kernel k: how a scheme turns
// its `--kernel` option into a template argument without copying itself.
template <class F>
decltype(auto) dispatch_kernel(TriKernel k, F&& f) {
  switch (k) {
    case TriKernel::moller: return f(std::integral_constant<TriKernel, TriKernel::moller>{});
    case TriKernel::plane: return f(std::integral_constant<TriKernel, TriKernel::plane>{});
    case TriKernel::plane_rcp: return f(std::integral_constant<TriKernel, TriKernel::plane_rcp>{});
    default: return f(std::integral_constant<TriKernel, TriKernel::watertight>{});
  }
}

}  // namespace tb
