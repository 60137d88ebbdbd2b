// mbvh8_interleave: mbvh8_single's traversal of several independent rays in turn, one visit each,
// the next node or leaf of a ray fetched while the others run (asynchronous memory access
// chaining, Kocberber, Falsafi and Grot 2015, "Asynchronous Memory Access Chaining", VLDB).
//
// Single-ray traversal is a chain of dependent loads: a node's planes, its nearest child's
// address, that child's planes or triangle block (docs/PERFORMANCE.md, session 26: the samples of
// the loop sit on those loads, and no prefetch inside one ray's traversal can start the next load
// earlier, because its address is what the visit computes). With `rays` rays in flight, a ray
// that has chosen the reference it visits next starts fetching it (prefetch_any: a node's four
// lines, or a leaf's first block) and yields; the other rays visit one node or leaf each, and by
// the time it resumes its lines have arrived. Each ray runs mbvh8_single's loop (mbvh_traverse_from)
// on mbvh8_single's cached tree, suspended between two visits exactly as treelet_queue suspends it
// at treelet edges, so it visits the same nodes and leaves in the same order as mbvh8_single with
// the same child order, and its hits are bit-identical (tests/test_mbvh.cpp). Not a
// single-ray scheme: like embree_stream it needs the batch's rays ahead of time, so it is one of
// the batch schemes of issue 17's goals.
//
// What it buys depends on where the tree lives (no-PGO AVX2 build, 512x512, one interleaved
// process per scene, ratio to mbvh8_single; docs/PERFORMANCE.md, session 35): on spheres:1000000,
// whose nodes and blocks exceed the 32 MiB L3, 2.0-2.1x on bounce:2 and bounce:3 with 12 rays
// (6: 1.7-1.8x, 8: 1.9-2.0x, 16: 2.1-2.2x, 32: 1.9-2.0x; mbvh_rs 1.2-1.3x, cwbvh_single 1.1x); on
// the scenes that fit it, 1.0-1.2x (sponza 1.00-1.03, crytek_sponza_partial 1.14-1.17,
// sibenik_lucy 1.20-1.24), where mbvh_rs gains 1.2-1.4x: there a visit waits less on memory than on
// its own instructions and branches, and with the prefetch left out the interleaving itself costs
// 0-3%. More rays than ~16 crowd the L1's outstanding misses (a prefetch then stalls at issue).
// Camera rays lose (0.74-0.84x on sponza and dragon_100k primary; 0.63-0.75x on spheres:2000000,
// crytek_sponza_partial and sibenik_lucy): neighbouring coherent rays find each other's nodes in
// the L1 and make the same branch decisions one after another, and interleaving spreads both out;
// with 2 rays 0.93-1.00x. A first version on cwbvh_single's compressed tree (cw_traverse_from,
// two-line nodes) read only 1.05x of mbvh8_single on spheres:2000000 bounce:2 (this tree: 2.28x,
// cwbvh_single alone 1.19x); why was not found this session, and it was not kept.
//
// Parameters: the MBVH8 ones of mbvh8_single (same defaults, so the tree is shared), `rays` (in
// flight) and `order` (mbvh8_single's: auto = branching for common-origin batches, sort_always
// otherwise).
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"

namespace tb {
namespace {

class MBVH8Interleave final : public MBVHScheme<MBVH8Interleave, MBVHData<8, 8>> {
 public:
  explicit MBVH8Interleave(const SchemeConfig& cfg)
      : MBVHScheme(cfg, kMBVH8Defaults),
        flight_(uint32_t(cfg.get_int("rays"))),
        order_(parse_order_param(cfg.get_choice("order"))) {}
  std::string_view name() const override { return "mbvh8_interleave"; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    data_.visit([&](const MBVHData<8, 8>& d) {
      if (sorts_batch(order_, batch)) run_order<ChildOrder::sort_always>(*d.mbvh, batch, range, hits, probe);
      else run_order<ChildOrder::branching>(*d.mbvh, batch, range, hits, probe);
    });
  }

 private:
  // One ray in flight: its node and triangle test constants (computed once, as mbvh8_single's
  // per-ray setup), where it resumes, its closest hit so far and its index in the batch.
  struct alignas(64) Slot {
    NodeRay<8> nr;
    TriRay<8> tr;
    MBVHCursor at;
    Hit hit;
    uint32_t ray;
  };

  template <ChildOrder O, class P>
  void run_order(const MBVH<8, 8>& m, const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    uint32_t next = batch.packet_begin[range.first];
    const uint32_t end = batch.packet_begin[range.last];
    if (next >= end) return;
    const uint32_t flight = std::min(flight_, end - next);
    const size_t cap = mbvh_stack_entries(8, m.stats.max_depth);
    std::vector<Slot> slots(flight);  // over-aligned: C++17's aligned new
    std::vector<MBVHStackEntry> stacks(flight * cap);
    const RayCtx::ShearAxes axes = RayCtx::axes_for(batch.common_origin);
    // Starts ray i in slot s (at the root, which every ray visits first and stays cached).
    const auto start = [&](Slot& s, uint32_t i) {
      const Ray& ray = batch.rays[i];
      probe.read(&ray, sizeof(Ray));
      if constexpr (P::enabled)
        if (probe.counts) probe.counts->rays++;
      const RayCtx rc(ray, axes);
      s.nr = NodeRay<8>(rc, ray.tmin, m.coord_bound);
      s.tr = TriRay<8>(rc, ray.tmin);
      s.at = {0, 0};
      s.hit = initial_hit(ray);
      s.ray = i;
    };
    uint32_t live = 0;
    for (; live < flight; ++live) start(slots[live], next++);
    // Round robin over the live slots; a finished ray's slot takes the next ray of the batch, and
    // once the batch is used up the last slot moves into it, so the live slots stay 0..live-1.
    while (live) {
      for (uint32_t k = 0; k < live;) {
        Slot& s = slots[k];
        bool resumed = true;
        // Visit the reference the ray was suspended at (fetched when it yielded), then yield at the
        // next one after starting its fetch.
        const auto leave = [&](uint32_t ref) __attribute__((always_inline)) {
          if (resumed) {
            resumed = false;
            return false;
          }
          prefetch_any(m, ref);
          return true;
        };
        if (!mbvh_traverse_from<8, 8, TriKernel::watertight, O>(m, nullptr, s.nr, s.tr, nullptr, s.at, s.hit,
                                                                 &stacks[k * cap], probe, leave)) {
          ++k;
          continue;
        }
        hits[s.ray] = finish_hit(s.hit);
        probe.write(&hits[s.ray], sizeof(Hit));
        if (next < end) {
          start(s, next++);
          ++k;
        } else if (k != --live) {  // the last live slot (its ray and stack) moves into this one
          s = slots[live];
          std::copy_n(&stacks[live * cap], s.at.sp, &stacks[k * cap]);
        }
      }
    }
  }

  uint32_t flight_;
  OrderParam order_;
};

}  // namespace

std::unique_ptr<Traverser> make_mbvh8_interleave(const SchemeConfig& cfg) {
  return std::make_unique<MBVH8Interleave>(cfg);
}
ParamSpecs params_mbvh8_interleave() {
  return mbvh_param_specs(kMBVH8Defaults) +
         ParamSpecs{int_param("rays", 12, 1, 1024, "rays in flight, each visiting one node or leaf per turn"),
                    mbvh8_order_param()};
}

}  // namespace tb
