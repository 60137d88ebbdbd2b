// Packet against one BVH node: the kernel library's slab test (traversal/kernels.h slab<8>) per
// group of 8 rays, with the plane selection and origin offsets hoisted as far as the packet
// allows (per group when its lanes share direction signs, per node for common-origin packets).
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <tuple>
#include <type_traits>

#include "traversal/packet.h"

namespace tb::packet {

// ---------------------------------------------------------------------------------------------
// The kernel library's slab test (kernels.h slab, as box_entry: padded far distance), 8 rays
// against one box. Near/far planes are selected per lane by the sign bit of the reciprocal
// direction (blendv reads the sign bit, so -0 -> -inf selects like the scalar test). Returns the
// lane mask of hits. The node's planes come broadcast (NodeTester::with_test does it once per node
// rather than once per group: sponza bounce:2, bvh_partition 219.4 M -> 208.4 M instructions, OLD
// 205.8 M).
// box_hits returns the hit lanes as a vector mask and their entry distances tn (mbvh8_packet keeps
// them per lane); box_mask the mask bits.
[[gnu::always_inline]] inline __m256 box_hits(const RayGroup& g, const __m256 lo[3], const __m256 hi[3], __m256& tn) {
  using S = simd::V<8>;
  __m256 xn[3], xf[3];
  for (int a = 0; a < 3; ++a) {
    const __m256 l = _mm256_sub_ps(lo[a], g.o[a]), h = _mm256_sub_ps(hi[a], g.o[a]);
    xn[a] = S::blendv(l, h, g.inv[a]);
    xf[a] = S::blendv(h, l, g.inv[a]);
  }
  return slab<8, false>(xn, xf, g.inv, g.inv, g.tmin, g.tfar, tn);
}
[[gnu::always_inline]] inline uint32_t box_mask(const RayGroup& g, const __m256 lo[3], const __m256 hi[3]) {
  __m256 tn;
  return uint32_t(_mm256_movemask_ps(box_hits(g, lo, hi, tn)));
}


// box_mask for group g of a packet, cheaper when the group's lanes agree on every direction sign
// (the common case for coherent rays): the near and far planes are then chosen once for the
// group, and with a common origin the plane offsets are scalars. Every lane computes the very
// same values as in box_mask: (plane - o) * inv, padded far, NaN-first min/max.
// Forced inline, as are NodeTester::operator() and ia_misses (packet_bounds.h): after session 8's
// merges g++ 12 made all three calls (one per 8-ray group or node), e.g. bvh_ranged sponza
// bounce:2 270.3 M instructions, inlined 250.8 M (OLD 984423f 261.6 M; docs/PERFORMANCE.md, session 9).
// same_sign_hits is the same test on a group G whose lanes share the direction sign bits s >= 0
// (gsign) and, kCommon, the origin org: the box's planes lo, hi as scalars. It returns the hit
// lanes as a vector mask and their entry distances tn (mbvh8_packet's child test keeps them per
// lane); group_box the mask bits of packet group g, either case.
template <bool kCommon>
[[gnu::always_inline]] inline __m256 same_sign_hits(const RayGroup& G, int s, const Vec3& org, const float* lo,
                                                    const float* hi, __m256& tn) {
  __m256 xn[3], xf[3];
  for (int a = 0; a < 3; ++a) {
    const bool neg = (s >> a) & 1;
    const float pn = neg ? hi[a] : lo[a], pf = neg ? lo[a] : hi[a];
    if constexpr (kCommon) {
      xn[a] = _mm256_set1_ps(pn - org[a]);
      xf[a] = _mm256_set1_ps(pf - org[a]);
    } else {
      xn[a] = _mm256_sub_ps(_mm256_set1_ps(pn), G.o[a]);
      xf[a] = _mm256_sub_ps(_mm256_set1_ps(pf), G.o[a]);
    }
  }
  return slab<8, false>(xn, xf, G.inv, G.inv, G.tmin, G.tfar, tn);
}
template <bool kCommon>
[[gnu::always_inline]] inline uint32_t group_box(const Packet& p, uint32_t g, const BVHNode& n, const __m256 lo8[3], const __m256 hi8[3]) {
  const int s = p.gsign[g];
  const RayGroup& G = p.rg[g];
  if (s < 0) return box_mask(G, lo8, hi8);
  __m256 tn;
  return uint32_t(_mm256_movemask_ps(same_sign_hits<kCommon>(G, s, p.org, &n.lo.x, &n.hi.x, tn)));
}

// group_box with the node's work hoisted out of the per-group loop: when every group of a
// common-origin packet shares its direction signs (primary packets away from the axis planes),
// the near/far plane offsets (plane - org) are the same scalars for every group, so they are
// broadcast once per node. The far offset is also padded once per node, (plane - org) * kFarPad,
// and each group test is slab<8, kPadRcp = true> on it: 6 multiplies (instead of 9), 6 min/max
// and a compare. The far distance is then ((pf - o) * pad) * inv instead of ((pf - o) * inv) *
// pad: the same roundings (subtract, reciprocal, pad, multiply), so Ize's bound holds as it does
// for the MBVH layouts' inv * pad (kernels.h slab); the values may differ from box_mask's in the
// last bit, never in which boxes a ray really enters, so hits are unchanged (tests/test_packets.cpp
// compares them with the single-ray schemes). Callgrind, sponza primary 128x128: bvh_partition
// 36.67 M -> 36.02 M (docs/PERFORMANCE.md, session 7).
template <bool kCommon, bool kHoistPlanes = false>
struct NodeTester {
  const Packet& p;
  const BVHNode& n;
  bool pre = false;
  __m256 xn[3], xf[3];  // hoisted case: plane offsets (far padded)
  // kHoistPlanes: otherwise the node's planes broadcast once per node for box_mask (bvh_ranged,
  // which tests many groups per tester: sponza bounce:2 270.9 M -> 260.0 M instructions, OLD
  // 261.6 M). Not by default: bvh_masked builds two testers per node and tests few groups with
  // each (+19% on the same rays with the broadcasts in every tester).
  struct Planes {
    __m256 v[6];  // lo x, y, z, hi x, y, z
  };
  [[no_unique_address]] std::conditional_t<kHoistPlanes, Planes, std::tuple<>> planes;  // filled only when !pre
  NodeTester(const Packet& pk, const BVHNode& nd) : p(pk), n(nd) {
    if constexpr (kCommon) {
      if (p.psign >= 0) {
        pre = true;
        const float* lo = &n.lo.x;
        const float* hi = &n.hi.x;
        for (int a = 0; a < 3; ++a) {
          const bool neg = (p.psign >> a) & 1;
          xn[a] = _mm256_set1_ps((neg ? hi[a] : lo[a]) - p.org[a]);
          xf[a] = _mm256_set1_ps(((neg ? lo[a] : hi[a]) - p.org[a]) * kFarPad);
        }
      }
    }
    if constexpr (kHoistPlanes)
      if (!pre)
        for (int a = 0; a < 3; ++a) planes.v[a] = _mm256_set1_ps((&n.lo.x)[a]), planes.v[3 + a] = _mm256_set1_ps((&n.hi.x)[a]);
  }
  // Calls f with the group test as a callable of its own type for each case, so that a loop over
  // groups is compiled once per case: in the hoisted case the six plane vectors are then locals of
  // the loop (g++ 12 otherwise copies them between stack slots at every node).
  template <class F>
  [[gnu::always_inline]] void with_test(F&& f) const {
    if (pre) {
      const __m256 n0 = xn[0], n1 = xn[1], n2 = xn[2], f0 = xf[0], f1 = xf[1], f2 = xf[2];
      const RayGroup* rg = p.rg;
      f([=](uint32_t g) {
        const RayGroup& G = rg[g];
        const __m256 an[3] = {n0, n1, n2}, af[3] = {f0, f1, f2};
        __m256 tn;
        return uint32_t(_mm256_movemask_ps(slab<8, true>(an, af, G.inv, G.inv, G.tmin, G.tfar, tn)));
      });
    } else {
      // The node's planes broadcast once for the whole loop (box_mask, the mixed-sign path of
      // bounce groups), not once per group. Only here: a NodeTester member filled in the
      // constructor cost bvh_masked, which builds two testers per node, +19% instructions on
      // sponza bounce:2 (222.3 M -> 263.9 M).
      const __m256 l0 = _mm256_set1_ps(n.lo.x), l1 = _mm256_set1_ps(n.lo.y), l2 = _mm256_set1_ps(n.lo.z);
      const __m256 h0 = _mm256_set1_ps(n.hi.x), h1 = _mm256_set1_ps(n.hi.y), h2 = _mm256_set1_ps(n.hi.z);
      f([=, this](uint32_t g) {
        const __m256 L[3] = {l0, l1, l2}, H[3] = {h0, h1, h2};
        return group_box<kCommon>(p, g, n, L, H);
      });
    }
  }
  [[gnu::always_inline]] uint32_t operator()(uint32_t g) const {  // forced inline: see group_box
    if (!pre) {
      if constexpr (kHoistPlanes) return group_box<kCommon>(p, g, n, planes.v, planes.v + 3);
      const __m256 L[3] = {_mm256_set1_ps(n.lo.x), _mm256_set1_ps(n.lo.y), _mm256_set1_ps(n.lo.z)};
      const __m256 H[3] = {_mm256_set1_ps(n.hi.x), _mm256_set1_ps(n.hi.y), _mm256_set1_ps(n.hi.z)};
      return group_box<kCommon>(p, g, n, L, H);
    }
    const RayGroup& G = p.rg[g];
    __m256 tn;
    return uint32_t(_mm256_movemask_ps(slab<8, true>(xn, xf, G.inv, G.inv, G.tmin, G.tfar, tn)));
  }
};

}  // namespace tb::packet
