// mbvh8_packet: 8-ray packets over the 8-wide MBVH — the hybrid traversal of Benthin, Wald, Woop,
// Ernst and Mark (2012, "Combining single and packet-ray tracing for arbitrary ray distributions on
// the Intel MIC architecture", §4) that Embree's rtcIntersect8 runs (Wald et al. 2014, "Embree: a
// kernel framework for efficient CPU ray tracing", §4.2), on mbvh8_single's cached tree (same
// build parameters and defaults, spatial splits included).
//
// Every 8 consecutive rays of the batch (one per AVX2 lane, packet.h's RayGroup) walk the MBVH8
// together; a stack entry keeps each lane's entry distance of the child, so a popped child is
// entered only by the lanes whose closest hit still lies beyond it (Embree's per-lane tNear).
//   * Interior nodes, coherent groups (one origin and common direction signs, in a common-origin
//     batch: Embree's coherent hint): the group's interval bounds (GroupIA below) test all 8
//     children at once, as one interval ray, and order them; each child they keep is then tested
//     against the active lanes (one 8-lane slab test, the kernel library's slab<8>, on the plane
//     offsets the interval test has already formed) and pushed only if some lane enters it; the
//     nearest such child is entered at once, without a push and pop (as Embree's coherent
//     traversal keeps its `cur`). One or two kept children are ordered without the sort network.
//     Those three together with the tfar update (Group::sync_lane): +2 to +19% (median +9%) against
//     embree_packet8 on the scanned models, the held-out-shaped scene, spheres:1M and sponza, the
//     same hits (docs/PERFORMANCE.md, session 27).
//   * Interior nodes, other groups: every child against the active lanes, ordered by the nearest
//     lane's entry distance.
//   * Leaves: each active lane tests the leaf's triangle blocks with mbvh8_single's block test
//     (block_intersect: one ray against 8 triangles). A leaf is reached by ~3 of the 8 lanes on
//     primary rays (dragon_100k), so testing each triangle against all 8 lanes at every leaf (the
//     ray-parallel test of the binary packet schemes) did 2-3x the triangle work (callgrind:
//     docs/PERFORMANCE.md, "mbvh8_packet"). Only a leaf with few triangles and many active lanes
//     (2 x triangles < lanes x blocks: a floor or a wall seen by the whole group) is tested one
//     triangle against all lanes at a time (Group::parallel_block, the same operations per lane).
//   * When at most `switch` lanes are active at a node, each finishes that subtree alone with
//     mbvh8_single's loop (mbvh_traverse_from), Benthin et al.'s single-ray switch.
// A lane's per-ray constants (RayCtx, the block test's TriRay, the loop's NodeRay) are built the
// first time it needs them: a group that misses the scene after the root builds none.
//
// Why it exists: on the scanned models (bunny, dragon, lucy, buddha) and the held-out-shaped
// scene, the binary BVH packet schemes of the thesis (bvh_ranged, bvh_partition) trace primary
// rays at 0.75-0.91x embree_packet8 (issue 17); this is Embree's structure for them — 8 rays,
// 8-wide nodes, single-ray fallback — on travbench's own tree and kernels.
//
// Parameters: switch (0..8; default 0 for coherent groups, 2 for the other groups of common-origin
// batches, 8 without a common origin: measured, see kSwitchCoherent) and the MBVH build
// parameters of mbvh8_single.
#include <optional>

#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"
#include "traversal/packet.h"
#include "traversal/packet_box.h"

namespace tb {
namespace {

using packet::kW;
using packet::Packet;
using packet::RayGroup;

constexpr MBVHDefaults kDefaults = kMBVH8Defaults;  // mbvh8_single's cached tree
// `switch` by default: 0 for coherent groups (those the interval test takes: one origin, common
// direction signs, in a common-origin batch) and 8 in batches without a common origin. Measured, ratio
// to embree_packet8 on dragon_100k primary 512x512 (interleaved, 3 rounds): switch 0 / 1 / 2 =
// 0.95 / 0.93 / 0.87; on bounce:2, ratio to mbvh8_single: switch 0 / 1 / 2 / 4 / 6 / 8 = 0.45 /
// 0.58 / 0.66 / 0.71 / 0.81 / 0.87 — incoherent rays share too few nodes for 8-ray groups to pay,
// so each is traced alone from the root, as Embree's hybrid traversal does when few lanes are
// active (docs/PERFORMANCE.md, "mbvh8_packet"). The groups of a common-origin batch that the
// interval test refuses (mixed direction signs: `rnd`, random directions from one point) take 2:
// `rnd`, ratio to mbvh8_single (2-3 interleaved rounds), switch 0 / 2 / 8: sibenik 0.55 / 0.80 /
// 0.95, conference — / 0.93 / 0.97, dragon_100k 0.89 / 1.34 / 0.74, bunny — / 1.35 / 0.72 (the
// rays that miss an object leave together after a few group tests; those in a closed room do not).
constexpr uint32_t kSwitchCoherent = 0, kSwitchMixed = 2, kSwitchIncoherent = 8;

// A pending child of the group: its reference and each lane's entry distance (+inf: the lane does
// not enter it).
struct alignas(32) GroupEntry {
  __m256 tn;
  uint32_t ref;
};

// Eight rays of the batch, their hits and their lazily built one-ray constants.
struct Group {
  RayGroup G;          // o, inv, tmin, tfar (the closest hit so far; -inf for lanes past the rays)
  int sign = -1;       // direction sign bits shared by all lanes (x: 1, y: 2, z: 4), else -1
  bool common = false; // all lanes share one origin (org)
  Vec3 org;
  const Ray* rays = nullptr;
  uint32_t n = 0;
  Hit hit[kW];
  float tfar_max = 0;  // the largest lane of G.tfar
  uint32_t ready = 0;  // lanes whose hit record is set (prepare_lane)
  uint32_t rc_ready = 0, tr_ready = 0;  // lanes whose rc, tr are built
  alignas(32) int32_t kx[kW], ky[kW], kz[kW];  // shear8's
  alignas(32) float sx[kW], sy[kW], sz[kW];
  __m256 sx8, sy8, d8[3];  // shear8's sx, sy and the lanes' directions, as vectors
  bool uniform = false;    // every lane has the same kx, ky, kz
  std::optional<RayCtx> rc[kW];
  TriRay<8> tr[kW];

  template <class P>
  void load(const Ray* r, uint32_t count, P& probe) {
    rays = r, n = count, ready = 0, rc_ready = 0, tr_ready = 0;
    __m256 v[8];
    sign = packet::load_group(G, r, 0, n, v);
    org = r[0].org;
    common = true;
    for (int a = 0; a < 3; ++a) {
      d8[a] = v[4 + a];
      common &= _mm256_movemask_ps(_mm256_cmp_ps(v[a], _mm256_set1_ps(org[a]), _CMP_EQ_OQ)) == 0xFF;
    }
    tfar_max = Packet::hmax8(G.tfar);
    if constexpr (P::enabled) {
      for (uint32_t l = 0; l < n; ++l) probe.read(&r[l], sizeof(Ray));
      if (probe.counts) probe.counts->rays += n;
    }
  }
  // Lane l's hit record, set when the lane first reaches a leaf (a lane that never does hits
  // nothing: result). The shear of all 8 lanes is computed then, once, in SIMD (shear8); the
  // lane's TriRay (tr_of) and RayCtx (rc_of) only when the per-lane block test, a scalar kernel
  // or the one-ray loop reads them. A scalar RayCtx and TriRay per lane cost ~200 instructions,
  // most of a primary ray on the held-out-shaped scene (callgrind).
  // Forced inline with tr_of: g++ 12 kept both out of line, a call per lane at every leaf
  // (callgrind, held-out-shaped primary: 7% and 4% of the instructions); inlined, -1.5%
  // instructions and +2 to +8% time against embree_packet8 (session 17, docs/PERFORMANCE.md).
  [[gnu::always_inline]] void prepare_lane(uint32_t l) {
    if (ready >> l & 1) return;
    if (!ready) shear8();
    hit[l] = initial_hit(rays[l]);
    ready |= 1u << l;
  }
  // Lane l's block-test constants (the ray-parallel leaf test reads the group's instead).
  [[gnu::always_inline]] const TriRay<8>& tr_of(uint32_t l) {
    if (!(tr_ready >> l & 1)) {
      tr[l] = TriRay<8>(rays[l].org, rays[l].dir, kx[l], ky[l], kz[l], sx[l], sy[l], sz[l], rays[l].tmin);
      tr_ready |= 1u << l;
    }
    return tr[l];
  }
  const RayCtx& rc_of(uint32_t l) {
    if (!(rc_ready >> l & 1)) rc[l].emplace(rays[l]), rc_ready |= 1u << l;
    return *rc[l];
  }
  // RayCtx's watertight shear (kernels.h, Woop et al. 2013) for the 8 lanes at once: the same
  // comparisons pick the same axes (kz the dominant one, kx and ky swapped where dir[kz] < 0) and
  // the same divisions give the same sx, sy, sz, so each lane's TriRay equals TriRay(RayCtx(ray)).
  void shear8() {
    const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
    const __m256* d = d8;  // load's transposed directions
    __m256 a[3];
    for (int k = 0; k < 3; ++k) a[k] = _mm256_and_ps(d[k], absmask);
    const __m256 xy = _mm256_cmp_ps(a[0], a[1], _CMP_GE_OQ), xz = _mm256_cmp_ps(a[0], a[2], _CMP_GE_OQ),
                 yz = _mm256_cmp_ps(a[1], a[2], _CMP_GE_OQ);
    const __m256i z0 = _mm256_castps_si256(_mm256_and_ps(xy, xz)), z1 = _mm256_castps_si256(_mm256_andnot_ps(xy, yz));
    // kz = 0, 1 or 2; kx = kz + 1, ky = kz + 2 (mod 3).
    const __m256i two = _mm256_set1_epi32(2), one = _mm256_set1_epi32(1), zero = _mm256_setzero_si256();
    const __m256i vkz = _mm256_blendv_epi8(_mm256_blendv_epi8(two, one, z1), zero, z0);
    __m256i vkx = _mm256_blendv_epi8(_mm256_blendv_epi8(zero, two, z1), one, z0);
    __m256i vky = _mm256_blendv_epi8(_mm256_blendv_epi8(one, zero, z1), two, z0);
    auto pick = [&](__m256i k) {
      const __m256 m1 = _mm256_castsi256_ps(_mm256_cmpeq_epi32(k, one)), m2 = _mm256_castsi256_ps(_mm256_cmpeq_epi32(k, two));
      return _mm256_blendv_ps(_mm256_blendv_ps(d[0], d[1], m1), d[2], m2);
    };
    const __m256 dz = pick(vkz);
    const __m256i neg = _mm256_castps_si256(_mm256_cmp_ps(dz, _mm256_setzero_ps(), _CMP_LT_OQ));
    const __m256i tx = vkx;
    vkx = _mm256_blendv_epi8(vkx, vky, neg);
    vky = _mm256_blendv_epi8(vky, tx, neg);
    const __m256 vsx = _mm256_div_ps(pick(vkx), dz), vsy = _mm256_div_ps(pick(vky), dz);
    const __m256 vsz = _mm256_div_ps(_mm256_set1_ps(1.f), dz);
    _mm256_store_si256(reinterpret_cast<__m256i*>(kx), vkx);
    _mm256_store_si256(reinterpret_cast<__m256i*>(ky), vky);
    _mm256_store_si256(reinterpret_cast<__m256i*>(kz), vkz);
    _mm256_store_ps(sx, vsx), _mm256_store_ps(sy, vsy), _mm256_store_ps(sz, vsz);
    sx8 = vsx, sy8 = vsy;
    uniform = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(vkx, _mm256_set1_epi32(kx[0])))) == 0xFF &&
              _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(vky, _mm256_set1_epi32(ky[0])))) == 0xFF &&
              _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(vkz, _mm256_set1_epi32(kz[0])))) == 0xFF;
  }

  // The lanes `active` against the first `count` triangles of block b, one triangle against all
  // lanes at a time (the ray-parallel form of block_intersect, for a leaf with few triangles and
  // many lanes: the held-out-shaped scene's ground). Only when every lane shares its shear axes
  // (uniform): each lane then computes block_intersect's float operations in its order — the
  // vertex minus the lane's origin, the shear with the lane's sx and sy, watertight_inside — and
  // the candidates' distances come from the same double plane equation (four lanes at a time, the
  // triangle's normal hoisted, as packet_tri.h does), so every lane's hit equals the one-ray test's.
  // Its lanes must be prepared (prepare_lane).
  template <int BW>
  void parallel_block(const TriBlock<BW>& b, uint32_t count, uint32_t active) {
    const int ax = kx[0], ay = ky[0], az = kz[0];
    for (uint32_t j = 0; j < count; ++j) {
      __m256 P[3][3];  // vertex c, axis a, minus each lane's origin
      for (int c = 0; c < 3; ++c)
        for (int a = 0; a < 3; ++a) P[c][a] = _mm256_sub_ps(_mm256_set1_ps(b.v[c][a][j]), G.o[a]);
      const __m256 Ax = shear<8>(P[0][ax], sx8, P[0][az]), Ay = shear<8>(P[0][ay], sy8, P[0][az]);
      const __m256 Bx = shear<8>(P[1][ax], sx8, P[1][az]), By = shear<8>(P[1][ay], sy8, P[1][az]);
      const __m256 Cx = shear<8>(P[2][ax], sx8, P[2][az]), Cy = shear<8>(P[2][ay], sy8, P[2][az]);
      __m256 U, V, W, det;
      uint32_t m = uint32_t(_mm256_movemask_ps(watertight_inside<8>(Ax, Ay, Bx, By, Cx, Cy, U, V, W, det))) & active;
      const uint32_t prim = b.prim[j];
      for (uint32_t k = m; k; k &= k - 1)  // a lane's closest hit again: the same t (block_intersect)
        if (hit[std::countr_zero(k)].prim == prim) m &= ~(1u << std::countr_zero(k));
      if (!m) continue;
      using D = simd::D4v;
      const Vec3D<double> v0{b.v[0][0][j], b.v[0][1][j], b.v[0][2][j]};
      const Vec3D<double> nd = plane_normal(v0, Vec3D<double>{b.v[1][0][j], b.v[1][1][j], b.v[1][2][j]},
                                            Vec3D<double>{b.v[2][0][j], b.v[2][1][j], b.v[2][2][j]});
      const Vec3D<D> n{D(nd.x), D(nd.y), D(nd.z)};
      alignas(32) float ts[kW], us[kW], vs[kW], ws[kW], dets[kW], azs[kW], bzs[kW], czs[kW];
      uint32_t parallel = 0;
      for (int h = 0; h < 2; ++h) {
        auto half = [h](__m256 v) { return D(h ? _mm256_extractf128_ps(v, 1) : _mm256_castps256_ps128(v)); };
        const D dn = plane_dot(n, Vec3D<D>{half(d8[0]), half(d8[1]), half(d8[2])});
        const D num = plane_dot(n, Vec3D<D>{D(v0.x) - half(G.o[0]), D(v0.y) - half(G.o[1]), D(v0.z) - half(G.o[2])});
        parallel |= uint32_t(dn.zero_mask()) << (4 * h);
        _mm_store_ps(ts + 4 * h, (num / dn).to_float());
      }
      _mm256_store_ps(us, U), _mm256_store_ps(vs, V), _mm256_store_ps(ws, W), _mm256_store_ps(dets, det);
      if (parallel & m) {
        _mm256_store_ps(azs, P[0][az]), _mm256_store_ps(bzs, P[1][az]), _mm256_store_ps(czs, P[2][az]);
      }
      for (; m; m &= m - 1) {
        const uint32_t l = uint32_t(std::countr_zero(m));
        const float inv_det = 1.f / dets[l];
        const float t = parallel >> l & 1 ? sheared_distance<1>(sz[l], us[l], vs[l], ws[l], azs[l], bzs[l], czs[l], inv_det)
                                          : ts[l];
        if (!(t >= rays[l].tmin && t < hit[l].t)) continue;
        hit[l] = Hit{t, prim, vs[l] * inv_det, ws[l] * inv_det};
      }
    }
  }
  // Lane l of G.tfar from its closest hit: a broadcast and a blend, not a scalar store into an
  // array that sync then reads as a vector (a 4-byte store cannot forward to a 32-byte load: perf
  // put 5% of the packet loop's samples on that reload after every leaf).
  void sync_lane(uint32_t l) {
    const __m256 lane = _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), _mm256_set1_epi32(int(l))));
    G.tfar = _mm256_blendv_ps(G.tfar, _mm256_set1_ps(hit[l].t), lane);
  }
  void sync() { tfar_max = Packet::hmax8(G.tfar); }
  // A lane that never needed its constants never reached a leaf: it hits nothing.
  [[gnu::always_inline]] Hit result(uint32_t l) const { return ready >> l & 1 ? finish_hit(hit[l]) : finish_hit(Hit{INFINITY, kNoHit, 0.f, 0.f}); }
};

// The coherent path's bounds (Embree's packet frustum for coherent rays), for a group whose rays
// share one origin o and, per axis, direction signs: their reciprocal directions lie in [r0, r1].
// A lane computes a child's near-plane distance as fl(fl(pn - o) * r) and its far-plane distance
// as fl(fl(fl(pf - o) * r) * kFarPad) (slab<8>); rounding is monotonic, so over the lanes those lie
// between the corner products with r0 and r1. The least near and the greatest (padded) far over
// the corners bound every lane's test from outside: one 8-wide test of a node's children skips
// only children that no lane enters by its own test, and orders the others by their bound.
// Unusable (init false) without a common origin and common signs, or when a reciprocal
// direction is infinite, zero or NaN (a corner product would be NaN). Tried and dropped: the
// inner bound (greatest near against least far) to skip the lanes' own test where every lane
// must enter: 2-3% slower on dragon_100k, bunny and the held-out-shaped scene (primary).
struct GroupIA {
  __m256 o[3], r0[3], r1[3], tmin;
  bool neg[3];
  bool init(const Group& grp) {
    if (grp.sign < 0 || !grp.common) return false;
    const RayGroup& G = grp.G;
    const __m256 absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
    __m256 ok = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
    for (int a = 0; a < 3; ++a) {
      const __m256 ar = _mm256_and_ps(G.inv[a], absmask);
      ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(ar, _mm256_setzero_ps(), _CMP_GT_OQ),
                                           _mm256_cmp_ps(ar, _mm256_set1_ps(INFINITY), _CMP_LT_OQ)));
    }
    if (_mm256_movemask_ps(ok) != 0xFF) return false;
    for (int a = 0; a < 3; ++a) {
      neg[a] = (grp.sign >> a) & 1;
      o[a] = _mm256_set1_ps(grp.org[a]);
      r0[a] = _mm256_set1_ps(Packet::hmin8(G.inv[a])), r1[a] = _mm256_set1_ps(Packet::hmax8(G.inv[a]));
    }
    tmin = _mm256_set1_ps(Packet::hmin8(G.tmin));
    return true;
  }
  // The children some lane may enter before tfar (all-ones lanes) and their entry bounds n; xn,
  // xf: each child's near and far plane offsets (plane - o) per axis, as child_test's
  // same_sign_hits<true> computes them (the same subtraction: child_ia_test reuses them).
  [[gnu::always_inline]] __m256 test(const MBVHNode<8>& nd, float tfar, __m256& n, __m256 (&xn)[3], __m256 (&xf)[3]) const {
    const __m256 pad = _mm256_set1_ps(kFarPad);
    __m256 lo = tmin, hi = _mm256_set1_ps(tfar);
    for (int a = 0; a < 3; ++a) {
      const __m256 bl = _mm256_load_ps(nd.box[a]), bh = _mm256_load_ps(nd.box[3 + a]);
      xn[a] = _mm256_sub_ps(neg[a] ? bh : bl, o[a]), xf[a] = _mm256_sub_ps(neg[a] ? bl : bh, o[a]);
      lo = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(xn[a], r0[a]), _mm256_mul_ps(xn[a], r1[a])), lo);
      hi = _mm256_min_ps(_mm256_mul_ps(_mm256_max_ps(_mm256_mul_ps(xf[a], r0[a]), _mm256_mul_ps(xf[a], r1[a])), pad), hi);
    }
    n = lo;
    return _mm256_cmp_ps(lo, hi, _CMP_LE_OQ);
  }
};

// The lanes `act` of the group against child c of node nd: the entering lanes (all-ones) and their
// entry distances tn, by packet_box.h's group test (planes selected once for the group when its
// lanes share direction signs, scalar offsets with a common origin, per lane otherwise).
[[gnu::always_inline]] inline __m256 child_test(const Group& grp, const MBVHNode<8>& nd, uint32_t c, __m256 act,
                                                __m256& tn) {
  const float lo[3] = {nd.box[0][c], nd.box[1][c], nd.box[2][c]}, hi[3] = {nd.box[3][c], nd.box[4][c], nd.box[5][c]};
  __m256 in;
  if (grp.sign < 0) {
    const __m256 lo8[3] = {_mm256_set1_ps(lo[0]), _mm256_set1_ps(lo[1]), _mm256_set1_ps(lo[2])};
    const __m256 hi8[3] = {_mm256_set1_ps(hi[0]), _mm256_set1_ps(hi[1]), _mm256_set1_ps(hi[2])};
    in = packet::box_hits(grp.G, lo8, hi8, tn);
  } else if (grp.common) {
    in = packet::same_sign_hits<true>(grp.G, grp.sign, grp.org, lo, hi, tn);
  } else {
    in = packet::same_sign_hits<false>(grp.G, grp.sign, grp.org, lo, hi, tn);
  }
  return _mm256_and_ps(in, act);
}

// child_test for a coherent group (GroupIA's: one origin, shared direction signs) from the plane
// offsets GroupIA::test computed for all children: child c's lane broadcast instead of its six
// planes loaded, subtracted and broadcast again. The same values as same_sign_hits<true> (the
// same subtraction of the same operands), so the same lanes and distances.
[[gnu::always_inline]] inline __m256 child_ia_test(const Group& grp, const __m256 (&xn)[3], const __m256 (&xf)[3], uint32_t c,
                                                   __m256 act, __m256& tn) {
  const __m256i ci = _mm256_set1_epi32(int(c));
  const __m256 n[3] = {_mm256_permutevar8x32_ps(xn[0], ci), _mm256_permutevar8x32_ps(xn[1], ci), _mm256_permutevar8x32_ps(xn[2], ci)};
  const __m256 f[3] = {_mm256_permutevar8x32_ps(xf[0], ci), _mm256_permutevar8x32_ps(xf[1], ci), _mm256_permutevar8x32_ps(xf[2], ci)};
  return _mm256_and_ps(slab<8, false>(n, f, grp.G.inv, grp.G.inv, grp.G.tmin, grp.G.tfar, tn), act);
}

class MBVH8Packet final : public MBVHScheme<MBVH8Packet, MBVHData<8, 8>> {
 public:
  explicit MBVH8Packet(const SchemeConfig& cfg)
      : MBVHScheme(cfg, kDefaults), switch_(cfg.find_int("switch")) {}
  std::string_view name() const override { return "mbvh8_packet"; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const MBVHData<8, 8>& d = std::get<0>(data_.data);
    const size_t depth = mbvh_stack_entries(8, d.mbvh->stats.max_depth);
    auto grp = std::make_unique<Group>();
    std::vector<GroupEntry> stack(depth);
    std::vector<MBVHStackEntry> single(depth);
    const uint32_t end = batch.packet_begin[range.last];
    // A group the interval test takes (common origin and direction signs) is coherent; the others
    // are groups of random directions from one point (`rnd`) or of a batch without a common origin.
    const uint32_t sw_coherent = switch_ ? uint32_t(*switch_) : kSwitchCoherent;
    const uint32_t sw_other = switch_ ? uint32_t(*switch_) : batch.common_origin ? kSwitchMixed : kSwitchIncoherent;
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      constexpr TriKernel K = decltype(k)::value;
      auto go = [&](auto order, auto coherent) {
        for (uint32_t i = batch.packet_begin[range.first]; i < end; i += kW) {
          Group& g = *grp;
          g.load(&batch.rays[i], std::min<uint32_t>(kW, end - i), probe);
          GroupIA ia;
          if (decltype(coherent)::value && ia.init(g))
            trace_group<K, decltype(order)::value, true>(d, g, sw_coherent, stack.data(), single.data(), &ia, probe);
          else
            trace_group<K, decltype(order)::value, false>(d, g, sw_other, stack.data(), single.data(), nullptr, probe);
          for (uint32_t l = 0; l < g.n; ++l) {
            hits[i + l] = g.result(l);
            probe.write(&hits[i + l], sizeof(Hit));
          }
        }
      };
      // The single-ray loop's child order as mbvh8_single's `auto` (mbvh_traverse.h, ChildOrder).
      if (batch.common_origin)
        go(std::integral_constant<ChildOrder, ChildOrder::branching>{}, std::true_type{});
      else if constexpr (K == TriKernel::watertight)
        go(std::integral_constant<ChildOrder, ChildOrder::sort_always>{}, std::false_type{});
      else
        go(std::integral_constant<ChildOrder, ChildOrder::branching>{}, std::false_type{});
    });
  }

 private:
  template <TriKernel K, ChildOrder O, bool kIA, class P>
  static void trace_group(const MBVHData<8, 8>& d, Group& g, uint32_t sw, GroupEntry* stack, MBVHStackEntry* single,
                          const GroupIA* ia, P& probe) {
    const MBVH<8, 8>& m = *d.mbvh;
    const __m256 inf = _mm256_set1_ps(INFINITY);
    uint32_t sp = 0, cur = 0;
    __m256 tn_cur = g.G.tmin;  // lanes past the batch's rays have tfar = -inf: never active
    for (;;) {
      // The lanes that still enter `cur`: its entry distance lies before their closest hit (a hit
      // at the entry distance or beyond cannot be closer).
      const __m256 act = _mm256_cmp_ps(tn_cur, g.G.tfar, _CMP_LT_OQ);
      const uint32_t active = uint32_t(_mm256_movemask_ps(act));
      if (active) {
        const uint32_t count = uint32_t(std::popcount(active));
        if (count <= sw) {
          for (uint32_t a = active; a; a &= a - 1) finish_lane<K, O>(d, g, uint32_t(std::countr_zero(a)), cur, single, probe);
          g.sync();
        } else if (mbvh_ref::is_leaf(cur)) {
          probe_leaf(m, cur, probe, count);
          const uint32_t first = mbvh_ref::first_block(cur), nt = mbvh_ref::num_tris(cur);
          const bool small = nt <= m.small_leaf;
          // Few triangles, many lanes (a leaf of nt triangles in `blocks` blocks): one triangle
          // against all lanes at a time; otherwise each lane tests the blocks (block_intersect).
          bool ray_parallel = false;
          if constexpr (K == TriKernel::watertight) {
            g.prepare_lane(uint32_t(std::countr_zero(active)));  // the group's shear (uniform)
            ray_parallel = g.uniform && 2 * nt < count * (small ? 1 : (nt + 7) / 8);
          }
          if (ray_parallel) {
            for (uint32_t a = active; a; a &= a - 1) g.prepare_lane(uint32_t(std::countr_zero(a)));
            if (small) {
              g.parallel_block(m.small[first], nt, active);
            } else {
              for (uint32_t k = 0; k * 8 < nt; ++k) g.parallel_block(m.blocks[first + k], std::min(8u, nt - k * 8), active);
            }
            for (uint32_t a = active; a; a &= a - 1) g.sync_lane(uint32_t(std::countr_zero(a)));
          } else {
            for (uint32_t a = active; a; a &= a - 1) {
              const uint32_t l = uint32_t(std::countr_zero(a));
              g.prepare_lane(l);
              leaf_test<8, 8, K>(m, d.tris.get(), g.tr_of(l), K == TriKernel::watertight ? nullptr : &g.rc_of(l), cur,
                                 g.hit[l]);
              g.sync_lane(l);
            }
          }
          g.sync();
        } else {
          const MBVHNode<8>& nd = m.nodes[cur];
          probe.node(&nd, sizeof(nd), count);
          if constexpr (kIA) {
            // The interval test culls and orders the children (nearest bound first); each child it
            // keeps is pushed, far to near, if some active lane's own test enters it, except the
            // nearest such child, which is entered at once. Two kept children are ordered by their
            // bounds, an exact tie to the lower slot (the network's keys give the distance's low 3
            // bits to the slot, so within 8 ulps they may order by slot: the order differs there,
            // never a lane's closest distance).
            __m256 bound, xn[3], xf[3];
            const __m256 maybe = ia->test(nd, g.tfar_max, bound, xn, xf);
            const int mask = _mm256_movemask_ps(maybe);
            alignas(32) uint32_t keys[8];
            const int kept = std::popcount(unsigned(mask));
            if (kept == 1) {
              keys[0] = uint32_t(std::countr_zero(unsigned(mask)));
            } else if (kept == 2) {
              uint32_t c0 = uint32_t(std::countr_zero(unsigned(mask))), c1 = uint32_t(std::countr_zero(unsigned(mask & (mask - 1))));
              alignas(32) float b[8];
              _mm256_store_ps(b, bound);
              if (b[c1] < b[c0]) std::swap(c0, c1);
              keys[0] = c0, keys[1] = c1;
            } else {
              _mm256_store_si256(reinterpret_cast<__m256i*>(keys), mbvh_simd::sort8(mbvh_simd::sort_keys8(bound, maybe)));
            }
            bool any = false;
            uint32_t next = 0;
            __m256 next_tn = inf;
            for (int j = kept; j-- > 0;) {
              const uint32_t c = keys[j] & 7;
              __m256 tn;
              const __m256 in = child_ia_test(g, xn, xf, c, act, tn);
              if (_mm256_testz_ps(in, in)) continue;
              prefetch_any(m, nd.ref[c]);
              if (any) push(stack, sp, next_tn, next, probe);
              any = true, next = nd.ref[c], next_tn = _mm256_blendv_ps(inf, tn, in);
            }
            if (any) {
              cur = next, tn_cur = next_tn;
              continue;
            }
          } else {
            // Every child against the active lanes, ordered by the nearest lane's entry distance.
            __m256 tns[8];
            float key[8];
            uint32_t idx[8], cnt = 0;
            for (uint32_t c = 0; c < nd.num_children; ++c) {
              __m256 tn;
              const __m256 in = child_test(g, nd, c, act, tn);
              if (_mm256_testz_ps(in, in)) continue;
              tns[c] = _mm256_blendv_ps(inf, tn, in);
              key[c] = Packet::hmin8(tns[c]);
              uint32_t j = cnt++;
              for (; j > 0 && key[idx[j - 1]] > key[c]; --j) idx[j] = idx[j - 1];
              idx[j] = c;
            }
            for (uint32_t j = cnt; j-- > 0;) {
              if (j > 0) prefetch_ref(m, nd.ref[idx[j]]);
              push(stack, sp, tns[idx[j]], nd.ref[idx[j]], probe);
            }
          }
        }
      }
      if (sp == 0) return;
      --sp;
      probe.read(&stack[sp], sizeof(GroupEntry));
      cur = stack[sp].ref;
      tn_cur = stack[sp].tn;
    }
  }

  template <class P>
  [[gnu::always_inline]] static void push(GroupEntry* stack, uint32_t& sp, __m256 tn, uint32_t ref, P& probe) {
    stack[sp].tn = tn;
    stack[sp].ref = ref;
    probe.write(&stack[sp], sizeof(GroupEntry));
    ++sp;
  }

  // Lane l leaves the group at subtree `ref` and finishes it alone with mbvh8_single's loop.
  template <TriKernel K, ChildOrder O, class P>
  static void finish_lane(const MBVHData<8, 8>& d, Group& g, uint32_t l, uint32_t ref, MBVHStackEntry* stack,
                          P& probe) {
    g.prepare_lane(l);
    const RayCtx& rc = g.rc_of(l);
    const NodeRay<8> nr(rc, g.rays[l].tmin, d.mbvh->coord_bound);
    MBVHCursor at{ref, 0};
    mbvh_traverse_from<8, 8, K, O>(*d.mbvh, d.tris.get(), nr, g.tr_of(l), &rc, at, g.hit[l], stack, probe,
                                   NeverLeave{});
    g.sync_lane(l);
  }

  std::optional<int> switch_;  // unset: kSwitchCoherent or kSwitchIncoherent by batch
};

}  // namespace

std::unique_ptr<Traverser> make_mbvh8_packet(const SchemeConfig& cfg) { return std::make_unique<MBVH8Packet>(cfg); }
ParamSpecs params_mbvh8_packet() {
  return mbvh_param_specs(kDefaults) +
         ParamSpecs{auto_default(int_param("switch", 0, 0, 8,
                                           "a group with at most this many active rays at a node finishes that subtree "
                                           "one ray at a time (mbvh8_single's loop); 0: never, 8: always"),
                                 "0 for groups of a common-origin batch sharing direction signs, 2 for its other "
                                 "groups, 8 without a common origin")};
}

}  // namespace tb
