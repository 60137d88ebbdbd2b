// What the three BVH packet schemes share (thesis §2.2.2, §3.3; Overbeck et al. 2008 naming:
// bvh_masked, bvh_ranged, bvh_partition): the packet's rays as SoA groups of 8 (AVX2), the 8-wide
// ray/box and ray/triangle tests, and the packet bounds used for early misses — a frustum of
// four planes for packets with a common origin, interval arithmetic (IA) over origins and
// reciprocal directions for all packets.
//
// Robustness contract (the same as the single-ray schemes): the box test is the conservative,
// NaN-aware slab test of kernels.h evaluated lane-wise; the IA bounds are built from exactly the
// quantities the per-ray slab test computes, so by monotonic rounding they never cull a node any
// ray of the packet would enter; frustum planes are fitted to the rays, proven to hold every ray
// by a float check whose margin exceeds its rounding error, and are evaluated against boxes and
// triangles with such a margin too. The box and triangle tests are the kernel library's
// (traversal/kernels.h: slab<8>, watertight_inside<8>, moller<8>, plane<8>), so every lane
// computes the very same values as the one-ray tests; the rare lanes whose ray is parallel to a
// triangle's plane go to the scalar kernel.
//
// The concepts live in focused headers, all included here:
//   packet.h          the packet (SoA groups), loading rays, storing hits, sub-packets
//   packet_bounds.h   interval-arithmetic and frustum bounds, their box/triangle culling tests
//   packet_frustum.h  fitting the frustum and the split planes to a packet
//   packet_box.h      packet vs box (slab<8>)
//   packet_tri.h      packet vs triangle (the kernel library's 8-wide tests)
#pragma once
#include "traversal/packet.h"
#include "traversal/packet_box.h"
#include "traversal/packet_bounds.h"
#include "traversal/packet_frustum.h"
#include "traversal/packet_tri.h"
#include "traversal/bvh_common.h"

namespace tb::packet {

// Group g of the packet against the node `box` was set up for; the probe sees the group's read.
template <bool kCommon, class P, bool kHoist>
[[gnu::always_inline]] inline uint32_t test_group(const Packet& pk, uint32_t g, const NodeTester<kCommon, kHoist>& box,
                                                  P& probe) {
  probe.read(&pk.rg[g], sizeof(RayGroup));
  return box(g);
}

// The packet loop of the three schemes: each packet of `range` (or its sub-packets, with `split`)
// is loaded, handed to `traverse(pk, stack, common)` — `common` is std::true_type for a packet
// whose rays share an origin, std::false_type otherwise — and its hits stored. A common-origin
// packet's frustum is built lazily, on the first node its IA bounds do not decide, with the
// split planes when `frustum_split` (bvh_masked never reads it). The packet and the stack of `stack_size` entries are allocated per call, so concurrent
// calls on disjoint ranges are safe.
template <class Entry, class P, class F>
void trace_packets(const RayBatch& batch, PacketRange range, std::span<Hit> hits, bool split, bool frustum_split,
                   size_t stack_size, P& probe, F&& traverse) {
  struct Scratch {
    Packet pk;
    std::vector<Entry> stack;
  };
  auto s = std::make_unique<Scratch>();
  s->stack.resize(stack_size);
  for (uint32_t p = range.first; p < range.last; ++p) {
    for_each_subpacket(batch, batch.packet_begin[p], batch.packet_begin[p + 1], split, [&](uint32_t b, uint32_t e) {
      Packet& pk = s->pk;
      load_packet(pk, &batch.rays[b], e - b, probe);
      if constexpr (P::enabled)
        if (probe.counts) probe.counts->rays += e - b;
      if (pk.common_origin) {
        pk.frustum_pending = true;
        pk.frustum_split = frustum_split;
        traverse(pk, s->stack.data(), std::true_type{});
      } else {
        traverse(pk, s->stack.data(), std::false_type{});
      }
      store_hits(pk, &hits[b], probe);
    });
  }
}

// The base of the three schemes: the BVH (BVHScheme), the `split` parameter and the packet loop.
// Derived provides a public `struct Entry` (its stack entry) and
// `template <TriKernel K, bool kCommon, class P> void traverse(Packet&, Entry* stack, P&) const`;
// `frustum_split`: fit the four split planes with the frustum (bvh_ranged's sub-frusta).
template <class Derived>
class BVHPacketScheme : public BVHScheme<Derived> {
 public:
  explicit BVHPacketScheme(const SchemeConfig& cfg, bool frustum_split = false)
      : BVHScheme<Derived>(cfg), split_(cfg.get_bool("split")), frustum_split_(frustum_split) {}
  template <TriKernel K, class P>
  void run_kernel(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const Derived& self = static_cast<const Derived&>(*this);
    trace_packets<typename Derived::Entry>(
        batch, range, hits, split_, frustum_split_, this->data_.tree->stats.max_depth + 2, probe,
        [&](Packet& pk, auto* stack, auto common) { self.template traverse<K, decltype(common)::value>(pk, stack, probe); });
  }

 private:
  bool split_, frustum_split_;
};

}  // namespace tb::packet
