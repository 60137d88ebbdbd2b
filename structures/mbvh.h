// Multi-branching BVHs (MBVH, "QBVH"; thesis §2.2 "MBVH traversal" and ch. 5 baseline): N = 4 or 8
// children per node, collapsed from the binary binned-SAH BVH (Dammertz et al. 2008, Wald et al.
// 2008), with the N child boxes stored SoA so that one node test is one SIMD operation per slab.
//
// This header holds the layout, its builder, and the SIMD primitives that read the layout (node
// test, triangle-block test, ordered single-ray traversal). They live together on purpose: the
// primitives are the layout's only readers, and mbvh4_single, mbvh8_single and mbvh_rs (whose
// one-ray fallback is the same loop, thesis §2.2 / Tsakok 2009) all share them.
//
// Robustness is that of traversal/kernels.h: the box test keeps box_entry's semantics exactly
// (sign-selected slabs, NaN slabs ignored, Ize far padding), and the SIMD triangle test is the
// watertight test of Woop, Benthin and Wald (2013) lane by lane — the same float operations in
// the same order, so shared edges give exactly negated edge functions (-ffp-contract=off).
#pragma once
#include <immintrin.h>

#include <bit>
#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "structures/aligned.h"
#include "structures/bvh.h"
#include "structures/scene.h"
#include "structures/structure_cache.h"
#include "traversal/bvh_common.h"
#include "traversal/kernels.h"
#include "traversal/probe.h"
#include "traversal/traverser.h"

namespace tb {

// ---------------------------------------------------------------------------------------------
// Layout

// A child reference is one 32-bit word: an interior child is its node index; a leaf has the top
// bit set, its first triangle block in bits 30..6 and its triangle count minus one in bits 5..0.
// Keeping the leaf inside the parent's slot saves a node fetch per leaf visit.
namespace mbvh_ref {
inline constexpr uint32_t kLeaf = 0x80000000u;
inline constexpr uint32_t kMaxLeafTris = 64;
inline constexpr uint32_t kMaxBlocks = 1u << 25;
constexpr bool is_leaf(uint32_t r) { return (r & kLeaf) != 0; }
constexpr uint32_t make_leaf(uint32_t first_block, uint32_t ntris) { return kLeaf | first_block << 6 | (ntris - 1); }
constexpr uint32_t first_block(uint32_t r) { return (r >> 6) & (kMaxBlocks - 1); }
constexpr uint32_t num_tris(uint32_t r) { return (r & 63u) + 1; }
}  // namespace mbvh_ref

// N child boxes SoA: box[0..2] = lo x,y,z, box[3..5] = hi x,y,z, N floats each. Valid children
// come first; unused slots hold an empty box (lo = +inf, hi = -inf) that no ray enters, so the
// traversal needs no validity mask. 128 bytes (N = 4) or 256 bytes (N = 8): whole cache lines.
template <int N>
struct alignas(64) MBVHNode {
  float box[6][N];
  uint32_t ref[N];
  uint32_t num_children;
  AABB child_box(int i) const { return {{box[0][i], box[1][i], box[2][i]}, {box[3][i], box[4][i], box[5][i]}}; }
};
static_assert(sizeof(MBVHNode<4>) == 128 && sizeof(MBVHNode<8>) == 256);

// W triangles SoA for the SIMD watertight test (v[corner][axis][lane]) and their scene indices:
// 40 bytes per triangle. Nothing else is precomputed: the watertight decision must come from
// the vertices themselves (shared edges give exactly negated edge functions), and the hit
// distance of the rare candidate that passes it is computed in double from the vertices (as in
// intersect_watertight). A leaf's last block is padded with copies of its last triangle, so
// every lane is a real triangle: no mask, and a duplicate can never report a different hit.
template <int W>
struct alignas(W * 4) TriBlock {
  float v[3][3][W];
  uint32_t prim[W];
};
static_assert(sizeof(TriBlock<4>) == 160 && sizeof(TriBlock<8>) == 320);

struct MBVHBuildParams {
  BVHBuildParams bvh;  // the binary BVH that is collapsed
  // Binary subtrees with at most `merge` triangles become one leaf (one or two SIMD blocks instead
  // of a node visit and several partly filled blocks); 0 disables merging. With the SAH collapse,
  // the largest leaf it may form.
  int merge = 0;
  // false: greedy collapse (open the largest child until N). true: the SAH-optimal collapse by
  // dynamic programming over the binary tree (Ylitie, Karras, Laine 2017, §3.2): every binary
  // subtree becomes a leaf, a node, or is dissolved into up to N slots, whichever minimises
  // sum(area * node cost) + sum(area * block tests * tri_cost / 100).
  bool sah_collapse = false;
  int tri_cost = 100;  // cost of one triangle-block test in percent of a node visit
  // 8-wide blocks: leaves of up to `small` triangles (0 or 4) take a 4-wide block instead.
  int small = 4;
  std::string key(int width, int tri_width) const;
};

struct MBVHStats {
  uint32_t width = 0, tri_width = 0;
  uint32_t nodes = 0, leaves = 0, blocks = 0, triangles = 0, max_depth = 0;
  double avg_children = 0, avg_leaf_tris = 0, lane_fill = 0;  // lane_fill: real triangles / block lanes
  double sah_cost = 0, bvh_build_ms = 0, collapse_ms = 0;
  size_t node_bytes = 0, tri_bytes = 0;
  std::string describe() const;
};

template <int N, int W>
struct MBVH {
  static constexpr int kWidth = N, kTriWidth = W;
  using Node = MBVHNode<N>;
  using Block = TriBlock<W>;
  aligned_vector<Node> nodes;    // nodes[0] = root (always an interior node, possibly with 0 or 1 child)
  aligned_vector<Block> blocks;  // leaf triangles in depth-first leaf order
  // With 8-wide blocks, leaves of at most 4 triangles take one 4-wide block here instead (the
  // leaf's triangle count says which array): half the bytes of a mostly empty 8-wide block.
  aligned_vector<TriBlock<4>> small;
  uint32_t small_leaf = 0;  // leaves of at most this many triangles are small (0 or 4; 0 when W = 4)
  MBVHStats stats;

  // Collapses the binary BVH (whose subtrees hold contiguous ranges of prim_index). Greedy
  // (Dammertz et al. 2008, the thesis' construction): start from the binary node's two children
  // and repeatedly open the interior child with the largest surface area until there are N.
  // SAH (params.sah_collapse): the dynamic programme described at MBVHBuildParams.
  static MBVH collapse(const Scene& scene, const BVH& bvh, const MBVHBuildParams& params);
  // Scene triangle of every block lane (block * W + lane, then the small blocks' lanes): the
  // order of the TriangleSet the scalar kernels (--kernel moller/plane/plane_rcp) index.
  std::vector<uint32_t> lane_prims() const;
  uint32_t small_lane(uint32_t block, uint32_t lane) const { return uint32_t(blocks.size()) * W + block * 4 + lane; }
};
extern template struct MBVH<4, 4>;
extern template struct MBVH<8, 4>;
extern template struct MBVH<8, 8>;

// The structure and, for the scalar kernels, their triangle set in lane order.
template <int N, int W>
struct MBVHData {
  std::shared_ptr<const MBVH<N, W>> mbvh;
  std::shared_ptr<const TriangleSet> tris;  // null for the watertight kernel (it reads the blocks)
};
// Nodes + triangle blocks (+ the scalar kernels' triangle set when one is used).
template <int N, int W>
size_t mbvh_bytes(const MBVHData<N, W>& d, TriKernel k) {
  return d.mbvh->stats.node_bytes + d.mbvh->stats.tri_bytes +
         (d.tris ? d.tris->size() * (TriangleSet::bytes(k) + sizeof(uint32_t)) : 0);
}
// mbvh_params and fetch_mbvh (a scheme's config -> MBVHBuildParams; the cached MBVH) live in
// traversal/mbvh_fetch.h.

// ---------------------------------------------------------------------------------------------
// SIMD primitives

namespace mbvh_simd {

template <int W>
struct V;
template <>
struct V<4> {
  using f = __m128;
  using i = __m128i;
  static f load(const float* p) { return _mm_load_ps(p); }
  static f set1(float x) { return _mm_set1_ps(x); }
  static f add(f a, f b) { return _mm_add_ps(a, b); }
  static f sub(f a, f b) { return _mm_sub_ps(a, b); }
  static f mul(f a, f b) { return _mm_mul_ps(a, b); }
  static f div(f a, f b) { return _mm_div_ps(a, b); }
  static f min(f a, f b) { return _mm_min_ps(a, b); }
  static f max(f a, f b) { return _mm_max_ps(a, b); }
  static f and_(f a, f b) { return _mm_and_ps(a, b); }
  static f or_(f a, f b) { return _mm_or_ps(a, b); }
  static f andnot(f a, f b) { return _mm_andnot_ps(a, b); }  // ~a & b
  static f blendv(f a, f b, f m) { return _mm_blendv_ps(a, b, m); }
  static f lt(f a, f b) { return _mm_cmplt_ps(a, b); }
  static f le(f a, f b) { return _mm_cmple_ps(a, b); }
  static f gt(f a, f b) { return _mm_cmpgt_ps(a, b); }
  static f ge(f a, f b) { return _mm_cmpge_ps(a, b); }
  static f eq(f a, f b) { return _mm_cmpeq_ps(a, b); }
  static f neq(f a, f b) { return _mm_cmpneq_ps(a, b); }
  static f zero() { return _mm_setzero_ps(); }
  static f abs(f a) { return _mm_andnot_ps(_mm_set1_ps(-0.f), a); }
  static int mask(f a) { return _mm_movemask_ps(a); }
  static void store(float* p, f a) { _mm_store_ps(p, a); }
  static float hmin(f a) {
    a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
    a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2)));
    return _mm_cvtss_f32(a);
  }
};
template <>
struct V<8> {
  using f = __m256;
  using i = __m256i;
  static f load(const float* p) { return _mm256_load_ps(p); }
  static f set1(float x) { return _mm256_set1_ps(x); }
  static f add(f a, f b) { return _mm256_add_ps(a, b); }
  static f sub(f a, f b) { return _mm256_sub_ps(a, b); }
  static f mul(f a, f b) { return _mm256_mul_ps(a, b); }
  static f div(f a, f b) { return _mm256_div_ps(a, b); }
  static f min(f a, f b) { return _mm256_min_ps(a, b); }
  static f max(f a, f b) { return _mm256_max_ps(a, b); }
  static f and_(f a, f b) { return _mm256_and_ps(a, b); }
  static f or_(f a, f b) { return _mm256_or_ps(a, b); }
  static f andnot(f a, f b) { return _mm256_andnot_ps(a, b); }
  static f blendv(f a, f b, f m) { return _mm256_blendv_ps(a, b, m); }
  static f lt(f a, f b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
  static f le(f a, f b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
  static f gt(f a, f b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
  static f ge(f a, f b) { return _mm256_cmp_ps(a, b, _CMP_GE_OQ); }
  static f eq(f a, f b) { return _mm256_cmp_ps(a, b, _CMP_EQ_OQ); }
  static f neq(f a, f b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_UQ); }
  static f zero() { return _mm256_setzero_ps(); }
  static f abs(f a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.f), a); }
  static int mask(f a) { return _mm256_movemask_ps(a); }
  static void store(float* p, f a) { _mm256_store_ps(p, a); }
  static float hmin(f a) {
    __m128 m = _mm_min_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1));
    return V<4>::hmin(m);
  }
};

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
inline __m256i sort_keys8(__m256 dist, __m256 hit) {
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  __m256i k = _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF)), dist, hit));
  return _mm256_or_si256(_mm256_and_si256(k, _mm256_set1_epi32(~7)), lane);
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

// Per-ray constants of the N-wide box test: origin, reciprocal direction, the reciprocal padded
// for far planes (Ize 2013: the pad multiplies the reciprocal; the rounding count — subtract,
// reciprocal, pad, multiply — is the same as box_entry's, so the same bound holds), and the rows
// of the near and far planes per axis (sign-selected slabs, Williams et al. 2005).
template <int N>
struct NodeRay {
  using f = typename mbvh_simd::V<N>::f;
  f ox, oy, oz, ix, iy, iz, fx, fy, fz, tmin;
  uint32_t near[3], far[3];  // float offsets into MBVHNode::box
  NodeRay(const RayCtx& rc, float t0) { init(rc.org, rc.inv, t0); }
  NodeRay(Vec3 org, Vec3 inv, float t0) { init(org, inv, t0); }
  void init(Vec3 org, Vec3 inv, float t0) {
    using S = mbvh_simd::V<N>;
    ox = S::set1(org.x), oy = S::set1(org.y), oz = S::set1(org.z);
    ix = S::set1(inv.x), iy = S::set1(inv.y), iz = S::set1(inv.z);
    fx = S::set1(inv.x * kFarPad), fy = S::set1(inv.y * kFarPad), fz = S::set1(inv.z * kFarPad);
    tmin = S::set1(t0);
    for (int a = 0; a < 3; ++a) {
      const bool neg = std::signbit(inv[a]);
      near[a] = uint32_t(((neg ? 3 : 0) + a) * N);
      far[a] = uint32_t(((neg ? 0 : 3) + a) * N);
    }
  }
};

// Entry distances `tn` of the N children and the lanes the ray enters before `tfar` (all-ones
// lanes; movemask gives the bits): box_entry of kernels.h, N children at once. minps/maxps return
// their second operand when either is NaN, so the new slab value goes first and the running
// bound second: a NaN slab (origin on the plane of an axis-parallel ray, (plane - org) * inf)
// leaves the bound unchanged, exactly as std::max/std::min do in box_entry.
template <int N>
inline typename mbvh_simd::V<N>::f box_test(const MBVHNode<N>& nd, const NodeRay<N>& r, float tfar,
                                            typename mbvh_simd::V<N>::f& tn_out) {
  using S = mbvh_simd::V<N>;
  const float* b = &nd.box[0][0];
  const auto tnx = S::mul(S::sub(S::load(b + r.near[0]), r.ox), r.ix);
  const auto tny = S::mul(S::sub(S::load(b + r.near[1]), r.oy), r.iy);
  const auto tnz = S::mul(S::sub(S::load(b + r.near[2]), r.oz), r.iz);
  const auto tfx = S::mul(S::sub(S::load(b + r.far[0]), r.ox), r.fx);
  const auto tfy = S::mul(S::sub(S::load(b + r.far[1]), r.oy), r.fy);
  const auto tfz = S::mul(S::sub(S::load(b + r.far[2]), r.oz), r.fz);
  const auto tn = S::max(tnz, S::max(tny, S::max(tnx, r.tmin)));
  const auto tf = S::min(tfz, S::min(tfy, S::min(tfx, S::set1(tfar))));
  tn_out = tn;
  return S::le(tn, tf);
}

// Per-ray constants of the W-wide watertight test: RayCtx's shear, broadcast.
template <int W>
struct TriRay {
  using f = typename mbvh_simd::V<W>::f;
  struct NoHalf {};
  f ox, oy, oz;  // origin, permuted (kx, ky, kz)
  f sx, sy, sz;
  Vec3 org, dir;
  float tmin, szs;
  uint32_t kx, ky, kz;
  // 8 wide: the 4-wide constants for the small leaves.
  [[no_unique_address]] std::conditional_t<W == 8, TriRay<4>, NoHalf> half;
  TriRay() = default;
  TriRay(const RayCtx& rc, float t0) : TriRay(rc.org, rc.dir, rc.kx, rc.ky, rc.kz, rc.sx, rc.sy, rc.sz, t0) {}
  TriRay(Vec3 o, Vec3 d, int kx_, int ky_, int kz_, float sx_, float sy_, float sz_, float t0) {
    using S = mbvh_simd::V<W>;
    kx = uint32_t(kx_), ky = uint32_t(ky_), kz = uint32_t(kz_);
    ox = S::set1(o[kx_]), oy = S::set1(o[ky_]), oz = S::set1(o[kz_]);
    sx = S::set1(sx_), sy = S::set1(sy_), sz = S::set1(sz_);
    org = o, dir = d, tmin = t0, szs = sz_;
    if constexpr (W == 8) half = TriRay<4>(o, d, kx_, ky_, kz_, sx_, sy_, sz_, t0);
  }
};

// The sheared edge functions of intersect_watertight on S::f lanes (S: an mbvh_simd::V<W> or
// any type with the same operations): the same float operations in the same order per lane, and
// lanes where an edge passes (numerically) through the ray decided in double, so that the two
// triangles sharing the edge agree (Woop et al. 2013 §4). Shared by every SIMD copy of the kernel
// over MBVH blocks (block_intersect here, the stream kernel of traversal/mbvh_stream.h).
template <class S>
inline void edge_functions(typename S::f Ax, typename S::f Ay, typename S::f Bx, typename S::f By, typename S::f Cx,
                           typename S::f Cy, typename S::f& U, typename S::f& V, typename S::f& Wf) {
  using f = typename S::f;
  constexpr int L = sizeof(f) / sizeof(float);
  U = S::sub(S::mul(Cx, By), S::mul(Cy, Bx));
  V = S::sub(S::mul(Ax, Cy), S::mul(Ay, Cx));
  Wf = S::sub(S::mul(Bx, Ay), S::mul(By, Ax));
  const f z = S::zero();
  const int zmask = S::mask(S::or_(S::or_(S::eq(U, z), S::eq(V, z)), S::eq(Wf, z)));
  if (zmask) [[unlikely]] {
    alignas(32) float ax[L], ay[L], bx[L], by[L], cx[L], cy[L], u[L], v[L], w[L];
    S::store(ax, Ax), S::store(ay, Ay), S::store(bx, Bx), S::store(by, By), S::store(cx, Cx), S::store(cy, Cy);
    S::store(u, U), S::store(v, V), S::store(w, Wf);
    for (int m = zmask; m; m &= m - 1) {
      const int l = std::countr_zero(unsigned(m));
      u[l] = float(double(cx[l]) * by[l] - double(cy[l]) * bx[l]);
      v[l] = float(double(ax[l]) * cy[l] - double(ay[l]) * cx[l]);
      w[l] = float(double(bx[l]) * ay[l] - double(by[l]) * ax[l]);
    }
    U = S::load(u), V = S::load(v), Wf = S::load(w);
  }
}

// The watertight test of intersect_watertight on W triangles at once: the same float
// operations in the same order per lane, so its watertightness carries over. On a hit with
// tmin <= t < hit.t records the closest (the first lane on ties, as a scalar loop would) and
// returns true.
template <int W>
[[gnu::noinline]] inline bool block_intersect(const TriRay<W>& r, const TriBlock<W>& b, Hit& hit) {
  using S = mbvh_simd::V<W>;
  using f = typename S::f;
  const f Az = S::sub(S::load(b.v[0][r.kz]), r.oz);
  const f Bz = S::sub(S::load(b.v[1][r.kz]), r.oz);
  const f Cz = S::sub(S::load(b.v[2][r.kz]), r.oz);
  const f Ax = S::sub(S::sub(S::load(b.v[0][r.kx]), r.ox), S::mul(r.sx, Az));
  const f Ay = S::sub(S::sub(S::load(b.v[0][r.ky]), r.oy), S::mul(r.sy, Az));
  const f Bx = S::sub(S::sub(S::load(b.v[1][r.kx]), r.ox), S::mul(r.sx, Bz));
  const f By = S::sub(S::sub(S::load(b.v[1][r.ky]), r.oy), S::mul(r.sy, Bz));
  const f Cx = S::sub(S::sub(S::load(b.v[2][r.kx]), r.ox), S::mul(r.sx, Cz));
  const f Cy = S::sub(S::sub(S::load(b.v[2][r.ky]), r.oy), S::mul(r.sy, Cz));
  f U, Vv, Ww;
  edge_functions<S>(Ax, Ay, Bx, By, Cx, Cy, U, Vv, Ww);
  const f z = S::zero();
  // (U < 0 || V < 0 || W < 0) && (U > 0 || V > 0 || W > 0), as min < 0 and max > 0 (no NaN
  // can occur: vertices and origin are finite).
  const f neg = S::lt(S::min(S::min(U, Vv), Ww), z);
  const f pos = S::gt(S::max(S::max(U, Vv), Ww), z);
  const f det = S::add(S::add(U, Vv), Ww);
  const f inside = S::andnot(S::and_(neg, pos), S::neq(det, z));  // det == 0: degenerate, never a hit
  int m = S::mask(inside);
  if (!m) return false;
  // The candidates (usually none or one per block): the distance from the triangle's plane in
  // double, exactly as intersect_watertight computes it.
  alignas(32) float us[W], vs[W], ws[W], dets[W];
  S::store(us, U), S::store(vs, Vv), S::store(ws, Ww), S::store(dets, det);
  bool found = false;
  for (; m; m &= m - 1) {
    const int l = std::countr_zero(unsigned(m));
    const double v0x = b.v[0][0][l], v0y = b.v[0][1][l], v0z = b.v[0][2][l];
    const double ax = v0x - r.org.x, ay = v0y - r.org.y, az = v0z - r.org.z;
    const double e1x = b.v[1][0][l] - v0x, e1y = b.v[1][1][l] - v0y, e1z = b.v[1][2][l] - v0z;
    const double e2x = b.v[2][0][l] - v0x, e2y = b.v[2][1][l] - v0y, e2z = b.v[2][2][l] - v0z;
    const double nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
    const double dn = nx * r.dir.x + ny * r.dir.y + nz * r.dir.z;
    const float inv_det = 1.f / dets[l];
    float t;
    if (dn != 0.0) [[likely]] {
      t = float((nx * ax + ny * ay + nz * az) / dn);
    } else {
      alignas(32) float azs[W], bzs[W], czs[W];
      S::store(azs, Az), S::store(bzs, Bz), S::store(czs, Cz);
      t = r.szs * (us[l] * azs[l] + vs[l] * bzs[l] + ws[l] * czs[l]) * inv_det;
    }
    if (!(t >= r.tmin && t < hit.t)) continue;
    hit.t = t;
    hit.u = vs[l] * inv_det;
    hit.v = ws[l] * inv_det;
    hit.prim = b.prim[l];
    found = true;
  }
  return found;
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
      block_intersect<W>(tr, blocks[first + k], hit);
    } else {
      const uint32_t lanes = std::min<uint32_t>(W, ntris - k * W);
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
      probe.tris(&blocks[first + k], sizeof(TriBlock<W>), std::min<uint32_t>(W, ntris - k * W) * active);
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
        block_intersect<4>(tr.half, m.small[first], hit);
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

// Starts fetching a node that goes onto the stack: single-ray traversal is bound by the latency
// of one dependent node fetch after another, and a pushed child is usually visited (it was
// entered before the closest hit known so far).
template <int N, int W>
inline void prefetch_ref(const MBVH<N, W>& m, uint32_t ref) {
  if (mbvh_ref::is_leaf(ref)) return;
  const char* p = reinterpret_cast<const char*>(&m.nodes[ref]);
  for (size_t l = 0; l < sizeof(MBVHNode<N>); l += 64) _mm_prefetch(p + l, _MM_HINT_T0);
}

struct MBVHStackEntry {
  uint32_t ref;
  float dist;  // entry distance: popped entries at or beyond the closest hit are skipped
};

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

// Lane i of a vector, without a round trip through memory.
namespace mbvh_simd {
inline float lane(__m128 v, uint32_t i) {
  return _mm_cvtss_f32(_mm_permutevar_ps(v, _mm_cvtsi32_si128(int(i))));
}
inline float lane(__m256 v, uint32_t i) {
  return _mm256_cvtss_f32(_mm256_permutevar8x32_ps(v, _mm256_castsi128_si256(_mm_cvtsi32_si128(int(i)))));
}
}  // namespace mbvh_simd

// Sorts the `count` (>= 3) entered children near-to-far and writes all but the nearest to
// out[0 .. count-2], farthest first (so the second nearest ends on top); returns the nearest.
// Writes N entries (see mbvh_traverse for why the stack always has room for them).
template <int N>
inline uint32_t push_sorted(const MBVHNode<N>& nd, typename mbvh_simd::V<N>::f tn, typename mbvh_simd::V<N>::f entered,
                            int count, MBVHStackEntry* out) {
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
    const __m256i keys = mbvh_simd::sort8(mbvh_simd::sort_keys8(tn, entered));
    const __m256i rev = _mm256_sub_epi32(_mm256_set1_epi32(count - 1), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    const __m256i idx = _mm256_and_si256(_mm256_permutevar8x32_epi32(keys, rev), _mm256_set1_epi32(7));
    const __m256i refs =
        _mm256_permutevar8x32_epi32(_mm256_load_si256(reinterpret_cast<const __m256i*>(nd.ref)), idx);
    const __m256i dist = _mm256_permutevar8x32_epi32(_mm256_castps_si256(tn), idx);
    const __m256i lo = _mm256_unpacklo_epi32(refs, dist), hi = _mm256_unpackhi_epi32(refs, dist);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out), _mm256_permute2x128_si256(lo, hi, 0x20));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out) + 1, _mm256_permute2x128_si256(lo, hi, 0x31));
    return nd.ref[uint32_t(_mm256_cvtsi256_si32(keys)) & 7];
  }
}

// Ordered single-ray traversal (thesis Alg. 2.8 with front-to-back order): the N children are
// tested at once; one hit child is entered directly, two are compared, three or more are sorted
// with the branch-free network (Alg. 2.10 for N = 4, bitonic for N = 8); the nearest is entered
// and the others are pushed far-to-near with their entry distances. Starts at `start` (the root,
// or a subtree when mbvh_rs falls back to one ray); `stack` must hold (N-1)*max_depth+1 entries
// (at depth d at most (N-1)*(d-1) are pending, so push_sorted's N-entry store stays inside).
template <int N, int W, TriKernel K, class P>
inline void mbvh_traverse(const MBVH<N, W>& m, const TriangleSet* ts, const NodeRay<N>& nr, const TriRay<W>& tr,
                          const RayCtx* rc, uint32_t start, Hit& hit, MBVHStackEntry* stack, P& probe) {
  using S = mbvh_simd::V<N>;
  const MBVHNode<N>* nodes = m.nodes.data();
  uint32_t sp = 0, cur = start;
  float tfar = hit.t;  // a register copy: stack stores could alias hit.t and force reloads
  for (;;) {
    if (!mbvh_ref::is_leaf(cur)) {
      const MBVHNode<N>& nd = nodes[cur];
      probe.node(&nd, sizeof(nd));
      typename S::f tn;
      const auto entered = box_test<N>(nd, nr, tfar, tn);
      int mask = S::mask(entered);
      if (mask) {
        uint32_t c0 = uint32_t(std::countr_zero(unsigned(mask)));
        const int rest = mask & (mask - 1);
        if (!rest) {
          cur = nd.ref[c0];
          continue;
        }
        if (!(rest & (rest - 1))) {
          uint32_t c1 = uint32_t(std::countr_zero(unsigned(rest)));
          float d0 = mbvh_simd::lane(tn, c0), d1 = mbvh_simd::lane(tn, c1);
          if (d1 < d0) std::swap(c0, c1), std::swap(d0, d1);
          prefetch_ref(m, nd.ref[c1]);
          stack[sp] = {nd.ref[c1], d1};
          probe.write(&stack[sp], sizeof(MBVHStackEntry));
          ++sp;
          cur = nd.ref[c0];
          continue;
        }
        // Three or more: sort branch-free (keys carry the child index in their low bits) and
        // push the entries far-to-near with whole-vector stores; enter the nearest.
        const int count = std::popcount(unsigned(mask));
        cur = push_sorted<N>(nd, tn, entered, count, stack + sp);
        if constexpr (P::enabled) {
          for (int j = 0; j < count - 1; ++j) probe.write(&stack[sp + j], sizeof(MBVHStackEntry));
        }
        sp += uint32_t(count - 1);
        continue;
      }
    } else {
      probe_leaf(m, cur, probe, 1);
      leaf_test<N, W, K>(m, ts, tr, rc, cur, hit);
      tfar = hit.t;
    }
    if (!pop_pending(stack, sp, tfar, cur, probe)) return;
  }
}

// The per-ray loop of the single-ray MBVH schemes: sets up each ray of `range` and hands it to
// `traverse(nr, tr, rc, hit, stack)`.
template <int N, int W, class P, class F>
void mbvh_for_each_ray(const MBVH<N, W>& m, const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe,
                       F&& traverse) {
  std::vector<MBVHStackEntry> stack(size_t(N - 1) * m.stats.max_depth + N + 2);
  for (uint32_t i = batch.packet_begin[range.first]; i < batch.packet_begin[range.last]; ++i) {
    const Ray& ray = batch.rays[i];
    probe.read(&ray, sizeof(Ray));
    if constexpr (P::enabled)
      if (probe.counts) probe.counts->rays++;
    const RayCtx rc(ray);
    const NodeRay<N> nr(rc, ray.tmin);
    const TriRay<W> tr(rc, ray.tmin);
    Hit hit = initial_hit(ray);
    traverse(nr, tr, rc, hit, stack.data());
    hits[i] = finish_hit(hit);
    probe.write(&hits[i], sizeof(Hit));
  }
}

// Single-ray traversal of the rays of `range` (mbvh4_single, mbvh8_single): the timed loop.
template <int N, int W, TriKernel K, class P>
void mbvh_trace_rays(const MBVHData<N, W>& d, const RayBatch& batch, PacketRange range, std::span<Hit> hits,
                     P& probe) {
  const MBVH<N, W>& m = *d.mbvh;
  mbvh_for_each_ray(m, batch, range, hits, probe,
                    [&](const NodeRay<N>& nr, const TriRay<W>& tr, const RayCtx& rc, Hit& hit, MBVHStackEntry* stack) {
                      mbvh_traverse<N, W, K>(m, d.tris.get(), nr, tr, &rc, 0, hit, stack, probe);
                    });
}

}  // namespace tb
