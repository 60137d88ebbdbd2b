// bvh_masked: masked packet traversal of the binary BVH (thesis Alg. 2.5; the "masked" scheme of
// Overbeck et al. 2008). A node is visited when any active ray of the packet hits it; every
// group of 8 rays that still has an active lane is tested against both children with one AVX2
// slab test, and the resulting lane masks travel down the tree (and onto the stack with the far
// child). There is no early hit or early miss: the cost of a node visit is proportional to the
// number of active groups, which is what ranged and partition traversal improve on.
//
// Parameters: split=1|0 — after the first intersection (bounce and shadow batches) continue as
// four sub-packets, Arauna's 8x8 packets (§3.3); default 1, measured (see kDefaultSplit).
#include "traversal/bvh_packet.h"

namespace tb {
namespace {

using namespace packet;

// split=1 is the default: on sponza at 512x512 (1 thread, alternating runs, median of 25) the four
// 8x8 sub-packets were faster on bounce:1 (362 vs 410 ms) and bounce:2 (483 vs 565 ms), equal on
// shadow (32.7 vs 32.9 ms): masked traversal pays for every group with an active lane at every
// node, and a 64-ray packet of divergent rays reaches fewer nodes than a 256-ray one.
constexpr int kDefaultSplit = 1;

class BVHMasked final : public BVHPacketScheme<BVHMasked> {
  friend BVHPacketScheme;  // its packet loop calls traverse with our Entry

 public:
  explicit BVHMasked(const SchemeConfig& cfg) : BVHPacketScheme(cfg) {}
  std::string_view name() const override { return "bvh_masked"; }

 private:
  // A stacked node with the lanes (one byte per group of 8 rays) that hit it when it was pushed.
  struct alignas(32) Entry {
    uint8_t mask[kMaxGroups];
    uint32_t node;
  };
  // Re-tests the lanes of `m` against node n with the current closest hits; false when none is left.
  template <bool kCommon, class P>
  static bool retest(const Packet& pk, const BVHNode& n, uint8_t* m, P& probe) {
    uint32_t any = 0;
    const NodeTester<kCommon> box(pk, n);
    for (uint32_t g = 0; g < pk.groups; ++g)
      if (m[g]) any |= m[g] = uint8_t(m[g] & test_group<kCommon>(pk, g, box, probe));
    return any != 0;
  }

  template <TriKernel K, bool kCommon, class P>
  void traverse(Packet& pk, Entry* stack, P& probe) const {
    const BVHNode* nodes = data_.tree->nodes.data();
    const TriangleSet& ts = *data_.tris;
    alignas(32) uint8_t cur[kMaxGroups], ml[kMaxGroups], mr[kMaxGroups];
    std::memset(cur, 0xFF, sizeof cur);
    uint32_t sp = 0, node = 0;
    bool active = retest<kCommon>(pk, nodes[0], cur, probe);
    auto count = [&](const uint8_t* m) {
      uint32_t c = 0;
      for (uint32_t g = 0; g < pk.groups; ++g) c += popcount8(m[g]);
      return c;
    };
    for (;;) {
      if (active) {
        const BVHNode& nd = nodes[node];
        if (!nd.is_leaf()) {
          if constexpr (P::enabled) probe.node(&nd, sizeof(BVHNode), count(cur));
          const BVHNode* c = &nodes[nd.left_first];
          probe.read(c, 2 * sizeof(BVHNode));  // both children's boxes are tested
          uint32_t anyl = 0, anyr = 0;
          const NodeTester<kCommon> box0(pk, c[0]), box1(pk, c[1]);
          for (uint32_t g = 0; g < pk.groups; ++g) {
            ml[g] = mr[g] = 0;
            if (!cur[g]) continue;
            anyl |= ml[g] = uint8_t(cur[g] & test_group<kCommon>(pk, g, box0, probe));
            anyr |= mr[g] = uint8_t(cur[g] & test_group<kCommon>(pk, g, box1, probe));
          }
          if (anyl && anyr) {
            const bool rf = right_first(c, pk.mean_dir);
            Entry& e = stack[sp++];
            e.node = nd.left_first + (rf ? 0u : 1u);
            std::memcpy(e.mask, rf ? ml : mr, kMaxGroups);
            probe.write(&e, sizeof(Entry));
            std::memcpy(cur, rf ? mr : ml, kMaxGroups);
            node = nd.left_first + (rf ? 1u : 0u);
            continue;
          }
          if (anyl || anyr) {
            std::memcpy(cur, anyl ? ml : mr, kMaxGroups);
            node = nd.left_first + (anyl ? 0u : 1u);
            continue;
          }
        } else {
          if constexpr (P::enabled) probe.leaf(&nd, sizeof(BVHNode), count(cur));
          for (uint32_t k = nd.left_first; k < nd.left_first + nd.count; ++k)
            for (uint32_t g = 0; g < pk.groups; ++g) {
              if (!cur[g]) continue;
              probe.tris(ts.data_at(k, K), TriangleSet::bytes(K), popcount8(cur[g]));
              probe.read(&pk.tg[g], sizeof(TriGroup));
              intersect_group<K, kCommon>(pk, g, cur[g], ts, k);
            }
        }
      }
      // Pop; the stacked lanes are re-tested against the node with the closest hits found since
      // it was pushed, so subtrees occluded for every ray are dropped before their children.
      if (sp == 0) break;
      Entry& e = stack[--sp];
      probe.read(&e, sizeof(Entry));
      node = e.node;
      std::memcpy(cur, e.mask, kMaxGroups);
      active = retest<kCommon>(pk, nodes[node], cur, probe);
    }
  }

};

}  // namespace

std::unique_ptr<Traverser> make_bvh_masked(const SchemeConfig& cfg) { return std::make_unique<BVHMasked>(cfg); }
ParamSpecs params_bvh_masked() {
  return bvh_param_specs() + ParamSpecs{bool_param("split", kDefaultSplit, "after the first intersection (bounce, shadow) continue as four 8x8 sub-packets (thesis 3.3)")};
}

}  // namespace tb
