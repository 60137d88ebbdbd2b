// bvh_partition: partition traversal of the binary BVH (Overbeck, Ramamoorthi, Mark 2008, "Large
// ray packets for real-time Whitted ray tracing"; thesis Alg. 2.7). The packet keeps an array of
// the indices of its SIMD rays (groups of 8 rays, thesis footnote 11); at each node the groups
// that hit it are swapped to the front in place, so the active set is the prefix [0, count) and
// a child is only tested against its parent's active groups. Unlike ranged traversal the active
// set never contains a long run of inactive rays, which is why the scheme degrades more slowly
// for divergent rays (thesis Fig. 12, Table 7). The stack stores the far child with the parent's
// count: every partition permutes only inside a prefix of that length, so the prefix still holds
// exactly the parent's active groups when the far child is popped.
//
// As in Alg. 2.7 a node is first tested against the packet's frustum (common origin) or its
// interval-arithmetic bounds, and skipped when they miss it. The frustum is fitted lazily, on the
// first node the IA bounds do not cull (Packet::frustum_pending): primary packets around a single
// object mostly miss the scene after a root test or two and never need it.
//
// Parameters: split=1|0 — after the first intersection (bounce and shadow batches) continue as
// four sub-packets, Arauna's 8x8 packets (§3.3); default 0, measured (see kDefaultSplit).
#include "traversal/bvh_packet.h"

namespace tb {
namespace {

using namespace packet;

// split=0 is the default: on sponza at 512x512 (1 thread, alternating runs, median of 25) the whole
// packet was faster on bounce:1 (352 vs 385 ms), bounce:2 (472 vs 524 ms) and shadow (31.3 vs
// 32.4 ms): the partition already drops inactive groups, so smaller packets only lose the
// amortisation of the nodes near the root (Overbeck et al. 2008 favour large packets too).
constexpr int kDefaultSplit = 0;

class BVHPartition final : public BVHPacketScheme<BVHPartition> {
  friend BVHPacketScheme;  // its packet loop calls traverse with our Entry

 public:
  explicit BVHPartition(const SchemeConfig& cfg) : BVHPacketScheme(cfg) {}
  std::string_view name() const override { return "bvh_partition"; }

 private:
  struct Entry {
    uint32_t node, count;
  };
  template <TriKernel K, bool kCommon, class P>
  void traverse(Packet& pk, Entry* stack, P& probe) const {
    const BVHNode* nodes = data_.tree->nodes.data();
    const TriangleSet& ts = *data_.tris;
    uint8_t idx[kMaxGroups];   // group indices, active ones first
    uint8_t lanes[kMaxGroups]; // per group: its lanes that hit the node last tested
    for (uint32_t g = 0; g < pk.groups; ++g) idx[g] = uint8_t(g);
    uint32_t sp = 0, node = 0, count = pk.groups;
    for (;;) {
      const BVHNode& nd = nodes[node];
      // Alg. 2.7 FindFirst: frustum / interval early miss, then the in-place partition.
      uint32_t active = 0;
      bool culled = ia_misses(pk.ia, nd);
      if constexpr (kCommon) culled = culled || frustum_culls(pk, nd);
      if (!culled) {
        NodeTester<kCommon>(pk, nd).with_test([&](auto box) {
          for (uint32_t i = 0; i < count; ++i) {
            const uint32_t g = idx[i];
            probe.read(&idx[i], 1);
            probe.read(&pk.rg[g], sizeof(RayGroup));
            const uint32_t m = box(g);
            if (m) {
              lanes[g] = uint8_t(m);
              std::swap(idx[active], idx[i]);
              probe.write(&idx[active], 1);
              ++active;
            }
          }
        });
      }
      if (active) {
        uint32_t rays = 0;
        if constexpr (P::enabled)
          for (uint32_t i = 0; i < active; ++i) rays += popcount8(lanes[idx[i]]);
        if (!nd.is_leaf()) {
          probe.node(&nd, sizeof(BVHNode), rays);
          probe.read(&nodes[nd.left_first], 2 * sizeof(BVHNode));  // children, for the order
          const bool rf = right_first(&nodes[nd.left_first], pk.mean_dir);
          stack[sp++] = {nd.left_first + (rf ? 0u : 1u), active};
          probe.write(&stack[sp - 1], sizeof(Entry));
          node = nd.left_first + (rf ? 1u : 0u);
          count = active;
          continue;
        }
        probe.leaf(&nd, sizeof(BVHNode), rays);
        bool hit = false;
        for (uint32_t k = nd.left_first; k < nd.left_first + nd.count; ++k)
          for (uint32_t i = 0; i < active; ++i) {
            const uint32_t g = idx[i];
            probe.tris(ts.data_at(k, K), TriangleSet::bytes(K), popcount8(lanes[g]));
            probe.read(&pk.tg[g], sizeof(TriGroup));
            if (intersect_group<K, kCommon>(pk, g, lanes[g], ts, k)) hit = true;
          }
        if (hit) pk.update_tfar_max();
      } else {
        probe.read(&nd, sizeof(BVHNode));  // fetched to be culled: not a visit, still a read
      }
      if (sp == 0) break;
      const Entry& e = stack[--sp];
      probe.read(&e, sizeof(Entry));
      node = e.node, count = e.count;
    }
  }

};

}  // namespace

std::unique_ptr<Traverser> make_bvh_partition(const SchemeConfig& cfg) {
  return std::make_unique<BVHPartition>(cfg);
}
ParamSpecs params_bvh_partition() {
  return bvh_param_specs() + ParamSpecs{bool_param("split", kDefaultSplit, "after the first intersection (bounce, shadow) continue as four 8x8 sub-packets (thesis 3.3)")};
}

}  // namespace tb
