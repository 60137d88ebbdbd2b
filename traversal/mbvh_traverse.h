// What reads the MBVH layout of structures/mbvh.h (thesis §2.2 "MBVH traversal"): the per-ray
// constants of the N-wide node test and the W-wide triangle-block test, the node test, the
// triangle-block test, the ordered single-ray traversal (mbvh_traverse) and the timed per-ray loop
// of mbvh4_single / mbvh8_single. mbvh_rs's one-ray fallback (thesis §2.2 / Tsakok 2009) and the
// RayGrid's mini-MBVHs use the same loop.
//
// The arithmetic is the kernel library's (traversal/kernels.h): the node test is its fused slab
// test (FusedPlanes: sign-selected slabs, one fma per plane, NaN slabs ignored, a proven per-ray
// error bound instead of Ize's far padding), the block test is the watertight test of
// Woop, Benthin and Wald (2013) on W lanes — the same float operations in the same order as the
// one-ray test, so shared edges give exactly negated edge functions (-ffp-contract=off).
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "structures/mbvh.h"
#include "traversal/bvh_common.h"
#include "traversal/kernels.h"
#include "traversal/probe.h"
#include "traversal/simd.h"
#include "traversal/traverser.h"

namespace tb {

namespace mbvh_simd {

using simd::V;

// Sort keys of child distances: the distance's bit pattern with the child index in the low
// bits (thesis Alg. 2.10), misses as the largest key. Integer min/max instead of the thesis'
// minps/maxps: under DAZ (set in every tracing thread) a distance of 0 with index bits is a
// denormal that compares equal to its neighbour, and minps/maxps of equal operands both return
// the second one — the network would duplicate one child and lose another. Distances are >= 0
// (tn >= tmin >= 0), where signed-integer order is float order, so the result is the same order.
inline __m128i sort_keys4(__m128 dist, __m128 hit) {
  const __m128i lane = _mm_setr_epi32(0, 1, 2, 3);
  __m128i k = _mm_castps_si128(_mm_blendv_ps(_mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF)), dist, hit));
  return _mm_or_si128(_mm_and_si128(k, _mm_set1_epi32(~3)), lane);
}
// Thesis Alg. 2.10 (after Furtak et al. 2007): a branch-free 4-element sorting network in one
// register, comparators (0,1)(2,3), (0,2)(1,3), (1,2).
inline __m128i sort4(__m128i k) {
  __m128i p = _mm_shuffle_epi32(k, _MM_SHUFFLE(2, 3, 0, 1));
  k = _mm_blend_epi32(_mm_min_epi32(k, p), _mm_max_epi32(k, p), 0b1010);
  p = _mm_shuffle_epi32(k, _MM_SHUFFLE(1, 0, 3, 2));
  k = _mm_blend_epi32(_mm_min_epi32(k, p), _mm_max_epi32(k, p), 0b1100);
  p = _mm_shuffle_epi32(k, _MM_SHUFFLE(3, 1, 2, 0));
  return _mm_blend_epi32(_mm_min_epi32(k, p), _mm_max_epi32(k, p), 0b0100);
}
// The index bits go in before the blend (the miss keys are constants): the and/or then run beside
// the plane compare that makes `hit`, not after it on the path to the next node's address.
inline __m256i sort_keys8(__m256 dist, __m256 hit) {
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i k = _mm256_or_si256(_mm256_and_si256(_mm256_castps_si256(dist), _mm256_set1_epi32(~7)), lane);
  const __m256i miss = _mm256_or_si256(_mm256_set1_epi32(0x7FFFFFF8), lane);
  return _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(miss), _mm256_castsi256_ps(k), hit));
}
// The 8-wide equivalent: Batcher's bitonic network, 6 stages of (partner shuffle, min, max, blend).
inline __m256i sort8(__m256i k) {
  auto stage = [](__m256i k, __m256i p, auto imm) {
    return _mm256_blend_epi32(_mm256_min_epi32(k, p), _mm256_max_epi32(k, p), decltype(imm)::value);
  };
  using std::integral_constant;
  k = stage(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(2, 3, 0, 1)), integral_constant<int, 0x66>{});
  k = stage(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(1, 0, 3, 2)), integral_constant<int, 0x3C>{});
  k = stage(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(2, 3, 0, 1)), integral_constant<int, 0x5A>{});
  k = stage(k, _mm256_permute2x128_si256(k, k, 0x01), integral_constant<int, 0xF0>{});
  k = stage(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(1, 0, 3, 2)), integral_constant<int, 0xCC>{});
  return stage(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(2, 3, 0, 1)), integral_constant<int, 0xAA>{});
}

}  // namespace mbvh_simd

// Float offsets into MBVHNode<N>::box of the near (0..2) and far (3..5) plane row of each axis,
// by ray octant (bit a set: direction a negative, entered through hi). A per-ray pointer into this
// table replaces six per-ray offsets: in the 8-wide loop g++ 12 kept those in stack slots anyway,
// loaded at every node, so the node test is unchanged and the ray setup saves their computation
// and stores (callgrind, dragon_100k primary 128x128: docs/PERFORMANCE.md, session 7). The 4-wide
// loop had kept them in registers and loaded them at every node through the pointer (+23% data
// reads, ~3% slower on primary rays: docs/PERFORMANCE.md, session 8), so mbvh4_single compiles
// its loop once per octant (mbvh_trace_rays' kPerOctant), where the rows are constants.
template <int N>
inline constexpr std::array<std::array<uint32_t, 6>, 8> kPlaneRows = octant_plane_rows(0, 3 * N, N);

// Per-ray constants of the N-wide box test: the kernel library's fused slab test (kernels.h,
// FusedPlanes: t = P * r + c, one fused multiply-add per plane, with c carrying a proven absolute
// error bound so near distances are lower and far ones upper bounds of the exact ones), and the
// rows of the near and far planes per axis (sign-selected slabs, Williams et al. 2005). `bound` is
// the tree's MBVH::coord_bound (>= |P| of every plane the test reads).
// It replaced Ize's (2013) subtract-and-multiply slab with a relative far pad: one instruction per
// plane instead of two, and a shorter path from a node's load to its children's distances (the
// loop waits on it at every node). Measured in docs/PERFORMANCE.md, session 13.
template <int N>
struct NodeRay {
  using f = typename simd::V<N>::f;
  f rx, ry, rz, cnx, cny, cnz, cfx, cfy, cfz, tmin;  // FusedPlanes' r, c_near, c_far per axis
  const uint32_t* rows;  // kPlaneRows<N> of the ray's octant
  uint32_t octant;       // bit a set: direction a negative
  NodeRay() = default;  // fields set by the caller (cwbvh_traverse.h's cw_full_ray)
  NodeRay(const RayCtx& rc, float t0, const float bound[3])
      : NodeRay(fused_planes(rc.org, rc.inv, bound), t0, rc.octant()) {}
  NodeRay(const FusedPlanes<4>& p, float t0, uint32_t oct) {
    alignas(16) float r[4], cn[4], cf[4];
    _mm_store_ps(r, p.r), _mm_store_ps(cn, p.cn), _mm_store_ps(cf, p.cf);
    *this = NodeRay(Vec3{r[0], r[1], r[2]}, Vec3{cn[0], cn[1], cn[2]}, Vec3{cf[0], cf[1], cf[2]}, t0, oct);
  }
  // From constants computed ahead (mbvh_stream::prepare does so for a whole stream).
  NodeRay(Vec3 r, Vec3 cn, Vec3 cf, float t0, uint32_t oct) {
    using S = simd::V<N>;
    rx = S::set1(r.x), ry = S::set1(r.y), rz = S::set1(r.z);
    cnx = S::set1(cn.x), cny = S::set1(cn.y), cnz = S::set1(cn.z);
    cfx = S::set1(cf.x), cfy = S::set1(cf.y), cfz = S::set1(cf.z);
    tmin = S::set1(t0);
    octant = oct;
    rows = kPlaneRows<N>[octant].data();
  }
};

// The ray octant a traversal loop is compiled for: kAnyOctant reads the plane rows through
// NodeRay::rows; 0..7 makes them constants of the loop (mbvh_trace_rays' kPerOctant).
inline constexpr int kAnyOctant = -1;

// Entry distances `tn` of the N children (lower bounds of the exact ones) and the lanes the ray
// enters before `tfar` (all-ones lanes; movemask gives the bits): the fused slab test on N lanes,
// one lane per child. As in the kernel library's slab, the new plane distance is max/min's first
// operand, so a NaN one (an axis left out) constrains nothing. Oct (0..7, the ray's octant) fixes
// the plane rows at compile time: every load then has a constant offset and folds into its fma.
template <int N, int Oct = kAnyOctant>
[[gnu::always_inline]] inline typename simd::V<N>::f box_test(const MBVHNode<N>& nd, const NodeRay<N>& r, float tfar,
                                                              typename simd::V<N>::f& tn_out) {
  using S = simd::V<N>;
  const float* b = &nd.box[0][0];
  const uint32_t* row = Oct == kAnyOctant ? r.rows : kPlaneRows<N>[Oct].data();
  typename S::f n = r.tmin, f = S::set1(tfar);
  // Unrolled by hand (each axis its own constants, no array): written as a loop, the profile-guided
  // build kept it a loop wherever the training did not make it the hottest code — mbvh_rs's stream
  // test and every parameter variant the training does not run (cwbvh_single:leaves=blocks) — with
  // the per-axis constants stored to a stack array at every node and read back. Unrolled, mbvh_rs
  // traced 1.04-1.13x faster (4 scenes, primary and bounce:2) and cwbvh_single:full_top=100:
  // leaves=blocks 1.13-1.23x on primary rays of sponza and spheres:2M (each against embree_single in
  // its process); the trained loops unchanged (docs/PERFORMANCE.md, session 40).
  const auto axis = [&](const typename S::f& rr, const typename S::f& cn, const typename S::f& cf, uint32_t near,
                        uint32_t far) __attribute__((always_inline)) {
    n = S::max(S::fma(S::load(b + near), rr, cn), n);
    f = S::min(S::fma(S::load(b + far), rr, cf), f);
  };
  axis(r.rx, r.cnx, r.cfx, row[0], row[3]);
  axis(r.ry, r.cny, r.cfy, row[1], row[4]);
  axis(r.rz, r.cnz, r.cfz, row[2], row[5]);
  tn_out = n;
  return S::le(n, f);
}

// Per-ray constants of the W-wide watertight test: RayCtx's shear, broadcast. An 8-wide one also
// serves the 4-wide blocks of small leaves through the low halves of its vectors (lanes_of): it
// used to carry a 4-wide copy, built for every ray whether or not a small leaf came (by default
// none does, small=0), and the origin was picked with Vec3's branching operator[]: ~45
// instructions of the per-ray setup (callgrind, mbvh8_single bounce:2, held-out-shaped scene:
// docs/PERFORMANCE.md, session 8).
template <int W>
struct TriRay {
  using f = typename simd::V<W>::f;
  f ox, oy, oz;  // origin, permuted (kx, ky, kz)
  f sx, sy, sz;
  Vec3 org, dir;
  float tmin, szs;
  uint32_t kx, ky, kz;
  TriRay() = default;
  TriRay(const RayCtx& rc, float t0) : TriRay(rc.org, rc.dir, rc.kx, rc.ky, rc.kz, rc.sx, rc.sy, rc.sz, t0) {}
  TriRay(Vec3 o, Vec3 d, int kx_, int ky_, int kz_, float sx_, float sy_, float sz_, float t0) {
    using S = simd::V<W>;
    kx = uint32_t(kx_), ky = uint32_t(ky_), kz = uint32_t(kz_);
    const float oa[3] = {o.x, o.y, o.z};
    ox = S::set1(oa[kx_]), oy = S::set1(oa[ky_]), oz = S::set1(oa[kz_]);
    sx = S::set1(sx_), sy = S::set1(sy_), sz = S::set1(sz_);
    org = o, dir = d, tmin = t0, szs = sz_;
  }
};
// The W lanes of a broadcast ray constant of a TriRay<RW> (RW >= W: every lane holds the same value).
template <int W, int RW>
[[gnu::always_inline]] inline typename simd::V<W>::f lanes_of(const typename simd::V<RW>::f& x) {
  if constexpr (W == RW) {
    return x;
  } else {
    static_assert(W == 4 && RW == 8);
    return _mm256_castps256_ps128(x);
  }
}

// The real triangles of block k of a leaf of ntris triangles in W-wide blocks (the last block pads
// with copies of the leaf's last triangle), and the low n bits set: those lanes.
template <int W>
constexpr uint32_t block_tris(uint32_t ntris, uint32_t k) { return std::min<uint32_t>(W, ntris - k * W); }
constexpr uint32_t lane_bits(uint32_t n) { return (1u << n) - 1; }

// Part (3) of the W-wide watertight test for the lanes `m` that passed parts (1)-(2) (usually none
// or one per block): exact_plane_distance's plane equation in double (plane_terms), the sheared
// distance only for a ray in the triangle's plane. vert(l, c) is lane l's corner c in double and
// prim(l) its scene triangle, however the block stores them (TriBlock, or the indexed CWTriBlock of
// structures/cwbvh.h). On a hit with tmin <= t < hit.t records the closest (the first lane on ties)
// and returns true.
template <int W, int RW, class Vert, class Prim>
[[gnu::always_inline]] inline bool block_candidates(const TriRay<RW>& r, int m, typename simd::V<W>::f U,
                                                    typename simd::V<W>::f Vv, typename simd::V<W>::f Ww,
                                                    typename simd::V<W>::f det, typename simd::V<W>::f Az,
                                                    typename simd::V<W>::f Bz, typename simd::V<W>::f Cz, Vert&& vert,
                                                    Prim&& prim, Hit& hit) {
  using S = simd::V<W>;
  alignas(32) float us[W], vs[W], ws[W], dets[W];
  S::store(us, U), S::store(vs, Vv), S::store(ws, Ww), S::store(dets, det);
  bool found = false;
  for (; m; m &= m - 1) {
    const int l = std::countr_zero(unsigned(m));
    // The ray's current closest hit again (a spatial-split tree references a big triangle from
    // every leaf it was split into, and the leaves along a ray repeat it): the same vertices
    // give the same t, which cannot be closer, so its double evaluation is skipped. Plain trees:
    // +-0.03% instructions; stadium with spatial=1: primary -3.7%, mispredictions -21% (callgrind).
    const uint32_t p = prim(l);
    if (p == hit.prim) continue;
    const Vec3D<double> v0 = vert(l, 0);
    double num, dn;
    plane_terms(plane_normal(v0, vert(l, 1), vert(l, 2)), v0, to_double(r.org), to_double(r.dir), num, dn);
    const float inv_det = 1.f / dets[l];
    float t;
    if (dn != 0.0) [[likely]] {
      t = float(num / dn);
    } else {
      alignas(32) float azs[W], bzs[W], czs[W];
      S::store(azs, Az), S::store(bzs, Bz), S::store(czs, Cz);
      t = sheared_distance<1>(r.szs, us[l], vs[l], ws[l], azs[l], bzs[l], czs[l], inv_det);
    }
    if (!(t >= r.tmin && t < hit.t)) continue;
    hit.t = t;
    hit.u = vs[l] * inv_det;
    hit.v = ws[l] * inv_det;
    hit.prim = p;
    found = true;
  }
  return found;
}

// The watertight test of the kernel library on W triangles at once (one ray, W lanes): the same
// float operations in the same order per lane as intersect_watertight, so its watertightness
// carries over. On a hit with tmin <= t < hit.t records the closest (the first lane on ties, as a
// scalar loop would) and returns true. `tris` counts the leaf's triangles from this block on (>= W:
// every lane is real): the last block of a leaf pads with copies of its last triangle, and a ray
// whose line crosses that triangle (one leaving it, say) would otherwise pay the double distance
// once per copy (issue 17). The padding lanes are masked only once some lane passes the edge
// test: most blocks are missed by every lane, and building the mask before the test cost ~3
// instructions per block (callgrind, mbvh4_single sponza primary: 1.0 M of 59.6 M).
// The ray's constants may come from a wider TriRay (RW = 8 for the 4-wide small-leaf blocks).
template <int W, int RW = W>
[[gnu::noinline]] inline bool block_intersect(const TriRay<RW>& r, const TriBlock<W>& b, Hit& hit, uint32_t tris) {
  using S = simd::V<W>;
  using f = typename S::f;
  const f ox = lanes_of<W, RW>(r.ox), oy = lanes_of<W, RW>(r.oy), oz = lanes_of<W, RW>(r.oz);
  const f sx = lanes_of<W, RW>(r.sx), sy = lanes_of<W, RW>(r.sy);
  const f Az = S::sub(S::load(b.v[0][r.kz]), oz);
  const f Bz = S::sub(S::load(b.v[1][r.kz]), oz);
  const f Cz = S::sub(S::load(b.v[2][r.kz]), oz);
  const f Ax = shear<W>(S::sub(S::load(b.v[0][r.kx]), ox), sx, Az);
  const f Ay = shear<W>(S::sub(S::load(b.v[0][r.ky]), oy), sy, Az);
  const f Bx = shear<W>(S::sub(S::load(b.v[1][r.kx]), ox), sx, Bz);
  const f By = shear<W>(S::sub(S::load(b.v[1][r.ky]), oy), sy, Bz);
  const f Cx = shear<W>(S::sub(S::load(b.v[2][r.kx]), ox), sx, Cz);
  const f Cy = shear<W>(S::sub(S::load(b.v[2][r.ky]), oy), sy, Cz);
  f U, Vv, Ww, det;
  int m = S::mask(watertight_inside<W>(Ax, Ay, Bx, By, Cx, Cy, U, Vv, Ww, det));
  if (!m) return false;
  // Without a branch: `if (tris < W)` mispredicted 0.33 times per bunny bounce:2 ray (callgrind);
  // branch-free, mbvh8_single +0.6 to +1.2% on bounce:2 of 5 of 6 scenes (session 21).
  m &= int(lane_bits(std::min<uint32_t>(tris, W)));
  return block_candidates<W>(
      r, m, U, Vv, Ww, det, Az, Bz, Cz,
      [&](int l, int c) { return Vec3D<double>{b.v[c][0][l], b.v[c][1][l], b.v[c][2][l]}; },
      [&](int l) { return b.prim[l]; }, hit);
}

// Tests the triangles of leaf `ref` in an array of W-wide blocks for one ray (a layout without
// small leaves: MBVH<4, 4>, RayGrid's mini-MBVHs). The watertight kernel runs on the SIMD blocks;
// the scalar kernels (moller, plane, plane_rcp) run kernels.h's tests lane by lane on `ts`.
template <int W, TriKernel K>
inline void leaf_test(const TriBlock<W>* blocks, const TriangleSet* ts, const TriRay<W>& tr, const RayCtx* rc,
                      uint32_t ref, Hit& hit) {
  const uint32_t first = mbvh_ref::first_block(ref), ntris = mbvh_ref::num_tris(ref);
  for (uint32_t k = 0; k * W < ntris; ++k) {
    if constexpr (K == TriKernel::watertight) {
      block_intersect<W>(tr, blocks[first + k], hit, ntris - k * W);
    } else {
      const uint32_t lanes = block_tris<W>(ntris, k);
      for (uint32_t l = 0; l < lanes; ++l) intersect_tri<K>(*rc, *ts, (first + k) * W + l, tr.tmin, hit);
    }
  }
}
// What a visit of leaf `ref` by `active` rays reads. A leaf has no record of its own (it lives
// in its parent's slot), so the visit itself reads nothing; each block is one read, tested
// against `active` rays (tests count real triangles, not padding lanes).
template <int W, class P>
inline void probe_leaf(const TriBlock<W>* blocks, uint32_t ref, P& probe, uint32_t active) {
  if constexpr (P::enabled) {
    const uint32_t first = mbvh_ref::first_block(ref), ntris = mbvh_ref::num_tris(ref);
    probe.leaf(&blocks[first], 0, active);
    for (uint32_t k = 0; k * W < ntris; ++k)
      probe.tris(&blocks[first + k], sizeof(TriBlock<W>), block_tris<W>(ntris, k) * active);
  }
}
// The same on an MBVH, whose small leaves (8-wide layout, <= 4 triangles) sit in 4-wide blocks.
template <int N, int W, TriKernel K>
inline void leaf_test(const MBVH<N, W>& m, const TriangleSet* ts, const TriRay<W>& tr, const RayCtx* rc, uint32_t ref,
                      Hit& hit) {
  const uint32_t first = mbvh_ref::first_block(ref), ntris = mbvh_ref::num_tris(ref);
  if constexpr (W == 8) {
    if (ntris <= m.small_leaf) {
      if constexpr (K == TriKernel::watertight) {
        block_intersect<4, W>(tr, m.small[first], hit, ntris);
      } else {
        for (uint32_t l = 0; l < ntris; ++l) intersect_tri<K>(*rc, *ts, m.small_lane(first, l), tr.tmin, hit);
      }
      return;
    }
  }
  leaf_test<W, K>(m.blocks.data(), ts, tr, rc, ref, hit);
}
template <int N, int W, class P>
inline void probe_leaf(const MBVH<N, W>& m, uint32_t ref, P& probe, uint32_t active) {
  if constexpr (P::enabled) {
    const uint32_t first = mbvh_ref::first_block(ref), ntris = mbvh_ref::num_tris(ref);
    if (ntris <= m.small_leaf) {
      probe.leaf(&m.small[first], 0, active);
      probe.tris(&m.small[first], sizeof(TriBlock<4>), ntris * active);
      return;
    }
    probe_leaf<W>(m.blocks.data(), ref, probe, active);
  }
}

// Starts fetching what `ref` names: an interior node, or a leaf's first triangle block (all five
// lines of an 8-wide one). prefetch_ref (below) skips leaves; mbvh8_packet's coherent path
// prefetches every child it pushes, the nearest included, with this: +1 to +3% against
// embree_packet8 on primary rays of the scanned models and the held-out-shaped scene, and the whole
// block instead of its first four lines +3% more on spheres:1000000 (interleaved, pinned runs;
// docs/PERFORMANCE.md, session 20). The one-ray loop measured no difference and keeps prefetch_ref.
template <int N, int W>
[[gnu::always_inline]] inline void prefetch_any(const MBVH<N, W>& m, uint32_t ref) {
  const char* p;
  size_t bytes;
  if (!mbvh_ref::is_leaf(ref)) {
    p = reinterpret_cast<const char*>(&m.nodes[ref]), bytes = sizeof(MBVHNode<N>);
  } else if (W == 8 && mbvh_ref::num_tris(ref) <= m.small_leaf) {
    p = reinterpret_cast<const char*>(&m.small[mbvh_ref::first_block(ref)]), bytes = sizeof(TriBlock<4>);
  } else {
    p = reinterpret_cast<const char*>(&m.blocks[mbvh_ref::first_block(ref)]), bytes = sizeof(TriBlock<W>);
  }
  for (size_t l = 0; l < bytes; l += 64) _mm_prefetch(p + l, _MM_HINT_T0);
}

// Starts fetching a node that goes onto the stack: single-ray traversal is bound by the latency
// of one dependent node fetch after another, and a pushed child is usually visited (it was
// entered before the closest hit known so far).
// Forced inline, as every function between a traversal and its prefetch (see enter_branching).
template <int N, int W>
[[gnu::always_inline]] inline void prefetch_ref(const MBVH<N, W>& m, uint32_t ref) {
  if (mbvh_ref::is_leaf(ref)) return;
  const char* p = reinterpret_cast<const char*>(&m.nodes[ref]);
  for (size_t l = 0; l < sizeof(MBVHNode<N>); l += 64) _mm_prefetch(p + l, _MM_HINT_T0);
}

// Starts fetching the four lines at `node` or, for a leaf, at `block`, the address chosen by a
// select instead of a branch (the stack top after a push is a node or a leaf unpredictably).
// Addresses as integers: the one not chosen may lie outside its array (a leaf's reference read as
// a node index), as may the lines past a small record, and none is formed as a pointer. ChildOrder::sort_prefetch, cwbvh_single's
// sorted batches.
[[gnu::always_inline]] inline void prefetch_node_or_block(uintptr_t node, uintptr_t block, bool leaf) {
  const uintptr_t a = leaf ? block : node;
  for (uintptr_t l = 0; l < 256; l += 64) _mm_prefetch(reinterpret_cast<const char*>(a + l), _MM_HINT_T0);
}
// The same for the MBVH reference `ref`: a node, or a leaf's first block. A leaf of the `small`
// array fetches the lines of the `blocks` entry with its index instead: harmless, and small
// leaves are off by default.
template <int N, int W>
[[gnu::always_inline]] inline void prefetch_top(const MBVH<N, W>& m, uint32_t ref) {
  prefetch_node_or_block(reinterpret_cast<uintptr_t>(m.nodes.data()) + uintptr_t(ref & ~mbvh_ref::kLeaf) * sizeof(MBVHNode<N>),
                         reinterpret_cast<uintptr_t>(m.blocks.data()) +
                             uintptr_t(mbvh_ref::first_block(ref)) * sizeof(TriBlock<W>),
                         mbvh_ref::is_leaf(ref));
}

struct MBVHStackEntry {
  uint32_t ref;
  float dist;  // entry distance: popped entries at or beyond the closest hit are skipped
};
// The entries a stack of mbvh_traverse_from (or cw_traverse_from) is given on an N-wide tree whose
// deepest leaf is at `max_depth` (root = 1): at most (N-1) pending per level, plus room for
// push_sorted's whole-vector store of N entries past the top (see mbvh_traverse_from).
constexpr size_t mbvh_stack_entries(int n, uint32_t max_depth) { return size_t(n - 1) * max_depth + n + 2; }

// Pops the nearest pending child that may still hold a closer hit than `tfar` into `cur`
// (entries beyond it are dropped); false when the stack runs empty.
template <class P>
inline bool pop_pending(const MBVHStackEntry* stack, uint32_t& sp, float tfar, uint32_t& cur, P& probe) {
  for (;;) {
    if (sp == 0) return false;
    --sp;
    probe.read(&stack[sp], sizeof(MBVHStackEntry));
    if (stack[sp].dist < tfar) break;
  }
  cur = stack[sp].ref;
  return true;
}


// Writes the 8 stack entries (refs[idx[j]], tn[idx[j]]) to out[0..7]: the children in the order
// idx gives, with their entry distances (push_sorted8; cwbvh_single's octant order).
inline void push_in_order8(__m256i refs, __m256 tn, __m256i idx, MBVHStackEntry* out) {
  const __m256i sorted = _mm256_permutevar8x32_epi32(refs, idx);
  const __m256i dist = _mm256_permutevar8x32_epi32(_mm256_castps_si256(tn), idx);
  const __m256i lo = _mm256_unpacklo_epi32(sorted, dist), hi = _mm256_unpackhi_epi32(sorted, dist);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(out), _mm256_permute2x128_si256(lo, hi, 0x20));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(out) + 1, _mm256_permute2x128_si256(lo, hi, 0x31));
}

// The 8-wide case of push_sorted on the 8 child references `refs` (the compressed layout of
// cwbvh_single decodes its references instead of storing them).
// `second` (when given) receives the second-nearest child's reference, taken from registers: a
// 4-byte load of the entry just stored by the 32-byte stores would wait for store forwarding. With
// one entered child it is a non-entered slot's reference (never visited; fetching it is harmless).
inline uint32_t push_sorted8(__m256i refs, __m256 tn, __m256 entered, int count, MBVHStackEntry* out,
                             uint32_t* second = nullptr) {
  const __m256i keys = mbvh_simd::sort8(mbvh_simd::sort_keys8(tn, entered));
  const __m256i rev = _mm256_sub_epi32(_mm256_set1_epi32(count - 1), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  push_in_order8(refs, tn, _mm256_and_si256(_mm256_permutevar8x32_epi32(keys, rev), _mm256_set1_epi32(7)), out);
  const __m256i order = _mm256_permutevar8x32_epi32(refs, _mm256_and_si256(keys, _mm256_set1_epi32(7)));
  if (second) *second = uint32_t(_mm256_extract_epi32(order, 1));
  return uint32_t(_mm256_cvtsi256_si32(order));
}

// Sorts the `count` (>= 3) entered children near-to-far and writes all but the nearest to
// out[0 .. count-2], farthest first (so the second nearest ends on top); returns the nearest.
// Writes N entries (see mbvh_traverse for why the stack always has room for them).
template <int N>
inline uint32_t push_sorted(const MBVHNode<N>& nd, typename simd::V<N>::f tn, typename simd::V<N>::f entered,
                            int count, MBVHStackEntry* out, uint32_t* second = nullptr) {
  if constexpr (N == 4) {
    const __m128i keys = mbvh_simd::sort4(mbvh_simd::sort_keys4(tn, entered));
    // Position j takes sorted entry count-1-j.
    const __m128i rev = _mm_sub_epi32(_mm_set1_epi32(count - 1), _mm_setr_epi32(0, 1, 2, 3));
    const __m128i idx = _mm_and_si128(
        _mm_castps_si128(_mm_permutevar_ps(_mm_castsi128_ps(keys), _mm_and_si128(rev, _mm_set1_epi32(3)))),
        _mm_set1_epi32(3));
    const __m128i refs = _mm_castps_si128(
        _mm_permutevar_ps(_mm_castsi128_ps(_mm_load_si128(reinterpret_cast<const __m128i*>(nd.ref))), idx));
    const __m128i dist = _mm_castps_si128(_mm_permutevar_ps(tn, idx));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm_unpacklo_epi32(refs, dist));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out) + 1, _mm_unpackhi_epi32(refs, dist));
    return nd.ref[uint32_t(_mm_cvtsi128_si32(keys)) & 3];
  } else {
    return push_sorted8(_mm256_load_si256(reinterpret_cast<const __m256i*>(nd.ref)), tn, entered, count, out, second);
  }
}

// The smallest of 8 sort keys (mbvh_simd::sort_keys8: distance bits with the child index in the
// low 3 bits; misses are the largest key): three shuffle + min steps.
inline __m256i min_keys8(__m256i k) {
  k = _mm256_min_epi32(k, _mm256_permute2x128_si256(k, k, 0x01));
  k = _mm256_min_epi32(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(1, 0, 3, 2)));
  return _mm256_min_epi32(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(2, 3, 0, 1)));
}
// The reference of the child with the smallest key: a permute of the references by the key
// (vpermd reads its low 3 bits, the child index) instead of a move to a scalar register, a mask
// and a load. The single-ray loop is bound by the chain from a node's planes to its nearest
// child's address (perf: the samples sit on the node and block loads and on the key reduction,
// and a 9% cut in instructions that lengthened the chain at pops made bounce rays 4-13% slower),
// so cycles on that chain count, not instructions: with sort_keys8's and/or taken off it too,
// mbvh8_single +2 to +5% on bounce:2 (docs/PERFORMANCE.md, session 26).
inline uint32_t nearest_ref8(__m256i refs, __m256i keys) {
  return uint32_t(_mm256_cvtsi256_si32(_mm256_permutevar8x32_epi32(refs, min_keys8(keys))));
}
// The same on an MBVH8 node: the entered child (`entered`, entry distances `tn`) to visit first.
inline uint32_t nearest_child8(const MBVHNode<8>& nd, __m256 tn, __m256 entered) {
  return nearest_ref8(_mm256_load_si256(reinterpret_cast<const __m256i*>(nd.ref)), mbvh_simd::sort_keys8(tn, entered));
}

// How mbvh_traverse orders the entered children of a node (a template parameter of the one loop,
// as madmann91/bvh v2 makes its variants, rather than a copy of the loop per variant).
//  branching: one hit child is entered directly, two are compared, three or more are sorted with
//    the branch-free network (Alg. 2.10 for N = 4, bitonic for N = 8).
//  sort_always (N = 8): every node with an entered child takes the same path: the bitonic network
//    sorts the keys and pushes all but the nearest (push_sorted; with one child it pushes nothing),
//    and the nearest comes from a three-step min reduction of the unsorted keys (nearest_ref8), so the
//    next node's address does not wait for the whole network. With 8 children the count varies
//    from node to node and the branches of `branching`, plus the data-dependent compare of its
//    two-child case, mispredict often. Measured on bounce:2 (512x512, 7 reps, median, ratio to
//    embree_single): +4 to +13% over `branching` for mbvh8_single (8-wide blocks, watertight) on
//    the nine scenes of /work/shared/scenes (docs/PERFORMANCE.md). The "sort always" child
//    ordering discussed by Wald et al. (2008) and Ernst & Greiner (2008) for 4-wide nodes, with the
//    keys of thesis Alg. 2.10. On coherent (primary) rays `branching` is the faster one: its
//    branches predict well there and the next node's address waits for no key reduction
//    (mbvh8_single's `order=auto` picks per batch; docs/PERFORMANCE.md, session 8).
//  sort_prefetch (N = 8): sort_always, and after each push it starts fetching the new stack top (the
//    second-nearest entered child: prefetch_top). That child is visited after the nearest one's
//    subtree, so the fetch pays only where that subtree's visit does not evict it and the node
//    would otherwise come from memory: trees larger than the last-level cache. Measured on
//    bounce:2, on / off (docs/PERFORMANCE.md, session 22): spheres:500000 to 2000000 (33-132 MiB)
//    +5 to +11%, but 0.91-0.99 on the scenes whose trees stay cached (sibenik and dragon_100k
//    0.96, stadium 0.91); mbvh8_single's and cwbvh_single's `prefetch` parameter chooses it by the
//    structure's bytes. (Session 21's form read the reference back from the stack entry just
//    stored, a store-forwarding stall: 9-12% slower on cached scenes, no gain anywhere.)
enum class ChildOrder { branching, sort_always, sort_prefetch };
constexpr bool sorts_always(ChildOrder o) { return o != ChildOrder::branching; }

// The `order` parameter of mbvh8_single and cwbvh_single, parsed once when the scheme is made (the
// registry has already refused any other value): a fixed order, `auto` (branching for
// common-origin batches, sort_always otherwise: why, above), or cwbvh_single's `octant`.
enum class OrderParam { branching, sort, automatic, octant };
inline OrderParam parse_order_param(const std::string& v) {
  if (v == "branching") return OrderParam::branching;
  if (v == "sort") return OrderParam::sort;
  if (v == "auto") return OrderParam::automatic;
  if (v == "octant") return OrderParam::octant;
  throw InputError("order: unknown child order '" + v + "'");
}
// Whether a batch is traversed with ChildOrder::sort_always under `o`.
inline bool sorts_batch(OrderParam o, const RayBatch& batch) {
  return o == OrderParam::sort || (o == OrderParam::automatic && !batch.common_origin);
}

// ChildOrder::branching on the entered children `mask` (nonzero) of an N-wide node with entry
// distances tn: returns the child to enter and pushes the others far-to-near onto stack[sp..]
// (sp advanced). ref(i) is child i's reference, prefetch(ref) starts fetching a pushed child,
// sorted(count, out) is push_sorted on the node (returns the nearest). Shared by mbvh_traverse and
// cwbvh_single, whose nodes form their references differently.
// A `prefetch` lambda must be forced inline (__attribute__((always_inline)) after its parameters),
// and so must every function it calls on the way to _mm_prefetch: GCC 12 counts __builtin_prefetch
// as no side effect, so its local pure-const pass finds a function that only prefetches "looping
// pure", and a call of a pure function that returns nothing is dead code and deleted. Until
// session 35 the branching order of mbvh8_single and cwbvh_single had no prefetch in their
// compiled code for that reason (mbvh4_single kept its own, where the node array's operator[]
// stayed a call); restored, primary rays moved within the noise (2 alternating pairs of processes
// on five scenes, docs/PERFORMANCE.md, session 35).
template <int N, class Ref, class Prefetch, class Sorted, class P>
[[gnu::always_inline]] inline uint32_t enter_branching(int mask, typename simd::V<N>::f tn, Ref&& ref,
                                                       Prefetch&& prefetch, Sorted&& sorted, MBVHStackEntry* stack,
                                                       uint32_t& sp, P& probe) {
  using S = simd::V<N>;
  uint32_t c0 = uint32_t(std::countr_zero(unsigned(mask)));
  const int rest = mask & (mask - 1);
  if (!rest) return ref(c0);
  if (!(rest & (rest - 1))) {
    uint32_t c1 = uint32_t(std::countr_zero(unsigned(rest)));
    float d0 = S::lane(tn, c0), d1 = S::lane(tn, c1);
    if (d1 < d0) std::swap(c0, c1), std::swap(d0, d1);
    const uint32_t far = ref(c1);
    prefetch(far);
    stack[sp] = {far, d1};
    probe.write(&stack[sp], sizeof(MBVHStackEntry));
    ++sp;
    return ref(c0);
  }
  // Three or more: sort branch-free (keys carry the child index in their low bits) and push the
  // entries far-to-near with whole-vector stores; enter the nearest.
  const int count = std::popcount(unsigned(mask));
  const uint32_t nearest = sorted(count, stack + sp);
  if constexpr (P::enabled) {
    for (int j = 0; j < count - 1; ++j) probe.write(&stack[sp + j], sizeof(MBVHStackEntry));
  }
  sp += uint32_t(count - 1);
  return nearest;
}

// Where a suspended traversal resumes: the reference it visits next and its pending-stack depth.
struct MBVHCursor {
  uint32_t cur = 0, sp = 0;
};
// The suspension test of a traversal that never suspends (compiles away).
struct NeverLeave {
  constexpr bool operator()(uint32_t) const { return false; }
};

// Ordered single-ray traversal (thesis Alg. 2.8 with front-to-back order): the N children are
// tested at once, the entered ones ordered as `O` says; the nearest is entered and the others are
// pushed far-to-near with their entry distances. Runs from `at` (the root or a subtree with an
// empty stack when it starts; mbvh_rs falls back to one ray at a subtree); `stack` must hold
// (N-1)*max_depth+1 entries (at depth d at most (N-1)*(d-1) are pending, so push_sorted's N-entry
// store stays inside). Before each visit `leave(ref)` may suspend the ray: `at` then holds the
// reference it was about to visit and its stack depth, and the call returns false; resumed with
// the same `at`, stack and hit it visits exactly what an unsuspended traversal would
// (treelet_queue suspends at treelet boundaries; everyone else passes NeverLeave). True: done.
// Not forced inline: forced into mbvh_trace_rays' per-ray loop, GCC 12 keeps the node test's plane
// offsets and the ray origin in memory and reloads them at every node (42 instead of 32
// instructions per node test). Callgrind, sponza primary 128x128, instructions of the timed trace,
// forced -> left to GCC (which keeps it a function of its own): mbvh4_single 63.96 M -> 59.56 M,
// mbvh8_single 57.07 M -> 54.24 M, treelet_queue 114.5 M -> 100.0 M; raygrid 67.3 M -> 69.8 M,
// mbvh_rs unchanged. Wrapping the forced loop in a noinline function instead measured in between
// (61.2-61.5 M for mbvh4_single): register allocation, not the call, decides it.
template <int N, int W, TriKernel K, ChildOrder O = ChildOrder::branching, int Oct = kAnyOctant, class P, class Leave>
inline bool mbvh_traverse_from(const MBVH<N, W>& m, const TriangleSet* ts, const NodeRay<N>& nr, const TriRay<W>& tr,
                               const RayCtx* rc, MBVHCursor& at, Hit& hit, MBVHStackEntry* stack, P& probe,
                               Leave&& leave) {
  using S = simd::V<N>;
  const MBVHNode<N>* nodes = m.nodes.data();
  uint32_t sp = at.sp, cur = at.cur;
  float tfar = hit.t;  // a register copy: stack stores could alias hit.t and force reloads
  for (;;) {
    if (leave(cur)) {
      at = {cur, sp};
      return false;
    }
    if (!mbvh_ref::is_leaf(cur)) {
      const MBVHNode<N>& nd = nodes[cur];
      probe.node(&nd, sizeof(nd));
      typename S::f tn;
      const auto entered = box_test<N, Oct>(nd, nr, tfar, tn);
      int mask = S::mask(entered);
      if constexpr (sorts_always(O)) {
        static_assert(N == 8, "sort_always needs the 8-wide key reduction");
        if (mask) {
          const int count = std::popcount(unsigned(mask));
          if constexpr (O == ChildOrder::sort_prefetch) {
            uint32_t second;
            push_sorted<N>(nd, tn, entered, count, stack + sp, &second);
            prefetch_top(m, second);
          } else {
            push_sorted<N>(nd, tn, entered, count, stack + sp);
          }
          if constexpr (P::enabled) {
            for (int j = 0; j < count - 1; ++j) probe.write(&stack[sp + j], sizeof(MBVHStackEntry));
          }
          cur = nearest_child8(nd, tn, entered);
          sp += uint32_t(count - 1);
          continue;
        }
      } else if (mask) {
        cur = enter_branching<N>(
            mask, tn, [&](uint32_t i) { return nd.ref[i]; },
            [&](uint32_t ref) __attribute__((always_inline)) { prefetch_ref(m, ref); },  // inline: enter_branching
            [&](int count, MBVHStackEntry* out) {
              const uint32_t first = push_sorted<N>(nd, tn, entered, count, out);
              // N = 8: the nearest by the min reduction beside the network, not after it.
              if constexpr (N == 8) return nearest_child8(nd, tn, entered);
              else return first;
            },
            stack, sp, probe);
        continue;
      }
    } else {
      probe_leaf(m, cur, probe, 1);
      leaf_test<N, W, K>(m, ts, tr, rc, cur, hit);
      tfar = hit.t;
    }
    if (!pop_pending(stack, sp, tfar, cur, probe)) return true;
  }
}
template <int N, int W, TriKernel K, ChildOrder O = ChildOrder::branching, int Oct = kAnyOctant, class P>
inline void mbvh_traverse(const MBVH<N, W>& m, const TriangleSet* ts, const NodeRay<N>& nr, const TriRay<W>& tr,
                          const RayCtx* rc, uint32_t start, Hit& hit, MBVHStackEntry* stack, P& probe) {
  MBVHCursor at{start, 0};
  mbvh_traverse_from<N, W, K, O, Oct>(m, ts, nr, tr, rc, at, hit, stack, probe, NeverLeave{});
}

// Calls f(std::integral_constant<int, octant>{}): a runtime octant (0..7) as a template argument.
template <class F>
[[gnu::always_inline]] inline void with_octant(uint32_t octant, F&& f) {
  [&]<int... O>(std::integer_sequence<int, O...>) {
    (void)((octant == uint32_t(O) && (f(std::integral_constant<int, O>{}), true)) || ...);
  }(std::make_integer_sequence<int, 8>{});
}

// Single-ray traversal of the rays of `range` (mbvh4_single, mbvh8_single): the timed loop.
// kPerOctant compiles the traversal loop once per ray octant, so the node test's plane rows are
// constants (box_test's Oct) instead of six loads per node through NodeRay::rows: in the 4-wide
// loop g++ 12 cannot keep six per-ray offsets in registers (OLD 984423f did, with fewer live
// values; session 8 measured +23% data reads and ~3% slower primary rays without them). Callgrind,
// 128x128, mbvh4_single on conference: primary 30.99 M -> 30.09 M instructions (data reads +6.6%
// of OLD's instead of +23%), bounce:2 38.8 M (OLD 40.7 M). Not for mbvh8_single: its eight
// copies measured more instructions and stores (sponza bounce:2 45.8 M -> 51.0 M, primary
// 42.3 M -> 43.7 M; conference alike), so it keeps kPerOctant = false.
template <int N, int W, TriKernel K, ChildOrder O = ChildOrder::branching, bool kPerOctant = false, class P>
void mbvh_trace_rays(const MBVHData<N, W>& d, const RayBatch& batch, PacketRange range, std::span<Hit> hits,
                     P& probe) {
  const MBVH<N, W>& m = *d.mbvh;
  std::vector<MBVHStackEntry> stack(mbvh_stack_entries(N, m.stats.max_depth));
  const RayCtx::ShearAxes axes = RayCtx::axes_for(batch.common_origin);
  for_each_ray(batch, range, hits, probe, [&](const Ray& ray, Hit& hit) {
    const RayCtx rc(ray, axes);
    const NodeRay<N> nr(rc, ray.tmin, m.coord_bound);
    const TriRay<W> tr(rc, ray.tmin);
    if constexpr (kPerOctant) {
      with_octant(nr.octant, [&](auto oct) {
        mbvh_traverse<N, W, K, O, decltype(oct)::value>(m, d.tris.get(), nr, tr, &rc, 0, hit, stack.data(), probe);
      });
    } else {
      mbvh_traverse<N, W, K, O>(m, d.tris.get(), nr, tr, &rc, 0, hit, stack.data(), probe);
    }
  });
}

}  // namespace tb
