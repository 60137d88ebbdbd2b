// mbvh4_single: the thesis' single-ray baseline (ch. 5, §5.2.3 "Single ray traversal"): depth-first
// traversal of a 4-ary BVH collapsed from the binary SAH BVH, one SSE instruction per slab for
// the four child boxes (Alg. 2.8), children visited near-to-far with the 4-element sorting
// network of Alg. 2.10, a small stack of (child, entry distance) and culling of popped children
// beyond the closest hit. Leaves hold SSE blocks of 4 triangles for the watertight test.
// Dammertz et al. (2008) report 1.6-2.0x over the binary BVH for this layout.
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"

namespace tb {
namespace {

// Binary leaves of up to 4 triangles, and subtrees of up to 4 merged into one block.
constexpr MBVHDefaults kDefaults{4, 4, false, 0, false, false};

class MBVH4Single final : public MBVHScheme<MBVH4Single, MBVHData<4, 4>> {
 public:
  explicit MBVH4Single(const SchemeConfig& cfg) : MBVHScheme(cfg, kDefaults) {}
  std::string_view name() const override { return "mbvh4_single"; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const MBVHData<4, 4>& d = std::get<0>(data_.data);
    dispatch_kernel(cfg_.kernel, [&](auto k) { mbvh_trace_rays<4, 4, decltype(k)::value, ChildOrder::branching, true>(d, batch, range, hits, probe); });
  }
};

}  // namespace

std::unique_ptr<Traverser> make_mbvh4_single(const SchemeConfig& cfg) { return std::make_unique<MBVH4Single>(cfg); }
ParamSpecs params_mbvh4_single() { return mbvh_param_specs(kDefaults); }

}  // namespace tb
