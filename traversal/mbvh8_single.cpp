// mbvh8_single: the 8-wide variant of the thesis' MBVH baseline for AVX2 (N = SIMD width, §2.2
// "MBVH traversal"): eight child boxes per AVX2 slab operation, children ordered near-to-far
// (an 8-element bitonic network on distance keys with the child index in the low bits, the
// 8-wide equivalent of Alg. 2.10, for every node whatever the number of entered children), a stack of (child, entry
// distance) with culling of popped children beyond the closest hit, and leaves stored as SoA
// blocks of triangles for the SIMD watertight test.
// The tree is collapsed SAH-optimally (dynamic programming, Ylitie et al. 2017) rather than by
// the thesis' greedy rule: nodes fill 6-7 of 8 slots instead of ~4.4, for 3-12% more rays/s on
// sponza, conference and sibenik_lucy (bounce:2); leaves of up to 16 triangles (two blocks).
// Parameters: tri_width=4|8 (SSE or AVX2 triangle blocks), collapse=sah|greedy, merge (largest
// leaf), tri_cost (block test vs node visit, %), small (0 | 4: 4-wide blocks for leaves of <= 4
// triangles; default 0), leaf_size and bins (binary BVH).
// The watertight 8-wide case runs mbvh_traverse (traversal/mbvh_traverse.h) with
// ChildOrder::sort_always (child ordering without branching on the number of entered children);
// the other kernels and tri_width=4 with the default branching order.
#include "traversal/mbvh_traverse.h"
#include "traversal/mbvh_fetch.h"

namespace tb {
namespace {

constexpr MBVHDefaults kDefaults = kMBVH8Defaults;

class MBVH8Single final : public MBVHScheme<MBVH8Single, MBVHData<8, 4>, MBVHData<8, 8>> {
 public:
  // tri_width=4: layout 0, 8: layout 1.
  explicit MBVH8Single(const SchemeConfig& cfg) : MBVHScheme(cfg, kDefaults, cfg.get_int("tri_width") == 4 ? 0 : 1) {}
  std::string_view name() const override { return "mbvh8_single"; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      data_.visit([&](const auto& d) {
        constexpr TriKernel K = decltype(k)::value;
        constexpr int W = std::decay_t<decltype(d)>::kW;
        constexpr ChildOrder O = W == 8 && K == TriKernel::watertight ? ChildOrder::sort_always : ChildOrder::branching;
        mbvh_trace_rays<8, W, K, O>(d, batch, range, hits, probe);
      });
    });
  }
};

}  // namespace

std::unique_ptr<Traverser> make_mbvh8_single(const SchemeConfig& cfg) { return std::make_unique<MBVH8Single>(cfg); }
ParamSpecs params_mbvh8_single() {
  return mbvh_param_specs(kDefaults) +
         ParamSpecs{int_choice_param("tri_width", 8, {4, 8}, "triangles per leaf block: 4 (SSE) or 8 (AVX2)")};
}

}  // namespace tb
