#include "traversal/mbvh_fetch.h"

namespace tb {

ParamSpecs mbvh_param_specs(const MBVHDefaults& d) {
  const MBVHBuildParams p;
  return bvh_param_specs(d.leaf_size, d.spatial) +
         ParamSpecs{int_param("merge", d.merge, 0, 64,
                              "binary subtrees of at most this many triangles become one leaf (0: off; SAH "
                              "collapse: the largest leaf, never below one block: values under the block width act "
                              "as the block width)"),
                    choice_param("collapse", d.sah ? "sah" : "greedy", {"greedy", "sah"},
                                 "binary -> wide collapse: greedy (Dammertz 2008) or SAH-optimal (Ylitie 2017)"),
                    int_param("tri_cost", p.tri_cost, 1, 10000,
                              "SAH collapse: a triangle-block test's cost in percent of a node visit"),
                    int_param("prim_cost", p.prim_cost, 0, 10000,
                              "SAH collapse: each triangle of a leaf adds this cost in percent of a node visit "
                              "(a candidate's double-precision distance; 0: only block tests count)"),
                    real_param("prim_share", p.prim_share, 0, 1,
                               "SAH collapse: prim_cost charges only triangles whose box, clipped to the leaf's, "
                               "has at least this share of the leaf box's surface area (0: every triangle)"),
                    d.wide_blocks ? int_choice_param("small", d.small, {0, 4},
                                                     "8-wide blocks: leaves of at most this many triangles take a "
                                                     "4-wide block")
                                  : int_choice_param("small", 0, {0}, "always 0: this scheme's leaves are 4-wide blocks")};
}

ParamSpec mbvh8_order_param() {
  return choice_param("order", "auto", {"auto", "sort", "branching"},
                      "child order (ChildOrder, 8-wide blocks): sort = sort_always, branching, "
                      "auto = branching for common-origin batches, sort_always otherwise");
}

ParamSpecs prefetch_param_specs() {
  return {choice_param("prefetch", "auto", {"auto", "on", "off"},
                       "sorted batches fetch the second-nearest entered child early: on, off, or auto = when the "
                       "nodes and triangle blocks exceed llc_mib"),
          int_param("llc_mib", 32, 1, 65536,
                    "the last-level cache prefetch=auto compares the structure's bytes with, in MiB (default: the "
                    "reference machine's, a Zen 3 CCX's 32 MiB L3)")};
}

bool prefetch_second_child(const SchemeConfig& cfg, size_t bytes) {
  const std::string mode = cfg.get_choice("prefetch");
  return mode == "on" || (mode == "auto" && bytes > (size_t(cfg.get_int("llc_mib")) << 20));
}

void check_prefetch_params(const SchemeConfig& cfg, const char* unsorted) {
  if (unsorted) {
    for (const char* key : {"prefetch", "llc_mib"})
      cfg.refuse_if_changed(key, std::string("steers the sorted child order's early fetch, which this scheme does not "
                                             "take here (") + unsorted + "): drop " + key);
    return;
  }
  if (cfg.get_choice("prefetch") != "auto")
    cfg.refuse_if_changed("llc_mib", "is what prefetch=auto compares the structure with; with prefetch=" +
                                         cfg.get_choice("prefetch") + " drop llc_mib");
}

MBVHBuildParams mbvh_params(const SchemeConfig& cfg, const MBVHDefaults& d) {
  MBVHBuildParams p;
  p.bvh = bvh_params(cfg, d.spatial);
  p.merge = cfg.find_int("merge").value_or(d.merge);
  p.sah_collapse = cfg.find_choice("collapse").value_or(d.sah ? "sah" : "greedy") == "sah";
  p.tri_cost = cfg.get_int("tri_cost");
  p.prim_cost = cfg.get_int("prim_cost");
  p.prim_share = float(cfg.get_real("prim_share"));
  p.small = cfg.find_int("small").value_or(d.small);
  // The SAH collapse's costs steer nothing in the greedy collapse (Dammertz 2008 takes no cost),
  // and prim_share only scales prim_cost.
  if (!p.sah_collapse)
    for (const char* key : {"tri_cost", "prim_cost", "prim_share"})
      cfg.refuse_if_changed(key, std::string("steers the SAH collapse, and this scheme collapses greedily "
                                             "(collapse=greedy): add --param collapse=sah or drop ") + key);
  if (p.prim_cost == 0)
    cfg.refuse_if_changed("prim_share", "only scales prim_cost, which is 0: set prim_cost or drop prim_share");
  return p;
}

template <int N, int W>
MBVHData<N, W> fetch_mbvh(const Scene& scene, StructureCache& cache, const MBVHBuildParams& params, TriKernel kernel) {
  MBVHData<N, W> d;
  const std::string key = params.key(N, W);
  d.mbvh = cache.get<MBVH<N, W>>(key, [&] {
    auto bvh = cache.get<BVH>(params.bvh.key(), [&] { return BVH::build(scene, params.bvh); });
    return MBVH<N, W>::collapse(scene, *bvh, params);
  });
  if (kernel != TriKernel::watertight)  // the watertight kernel reads the SIMD blocks
    d.tris = fetch_triangles(scene, cache, key, kernel, [&] { return d.mbvh->lane_prims(); });
  return d;
}

std::shared_ptr<const CWBVH> fetch_cwbvh(const Scene& scene, StructureCache& cache, const MBVHBuildParams& params,
                                         int full_percent, CWSlots slots, CWLeaves leaves) {
  const MBVHData<8, 8> m = fetch_mbvh<8, 8>(scene, cache, params, TriKernel::watertight);
  return cache.get<CWBVH>(params.key(8, 8) + ":full" + std::to_string(full_percent) +
                              (slots == CWSlots::octant ? ":octant" : "") + (leaves == CWLeaves::indexed ? ":indexed" : ""),
                          [&] { return CWBVH::compress(*m.mbvh, full_percent / 100.0, slots, leaves); });
}

void check_cwbvh_params(const MBVHBuildParams& params, const std::string& prefix) {
  const int most = int(kCWMaxLeafTris);
  const std::string why = " (a compressed leaf holds at most " + std::to_string(most) + " triangles)";
  if (params.merge > most) throw InputError(prefix + "merge must be <= " + std::to_string(most) + why);
  if (params.bvh.max_leaf > most) throw InputError(prefix + "leaf_size must be <= " + std::to_string(most) + why);
  if (params.small != 0)
    throw InputError(prefix + "small must be 0 (the compressed layout holds 8-wide blocks only; tree=mbvh8 takes small=4)");
}

template MBVHData<4, 4> fetch_mbvh<4, 4>(const Scene&, StructureCache&, const MBVHBuildParams&, TriKernel);
template MBVHData<8, 4> fetch_mbvh<8, 4>(const Scene&, StructureCache&, const MBVHBuildParams&, TriKernel);
template MBVHData<8, 8> fetch_mbvh<8, 8>(const Scene&, StructureCache&, const MBVHBuildParams&, TriKernel);

}  // namespace tb
