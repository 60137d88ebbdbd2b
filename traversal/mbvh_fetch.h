// A scheme's MBVH: its declared build parameters (the binary BVH's plus the collapse's), read
// from a resolved SchemeConfig, and the cached structure. Kept out of structures/mbvh.h so that
// structures/ never parses a SchemeConfig (issue 15: layers point down).
#pragma once
#include <memory>
#include <string>
#include <utility>
#include <variant>

#include "structures/cwbvh.h"
#include "structures/mbvh.h"
#include "traversal/bvh_common.h"
#include "traversal/traverser.h"

namespace tb {

// A scheme's defaults for the MBVH parameters; the same struct feeds its declaration and its read,
// so the documented default is the one used.
struct MBVHDefaults {
  int leaf_size = 4;
  int merge = 4;
  bool sah = false;
  int small = 4;
  bool spatial = false;  // the binary BVH's spatial splits (bvh_param_specs)
  // false: the scheme's leaves are 4-wide blocks (MBVH<N, 4>), where `small` means nothing, so the
  // parameter only takes 0 (a value that changed nothing was accepted before).
  bool wide_blocks = true;
};
// mbvh8_single's (and treelet_queue's, which runs its loop on the same cached tree): SAH collapse,
// leaves of up to 16 triangles. Every leaf in 8-wide blocks by default (small=0): one leaf path
// instead of a branch between 4- and 8-wide blocks that mispredicts; +3 to +8% on bunny, dragon,
// buddha and lucy (bounce:2), within noise on the architectural scenes, for ~15% more triangle bytes.
// Spatial splits by default (structures/bvh_spatial.h, enclosures never clipped): ratio to
// embree_single 0.98 -> 1.22 on sponza bounce:2, 1.05 -> 1.13 crytek_sponza_partial, 1.05 -> 1.17
// buddha_100k, no scene slower beyond noise but conference primary (1.45 -> 1.36; docs/PERFORMANCE.md
// "Spatial splits by default").
inline constexpr MBVHDefaults kMBVH8Defaults{4, 16, true, 0, true};
// `bins`, `leaf_size` (binary BVH), `merge`, `collapse` (greedy | sah), `tri_cost`, `prim_cost`,
// `prim_share`, `small` (0 | 4).
ParamSpecs mbvh_param_specs(const MBVHDefaults& d);
// Reads them; a parameter declared with auto_default() (its default depends on another, as
// mbvh_rs's merge and collapse on its width) takes its value from `d`.
MBVHBuildParams mbvh_params(const SchemeConfig& cfg, const MBVHDefaults& d);
// `prefetch` (auto | on | off) and `llc_mib` of the single-ray schemes whose sorted batches may
// fetch the second-nearest entered child early (mbvh8_single: ChildOrder::sort_prefetch;
// cwbvh_single): that pays where the structure does not fit the last-level cache and costs where
// it does (docs/PERFORMANCE.md, session 22), so `auto` compares the structure's bytes with
// llc_mib. A parameter rather than a query: this VM's sysconf and CPUID report a 508 MiB L3.
ParamSpecs prefetch_param_specs();
// `order` (auto | sort | branching; parse_order_param) of the schemes that run mbvh8_single's loop
// on its MBVH8 (mbvh8_single, mbvh8_interleave).
ParamSpec mbvh8_order_param();
// Whether a structure of `bytes` (nodes and triangle blocks) gets the early fetch under `cfg`.
bool prefetch_second_child(const SchemeConfig& cfg, size_t bytes);
// Refuses prefetch and llc_mib where they change nothing: `unsorted` names why the scheme never
// takes the sorted order under `cfg` (nullptr: it may), and llc_mib is read only by prefetch=auto.
void check_prefetch_params(const SchemeConfig& cfg, const char* unsorted);
// What structure_info() appends so the build table and logs say which variant runs.
inline std::string prefetch_info(bool on) {
  return on ? ", second child prefetched (sorted batches)" : ", no second-child prefetch";
}
// Fetches (building on first use; the collapse fetches the binary BVH through the cache too) the
// MBVH and, for the scalar kernels, its triangles in lane order.
template <int N, int W>
MBVHData<N, W> fetch_mbvh(const Scene& scene, StructureCache& cache, const MBVHBuildParams& params, TriKernel kernel);
// cwbvh_single's default share of uncompressed nodes (`full_top`, percent; cwbvh_single.cpp says
// why 4), also the layout treelet_queue's `tree=cwbvh` cuts.
inline constexpr int kCWFullTop = 4;
// The compressed 8-wide BVH (structures/cwbvh.h) of the MBVH8 built with `params`, `full_percent`
// percent of its nodes uncompressed: one cached structure for cwbvh_single and treelet_queue's
// `tree=cwbvh` where their parameters agree.
std::shared_ptr<const CWBVH> fetch_cwbvh(const Scene& scene, StructureCache& cache, const MBVHBuildParams& params,
                                         int full_percent, CWSlots slots, CWLeaves leaves);
// Refuses (InputError, the message after `prefix`) MBVH parameters whose leaves a compressed BVH
// cannot hold: `merge` or `leaf_size` above 16 triangles. Called when a scheme that compresses is
// made, so a run refuses before it builds anything.
void check_cwbvh_params(const MBVHBuildParams& params, const std::string& prefix = "");

// The MBVH of a scheme, in the one of its layouts it runs (mbvh8_single's tri_width, mbvh_rs's
// width); `visit` hands it to a generic lambda (once per trace call, outside the per-ray loop).
template <class... Layouts>
struct MBVHChoice {
  std::variant<Layouts...> data;
  template <class F>
  decltype(auto) visit(F&& f) const {
    return std::visit(std::forward<F>(f), data);
  }
  std::string describe() const {
    return visit([](const auto& d) { return d.mbvh->stats.describe(); });
  }
  StructureBytes bytes(TriKernel k) const {
    return visit([&](const auto& d) { return StructureBytes{d.mbvh->stats.node_bytes, mbvh_prim_bytes(d, k)}; });
  }
};

// The base of the MBVH schemes (mbvh4_single, mbvh8_single, mbvh_rs): the config, the MBVH build
// parameters read with the scheme's defaults, and the cached MBVH in layout number `layout` of
// Layouts (MBVHData<N, W> types), with its description and size. Derived provides name() and
// run(), which runs data_ through data_.visit.
template <class Derived, class... Layouts>
class MBVHScheme : public TraverserBase<Derived> {
 public:
  MBVHScheme(const SchemeConfig& cfg, const MBVHDefaults& defaults, size_t layout = 0)
      : cfg_(cfg), params_(mbvh_params(cfg, defaults)), layout_(layout) {}
  void prepare(const Scene& scene, StructureCache& cache) override {
    [&]<size_t... I>(std::index_sequence<I...>) {
      (fetch_layout<I>(scene, cache), ...);
    }(std::index_sequence_for<Layouts...>{});
  }
  std::string structure_info() const override { return data_.describe(); }
  StructureBytes memory() const override { return data_.bytes(cfg_.kernel); }

 protected:
  SchemeConfig cfg_;
  MBVHBuildParams params_;
  size_t layout_;
  MBVHChoice<Layouts...> data_;

 private:
  template <size_t I>
  void fetch_layout(const Scene& scene, StructureCache& cache) {
    using D = std::variant_alternative_t<I, std::variant<Layouts...>>;
    if (layout_ == I) data_.data.template emplace<I>(fetch_mbvh<D::kN, D::kW>(scene, cache, params_, cfg_.kernel));
  }
};

}  // namespace tb
