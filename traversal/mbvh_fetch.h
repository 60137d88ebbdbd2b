// A scheme's MBVH: its declared build parameters (the binary BVH's plus the collapse's), read
// from a resolved SchemeConfig, and the cached structure. Kept out of structures/mbvh.h so that
// structures/ never parses a SchemeConfig (issue 15: layers point down).
#pragma once
#include <string>
#include <variant>

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
};
// `bins`, `leaf_size` (binary BVH), `merge`, `collapse` (greedy | sah), `tri_cost`, `small` (0 | 4).
ParamSpecs mbvh_param_specs(const MBVHDefaults& d);
// Reads them; a parameter declared with auto_default() (its default depends on another, as
// mbvh_rs's merge and collapse on its width) takes its value from `d`.
MBVHBuildParams mbvh_params(const SchemeConfig& cfg, const MBVHDefaults& d);
// Fetches (building on first use; the collapse fetches the binary BVH through the cache too) the
// MBVH and, for the scalar kernels, its triangles in lane order.
template <int N, int W>
MBVHData<N, W> fetch_mbvh(const Scene& scene, StructureCache& cache, const MBVHBuildParams& params, TriKernel kernel);

// The MBVH of a scheme that offers two layouts by a parameter (mbvh8_single's tri_width,
// mbvh_rs's width): it holds the one it runs, and `visit` hands that to a generic lambda (once per
// trace call, outside the per-ray loop).
template <class A, class B>
struct MBVHChoice {
  std::variant<A, B> data;
  template <class F>
  decltype(auto) visit(F&& f) const {
    return std::visit(std::forward<F>(f), data);
  }
  std::string describe() const {
    return visit([](const auto& d) { return d.mbvh->stats.describe(); });
  }
  size_t bytes(TriKernel k) const {
    return visit([&](const auto& d) { return mbvh_bytes(d, k); });
  }
};

}  // namespace tb
