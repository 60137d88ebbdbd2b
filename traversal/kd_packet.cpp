// kd_packet: SIMD ray-packet traversal of the SAH kD-tree (thesis §2.2.2, Alg. 2.3; Wald et al.
// 2001 "Interactive rendering with coherent ray tracing"), AVX2 8 rays per instruction.
//
// As Alg. 2.3 prescribes, every scalar of Alg. 2.2 becomes a vector (tnear, tfar and d per ray)
// and a node is visited when any active ray wants to visit it: all active rays near only -> near
// child; all far only -> far child; otherwise the far child is pushed with max(d, tnear)..tfar
// and the near child entered with tnear..min(d, tfar). (The thesis' listing states the two
// single-child tests with "any"; it is "all active rays", or rays would skip cells they cross.)
//
// Near and far must be the same child for every ray of a packet, so the thesis splits packets
// whose direction signs differ: "two packets traverse the kD-tree independently, both with some
// rays deactivated". Here each packet of the batch (16x16 primary rays; bounce rays keep their
// pixel's packet) is split into up to eight sign-coherent sub-packets, one per direction octant
// (the sign bit decides, so -0 goes with the negatives, matching the single-ray scheme), and the
// rays of an octant are compacted instead of masked so no SIMD lane is spent on another octant.
// Per-ray active masks are recomputed at every node from tnear <= min(tfar, closest hit); 8-ray
// groups without an active ray are skipped through a group bit mask (the "first active ray"
// idea of Reshetov's and Wald's large-packet traversals, per group). A ray whose hit lies inside
// the current leaf's cell is finished; the packet terminates when all its rays are (Alg. 2.3
// "if all Tfar <= ray.Tmax").
//
// Interval padding, +-0 and NaN distances behave exactly as in kd_single (see there and
// structures/kdtree.h), including the rule that a ray inside a split plane is not finished while
// the far child it shares its interval with is pending (per-lane counters here). The triangle
// tests are the kernel library's (traversal/kernels.h) on 8 lanes, the same templates kd_single
// runs on one (the build uses -ffp-contract=off; the watertight kernel's exact_plane_distance runs
// per hitting lane), so kd_packet returns bit-identical hits to kd_single for every kernel
// (tests/test_kdtree.cpp checks this); --kernel selects the variant through dispatch_kernel.
// Parameter kd_packet (8..256, multiple of 8) caps the rays of one sub-packet (default 256: a
// whole octant of a 16x16 packet traverses together).
#include <immintrin.h>

#include <bit>

#include "structures/kdtree.h"
#include "traversal/bvh_common.h"
#include "traversal/kd_common.h"

namespace tb {
namespace {

constexpr int kMaxRays = 256;
constexpr int kGroups = kMaxRays / 8;

// The suite's one SIMD wrapper (traversal/simd.h), 8 lanes.
using S = simd::V<8>;
// kd_pad_up / kd_pad_down of structures/kdtree.h, lane by lane: x * (1 +- copysign(pad, x)).
inline __m256 vpad_up(__m256 x) {
  return S::mul(x, S::add(S::set1(1.f), S::or_(S::set1(kKdPad), S::and_(x, S::set1(-0.f)))));
}
inline __m256 vpad_down(__m256 x) {
  return S::mul(x, S::sub(S::set1(1.f), S::or_(S::set1(kKdPad), S::and_(x, S::set1(-0.f)))));
}

// The 8-ray groups of a sub-packet that still take part are a bit mask (at most 32 groups).
#define TB_FOR_GROUPS(g, mask) for (uint32_t g##_m = (mask), g = 0; g##_m && ((g = __builtin_ctz(g##_m)), true); g##_m &= g##_m - 1)

// Copies the interval vectors of the groups in `mask`.
inline void copy_groups(float* dst, const float* src, uint32_t mask) {
  TB_FOR_GROUPS(g, mask) _mm256_store_ps(dst + 8 * g, _mm256_load_ps(src + 8 * g));
}

// One sign-coherent sub-packet in SoA form, plus its traversal stack. Every float array is
// 1 KiB, so all stay 32-byte aligned for the aligned AVX loads and stores.
struct alignas(32) Workspace {
  // Rays. ks_* hold the watertight kernel's axis permutation as lane masks: ks_x0 = (kx == 0).
  float ox[kMaxRays], oy[kMaxRays], oz[kMaxRays];
  float dx[kMaxRays], dy[kMaxRays], dz[kMaxRays];
  float ix[kMaxRays], iy[kMaxRays], iz[kMaxRays];
  float sx[kMaxRays], sy[kMaxRays], sz[kMaxRays], tmin[kMaxRays];
  float kx0[kMaxRays], kx1[kMaxRays], ky0[kMaxRays], ky1[kMaxRays], kz0[kMaxRays], kz1[kMaxRays];
  // Results and termination: lim = closest hit so far, or -inf once the ray is finished.
  float hit_t[kMaxRays], hit_u[kMaxRays], hit_v[kMaxRays], lim[kMaxRays];
  uint32_t prim[kMaxRays];
  // Current cell interval per ray and the per-node scratch of both children's intervals.
  float tn[kMaxRays], tf[kMaxRays], tf_near[kMaxRays], tn_far[kMaxRays];
  uint32_t ray[kMaxRays];
  // The stack: per level the node, the group range and the intervals of those groups.
  struct Level {
    uint32_t node;
    uint32_t groups;
    uint32_t nan_groups;  // groups with rays inside the split plane (their lanes: snan)
  };
  Level level[KDTree::kMaxDepth + 2];
  alignas(32) float stn[KDTree::kMaxDepth + 2][kMaxRays];
  alignas(32) float stf[KDTree::kMaxDepth + 2][kMaxRays];
  // Rays inside a split plane (NaN distance) see both children over one t-interval; while such
  // a far child is pending, a hit in the near child does not finish the ray (see kd_single).
  alignas(32) int32_t in_plane[kMaxRays];
  uint8_t nan_now[kGroups];
  uint8_t snan[KDTree::kMaxDepth + 2][kGroups];
};

class KDPacket final : public KDScheme<KDPacket> {
 public:
  explicit KDPacket(const SchemeConfig& cfg)
      : TreeScheme(cfg), max_rays_(cfg.get_int("kd_packet")) {
    if (max_rays_ % 8 != 0) throw InputError("parameter kd_packet must be a multiple of 8 in [8, 256]");
  }
  std::string_view name() const override { return "kd_packet"; }

  template <TriKernel K, class P>
  void run_kernel(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    thread_local std::unique_ptr<Workspace> ws_holder;
    if (!ws_holder) ws_holder = std::make_unique<Workspace>();
    Workspace& ws = *ws_holder;
    std::vector<uint32_t> octant[8];
    for (uint32_t p = range.first; p < range.last; ++p) {
      for (auto& o : octant) o.clear();
      for (uint32_t i = batch.packet_begin[p]; i < batch.packet_begin[p + 1]; ++i) {
        const Vec3 d = batch.rays[i].dir;
        octant[std::signbit(d.x) | (std::signbit(d.y) << 1) | (std::signbit(d.z) << 2)].push_back(i);
      }
      for (uint32_t o = 0; o < 8; ++o)
        for (size_t s = 0; s < octant[o].size(); s += size_t(max_rays_)) {
          const int n = int(std::min(octant[o].size() - s, size_t(max_rays_)));
          trace_subpacket<K>(batch, &octant[o][s], n, o, hits, ws, probe);
        }
    }
  }

 private:
  // Loads rays into the workspace; lanes past n (and rays that miss the root cell) are inactive.
  template <class P>
  int load(const RayBatch& batch, const uint32_t* idx, int n, Workspace& ws, P& probe) const {
    const KDTree& kd = *data_.tree;
    const int groups = (n + 7) / 8;
    int live = 0;
    for (int j = 0; j < groups * 8; ++j) {
      const uint32_t ri = idx[j < n ? j : 0];
      const Ray& r = batch.rays[ri];
      if (j < n) probe.read(&r, sizeof(Ray));
      const RayCtx rc(r);
      ws.ray[j] = ri;
      ws.ox[j] = r.org.x, ws.oy[j] = r.org.y, ws.oz[j] = r.org.z;
      ws.dx[j] = r.dir.x, ws.dy[j] = r.dir.y, ws.dz[j] = r.dir.z;
      ws.ix[j] = rc.inv.x, ws.iy[j] = rc.inv.y, ws.iz[j] = rc.inv.z;
      ws.sx[j] = rc.sx, ws.sy[j] = rc.sy, ws.sz[j] = rc.sz;
      ws.tmin[j] = r.tmin;
      const float ones = std::bit_cast<float>(~0u);
      ws.kx0[j] = rc.kx == 0 ? ones : 0.f, ws.kx1[j] = rc.kx == 1 ? ones : 0.f;
      ws.ky0[j] = rc.ky == 0 ? ones : 0.f, ws.ky1[j] = rc.ky == 1 ? ones : 0.f;
      ws.kz0[j] = rc.kz == 0 ? ones : 0.f, ws.kz1[j] = rc.kz == 1 ? ones : 0.f;
      ws.hit_t[j] = r.tmax, ws.hit_u[j] = 0.f, ws.hit_v[j] = 0.f, ws.prim[j] = kNoHit;
      ws.in_plane[j] = 0;
      float tn, tf;
      if (j < n && !kd.nodes.empty() && kd_clip_ray(kd.bounds, rc.org, rc.dir, rc.inv, r.tmin, r.tmax, tn, tf)) {
        ws.tn[j] = tn, ws.tf[j] = tf, ws.lim[j] = r.tmax;
        ++live;
      } else {
        ws.tn[j] = INFINITY, ws.tf[j] = -INFINITY, ws.lim[j] = -INFINITY;
      }
    }
    return live;
  }

  // Active lanes of group g: tnear <= min(tfar, limit).
  static __m256 active(const Workspace& ws, uint32_t g) {
    const __m256 tn = _mm256_load_ps(ws.tn + 8 * g), tf = _mm256_load_ps(ws.tf + 8 * g);
    return S::le(tn, _mm256_min_ps(tf, _mm256_load_ps(ws.lim + 8 * g)));
  }

  template <TriKernel K, class P>
  void trace_subpacket(const RayBatch& batch, const uint32_t* idx, int n, uint32_t oct, std::span<Hit> hits,
                       Workspace& ws, P& probe) const {
    if constexpr (P::enabled) if (probe.counts) probe.counts->rays += uint64_t(n);
    int live = load(batch, idx, n, ws, probe);
    const KDNode* nodes = data_.tree->nodes.data();
    const TriangleSet& tris = *data_.tris;
    const float* org[3] = {ws.ox, ws.oy, ws.oz};
    const float* inv[3] = {ws.ix, ws.iy, ws.iz};
    const int ngroups = (n + 7) / 8;
    uint32_t groups = ngroups == 32 ? ~0u : (1u << ngroups) - 1;  // groups with active rays
    int sp = 0;
    uint32_t node = 0;
    bool running = live > 0;
    while (running) {
      const KDNode* nd = &nodes[node];
      bool at_leaf = true;
      while (!nd->is_leaf()) {
        const int a = nd->axis();
        const uint32_t neg = (oct >> a) & 1u;
        const uint32_t near = nd->left() + neg, far = nd->left() + (neg ^ 1u);
        const __m256 split = S::set1(nd->split());
        uint32_t near_groups = 0, far_groups = 0, nan_groups = 0;
        int visitors = 0;
        TB_FOR_GROUPS(g, groups) {
          const __m256 tn = _mm256_load_ps(ws.tn + 8 * g), tf = _mm256_load_ps(ws.tf + 8 * g);
          const __m256 lim = _mm256_min_ps(tf, _mm256_load_ps(ws.lim + 8 * g));
          const __m256 d = S::mul(S::sub(split, _mm256_load_ps(org[a] + 8 * g)), _mm256_load_ps(inv[a] + 8 * g));
          // min_ps/max_ps return their second operand when either is NaN: a NaN distance keeps
          // the whole interval for both children, as in kd_single.
          const __m256 tfn = _mm256_min_ps(vpad_up(d), tf);
          const __m256 tnf = _mm256_max_ps(vpad_down(d), tn);
          _mm256_store_ps(ws.tf_near + 8 * g, tfn);
          _mm256_store_ps(ws.tn_far + 8 * g, tnf);
          const int mn = S::mask(S::le(tn, _mm256_min_ps(tfn, lim)));
          const int mf = S::mask(S::le(tnf, lim));
          const int nan = S::mask(_mm256_cmp_ps(d, d, _CMP_UNORD_Q)) & mf;
          ws.nan_now[g] = uint8_t(nan);
          near_groups |= uint32_t(mn != 0) << g;
          far_groups |= uint32_t(mf != 0) << g;
          nan_groups |= uint32_t(nan != 0) << g;
          if constexpr (P::enabled) visitors += __builtin_popcount(unsigned(mn | mf));
        }
        if (!(near_groups | far_groups)) {
          at_leaf = false;
          break;
        }
        probe.node(nd, sizeof(KDNode), uint32_t(visitors));
        if (near_groups && far_groups) {
          // Both children: push the far one with [max(d, tnear), tfar] for its groups.
          Workspace::Level& lv = ws.level[sp];
          lv = {far, far_groups, nan_groups};
          TB_FOR_GROUPS(g, nan_groups) {
            ws.snan[sp][g] = ws.nan_now[g];
            for (unsigned b = ws.nan_now[g]; b; b &= b - 1) ws.in_plane[8 * g + __builtin_ctz(b)]++;
          }
          copy_groups(ws.stn[sp], ws.tn_far, far_groups);
          copy_groups(ws.stf[sp], ws.tf, far_groups);
          if constexpr (P::enabled) {
            probe.write(&lv, sizeof lv);
            TB_FOR_GROUPS(g, far_groups) {
              probe.write(ws.stn[sp] + 8 * g, 32);
              probe.write(ws.stf[sp] + 8 * g, 32);
            }
          }
          ++sp;
        }
        if (near_groups) {
          copy_groups(ws.tf, ws.tf_near, near_groups);
          node = near, groups = near_groups;
        } else {
          copy_groups(ws.tn, ws.tn_far, far_groups);
          node = far, groups = far_groups;
        }
        nd = &nodes[node];
      }
      if (at_leaf) live -= intersect_leaf<K>(*nd, tris, groups, ws, probe);
      if (live <= 0) break;
      // Pop the nearest pending cell that some ray still needs.
      running = false;
      while (sp > 0) {
        --sp;
        const Workspace::Level lv = ws.level[sp];
        probe.read(&ws.level[sp], sizeof lv);
        TB_FOR_GROUPS(g, lv.nan_groups)
          for (unsigned b = ws.snan[sp][g]; b; b &= b - 1) ws.in_plane[8 * g + __builtin_ctz(b)]--;
        copy_groups(ws.tn, ws.stn[sp], lv.groups);
        copy_groups(ws.tf, ws.stf[sp], lv.groups);
        uint32_t alive = 0;
        TB_FOR_GROUPS(g, lv.groups) {
          if constexpr (P::enabled) {
            probe.read(ws.stn[sp] + 8 * g, 32);
            probe.read(ws.stf[sp] + 8 * g, 32);
          }
          alive |= uint32_t(S::mask(active(ws, g)) != 0) << g;
        }
        if (alive) {
          node = lv.node, groups = alive;
          running = true;
          break;
        }
      }
    }
    for (int j = 0; j < n; ++j) {
      Hit h{ws.hit_t[j], ws.prim[j], ws.hit_u[j], ws.hit_v[j]};
      Hit& out = hits[ws.ray[j]];
      out = finish_hit(h);
      probe.write(&out, sizeof(Hit));
    }
  }

  // Tests the leaf's triangles against the active rays of `groups`; rays whose closest hit
  // now lies inside this cell are finished. Returns how many rays finished. Group by group, so a
  // group's rays and closest hits stay in registers while it runs through the leaf.
  template <TriKernel K, class P>
  int intersect_leaf(const KDNode& nd, const TriangleSet& tris, uint32_t groups, Workspace& ws, P& probe) const {
    const uint32_t first = nd.first(), end = first + nd.count();
    int finished = 0, visitors = 0;
    TB_FOR_GROUPS(g, groups) {
      const __m256 m = active(ws, g);
      const int bits = S::mask(m);
      if (!bits) continue;
      visitors += __builtin_popcount(unsigned(bits));
      const int o = int(8 * g);
      const RayGroup r = load_group(ws, o);
      HitGroup h{_mm256_load_ps(ws.hit_t + o), _mm256_load_ps(ws.hit_u + o), _mm256_load_ps(ws.hit_v + o),
                 _mm256_load_si256((const __m256i*)(ws.prim + o))};
      for (uint32_t k = first; k < end; ++k) {
        probe.tris(tris.data_at(k, K), TriangleSet::bytes(K), uint32_t(__builtin_popcount(unsigned(bits))));
        if constexpr (K == TriKernel::watertight) watertight8(tris.verts[k], tris.prim_id[k], r, m, h);
        else if constexpr (K == TriKernel::moller) moller8(tris.verts[k], tris.prim_id[k], r, m, h);
        else plane8<K == TriKernel::plane_rcp>(tris.planes[k], tris.prim_id[k], r, m, h);
      }
      _mm256_store_ps(ws.hit_t + o, h.t);
      _mm256_store_ps(ws.hit_u + o, h.u);
      _mm256_store_ps(ws.hit_v + o, h.v);
      _mm256_store_si256((__m256i*)(ws.prim + o), h.prim);
      // Finished: a hit inside this cell (Alg. 2.3's termination test, per ray).
      const __m256 found = _mm256_castsi256_ps(
          _mm256_xor_si256(_mm256_cmpeq_epi32(h.prim, _mm256_set1_epi32(int(kNoHit))), _mm256_set1_epi32(-1)));
      const __m256 free = _mm256_castsi256_ps(
          _mm256_cmpeq_epi32(_mm256_load_si256((const __m256i*)(ws.in_plane + o)), _mm256_setzero_si256()));
      const __m256 done = S::and_(S::and_(S::and_(m, found), free), S::le(h.t, _mm256_load_ps(ws.tf + o)));
      const __m256 lim = _mm256_min_ps(_mm256_load_ps(ws.lim + o), h.t);
      _mm256_store_ps(ws.lim + o, S::blendv(lim, S::set1(-INFINITY), done));
      finished += __builtin_popcount(unsigned(S::mask(done)));
    }
    if (visitors) probe.leaf(&nd, sizeof(KDNode), uint32_t(visitors));
    return finished;
  }

  // One group's rays, loaded once per leaf.
  struct RayGroup {
    __m256 ox, oy, oz, dx, dy, dz, tmin;
    __m256 sx, sy, sz, kx0, kx1, ky0, ky1, kz0, kz1;  // watertight only
    const Workspace* ws;                              // the lanes' rays, for scalar fallbacks
    int o;
  };
  struct HitGroup {
    __m256 t, u, v;
    __m256i prim;
  };
  static RayGroup load_group(const Workspace& ws, int o) {
    RayGroup r;
    r.ox = _mm256_load_ps(ws.ox + o), r.oy = _mm256_load_ps(ws.oy + o), r.oz = _mm256_load_ps(ws.oz + o);
    r.dx = _mm256_load_ps(ws.dx + o), r.dy = _mm256_load_ps(ws.dy + o), r.dz = _mm256_load_ps(ws.dz + o);
    r.tmin = _mm256_load_ps(ws.tmin + o);
    r.sx = _mm256_load_ps(ws.sx + o), r.sy = _mm256_load_ps(ws.sy + o), r.sz = _mm256_load_ps(ws.sz + o);
    r.ws = &ws;
    r.o = o;
    r.kx0 = _mm256_load_ps(ws.kx0 + o), r.kx1 = _mm256_load_ps(ws.kx1 + o);
    r.ky0 = _mm256_load_ps(ws.ky0 + o), r.ky1 = _mm256_load_ps(ws.ky1 + o);
    r.kz0 = _mm256_load_ps(ws.kz0 + o), r.kz1 = _mm256_load_ps(ws.kz1 + o);
    return r;
  }
  // Records the hits of mask `ok` with distance t and barycentrics u, v.
  static void commit(HitGroup& h, __m256 ok, __m256 t, __m256 u, __m256 v, uint32_t prim) {
    h.t = S::blendv(h.t, t, ok);
    h.u = S::blendv(h.u, u, ok);
    h.v = S::blendv(h.v, v, ok);
    h.prim = _mm256_blendv_epi8(h.prim, _mm256_set1_epi32(int(prim)), _mm256_castps_si256(ok));
  }

  // The kernel library's watertight test (kernels.h), 8 rays against one triangle; the per-ray
  // axis permutation (kx, ky, kz) becomes two blends per selected component.
  static void watertight8(const TriVerts& tri, uint32_t prim, const RayGroup& r, __m256 m, HitGroup& h) {
    auto pick = [](__m256 x, __m256 y, __m256 z, __m256 m0, __m256 m1) { return S::blendv(S::blendv(z, y, m1), x, m0); };
    const __m256 Ax_ = S::sub(S::set1(tri.v0.x), r.ox), Ay_ = S::sub(S::set1(tri.v0.y), r.oy), Az_ = S::sub(S::set1(tri.v0.z), r.oz);
    const __m256 Bx_ = S::sub(S::set1(tri.v1.x), r.ox), By_ = S::sub(S::set1(tri.v1.y), r.oy), Bz_ = S::sub(S::set1(tri.v1.z), r.oz);
    const __m256 Cx_ = S::sub(S::set1(tri.v2.x), r.ox), Cy_ = S::sub(S::set1(tri.v2.y), r.oy), Cz_ = S::sub(S::set1(tri.v2.z), r.oz);
    const __m256 Akz = pick(Ax_, Ay_, Az_, r.kz0, r.kz1), Bkz = pick(Bx_, By_, Bz_, r.kz0, r.kz1),
                 Ckz = pick(Cx_, Cy_, Cz_, r.kz0, r.kz1);
    const __m256 Ax = shear<8>(pick(Ax_, Ay_, Az_, r.kx0, r.kx1), r.sx, Akz);
    const __m256 Ay = shear<8>(pick(Ax_, Ay_, Az_, r.ky0, r.ky1), r.sy, Akz);
    const __m256 Bx = shear<8>(pick(Bx_, By_, Bz_, r.kx0, r.kx1), r.sx, Bkz);
    const __m256 By = shear<8>(pick(Bx_, By_, Bz_, r.ky0, r.ky1), r.sy, Bkz);
    const __m256 Cx = shear<8>(pick(Cx_, Cy_, Cz_, r.kx0, r.kx1), r.sx, Ckz);
    const __m256 Cy = shear<8>(pick(Cx_, Cy_, Cz_, r.ky0, r.ky1), r.sy, Ckz);
    __m256 U, V, W, det;
    __m256 ok = S::and_(m, watertight_inside<8>(Ax, Ay, Bx, By, Cx, Cy, U, V, W, det));
    if (!S::mask(ok)) return;
    const __m256 inv_det = _mm256_div_ps(S::set1(1.f), det);
    // As intersect_watertight: t from exact_plane_distance (double) for the lanes that passed the
    // inside test, the sheared T/det only where the ray is parallel to the plane (NaN).
    alignas(32) float tl[8];
    _mm256_store_ps(tl, sheared_distance<8>(r.sz, U, V, W, Akz, Bkz, Ckz, inv_det));
    for (int bits = S::mask(ok); bits; bits &= bits - 1) {
      const int i = __builtin_ctz(unsigned(bits)), j = r.o + i;
      const float te = exact_plane_distance({r.ws->ox[j], r.ws->oy[j], r.ws->oz[j]},
                                            {r.ws->dx[j], r.ws->dy[j], r.ws->dz[j]}, tri);
      if (!std::isnan(te)) tl[i] = te;
    }
    const __m256 t = _mm256_load_ps(tl);
    ok = S::and_(ok, S::and_(S::ge(t, r.tmin), S::lt(t, h.t)));
    if (!S::mask(ok)) return;
    commit(h, ok, t, S::mul(V, inv_det), S::mul(W, inv_det), prim);
  }

  // The kernel library's moller<8>.
  static void moller8(const TriVerts& tri, uint32_t prim, const RayGroup& r, __m256 m, HitGroup& h) {
    const __m256 d[3] = {r.dx, r.dy, r.dz};
    const __m256 s[3] = {S::sub(r.ox, S::set1(tri.v0.x)), S::sub(r.oy, S::set1(tri.v0.y)), S::sub(r.oz, S::set1(tri.v0.z))};
    __m256 t, u, v;
    const __m256 ok = moller<8>(d, s, tri, r.tmin, h.t, m, t, u, v);
    if (S::mask(ok)) commit(h, ok, t, u, v, prim);
  }

  // The kernel library's plane<8> (thesis Appendix C); kApproxRcp uses rcpps as the thesis.
  template <bool kApproxRcp>
  static void plane8(const PlaneTri& tri, uint32_t prim, const RayGroup& r, __m256 m, HitGroup& h) {
    const __m256 o[3] = {r.ox, r.oy, r.oz}, d[3] = {r.dx, r.dy, r.dz};
    __m256 t, u, v;
    const __m256 ok = plane<8, kApproxRcp>(o, d, plane_offset<8>(o, tri.n), tri, r.tmin, h.t, m, t, u, v);
    if (S::mask(ok)) commit(h, ok, t, u, v, prim);
  }

  int max_rays_;
};

}  // namespace

std::unique_ptr<Traverser> make_kd_packet(const SchemeConfig& cfg) { return std::make_unique<KDPacket>(cfg); }
ParamSpecs params_kd_packet() {
  return kd_param_specs() +
         ParamSpecs{int_param("kd_packet", kMaxRays, 8, kMaxRays, "most rays of one sub-packet (a multiple of 8)")};
}

}  // namespace tb
