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
// leaf), tri_cost (block test vs node visit, %), prim_cost and prim_share (a per-triangle leaf cost
// in the collapse, on every triangle or on those as large as a share of the leaf box; default 0:
// measured neutral on average, docs/PERFORMANCE.md session 16), small (0 | 4: 4-wide blocks for
// leaves of <= 4 triangles; default 0), leaf_size and bins (binary BVH).
// The watertight 8-wide case runs mbvh_traverse (traversal/mbvh_traverse.h) with the child order
// of `order`: auto (default) takes ChildOrder::branching for common-origin batches (primary rays:
// coherent, so the branches on the number of entered children predict well, and the nearest
// child's address waits for no sort) and ChildOrder::sort_always (no such branches) otherwise
// (bounce rays); sort and branching force one. Interleaved runs, ratio to embree_single, primary
// 512x512, median of 3 (sort -> branching): sponza 0.81 -> 1.09, conference 1.23 -> 1.40,
// dragon_100k 1.11 -> 1.33, stadium 1.02 -> 1.11, the held-out-shaped scene 1.19 -> 1.35; on
// bounce:2 branching was 2-6% behind sort (docs/PERFORMANCE.md, session 8). The hint is the one
// the Embree baselines pass as RTC_INTERSECT_CONTEXT_FLAG_COHERENT. tri_width=4 always takes the
// branching order; every triangle kernel (--kernel) takes the order chosen (until session 39 the
// kernels other than watertight took the branching order whatever `order` said).
// prefetch=auto (default) makes the sorted batches fetch the second-nearest entered child early
// (ChildOrder::sort_prefetch) when the nodes and blocks exceed llc_mib (32: a Zen 3 CCX's L3; this
// VM's sysconf/CPUID report 508 MiB, so the size is a parameter, not a query). bounce:2, one
// interleaved process per scene, 2 rounds, prefetch on / off (znver3 build; docs/PERFORMANCE.md
// session 22): spheres:500000 (33 MiB) 1.06-1.08, spheres:1000000 (66 MiB) and spheres:2000000
// 1.07; at 16 MiB (spheres:250000) 0.96-1.01, and the cached scenes 0.91-0.99 (stadium 0.91,
// conference 0.96, sibenik and dragon_100k 0.96): the prefetch instructions cost where the child
// is in the cache anyway.
#include "traversal/mbvh_traverse.h"
#include "traversal/mbvh_fetch.h"

namespace tb {
namespace {

constexpr MBVHDefaults kDefaults = kMBVH8Defaults;

class MBVH8Single final : public MBVHScheme<MBVH8Single, MBVHData<8, 4>, MBVHData<8, 8>> {
 public:
  // tri_width=4: layout 0, 8: layout 1.
  explicit MBVH8Single(const SchemeConfig& cfg)
      : MBVHScheme(cfg, kDefaults, cfg.get_int("tri_width") == 4 ? 0 : 1),
        order_(parse_order_param(cfg.get_choice("order"))) {
    // Every option works or is refused: the sorted orders (and their prefetch) run on 8-wide
    // blocks only (run() below), under every triangle kernel, and tri_width=4 has 4-wide blocks
    // everywhere, so `small` has nothing to choose.
    const char* unsorted = cfg.get_int("tri_width") == 4 ? "tri_width=4 takes the branching order"
                           : order_ == OrderParam::branching ? "order=branching"
                                                             : nullptr;
    if (unsorted && order_ != OrderParam::branching)
      cfg.refuse_if_changed("order", std::string("picks among the loops of 8-wide blocks (") +
                                         unsorted + "): drop order");
    check_prefetch_params(cfg, unsorted);
    if (cfg.get_int("tri_width") == 4)
      cfg.refuse_if_changed("small", "selects 4-wide blocks for small leaves, and tri_width=4 has them for every leaf: drop small");
  }
  std::string_view name() const override { return "mbvh8_single"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    MBVHScheme::prepare(scene, cache);
    prefetch_ = prefetch_second_child(cfg_, memory().total());
  }
  std::string structure_info() const override { return MBVHScheme::structure_info() + prefetch_info(prefetch_); }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const bool sort = sorts_batch(order_, batch);
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      data_.visit([&](const auto& d) {
        constexpr TriKernel K = decltype(k)::value;
        constexpr int W = std::decay_t<decltype(d)>::kW;
        if constexpr (W == 8) {
          if (sort && prefetch_) {
            mbvh_trace_rays<8, W, K, ChildOrder::sort_prefetch>(d, batch, range, hits, probe);
            return;
          }
          if (sort) {
            mbvh_trace_rays<8, W, K, ChildOrder::sort_always>(d, batch, range, hits, probe);
            return;
          }
        }
        mbvh_trace_rays<8, W, K, ChildOrder::branching>(d, batch, range, hits, probe);
      });
    });
  }

 private:
  OrderParam order_;
  bool prefetch_ = false;  // sort_always batches take ChildOrder::sort_prefetch (decided in prepare)
};

}  // namespace

std::unique_ptr<Traverser> make_mbvh8_single(const SchemeConfig& cfg) { return std::make_unique<MBVH8Single>(cfg); }
ParamSpecs params_mbvh8_single() {
  return mbvh_param_specs(kDefaults) +
         ParamSpecs{int_choice_param("tri_width", 8, {4, 8}, "triangles per leaf block: 4 (SSE) or 8 (AVX2)"),
                    mbvh8_order_param()} +
         prefetch_param_specs();
}

}  // namespace tb
