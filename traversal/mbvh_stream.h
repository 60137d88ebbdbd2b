// The MBVH/RS stream kernel (Tsakok 2009; thesis §2.2 Alg. 2.9, Appendix C.1), shared by
// `mbvh_rs` (streams of consecutive packets over the scene's MBVH) and `raygrid` (the rays of one
// octree-leaf queue over that leaf's mini-MBVH, thesis §5.3). One kernel, templated on the node
// width N (4: the thesis' SSE layout; 8: AVX2 nodes, MBVHNode<8>), on 4-wide triangle blocks.
//
// A stream is a set of rays (`Rays`: SoA input, computed eight at a time into one two-line
// record per ray, `RayRecord`). Traversal: a task is (node, lane, count); its
// rays are the `count` ids on top of lane `lane`'s active-ray stack. Every ray of the task is
// tested against the node's N child boxes (one N-wide slab test per ray), and every ray that
// enters child c is pushed onto lane c's stack, so a child's stream holds only the rays that enter
// it. One task per entered child goes onto the task stack, ordered by the mean (or, as Alg. 2.10,
// the summed) entry distance of their rays (Alg. 2.10's sorting network, 8-wide for N = 8; `Order`
// below), the nearest popped first. Leaves
// intersect every ray of their stream, two rays per AVX2 pass (pair_intersect). A stream that has
// shrunk to one ray finishes with ordinary single-ray traversal (thesis: "falls back to efficient
// single ray traversal when the size of a stream drops to one").
//
// Differences from Appendix C.1 that do not change results:
// - the push is done per child after the box tests (N-bit masks per ray, ids left-packed eight
//   at a time with one byte shuffle) instead of N branch-free stores per ray: for N = 8 the
//   per-ray stores dominated;
// - the per-ray constants (reciprocals, padded reciprocals, watertight shear and permutation)
//   are computed for the whole stream eight rays per AVX2 instruction (prepare), from the same
//   float operations as RayCtx, so every test decides exactly as the single-ray schemes do;
// - the farther children of a node are prefetched when pushed.
#pragma once
#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "traversal/mbvh_traverse.h"

namespace tb::mbvh_stream {

// The order in which a node's entered children go onto the task stack (the nearest is popped
// first). Tsakok and the thesis (§2.2, Alg. 2.10) sort by the SUM of the entry distances of each
// child's rays; that sum grows with the number of rays, so a child entered by one far ray comes
// before one entered by fifty near rays. `mean` divides by the count: a child's rays' mean entry
// distance. bounce:3 at 512x512, best batch / best single (scripts/batch_goal.py, 4 interleaved
// rounds), sum -> mean: conference 1.40 -> 1.47, sibenik 1.30 -> 1.36, crytek_sponza_partial
// 1.53 -> 1.57 (raygrid), sibenik_lucy 1.26 -> 1.29, room 1.45 -> 1.47, stadium 1.35 -> 1.38,
// sponza 1.33 -> 1.28 (docs/PERFORMANCE.md, "Session 12"). The smallest entry distance instead:
// between the two on the scenes tried.
enum class Order { sum, mean };
inline ParamSpec order_param() {
  return choice_param("task_order", "mean", {"mean", "sum"},
                      "child order on the task stack: mean or summed (the thesis' Alg. 2.10) entry distance of "
                      "the child's rays; the thesis tables run sum");
}
inline Order order_of(const SchemeConfig& cfg) { return cfg.get_choice("task_order") == "sum" ? Order::sum : Order::mean; }

// One ray's record in the stream, two 64-byte lines. A task's rays are a sparse subset of the
// stream below the first levels of the tree, so what one ray's test touches is what counts:
// - line 0, read by every node test: the fused-plane constants r, c_near, c_far per axis
//   (kernels.h, FusedPlanes), tmin, the octant (bits 0-2, as a float's bit pattern), and the
//   closest hit so far (its t is the test's far limit);
// - line 1, read by leaf tests: the watertight test's origin permuted to (kx, ky, kz) and shear,
//   the ray itself (the double plane distance of candidates), and `meta`: the sign octant
//   (bits 0-2: reciprocal negative on x, y, z) and the axis permutation kx, ky, kz (bits 4-5,
//   6-7, 8-9).
// With the node constants in AoSoA groups of eight (six lines a ray) and the hits and the leaf
// constants in SoA arrays, a ray's node test touched seven lines and its leaf test fourteen
// (docs/PERFORMANCE.md, "Session 18").
enum NodeField : uint32_t { kNR = 0, kNCN = 3, kNCF = 6, kNTmin = 9, kNOct = 10, kNodeFields = 12 };
enum LeafField : uint32_t { kLP = 0, kLS = 3, kLO = 6, kLD = 9, kLMeta = 12, kLeafFields = 16 };
struct alignas(64) RayRecord {
  float node[kNodeFields];
  Hit hit;
  float leaf[kLeafFields];
  uint32_t meta() const {
    uint32_t m;
    std::memcpy(&m, &leaf[kLMeta], sizeof m);
    return m;
  }
  Vec3 org() const { return {leaf[kLO], leaf[kLO + 1], leaf[kLO + 2]}; }
  Vec3 dir() const { return {leaf[kLD], leaf[kLD + 1], leaf[kLD + 2]}; }
};
static_assert(sizeof(RayRecord) == 128 && offsetof(RayRecord, hit) == 48);

// The stream's rays. The caller fills ox..tmin (SoA, every array 32-byte aligned with room for n
// rounded up to 8) and each record's hit (t = the search limit, prim = kNoHit); prepare() fills
// the rest of the records (n rounded up to 8 of them) and ix.. the reciprocal direction
// (RayGrid's octree walk; null when no one reads it: mbvh_rs).
struct Rays {
  const float *ox, *oy, *oz, *dx, *dy, *dz, *tmin;
  float *ix, *iy, *iz;
  RayRecord* rec;  // n records
};

// The distance, in floats, between two field arrays of a SoA ray record of n rays: n rounded up
// to the SIMD width plus one cache line. At a power-of-two stride (4 KB: a stream of 1024 rays)
// all fields of one ray fall into one L1 set, more of them than an 8- or 12-way L1 holds: the
// node test, which read 12 SoA fields per ray before the per-ray records, then missed L1 on most
// of them (the simulated 32 KB L1 on sponza bounce:3: 164 L2 hits per ray). One ray's SoA fields
// are still read together by RayGrid's octree walk (prepare reads them eight rays at a time).
inline size_t field_stride(size_t n) { return ((n + 7) & ~size_t(7)) + 16; }

// Transposes eight rows of eight floats: afterwards r[j] holds what was column j (one ray's
// eight fields, from eight fields of eight rays).
[[gnu::always_inline]] inline void transpose8(__m256 r[8]) {
  const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
  const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
  const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
  const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
  const __m256 s0 = _mm256_shuffle_ps(t0, t2, 0x44), s1 = _mm256_shuffle_ps(t0, t2, 0xEE);
  const __m256 s2 = _mm256_shuffle_ps(t1, t3, 0x44), s3 = _mm256_shuffle_ps(t1, t3, 0xEE);
  const __m256 s4 = _mm256_shuffle_ps(t4, t6, 0x44), s5 = _mm256_shuffle_ps(t4, t6, 0xEE);
  const __m256 s6 = _mm256_shuffle_ps(t5, t7, 0x44), s7 = _mm256_shuffle_ps(t5, t7, 0xEE);
  r[0] = _mm256_permute2f128_ps(s0, s4, 0x20), r[1] = _mm256_permute2f128_ps(s1, s5, 0x20);
  r[2] = _mm256_permute2f128_ps(s2, s6, 0x20), r[3] = _mm256_permute2f128_ps(s3, s7, 0x20);
  r[4] = _mm256_permute2f128_ps(s0, s4, 0x31), r[5] = _mm256_permute2f128_ps(s1, s5, 0x31);
  r[6] = _mm256_permute2f128_ps(s2, s6, 0x31), r[7] = _mm256_permute2f128_ps(s3, s7, 0x31);
}

// RayCtx's constants for rays [0, n), eight at a time with the same float operations (1/d,
// d[kx]/d[kz], ...), so the watertight test sees exactly RayCtx's values, and NodeRay's for the
// tree's coordinate bound (MBVH::coord_bound). Reads the SoA fields and writes ix.. and the
// records (all but their hits) up to the next multiple of 8.
inline void prepare(const Rays& v, uint32_t n, const float bound[3]) {
  const __m256 one = _mm256_set1_ps(1.f), zero = _mm256_setzero_ps();
  const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  // (kz == 0, kz == 1, swap) -> kx | ky << 2 | kz << 4, as RayCtx chooses them, shifted to meta's
  // bits 4-9, indexed by kz == 0 | (kz == 1) << 1 | swap << 2.
  const __m256i perms = _mm256_slli_epi32(
      _mm256_setr_epi32(0 | 1 << 2 | 2 << 4, 1 | 2 << 2 | 0 << 4, 2 | 0 << 2 | 1 << 4, 0, 1 | 0 << 2 | 2 << 4,
                        2 | 1 << 2 | 0 << 4, 0 | 2 << 2 | 1 << 4, 0),
      4);
  for (uint32_t k = 0; k < n; k += 8) {
    const __m256 dx = _mm256_load_ps(v.dx + k), dy = _mm256_load_ps(v.dy + k), dz = _mm256_load_ps(v.dz + k);
    const __m256 ox = _mm256_load_ps(v.ox + k), oy = _mm256_load_ps(v.oy + k), oz = _mm256_load_ps(v.oz + k);
    const __m256 ix = _mm256_div_ps(one, dx), iy = _mm256_div_ps(one, dy), iz = _mm256_div_ps(one, dz);
    if (v.ix) _mm256_store_ps(v.ix + k, ix), _mm256_store_ps(v.iy + k, iy), _mm256_store_ps(v.iz + k, iz);
    // The octant: the reciprocal's sign bits.
    const __m256i oct = _mm256_or_si256(
        _mm256_srli_epi32(_mm256_castps_si256(ix), 31),
        _mm256_or_si256(_mm256_slli_epi32(_mm256_srli_epi32(_mm256_castps_si256(iy), 31), 1),
                        _mm256_slli_epi32(_mm256_srli_epi32(_mm256_castps_si256(iz), 31), 2)));
    __m256 nd[16];  // this group's node fields (rows), transposed below; 11-15 unused
    {
      const __m256 o[3] = {ox, oy, oz}, in[3] = {ix, iy, iz};
      const __m256 K[3] = {_mm256_set1_ps(bound[0]), _mm256_set1_ps(bound[1]), _mm256_set1_ps(bound[2])};
      FusedPlanes<8> p[3];
      for (int a = 0; a < 3; ++a) p[a] = fused_planes<8>(o[a], in[a], K[a]);
      // Rays that do not move along an axis (kernels.h: still_axes) need each ray's largest plane
      // distance on the axes it moves along.
      if (_mm256_movemask_ps(_mm256_or_ps(still_lanes<8>(ix), _mm256_or_ps(still_lanes<8>(iy), still_lanes<8>(iz)))))
          [[unlikely]] {
        const __m256 Tm = _mm256_max_ps(plane_distance_bound<8>(o[0], in[0], K[0]),
                                        _mm256_max_ps(plane_distance_bound<8>(o[1], in[1], K[1]),
                                                      plane_distance_bound<8>(o[2], in[2], K[2])));
        for (int a = 0; a < 3; ++a) still_axes<8>(p[a], o[a], in[a], K[a], Tm);
      }
      for (int a = 0; a < 3; ++a) nd[kNR + a] = p[a].r, nd[kNCN + a] = p[a].cn, nd[kNCF + a] = p[a].cf;
      nd[kNTmin] = _mm256_load_ps(v.tmin + k);
      nd[kNOct] = _mm256_castsi256_ps(oct);
      for (int f = kNOct + 1; f < 16; ++f) nd[f] = zero;
    }
    // kz = the dominant axis: a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2).
    const __m256 ax = _mm256_and_ps(dx, absmask), ay = _mm256_and_ps(dy, absmask), az = _mm256_and_ps(dz, absmask);
    const __m256 xy = _mm256_cmp_ps(ax, ay, _CMP_GE_OQ);
    const __m256 k0 = _mm256_and_ps(xy, _mm256_cmp_ps(ax, az, _CMP_GE_OQ));
    const __m256 k1 = _mm256_andnot_ps(xy, _mm256_cmp_ps(ay, az, _CMP_GE_OQ));
    // kx = kz + 1, ky = kx + 1 (mod 3), swapped when d[kz] < 0.
    const __m256 dkz = _mm256_blendv_ps(_mm256_blendv_ps(dz, dy, k1), dx, k0);
    const __m256 dkx = _mm256_blendv_ps(_mm256_blendv_ps(dx, dz, k1), dy, k0);
    const __m256 dky = _mm256_blendv_ps(_mm256_blendv_ps(dy, dx, k1), dz, k0);
    const __m256 swap = _mm256_cmp_ps(dkz, zero, _CMP_LT_OQ);
    __m256 lf[16];  // this group's leaf fields (rows), transposed below; 13-15 unused
    {  // the origin in the same permutation (TriRay's ox, oy, oz)
      const __m256 okz = _mm256_blendv_ps(_mm256_blendv_ps(oz, oy, k1), ox, k0);
      const __m256 okx = _mm256_blendv_ps(_mm256_blendv_ps(ox, oz, k1), oy, k0);
      const __m256 oky = _mm256_blendv_ps(_mm256_blendv_ps(oy, ox, k1), oz, k0);
      lf[kLP] = _mm256_blendv_ps(okx, oky, swap), lf[kLP + 1] = _mm256_blendv_ps(oky, okx, swap), lf[kLP + 2] = okz;
    }
    lf[kLS] = _mm256_div_ps(_mm256_blendv_ps(dkx, dky, swap), dkz);
    lf[kLS + 1] = _mm256_div_ps(_mm256_blendv_ps(dky, dkx, swap), dkz);
    lf[kLS + 2] = _mm256_div_ps(one, dkz);
    lf[kLO] = ox, lf[kLO + 1] = oy, lf[kLO + 2] = oz, lf[kLD] = dx, lf[kLD + 1] = dy, lf[kLD + 2] = dz;
    {  // meta = oct | perm << 4 (the all-ones compare masks shifted down to 0/1)
      const __m256i sel = _mm256_or_si256(
          _mm256_srli_epi32(_mm256_castps_si256(k0), 31),
          _mm256_or_si256(_mm256_slli_epi32(_mm256_srli_epi32(_mm256_castps_si256(k1), 31), 1),
                          _mm256_slli_epi32(_mm256_srli_epi32(_mm256_castps_si256(swap), 31), 2)));
      lf[kLMeta] = _mm256_castsi256_ps(_mm256_or_si256(oct, _mm256_permutevar8x32_epi32(perms, sel)));
    }
    for (int f = kLMeta + 1; f < 16; ++f) lf[f] = zero;
    // Rows to records: node fields 0-7 and 8-11 (the hit, 12-15, is the caller's), leaf fields
    // 0-7 and 8-15.
    transpose8(nd), transpose8(nd + 8), transpose8(lf), transpose8(lf + 8);
    for (int j = 0; j < 8; ++j) {
      RayRecord& r = v.rec[k + j];
      _mm256_store_ps(r.node, nd[j]);
      _mm_store_ps(r.node + 8, _mm256_castps256_ps128(nd[8 + j]));
      _mm256_store_ps(r.leaf, lf[j]), _mm256_store_ps(r.leaf + 8, lf[8 + j]);
    }
  }
}

// Two rays against one block of four triangles in one AVX2 pass: ray A in the low 128-bit half,
// ray B in the high half, each half the kernel library's watertight test as in block_intersect (mbvh_traverse.h) (Woop,
// Benthin and Wald 2013) with the same float operations in the same order per lane, so every
// lane decides exactly as the 4-wide test would — watertightness carries over — at half the
// instructions per ray. MBVH/RS leaf streams hold several rays (Table 10), so pairs are common.
struct PairRay {
  __m256 ox, oy, oz, sx, sy, sz;  // origin permuted to (kx, ky, kz) and the shear, per half
  uint32_t kx[2], ky[2], kz[2];
  RayRecord* rec[2];  // the rest of the two rays' records, read only for candidate hits
};

inline __m256 pair_rows(const TriBlock<4>& b, int corner, uint32_t row_a, uint32_t row_b) {
  return _mm256_loadu2_m128(b.v[corner][row_b], b.v[corner][row_a]);
}

// `lanes`: the block's real triangles (low 4 bits): padding lanes never reach the double distance.
inline void pair_intersect(const PairRay& r, const TriBlock<4>& b, uint32_t lanes) {
  using S = simd::V<8>;
  using f = __m256;
  using D = simd::D4v;
  const f Az = S::sub(pair_rows(b, 0, r.kz[0], r.kz[1]), r.oz);
  const f Bz = S::sub(pair_rows(b, 1, r.kz[0], r.kz[1]), r.oz);
  const f Cz = S::sub(pair_rows(b, 2, r.kz[0], r.kz[1]), r.oz);
  const f Ax = shear<8>(S::sub(pair_rows(b, 0, r.kx[0], r.kx[1]), r.ox), r.sx, Az);
  const f Ay = shear<8>(S::sub(pair_rows(b, 0, r.ky[0], r.ky[1]), r.oy), r.sy, Az);
  const f Bx = shear<8>(S::sub(pair_rows(b, 1, r.kx[0], r.kx[1]), r.ox), r.sx, Bz);
  const f By = shear<8>(S::sub(pair_rows(b, 1, r.ky[0], r.ky[1]), r.oy), r.sy, Bz);
  const f Cx = shear<8>(S::sub(pair_rows(b, 2, r.kx[0], r.kx[1]), r.ox), r.sx, Cz);
  const f Cy = shear<8>(S::sub(pair_rows(b, 2, r.ky[0], r.ky[1]), r.oy), r.sy, Cz);
  f U, Vv, Ww, det;
  int m = S::mask(watertight_inside<8>(Ax, Ay, Bx, By, Cx, Cy, U, Vv, Ww, det)) & int(lanes | lanes << 4);
  if (!m) return;
  // Candidates: exact_plane_distance's double plane equation, four lanes (the block's four
  // triangles) of a ray at once — a ray's line passes through several triangles of a leaf, most
  // of them out of range. The normals depend on the block only.
  alignas(32) float us[8], vs[8], ws[8], dets[8], ts[8];
  S::store(us, U), S::store(vs, Vv), S::store(ws, Ww), S::store(dets, det);
  const Vec3D<D> v0{D(_mm_load_ps(b.v[0][0])), D(_mm_load_ps(b.v[0][1])), D(_mm_load_ps(b.v[0][2]))};
  const Vec3D<D> n = plane_normal(v0, Vec3D<D>{D(_mm_load_ps(b.v[1][0])), D(_mm_load_ps(b.v[1][1])), D(_mm_load_ps(b.v[1][2]))},
                                  Vec3D<D>{D(_mm_load_ps(b.v[2][0])), D(_mm_load_ps(b.v[2][1])), D(_mm_load_ps(b.v[2][2]))});
  for (int ray = 0; ray < 2; ++ray) {
    const int rm = (m >> (4 * ray)) & 15;
    if (!rm) continue;
    const float* lf = r.rec[ray]->leaf;
    D num, dn;
    plane_terms(n, v0, Vec3D<D>{D(double(lf[kLO])), D(double(lf[kLO + 1])), D(double(lf[kLO + 2]))},
                Vec3D<D>{D(double(lf[kLD])), D(double(lf[kLD + 1])), D(double(lf[kLD + 2]))}, num, dn);
    _mm_store_ps(ts + 4 * ray, (num / dn).to_float());
    if (const int par = dn.zero_mask() & rm) [[unlikely]] {
      // Edge-on (the ray lies in the plane): the sheared distance, as intersect_watertight.
      alignas(32) float azs[8], bzs[8], czs[8];
      S::store(azs, Az), S::store(bzs, Bz), S::store(czs, Cz);
      for (int t4 = 0; t4 < 4; ++t4) {
        const int l = 4 * ray + t4;
        if (par >> t4 & 1)
          ts[l] = sheared_distance<1>(lf[kLS + 2], us[l], vs[l], ws[l], azs[l], bzs[l], czs[l], 1.f / dets[l]);
      }
    }
  }
  for (; m; m &= m - 1) {
    const int l = std::countr_zero(unsigned(m));
    const int ray = l >> 2, t4 = l & 3;
    Hit& h = r.rec[ray]->hit;
    const float t = ts[l];
    if (!(t >= r.rec[ray]->node[kNTmin] && t < h.t)) continue;
    const float inv_det = 1.f / dets[l];
    h.t = t;
    h.u = vs[l] * inv_det;
    h.v = ws[l] * inv_det;
    h.prim = b.prim[t4];
  }
}

inline TriRay<4> tri_ray(const RayRecord& r) {
  const uint32_t m = r.meta();
  return TriRay<4>(r.org(), r.dir(), int(m >> 4 & 3), int(m >> 6 & 3), int(m >> 8 & 3), r.leaf[kLS],
                   r.leaf[kLS + 1], r.leaf[kLS + 2], r.node[kNTmin]);
}
// The permuted origins come from prepare(), so a pair costs two loads and shuffles only (a pair
// is built per leaf visit: the component selection per ray was 137 instructions a pair; per-field
// broadcasts from the records, 1.4% more of mbvh_rs's instructions than these shuffles).
inline PairRay pair_ray(RayRecord& a, RayRecord& b) {
  PairRay p;
  const uint32_t ma = a.meta(), mb = b.meta();
  p.kx[0] = ma >> 4 & 3, p.ky[0] = ma >> 6 & 3, p.kz[0] = ma >> 8 & 3;
  p.kx[1] = mb >> 4 & 3, p.ky[1] = mb >> 6 & 3, p.kz[1] = mb >> 8 & 3;
  p.rec[0] = &a, p.rec[1] = &b;
  // Leaf fields 0-3 of A and B in one register ([A | B] halves), 4-7 in another; each field then
  // spread over its half by one in-lane shuffle.
  static_assert(kLP == 0 && kLS == 3);
  const __m256 la = _mm256_load_ps(a.leaf), lb = _mm256_load_ps(b.leaf);
  const __m256 lo = _mm256_permute2f128_ps(la, lb, 0x20), hi = _mm256_permute2f128_ps(la, lb, 0x31);
  p.ox = _mm256_permute_ps(lo, 0x00), p.oy = _mm256_permute_ps(lo, 0x55), p.oz = _mm256_permute_ps(lo, 0xAA);
  p.sx = _mm256_permute_ps(lo, 0xFF), p.sy = _mm256_permute_ps(hi, 0x00), p.sz = _mm256_permute_ps(hi, 0x55);
  return p;
}
// For the scalar kernels (moller, plane, plane_rcp): RayCtx rebuilt from the record (its tmax is
// unused: the kernels search up to the hit's t).
inline RayCtx ray_ctx(const RayRecord& r) { return RayCtx(Ray{r.org(), r.node[kNTmin], r.dir(), INFINITY}); }

// What the box test of one ray reads: its node fields and its hit's t (line 0).
template <class P>
inline void probe_ray(const Rays& v, uint32_t id, P& probe) {
  if constexpr (P::enabled) probe.read(&v.rec[id], offsetof(RayRecord, hit) + sizeof(float));
}
// What a leaf test of one ray reads: its leaf fields (line 1), tmin and its hit.
template <class P>
inline void probe_leaf_ray(const Rays& v, uint32_t id, P& probe) {
  if constexpr (P::enabled) {
    probe.read(&v.rec[id].node[kNTmin], sizeof(float));
    probe.read(&v.rec[id].hit, sizeof(Hit));
    probe.read(v.rec[id].leaf, (kLMeta + 1) * sizeof(float));
  }
}

// Left-packing shuffles: for an 8-bit mask, the byte shuffle that moves the 16-bit elements whose
// bit is set to the front, in order.
struct PackLut {
  alignas(16) uint8_t s[256][16];
  constexpr PackLut() : s{} {
    for (int m = 0; m < 256; ++m) {
      int o = 0;
      for (int e = 0; e < 8; ++e)
        if (m >> e & 1) s[m][2 * o] = uint8_t(2 * e), s[m][2 * o + 1] = uint8_t(2 * e + 1), ++o;
      for (; o < 8; ++o) s[m][2 * o] = s[m][2 * o + 1] = 0x80;
    }
  }
};
inline constexpr PackLut kPackLut{};

// Writes the ids of list[0, n) whose mask has bit c to dst (which may be list itself), in order;
// returns their number. Reads up to 15 entries past n and writes up to 7 past the result: the
// lane arrays and the mask buffer carry that slack (Scratch::reserve).
inline uint32_t pack_lane(const uint16_t* list, const uint8_t* masks, uint32_t n, unsigned c, uint16_t* dst) {
  const __m128i shift = _mm_cvtsi32_si128(int(7 - c));
  uint32_t o = 0;
  for (uint32_t i = 0; i < n; i += 16) {
    // Bit c of 16 mask bytes to bit 7 (a 16-bit shift moves each byte's bit c to its bit 7).
    uint32_t bits = uint32_t(_mm_movemask_epi8(
        _mm_sll_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(masks + i)), shift)));
    if (n - i < 16) bits &= (1u << (n - i)) - 1;
    for (uint32_t g = 0; g < 2 && i + 8 * g < n; ++g) {
      const uint32_t b8 = (bits >> (8 * g)) & 255u;
      const __m128i ids = _mm_loadu_si128(reinterpret_cast<const __m128i*>(list + i + 8 * g));
      _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + o),
                       _mm_shuffle_epi8(ids, _mm_load_si128(reinterpret_cast<const __m128i*>(kPackLut.s[b8]))));
      o += uint32_t(std::popcount(b8));
    }
  }
  return o;
}

struct Task {
  uint32_t ref;    // MBVH child reference (interior node or leaf)
  uint32_t lane;   // the active-ray stack holding its rays
  uint32_t count;  // how many (on top of that stack)
};

// The stacks of one stream traversal; reused across streams (one per thread of a call).
struct Scratch {
  std::vector<uint16_t> lanes[8];  // active-ray stacks, one per child slot (N used)
  std::vector<uint8_t> masks;      // per ray of a task: the children it entered
  std::vector<Task> tasks;
  std::vector<MBVHStackEntry> single;  // the one-ray fallback's stack

  // For streams of up to `rays` rays over an MBVH of width n whose deepest leaf is at `depth`
  // (root = 1). Per lane at most one pending task per tree level (siblings use distinct lanes,
  // and a task's children are all consumed before its next sibling), each with at most a
  // stream, plus pack_lane's slack; tasks: n - 1 siblings pending per level; the one-ray stack:
  // mbvh_stack_entries.
  void reserve(int n, uint32_t depth, uint32_t rays) {
    for (int l = 0; l < n; ++l)
      if (lanes[l].size() < size_t(depth + 1) * rays + 32) lanes[l].resize(size_t(depth + 1) * rays + 32);
    if (masks.size() < size_t(rays) + 32) masks.resize(size_t(rays) + 32);
    if (tasks.size() < size_t(n - 1) * depth + 2) tasks.resize(size_t(n - 1) * depth + 2);
    if (single.size() < mbvh_stack_entries(n, depth)) single.resize(mbvh_stack_entries(n, depth));
  }
};

// The node test's constants of ray `id`, from its record.
template <int N>
[[gnu::always_inline]] inline NodeRay<N> node_ray(const Rays& v, uint32_t id) {
  const float* f = v.rec[id].node;
  uint32_t oct;
  std::memcpy(&oct, f + kNOct, sizeof oct);
  return NodeRay<N>(Vec3{f[kNR], f[kNR + 1], f[kNR + 2]}, Vec3{f[kNCN], f[kNCN + 1], f[kNCN + 2]},
                    Vec3{f[kNCF], f[kNCF + 1], f[kNCF + 2]}, f[kNTmin], oct);
}

// Ordinary single-ray traversal of the subtree `ref` for ray `id` (streams of one).
template <int N, TriKernel K, class P>
inline void single(const MBVH<N, 4>& m, const TriangleSet* ts, Scratch& s, const Rays& v, uint32_t id, uint32_t ref,
                   P& probe) {
  const NodeRay<N> nr = node_ray<N>(v, id);
  RayRecord& r = v.rec[id];
  if constexpr (K == TriKernel::watertight) {
    mbvh_traverse<N, 4, K>(m, nullptr, nr, tri_ray(r), nullptr, ref, r.hit, s.single.data(), probe);
  } else {
    const RayCtx rc = ray_ctx(r);
    mbvh_traverse<N, 4, K>(m, ts, nr, tri_ray(r), &rc, ref, r.hit, s.single.data(), probe);
  }
}

// Alg. 2.9 on rays [0, n) of `v` (prepared) from node `root` of `m`; the closest hits go to
// the records' hits. `ts`: the triangle set in lane order for the scalar kernels (null for watertight).
// N = 4: the thesis' SSE MBVH/RS. N = 8: one AVX2 8-child box test per ray and eight active-ray
// stacks (the natural SIMD width of AVX2, as mbvh8_single).
template <int N, TriKernel K, class P>
void trace(const MBVH<N, 4>& m, const TriangleSet* ts, Scratch& s, const Rays& v, uint32_t n, uint32_t root,
           Order order, P& probe) {
  using SN = simd::V<N>;
  using f = typename SN::f;
  const MBVHNode<N>* nodes = m.nodes.data();
  const TriBlock<4>* blocks = m.blocks.data();
  if (n == 0) return;
  if (n == 1) {
    single<N, K>(m, ts, s, v, 0, root, probe);
    return;
  }
  uint16_t* lane[N];
  uint32_t head[N];
  for (int c = 0; c < N; ++c) lane[c] = s.lanes[c].data(), head[c] = 0;
  head[0] = n;
  for (uint32_t j = 0; j < n; ++j) lane[0][j] = uint16_t(j);
  Task* tasks = s.tasks.data();
  uint32_t ntasks = 0;
  tasks[ntasks++] = {root, 0, n};
  while (ntasks) {
    const Task t = tasks[--ntasks];
    probe.read(&tasks[ntasks], sizeof(Task));
    head[t.lane] -= t.count;
    uint16_t* list = lane[t.lane] + head[t.lane];
    if (t.count == 1) {  // a stream of one ray: ordinary single-ray traversal of the subtree
      probe.read(list, sizeof(uint16_t));
      probe_ray(v, list[0], probe);
      probe_leaf_ray(v, list[0], probe);
      single<N, K>(m, ts, s, v, list[0], t.ref, probe);
      continue;
    }
    if (mbvh_ref::is_leaf(t.ref)) {
      probe_leaf(m, t.ref, probe, t.count);
      uint32_t i = 0;
      if constexpr (K == TriKernel::watertight) {
        const uint32_t first = mbvh_ref::first_block(t.ref), ntris = mbvh_ref::num_tris(t.ref);
        const uint32_t nblocks = (ntris + 3) / 4;
        for (; i + 1 < t.count; i += 2) {
          probe.read(&list[i], 2 * sizeof(uint16_t));
          probe_leaf_ray(v, list[i], probe);
          probe_leaf_ray(v, list[i + 1], probe);
          const PairRay pr = pair_ray(v.rec[list[i]], v.rec[list[i + 1]]);
          for (uint32_t k = 0; k < nblocks; ++k) pair_intersect(pr, blocks[first + k], lane_bits(block_tris<4>(ntris, k)));
        }
      }
      for (; i < t.count; ++i) {
        probe.read(&list[i], sizeof(uint16_t));
        RayRecord& r = v.rec[list[i]];
        probe_leaf_ray(v, list[i], probe);
        if constexpr (K == TriKernel::watertight) {
          leaf_test<4, K>(blocks, nullptr, tri_ray(r), nullptr, t.ref, r.hit);
        } else {
          const RayCtx rc = ray_ctx(r);
          leaf_test<4, K>(blocks, ts, tri_ray(r), &rc, t.ref, r.hit);
        }
      }
      continue;
    }
    // Interior node: every ray of the task against the N child boxes: mbvh_traverse.h's box_test
    // (the kernel library's slab test) with the ray's constants from its record's first line.
    const MBVHNode<N>& nd = nodes[t.ref];
    probe.node(&nd, sizeof(nd), t.count);
    uint8_t* masks = s.masks.data();
    unsigned active = 0;
    f dsum = SN::zero();
    for (uint32_t i = 0; i < t.count; ++i) {
      probe.read(&list[i], sizeof(uint16_t));
      const uint16_t id = list[i];
      probe_ray(v, id, probe);
      // The record of the ray 8 places on: the list is in no address order (the hardware
      // prefetcher cannot follow it), and a record read at its turn waited on L2 or L3 at the head
      // of the test (perf: the most samples of the loop on its first load). bounce:3, 3
      // interleaved rounds, control-normalised, mbvh_rs +4 to +11% on 5 architectural scenes;
      // the same for the leaf line in the leaf loop: no change (docs/PERFORMANCE.md, session 26).
      if (i + 8 < t.count) _mm_prefetch(reinterpret_cast<const char*>(v.rec[list[i + 8]].node), _MM_HINT_T0);
      const NodeRay<N> nr = node_ray<N>(v, id);
      f tn;
      const f enter = box_test<N>(nd, nr, v.rec[id].hit.t, tn);
      dsum = SN::add(dsum, SN::and_(tn, enter));
      const unsigned mk = unsigned(SN::mask(enter));
      masks[i] = uint8_t(mk);
      active |= mk;
    }
    if (!active) continue;
    // Distribute the rays over the lanes of the children they entered. The task's own lane is
    // packed last and in place: its output never overtakes its input.
    uint32_t cnt[N] = {};
    const unsigned own = 1u << t.lane;
    for (unsigned todo = active; todo;) {
      const unsigned c = (todo & ~own) ? unsigned(std::countr_zero(todo & ~own)) : t.lane;
      todo &= ~(1u << c);
      uint16_t* dst = lane[c] + head[c];
      cnt[c] = pack_lane(list, masks, t.count, c, dst);
      if constexpr (P::enabled)
        for (uint32_t j = 0; j < cnt[c]; ++j) probe.write(&dst[j], sizeof(uint16_t));
      head[c] += cnt[c];
    }
    // Every child task pushed starts the fetch of its node or first block (prefetch_any: all of
    // it), the nearest too: its first ray's test would otherwise wait for the whole fetch.
    // bounce:3, 3 interleaved rounds, mbvh_rs / mbvh8_single, against the two lines of the farther
    // children only: sponza 1.301 -> 1.343, conference 1.376 -> 1.391, sibenik_lucy 1.207 -> 1.348
    // (docs/PERFORMANCE.md, session 20).
    if (!(active & (active - 1))) {
      const int c = std::countr_zero(active);
      prefetch_any(m, nd.ref[c]);
      tasks[ntasks] = {nd.ref[c], uint32_t(c), cnt[c]};
      probe.write(&tasks[ntasks++], sizeof(Task));
      continue;
    }
    // Several children: the nearest (smallest summed or mean entry distance, `task_order`) is popped
    // first. A child no ray entered has count 0 (its mean 0/0 is replaced by the miss key).
    alignas(32) int32_t keys[N];
    if constexpr (N == 4) {
      const __m128i c4 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(cnt));
      const __m128 act = _mm_castsi128_ps(_mm_cmpgt_epi32(c4, _mm_setzero_si128()));
      const __m128 key = order == Order::mean ? _mm_div_ps(dsum, _mm_cvtepi32_ps(c4)) : dsum;
      _mm_store_si128(reinterpret_cast<__m128i*>(keys), mbvh_simd::sort4(mbvh_simd::sort_keys4(key, act)));
    } else {
      const __m256i c8 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(cnt));
      const __m256 act = _mm256_castsi256_ps(_mm256_cmpgt_epi32(c8, _mm256_setzero_si256()));
      const __m256 key = order == Order::mean ? _mm256_div_ps(dsum, _mm256_cvtepi32_ps(c8)) : dsum;
      _mm256_store_si256(reinterpret_cast<__m256i*>(keys), mbvh_simd::sort8(mbvh_simd::sort_keys8(key, act)));
    }
    for (int j = std::popcount(active) - 1; j >= 0; --j) {
      const uint32_t c = uint32_t(keys[j]) & (N - 1);
      prefetch_any(m, nd.ref[c]);
      tasks[ntasks] = {nd.ref[c], c, cnt[c]};
      probe.write(&tasks[ntasks++], sizeof(Task));
    }
  }
}

}  // namespace tb::mbvh_stream
