#include "traversal/bvh_common.h"

namespace tb {

ParamSpecs spatial_param_specs(bool default_spatial, const std::string& extent) {
  const BVHBuildParams d;
  return {bool_param("spatial", default_spatial,
                     "spatial splits (Stich et al. 2009, structures/bvh_spatial.h): straddling triangles are clipped "
                     "and referenced from both sides"),
          real_param("split_alpha", 1e-5, 0, 1,
                     "spatial splits: tried where the object split's children overlap by more than this fraction of "
                     "the root's surface area"),
          real_param("split_overlap", d.split_overlap, 0, 1,
                     "spatial splits: also only where that overlap exceeds this fraction of the node's own surface "
                     "area (Embree 3.13 uses 0.1; 0: off)"),
          real_param("split_budget", 1.0, 0, 16, "spatial splits: at most this many extra references per triangle"),
          real_param("split_wall", d.split_wall, 0, 1,
                     "spatial splits: a triangle spanning this fraction of " + extent +
                         " on two axes (a floor, ceiling or wall around it) is never clipped; 0: every triangle may be"),
          bool_param("split_walls", d.split_walls,
                     "spatial splits: the SAH may also split a node into its walls (split_wall's triangles) and the "
                     "rest, so a wall is not kept among its neighbours (0: the binned splits only)")};
}

ParamSpecs bvh_param_specs(int default_leaf, bool default_spatial) {
  const BVHBuildParams d;
  return ParamSpecs{choice_param("builder", "travbench", {"travbench", "embree"},
                                 "who builds the binary BVH: travbench's binned SAH builder, or Embree 3's rtcBuildBVH "
                                 "(HIGH quality; spatial=1: its spatial-split builder) to compare kernels on Embree's "
                                 "tree (structures/embree_bvh.h)"),
                    int_param("bins", d.bins, 2, 256, "binned-SAH bins per axis of the binary BVH build"),
                    int_param("leaf_size", default_leaf, 1, 64, "most triangles in a leaf of the binary BVH")} +
         spatial_param_specs(default_spatial, "the scene's extent");
}

void read_spatial_params(const SchemeConfig& cfg, BVHBuildParams& p, bool spatial) {
  p.spatial = cfg.find_bool("spatial").value_or(spatial);
  p.split_alpha = float(cfg.get_real("split_alpha"));
  p.split_budget = float(cfg.get_real("split_budget"));
  p.split_wall = float(cfg.get_real("split_wall"));
  p.split_overlap = float(cfg.get_real("split_overlap"));
  p.split_walls = cfg.get_bool("split_walls");
  // A parameter that changes nothing under the chosen build is refused (every option either works
  // or is refused): a value other than its default (what the resolved config holds when the user
  // gave none). The split_* parameters steer the spatial-split build only.
  if (!p.spatial)
    for (const char* key : {"split_alpha", "split_overlap", "split_budget", "split_wall", "split_walls"})
      cfg.refuse_if_changed(key, std::string("only applies to spatial-split builds, and this scheme builds without them "
                                             "(spatial=0): add --param spatial=1 or drop ") + key);
}

BVHBuildParams bvh_params(const SchemeConfig& cfg) { return bvh_params(cfg, false); }

BVHBuildParams bvh_params(const SchemeConfig& cfg, bool spatial) {
  BVHBuildParams p;
  p.builder = cfg.get_choice("builder") == "embree" ? BVHBuilder::embree : BVHBuilder::travbench;
  p.bins = cfg.get_int("bins");
  p.max_leaf = cfg.get_int("leaf_size");
  read_spatial_params(cfg, p, spatial);
  // Embree's builder (structures/embree_bvh.h) takes none of travbench's builder knobs but spatial
  // and split_budget.
  if (p.builder == BVHBuilder::embree)
    for (const char* key : {"bins", "split_alpha", "split_overlap", "split_wall", "split_walls"})
      cfg.refuse_if_changed(key, std::string("steers travbench's BVH builder, not Embree's (builder=embree): drop ") + key);
  if (p.builder == BVHBuilder::embree && p.max_leaf > 32)
    throw InputError("leaf_size " + std::to_string(p.max_leaf) +
                     ": Embree's builder (builder=embree) makes leaves of at most 32 triangles");
  return p;
}

}  // namespace tb
