// bvh_ranged: ranged packet traversal of the binary BVH (Wald, Boulos, Shirley 2007, "Ray tracing
// deformable scenes using dynamic bounding volume hierarchies"; thesis Alg. 2.6 and §3.3; named
// "ranged" by Overbeck et al. 2008). The packet keeps the range [first, last] of rays that may
// still be active; a node is decided with at most three tests (§3.3):
//   1. early hit: the group of 8 rays holding the first active ray hits the node (one SIMD box
//      test, the thesis' single-ray test widened to the AVX2 group it lives in);
//   2. early miss: the node lies outside the packet's frustum (common-origin packets) or its
//      interval-arithmetic bounds (all packets; also culls nodes behind every ray's closest hit);
//   3. brute-force scan for the first active ray, then from the back for the last one.
// Leaves test the triangles against the active range, 8 rays at a time, each group masked by its
// hits on the leaf box. For primary packets the two extra planes of §3.3 split the frustum into
// four 64-ray quadrants (Fig. 16); a triangle can be tested against the packet frustum and the
// split planes at once (one 8-lane test) and then only against the quadrants it may touch (off by
// default: it measured a small loss, the leaf-box masks already drop most groups a triangle
// misses; see kDefaultTriCull). The frustum itself is fitted lazily, on the first node the IA
// bounds do not decide (Packet::frustum_pending).
//
// Parameters:
//   split=1|0   after the first intersection (bounce and shadow batches) continue as four
//               sub-packets, as Arauna does with its 8x8 packets (§3.3). Default 0, measured
//               (see kDefaultSplit).
//   subfrusta=1|0  the two §3.3 split planes (default 1, used only with tricull > 0);
//               tricull=N  test leaf triangles against the packet frustum and split planes when
//               at least N groups of 8 rays are active (default 0 = never, measured: see
//               kDefaultTriCull); leafmask=1|0  test each group of the range against the leaf box
//               before its triangles (default 1); last=1|0  keep the last active ray too, not
//               just the first (default 1).
#include "traversal/bvh_packet.h"

namespace tb {
namespace {

using namespace packet;

// split=0 is the default: on sponza at 512x512 (1 thread, alternating runs of both variants, median
// of 25) the whole packet was faster on bounce:1 (347 vs 379 ms), bounce:2 (481 vs 505 ms) and
// shadow (23.8 vs 27.9 ms). Unlike Arauna (§3.3), whose leaves tested every ray of the range,
// inactive rays cost us little here — leaves mask each group by its leaf-box hits and the IA bound
// culls occluded nodes — while four sub-packets repeat the descent from the root and the setup.
constexpr int kDefaultSplit = 0;

// tricull=0 is the default: primary, 512x512, 1 thread, median of 7, same-run ratios to
// embree_packet8 (after the lazy frustum and the hoisted node offsets): tricull=2 / 0 / 8 gave
// bunny 26.5 / 28.4 / 28.9, sponza 21.3 / 21.6 / 21.3, room 24.8 / 25.4 / 26.0, conference 34.7 /
// 34.3 / 33.5 Mrays/s. The leaf-box masks already drop most groups a triangle misses, so the
// 8-plane triangle test rarely pays for itself; with tricull=0 the split planes are not fitted.
constexpr int kDefaultTriCull = 0;

class BVHRanged final : public BVHPacketScheme<BVHRanged> {
  friend BVHPacketScheme;  // its packet loop calls traverse with our Entry

 public:
  // The sub-frusta's split planes only cull triangles: without tricull they are not fitted.
  explicit BVHRanged(const SchemeConfig& cfg)
      : BVHPacketScheme(cfg, cfg.get_bool("subfrusta") && cfg.get_int("tricull") > 0),
        tricull_(cfg.get_int("tricull")), leafmask_(cfg.get_bool("leafmask")), track_last_(cfg.get_bool("last")) {
    if (tricull_ == 0)
      cfg.refuse_if_changed("subfrusta", "only culls leaf triangles, which tricull=0 does not: set tricull or drop subfrusta");
  }
  std::string_view name() const override { return "bvh_ranged"; }

 private:
  struct Entry {
    uint32_t node;
    uint16_t first, last;
  };
  // Alg. 2.6 FindFirst, over groups: the first ray of [first, last] that hits n, or kNone.
  // `found_mask` receives the hit lanes of the group holding that ray.
  template <bool kCommon, class P>
  [[gnu::always_inline]] static uint32_t find_first(Packet& pk, const BVHNode& n, const NodeTester<kCommon, true>& box, uint32_t first,
                             uint32_t last, uint32_t& found_mask, P& probe) {
    const uint32_t g0 = first / kW, g1 = last / kW;
    uint32_t m = test_group<kCommon>(pk, g0, box, probe) & range_mask(g0, first, last);
    if (m) return found_mask = m, g0 * kW + std::countr_zero(m);  // 1. early hit
    if (ia_misses(pk.ia, n)) return kNone;                        // 2. early miss
    if constexpr (kCommon)
      if (frustum_culls(pk, n)) return kNone;
    for (uint32_t g = g0 + 1; g <= g1; ++g) {                      // 3. scan
      m = test_group<kCommon>(pk, g, box, probe) & range_mask(g, first, last);
      if (m) return found_mask = m, g * kW + std::countr_zero(m);
    }
    return kNone;
  }

  // The last ray of [first, last] that hits n, scanning from the back (Overbeck et al. 2008 keep
  // both ends of the range); `first` is known to hit, with `first_mask` its group's lanes.
  template <bool kCommon, class P>
  static uint32_t find_last(const Packet& pk, const NodeTester<kCommon, true>& box, uint32_t first, uint32_t last,
                            uint32_t first_mask, P& probe) {
    const uint32_t g0 = first / kW;
    for (uint32_t g = last / kW; g > g0; --g) {
      const uint32_t m = test_group<kCommon>(pk, g, box, probe) & range_mask(g, first, last);
      if (m) return g * kW + 31 - std::countl_zero(m);
    }
    return g0 * kW + 31 - std::countl_zero(first_mask);
  }

  // Thesis Table 8 counts "the average number of rays (of the original packet) that intersects each
  // visited node" (§5.2.3), not the width l - f + 1 of the range the scheme scans (which also holds
  // rays that miss it). Instrumented path only; a NullProbe, because this count is no access the
  // scheme makes.
  template <bool kCommon>
  static uint32_t rays_hitting(const Packet& pk, const NodeTester<kCommon, true>& box, uint32_t f, uint32_t l) {
    NullProbe none;
    uint32_t n = 0;
    for (uint32_t g = f / kW; g <= l / kW; ++g) n += std::popcount(test_group<kCommon>(pk, g, box, none) & range_mask(g, f, l));
    return n;
  }

  template <TriKernel K, bool kCommon, class P>
  void traverse(Packet& pk, Entry* stack, P& probe) const {
    const BVHNode* nodes = data_.tree->nodes.data();
    uint32_t sp = 0, node = 0, first = 0, last = pk.n - 1;
    for (;;) {
      const BVHNode& nd = nodes[node];
      uint32_t fmask = 0;
      const NodeTester<kCommon, true> box(pk, nd);
      const uint32_t f = find_first<kCommon>(pk, nd, box, first, last, fmask, probe);
      if (f != kNone) {
        const uint32_t l = track_last_ ? find_last<kCommon>(pk, box, f, last, fmask, probe) : last;
        if (!nd.is_leaf()) {
          if constexpr (P::enabled) probe.node_range(&nd, sizeof(BVHNode), rays_hitting<kCommon>(pk, box, f, l), l - f + 1);
          probe.read(&nodes[nd.left_first], 2 * sizeof(BVHNode));  // children, for the order
          const bool rf = right_first(&nodes[nd.left_first], pk.mean_dir);
          stack[sp++] = {nd.left_first + (rf ? 0u : 1u), uint16_t(f), uint16_t(l)};
          probe.write(&stack[sp - 1], sizeof(Entry));
          node = nd.left_first + (rf ? 1u : 0u);
          first = f, last = l;
          continue;
        }
        if constexpr (P::enabled) probe.leaf_range(&nd, sizeof(BVHNode), rays_hitting<kCommon>(pk, box, f, l), l - f + 1);
        intersect_leaf<K, kCommon>(pk, nd, box, f, l, fmask, probe);
      } else {
        probe.read(&nd, sizeof(BVHNode));  // fetched to be culled: not a visit, still a read
      }
      if (sp == 0) break;
      const Entry& e = stack[--sp];
      probe.read(&e, sizeof(Entry));
      node = e.node, first = e.first, last = e.last;
    }
  }

  template <TriKernel K, bool kCommon, class P>
  void intersect_leaf(Packet& pk, const BVHNode& nd, const NodeTester<kCommon, true>& box, uint32_t f, uint32_t l,
                      uint32_t fmask, P& probe) const {
    const TriangleSet& ts = *data_.tris;
    const uint32_t g0 = f / kW, g1 = l / kW;
    uint32_t lanes[kMaxGroups];
    for (uint32_t g = g0; g <= g1; ++g) {
      lanes[g] = range_mask(g, f, l);
      // The first group's hit lanes are known from FindFirst; the others cost one box test each,
      // far less than testing their rays against every triangle of the leaf.
      if (leafmask_) lanes[g] &= g == g0 ? fmask : test_group<kCommon>(pk, g, box, probe);
    }
    // §3.3: each triangle is first tested against the packet frustum and the two split planes
    // (one 8-lane test), and only the quadrants it may touch are tested. The test costs about
    // as much as one group's triangle test, so it is only done for ranges with several active
    // groups (`tricull`).
    bool cull = false;
    if constexpr (kCommon) {
      if (pk.frustum.valid && tricull_ > 0) {
        uint32_t active = 0;
        for (uint32_t g = g0; g <= g1; ++g) active += lanes[g] != 0;
        cull = active >= uint32_t(tricull_);
      }
    }
    bool hit = false;
    for (uint32_t k = nd.left_first; k < nd.left_first + nd.count; ++k) {
      uint32_t quads = 0xFu;
      if (cull) {
        quads = quadrants_touched(tri_outside(pk.cull, ts.verts[k]));
        if (!quads) continue;
      }
      for (uint32_t g = g0; g <= g1; ++g) {
        if (!lanes[g] || !((quads >> (g / 8)) & 1u)) continue;
        probe.tris(ts.data_at(k, K), TriangleSet::bytes(K), popcount8(lanes[g]));
        probe.read(&pk.tg[g], sizeof(TriGroup));
        if (intersect_group<K, kCommon>(pk, g, lanes[g], ts, k)) hit = true;
      }
    }
    if (hit) pk.update_tfar_max();
  }

  int tricull_;
  bool leafmask_, track_last_;
};

}  // namespace

std::unique_ptr<Traverser> make_bvh_ranged(const SchemeConfig& cfg) { return std::make_unique<BVHRanged>(cfg); }
ParamSpecs params_bvh_ranged() {
  return bvh_param_specs() +
         ParamSpecs{bool_param("split", kDefaultSplit, "after the first intersection (bounce, shadow) continue as four 8x8 sub-packets (thesis 3.3)"),
                    bool_param("subfrusta", true, "the two thesis 3.3 split planes (used only with tricull > 0)"),
                    int_param("tricull", kDefaultTriCull, 0, 1024,
                              "test leaf triangles against the frustum when at least this many 8-ray groups are active (0: never)"),
                    bool_param("leafmask", true, "test each 8-ray group against the leaf box before its triangles"),
                    bool_param("last", true, "track the last active ray too, not just the first")};
}

}  // namespace tb
