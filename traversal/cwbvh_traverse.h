// The node test of the compressed 8-wide BVH (structures/cwbvh.h; cwbvh_single): plane distances
// straight from the 8-bit child offsets, with a proven error bound instead of a decode.
//
// Ylitie, Karras and Laine (2017, §3.1) fold the decode into the slab test: a child plane
// p + q * 2^e is crossed at t = (p + q * 2^e - o) / d = q * A + B with A = 2^e * (1/d) and
// B = (p - o) * (1/d) computed once per node and axis, so a plane row costs one fused multiply-add
// instead of a decode (fma), a subtraction of the origin and a multiply. Here B = p * r + c with a
// per-ray constant c that also carries the error bound: c_near = -o r - E, c_far = -o r + E.
//
// That rounds differently from the decode the builder's conservative quantization is checked on
// (cw_decode), and the error of q * A + B is not relative to t (the terms cancel when the ray starts
// near the plane), so Ize's relative far padding does not cover it. The bound used instead
// (notation of PBR 3rd ed. §3.9: u = 2^-24, gamma_1 = u / (1 - u)); per ray and axis:
//   o the origin, r = fl(1/d) (normal: r = +-inf, 0 or NaN leaves the axis out, see below),
//   R = |r|, K = CWBVH::coord_bound (>= |p| + 255 * 2^e of every node, so >= |p + q 2^e|),
//   Z = (K + |o|) * R,   E = 8 u Z + 2^-110 (1 + R)   (evaluated in float: >= 7.99 u Z),
//   c = fl(-o * r -+ E)   (one fma: |c - (-o r -+ E)| <= u (|o| R + E) <= u (Z + E)).
// Per node A = fl(2^e r), B = fl(p r + c); per plane t = fl(q A + B); decoded plane D = fl(p + q 2^e)
// (the builder's one rounding: CWBVH.FusedDecodeEqualsTheBuilderDecode), exact distance
// T = (D - o) / d. With Y = p + q 2^e exact, q A + p r = Y r exactly, and:
//   * the two fma roundings: |t - (Y r + c)| <= u |p r + c| + u |q A + B| <= 3.02 u (Z + E), plus
//     flush-to-zero: < 2^-126 per result and < 255 * 2^-126 for q * A where A flushed (< 2^-117);
//   * 1/d = r (1 + rho), |rho| <= gamma_1: |T - (D - o) r| <= 1.01 gamma_1 Z;
//   * |D - Y| <= u |Y| + 2^-126 <= u K + 2^-126 (one rounding, FTZ): |(D - Y) r| <= u Z + 2^-126 R.
// Hence |t - (T -+ E)| <= 6.04 u Z + 4.02 u E + 2^-117 + 1.01 * 2^-126 R < E: every near plane's
// computed distance (c_near) is a LOWER bound of the exact one and every far plane's (c_far) an
// UPPER bound. So n = max(tmin, max_axes t_near) never exceeds the exact entry (the distance the
// children are sorted and culled by) and f = min(tfar, min_axes t_far) never falls below the exact
// exit: a child whose exact interval [max(tmin, T_near), min(tfar, T_far)] is non-empty passes
// n <= f. No false miss, at any offset, for flat children and origins on a plane
// (CWBVH.FusedNodeTestIsConservative hammers it against long-double distances; it fails with
// E = u Z).
// Overflow: an axis with E > 2^100 is left out, so |A|, |B|, |t| <= 2^123 stay finite.
// Left out (r = NaN: every t of the axis is NaN, which the slab-style max/min skip, so the axis
// constrains nothing — conservative): |d| > 2^126 (r flushed to 0), NaN, and the overflow case. An
// axis the ray does not move along (d = +-0) takes kernels.h's finite stand-in r0 = copysign(R0, d),
// E0 = 4 Tm with Z = (K + |o|) R0 <= E0 / (16 u): the error above is then < 6.04 u Z + 4.02 u E0 <
// 0.38 E0 against (D - o) r0, so near distances of boxes holding the ray's coordinate are < 0 and
// far ones > 2 Tm (kernels.h has the argument; before session 41 such axes were left out). The
// bound (2E ~ 16 u (K + |o|) R between near and far, a few float ulps of the scene's extent in t)
// also lets a ray into an unused slot (q_lo = 255 > q_hi = 0) of a tiny node: such a slot
// references a real one-triangle leaf (structures/cwbvh.h), so it costs a test.
#pragma once
#include <immintrin.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "structures/cwbvh.h"
#include "traversal/kernels.h"
#include "traversal/mbvh_traverse.h"

namespace tb {

// Byte offsets in a node of the quantized rows holding the near (0..2) and far (3..5) planes of each
// axis, by ray octant (bit a set: direction a negative, entered through hi; Williams et al. 2005).
inline constexpr std::array<std::array<uint32_t, 6>, 8> kCWPlaneRows =
    octant_plane_rows(uint32_t(offsetof(CWNode, qlo)), uint32_t(offsetof(CWNode, qhi)), 8);

// The entered children of a node in the octant order of the compressed layout (structures/cwbvh.h;
// Ylitie et al. 2017 §3.2/§4): for ray octant o the slots are visited in the order k ^ o, k = 0..7,
// so kCWOctantOrder[o][mask] lists the slots of mask's bits by k descending (far to near), one
// byte each from the low byte; the bytes after the last slot repeat slot 0 (never read as
// children). The nearest in that order is byte popcount(mask) - 1. A table lookup replaces the
// sort of the entry distances; 2 KB of it per octant, so a ray touches one 2 KB row set.
inline constexpr std::array<std::array<uint64_t, 256>, 8> kCWOctantOrder = [] {
  std::array<std::array<uint64_t, 256>, 8> t{};
  for (uint32_t o = 0; o < 8; ++o)
    for (uint32_t m = 0; m < 256; ++m) {
      uint64_t v = 0;
      uint32_t n = 0;
      for (int k = 7; k >= 0; --k)
        if (m >> (uint32_t(k) ^ o) & 1) v |= uint64_t(uint32_t(k) ^ o) << (8 * n++);
      t[o][m] = v;
    }
  return t;
}();

// Per-ray constants of the fused node test, broadcast per axis: r, c_near and c_far (an axis left
// out has r = NaN, c = 0), tmin, the plane rows and the child order of the ray's octant. Computed
// for the three axes at once in SSE, in float: each of the four operations of E rounds by at most
// u (E >= 7.99 u Z, where the bound needs 6.04 u Z + 4.02 u E), and c = fl(-o r -+ E) is one fused
// rounding.
// exp_add says whether A = fl(2^e r) may be formed by adding e to r's exponent field (cw_box_test's
// ExpAdd): exact, as the product, when r is a normal float and r_exp + e is a normal exponent
// (1..254) for every e of the tree (CWBVH::e_min..e_max) and every axis the test uses (an axis left
// out has r = NaN and B = NaN, so its A is never read into a distance). A ray with |d| near 2^126
// on a tree with very fine cells fails the check and takes the multiply, which flushes an
// underflowing A to zero as the bound allows.
struct CWRay {
  __m256 r44;  // [r | r] of the three axes (lanes 3 and 7 NaN)
  __m256 cn44, cf44;  // [c_near | c_near], [c_far | c_far]: two fmas give a node's six B = fl(p r + c)
  __m256 tmin;
  __m128i bias;  // 127 (the exponent bias), kept opaque so that it is not rebuilt at every node
  const uint32_t* rows;
  const uint32_t* full_rows;  // kPlaneRows<8> of the ray's octant (the full nodes' plane rows)
  const uint64_t* order;  // kCWOctantOrder of the ray's octant
  bool exp_add;

  CWRay(const RayCtx& ray, float t0, const float coord_bound[3], int e_min, int e_max) {
    // The kernel library's fused-plane constants (kernels.h) with the larger bound derived above:
    // E = 8 u (K + |o|) R + 2^-110 (1 + R). They also serve the full nodes of an uncompressed top
    // (structures/cwbvh.h) through the MBVH node test (box_test, cw_full_ray): that test needs
    // E >= 1.005 u (2 K + 3 |o|) R with K >= |P| for its float planes P, which CWBVH::coord_bound
    // covers, and 8 u (K + |o|) exceeds it. (Their own, ~4x smaller E changed nothing: crytek,
    // sponza and conference test the same leaves per ray within 1%, session 23.)
    const FusedPlanes<4> p = fused_planes(ray.org, ray.inv, coord_bound, 8 * kUlp, 8 * kUlp);
    r44 = _mm256_set_m128(p.r, p.r);
    cn44 = _mm256_set_m128(p.cn, p.cn);
    cf44 = _mm256_set_m128(p.cf, p.cf);
    // exp_add: every used axis (r not NaN) has a normal r and r_exp + e in 1..254 for e_min..e_max.
    const __m128i ex = _mm_and_si128(_mm_srli_epi32(_mm_castps_si128(p.r), 23), _mm_set1_epi32(0xFF));
    const __m128i lo = _mm_add_epi32(ex, _mm_set1_epi32(std::min(e_min, 0)));  // also r_exp >= 1: r normal
    const __m128i hi = _mm_add_epi32(ex, _mm_set1_epi32(e_max));
    const __m128i bad = _mm_or_si128(_mm_cmplt_epi32(lo, _mm_set1_epi32(1)), _mm_cmpgt_epi32(hi, _mm_set1_epi32(254)));
    const __m128 used = _mm_cmpord_ps(p.r, p.r);
    exp_add = _mm_movemask_ps(_mm_and_ps(used, _mm_castsi128_ps(bad))) == 0;
    tmin = _mm256_set1_ps(t0);
    bias = _mm_set1_epi32(127);
    __asm__("" : "+x"(bias));  // opaque: a memory operand, not rebuilt per node
    const uint32_t octant = ray.octant();
    rows = kCWPlaneRows[octant].data();
    full_rows = kPlaneRows<8>[octant].data();
    order = kCWOctantOrder[octant].data();
  }
};

// The t = q * A + B of one plane row of 8 slots (q at byte offset `at` in the node).
[[gnu::always_inline]] inline __m256 cw_plane(const CWNode& n, uint32_t at, __m256 A, __m256 B) {
  const auto* q = reinterpret_cast<const __m128i*>(reinterpret_cast<const uint8_t*>(&n) + at);
  return _mm256_fmadd_ps(_mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(q))), A, B);
}

// The lanes (all-ones) whose child box the ray enters before tfar (broadcast), and the entry distances tn (a
// lower bound of the exact entry: see the bound above). Operand order as kernels.h's slab: a NaN
// plane distance (an axis left out) is skipped by max/min.
// ExpAdd (only where the ray's exp_add holds) forms each axis' A = 2^e r as r's bits plus e * 2^23:
// the node's first 16 bytes (p, e, imask) broadcast to both halves, one byte shuffle putting e_a
// in the top byte of every lane, an arithmetic shift by 1 (e_a * 2^23, sign-extended) and an
// integer add. The same value as the multiply (CWBVH.ExponentAddEqualsTheProduct), on a shorter
// path from the node's bytes to its plane distances, which single-ray traversal waits on at every
// node: cwbvh_single +1.3 to +2.9% (crytek_sponza_partial, sponza, conference; docs/PERFORMANCE.md, session 17).
// The six B = fl(p r + c) come from two 8-wide fmas on [p | p] and [r | r], one with [c_near |
// c_near] and one with [c_far | c_far] (session 17: three broadcasts of p and six fmas on per-axis
// broadcasts before, 8-11% fewer instructions; 5 ray constants in registers instead of 10, AVX2
// has 16). Each axis' B_near and B_far is then an in-lane permute (session 21: one fma giving
// [c_near | c_far] needed two lane-crossing permutes per axis, 3 cycles each on the path from the
// node's load to its distances; the same values, cwbvh_single / mbvh8_single +1.5% on primary
// rays of spheres:2M, crytek and bunny, AVX2 build, interleaved; bounce:2 unchanged).
template <bool ExpAdd = false>
[[gnu::always_inline]] inline __m256 cw_box_test(const CWNode& nd, const CWRay& r, __m256 tfar, __m256& tn) {
  static_assert(offsetof(CWNode, p) == 0 && offsetof(CWNode, e) == 12 && offsetof(CWNode, imask) == 15);
  // [p e | p e]: the node's first 16 bytes in both halves (lanes 3 and 7 hold e and imask: junk,
  // never read into a distance).
  const __m256 head = _mm256_broadcast_ps(reinterpret_cast<const __m128*>(&nd));
  // [B_near | B_near] and [B_far | B_far] of the three axes, B = fl(p r + c): each axis' B is then
  // one in-lane permute away from a broadcast (no lane crossing on the path to the plane distances).
  const __m256 Bn8 = _mm256_fmadd_ps(head, r.r44, r.cn44), Bf8 = _mm256_fmadd_ps(head, r.r44, r.cf44);
  __m256 A8;  // [A | A], A = 2^e r
  if constexpr (ExpAdd) {
    // e_a into the top byte of lane a (zeros below: 0x80 selects 0), shifted down to e_a * 2^23
    // (sign-extended) and added to r's bits.
    const __m256i top = _mm256_setr_epi32(0x0C808080, 0x0D808080, 0x0E808080, -1, 0x0C808080, 0x0D808080, 0x0E808080, -1);
    const __m256i eb = _mm256_srai_epi32(_mm256_shuffle_epi8(_mm256_castps_si256(head), top), 1);
    A8 = _mm256_castsi256_ps(_mm256_add_epi32(eb, _mm256_castps_si256(r.r44)));
  } else {
    // [2^e_x 2^e_y 2^e_z junk]: the cells from e[0..2] (imask's lane unused), one 4-wide multiply.
    int32_t e4;
    std::memcpy(&e4, reinterpret_cast<const char*>(&nd) + offsetof(CWNode, e), sizeof e4);
    const __m128 cells = _mm_castsi128_ps(_mm_slli_epi32(_mm_add_epi32(_mm_cvtepi8_epi32(_mm_cvtsi32_si128(e4)), r.bias), 23));
    const __m128 A4 = _mm_mul_ps(cells, _mm256_castps256_ps128(r.r44));
    A8 = _mm256_set_m128(A4, A4);
  }
  __m256 n = r.tmin, f = tfar;
  // One axis at a time; the permute's selector is a template argument, an immediate whether or not
  // the compiler unrolls (a loop over `a` does not build at -O0 or with -fprofile-generate).
  const auto axis = [&]<int a>() {
    const __m256 A = _mm256_permute_ps(A8, 0x55 * a);
    const __m256 Bn = _mm256_permute_ps(Bn8, 0x55 * a), Bf = _mm256_permute_ps(Bf8, 0x55 * a);
    n = _mm256_max_ps(cw_plane(nd, r.rows[a], A, Bn), n);
    f = _mm256_min_ps(cw_plane(nd, r.rows[3 + a], A, Bf), f);
  };
  axis.template operator()<0>(), axis.template operator()<1>(), axis.template operator()<2>();
  tn = n;
  return _mm256_cmp_ps(n, f, _CMP_LE_OQ);
}

// The MBVH node test's per-ray constants (NodeRay<8>, for box_test on the full nodes of an
// uncompressed top): each axis' r, c_near and c_far an in-lane permute of CWRay's [x | x]
// constants, which the compressed test keeps in registers. Formed where a full node is tested
// rather than kept per ray as a NodeRay (nine vectors more than the 16 AVX2 registers hold beside
// the compressed test's: built per ray and spilled, they cost ~60 more instructions per ray on
// crytek primary rays, session 23).
[[gnu::always_inline]] inline NodeRay<8> cw_full_ray(const CWRay& r) {
  NodeRay<8> f;
  f.rx = _mm256_permute_ps(r.r44, 0x00), f.ry = _mm256_permute_ps(r.r44, 0x55), f.rz = _mm256_permute_ps(r.r44, 0xAA);
  f.cnx = _mm256_permute_ps(r.cn44, 0x00), f.cny = _mm256_permute_ps(r.cn44, 0x55), f.cnz = _mm256_permute_ps(r.cn44, 0xAA);
  f.cfx = _mm256_permute_ps(r.cf44, 0x00), f.cfy = _mm256_permute_ps(r.cf44, 0x55), f.cfz = _mm256_permute_ps(r.cf44, 0xAA);
  f.tmin = r.tmin;
  f.rows = r.full_rows;
  return f;
}

// The 8 child references of a node: child_base + meta for interior slots, leaf_base + meta (the
// compressed leaf reference, cw_leaf_ref) for the others. imask is the top byte of the dword at e:
// shifting it left by 7 - i puts slot i's bit in lane i's sign bit, which blendv reads.
[[gnu::always_inline]] inline __m256i cw_child_refs(const CWNode& n) {
  int32_t e4;
  std::memcpy(&e4, reinterpret_cast<const char*>(&n) + offsetof(CWNode, e), sizeof e4);
  const __m256i interior = _mm256_sllv_epi32(_mm256_set1_epi32(e4), _mm256_setr_epi32(7, 6, 5, 4, 3, 2, 1, 0));
  const __m256 base = _mm256_blendv_ps(_mm256_castsi256_ps(_mm256_set1_epi32(int(n.leaf_base))),
                                       _mm256_castsi256_ps(_mm256_set1_epi32(int(n.child_base))), _mm256_castsi256_ps(interior));
  const __m256i meta = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(n.meta)));
  return _mm256_add_epi32(_mm256_castps_si256(base), meta);
}

// Slot s's child reference (cw_child_refs' lane s), in scalar registers.
[[gnu::always_inline]] inline uint32_t cw_child_ref(const CWNode& n, uint32_t s) {
  return ((n.imask >> s & 1) ? n.child_base : n.leaf_base) + n.meta[s];
}

// The watertight test on an indexed leaf block (structures/cwbvh.h, CWTriBlock): parts (1)-(2) of
// the kernel library's test run on the block's vertex table — origin subtraction and shear once per
// table vertex — and each corner of each lane is a permute of the results by its index, so every
// lane sees the values block_intersect computes from a TriBlock<8> holding the same triangles (bit
// for bit: the same float operations on the same floats). Part (3) is block_candidates.
[[gnu::noinline]] inline bool indexed_block_intersect(const TriRay<8>& r, const CWTriBlock& b, Hit& hit) {
  using S = simd::V<8>;
  const __m256 Z = S::sub(S::load(b.v[r.kz]), r.oz);
  const __m256 X = shear<8>(S::sub(S::load(b.v[r.kx]), r.ox), r.sx, Z);
  const __m256 Y = shear<8>(S::sub(S::load(b.v[r.ky]), r.oy), r.sy, Z);
  const auto corner = [&](int c) { return _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(b.idx[c]))); };
  const __m256i ia = corner(0), ib = corner(1), ic = corner(2);
  const __m256 Az = _mm256_permutevar8x32_ps(Z, ia), Bz = _mm256_permutevar8x32_ps(Z, ib), Cz = _mm256_permutevar8x32_ps(Z, ic);
  __m256 U, Vv, Ww, det;
  int m = S::mask(watertight_inside<8>(_mm256_permutevar8x32_ps(X, ia), _mm256_permutevar8x32_ps(Y, ia),
                                       _mm256_permutevar8x32_ps(X, ib), _mm256_permutevar8x32_ps(Y, ib),
                                       _mm256_permutevar8x32_ps(X, ic), _mm256_permutevar8x32_ps(Y, ic), U, Vv, Ww, det));
  if (!m) return false;
  m &= int(lane_bits(b.lanes));
  return block_candidates<8>(
      r, m, U, Vv, Ww, det, Az, Bz, Cz,
      [&](int l, int c) {
        const uint32_t i = b.idx[c][l];
        return Vec3D<double>{b.v[0][i], b.v[1][i], b.v[2][i]};
      },
      [&](int l) { return b.prim[l]; }, hit);
}

// sort_prefetch: sort, and the second-nearest entered child's node or first block lines fetched
// after the push (as mbvh8_single's ChildOrder::sort_prefetch; `prefetch`).
enum class CWOrder { branching, sort, sort_prefetch, octant };

// The address of the node an interior reference names (either kind, structures/cwbvh.h), as an
// integer: the prefetches below may form it for a leaf's reference, which is never dereferenced.
inline uintptr_t cw_node_address(const CWBVH& t, uint32_t ref) {
  return (ref & kCWFull) ? reinterpret_cast<uintptr_t>(t.full.data()) + uintptr_t(ref & ~(kCWFull | mbvh_ref::kLeaf)) * sizeof(MBVHNode<8>)
                         : reinterpret_cast<uintptr_t>(t.nodes.data()) + uintptr_t(ref & ~mbvh_ref::kLeaf) * sizeof(CWNode);
}

// One traversal for both node kinds: a full node (kCWFull) takes the MBVH8's fused node test
// (box_test on cw_full_ray's constants, the same as `r`'s), a compressed node
// the fused test on 8-bit planes; what follows the test (ordering, push, prefetch) is the same
// code, instantiated per kind with the node's reference getters.
// Runs from `at` (the root with an empty stack, or where a suspended traversal left off) as
// mbvh_traverse_from does: before each visit `leave(ref)` may suspend the ray (`at` then holds
// the reference it was about to visit and its stack depth; false is returned), and resumed with
// the same `at`, stack and hit it visits exactly what an unsuspended traversal would
// (treelet_queue with `tree=cwbvh`). True: done.
template <CWOrder O, bool ExpAdd, bool Indexed, class P, class Leave>
bool cw_traverse_from(const CWBVH& t, const CWRay& r, const TriRay<8>& tr, MBVHCursor& at, Hit& hit,
                      MBVHStackEntry* stack, P& probe, Leave&& leave) {
  using S = simd::V<8>;
  const CWNode* nodes = t.nodes.data();
  const MBVHNode<8>* full = t.full.data();
  uint32_t sp = at.sp, cur = at.cur;
  float tfar = hit.t;
  __m256 tfar8 = _mm256_set1_ps(tfar);  // changes only at a leaf
  // The entered children (mask non-zero) of the node just tested: `refs` gives the 8 references as
  // a vector, ref(i) slot i's. Sets cur (and sp); false: none entered.
  const auto descend = [&](const __m256 entered, const __m256 tn, auto&& refs, auto&& ref) {
    const int mask = S::mask(entered);
    if (!mask) return false;
    if constexpr (O == CWOrder::branching) {
      const auto prefetch = [&](uint32_t c) __attribute__((always_inline)) {  // inline: enter_branching
        if (mbvh_ref::is_leaf(c)) return;
        const char* a = reinterpret_cast<const char*>(cw_node_address(t, c));
        if (c & kCWFull) {
          for (size_t l = 0; l < sizeof(MBVHNode<8>); l += 64) _mm_prefetch(a + l, _MM_HINT_T0);
        } else {  // 80 bytes, 16-aligned: two lines
          _mm_prefetch(a, _MM_HINT_T0), _mm_prefetch(a + sizeof(CWNode) - 1, _MM_HINT_T0);
        }
      };
      cur = enter_branching<8>(
          mask, tn, ref, prefetch,
          [&](int count, MBVHStackEntry* out) {
            const __m256i rv = refs();
            push_sorted8(rv, tn, entered, count, out);
            return nearest_ref8(rv, mbvh_simd::sort_keys8(tn, entered));  // beside the network, not after it
          },
          stack, sp, probe);
      return true;
    } else {
      const int count = std::popcount(unsigned(mask));
      const __m256i rv = refs();
      if constexpr (O == CWOrder::octant) {
        const uint64_t order = r.order[mask];
        push_in_order8(rv, tn, _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(int64_t(order))), stack + sp);
        cur = ref(uint32_t(order >> (8 * (count - 1))) & 7);
      } else {
        if constexpr (O == CWOrder::sort_prefetch) {
          uint32_t second;
          push_sorted8(rv, tn, entered, count, stack + sp, &second);
          const uintptr_t block =
              Indexed ? reinterpret_cast<uintptr_t>(t.iblocks.data()) + uintptr_t(cw_ileaf_block(second)) * sizeof(CWTriBlock)
                      : reinterpret_cast<uintptr_t>(t.blocks.data()) +
                            uintptr_t(mbvh_ref::first_block(cw_leaf_to_mbvh(second))) * sizeof(TriBlock<8>);
          prefetch_node_or_block(cw_node_address(t, second), block, mbvh_ref::is_leaf(second));
        } else {
          push_sorted8(rv, tn, entered, count, stack + sp);
        }
        cur = nearest_ref8(rv, mbvh_simd::sort_keys8(tn, entered));
      }
      if constexpr (P::enabled) {
        for (int j = 0; j < count - 1; ++j) probe.write(&stack[sp + j], sizeof(MBVHStackEntry));
      }
      sp += uint32_t(count - 1);
      return true;
    }
  };
  for (;;) {
    if (leave(cur)) {
      at = {cur, sp};
      return false;
    }
    if (!mbvh_ref::is_leaf(cur)) {
      __m256 tn;
      if (cur & kCWFull) {
        const MBVHNode<8>& nd = full[cur & ~kCWFull];
        probe.node(&nd, sizeof(nd));
        const __m256 entered = box_test<8>(nd, cw_full_ray(r), tfar, tn);
        if (descend(
                entered, tn, [&] { return _mm256_load_si256(reinterpret_cast<const __m256i*>(nd.ref)); },
                [&](uint32_t i) { return nd.ref[i]; }))
          continue;
      } else {
        const CWNode& nd = nodes[cur];
        probe.node(&nd, sizeof(nd));
        const __m256 entered = cw_box_test<ExpAdd>(nd, r, tfar8, tn);
        if (descend(
                entered, tn, [&] { return cw_child_refs(nd); }, [&](uint32_t i) { return cw_child_ref(nd, i); }))
          continue;
      }
    } else {
      if constexpr (Indexed) {
        uint32_t k = cw_ileaf_block(cur);
        probe.leaf(&t.iblocks[k], 0, 1);
        for (;; ++k) {
          const CWTriBlock& b = t.iblocks[k];
          probe.tris(&b, sizeof(CWTriBlock), b.lanes);
          indexed_block_intersect(tr, b, hit);
          if (b.last) break;
        }
      } else {
        const uint32_t leaf = cw_leaf_to_mbvh(cur);
        probe_leaf<8>(t.blocks.data(), leaf, probe, 1);
        leaf_test<8, TriKernel::watertight>(t.blocks.data(), nullptr, tr, nullptr, leaf, hit);
      }
      tfar = hit.t;
      tfar8 = _mm256_set1_ps(tfar);
    }
    if (!pop_pending(stack, sp, tfar, cur, probe)) return true;
  }
}
template <CWOrder O, bool ExpAdd, bool Indexed, class P>
void cw_traverse(const CWBVH& t, const CWRay& r, const TriRay<8>& tr, Hit& hit, MBVHStackEntry* stack, P& probe) {
  MBVHCursor at{t.root, 0};
  cw_traverse_from<O, ExpAdd, Indexed>(t, r, tr, at, hit, stack, probe, NeverLeave{});
}

}  // namespace tb
