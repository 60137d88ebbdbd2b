#include "traversal/bvh_common.h"

namespace tb {

ParamSpecs bvh_param_specs(int default_leaf, bool default_spatial) {
  const BVHBuildParams d;
  return {int_param("bins", d.bins, 2, 256, "binned-SAH bins per axis of the binary BVH build"),
          int_param("leaf_size", default_leaf, 1, 64, "most triangles in a leaf of the binary BVH"),
          bool_param("spatial", default_spatial,
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
                     "spatial splits: a triangle spanning this fraction of the scene's extent on two axes (a "
                     "floor, ceiling or wall of the whole scene) is never clipped; 0: every triangle may be"),
          bool_param("split_walls", d.split_walls,
                     "spatial splits: the SAH may also split a node into its walls (split_wall's triangles) and the "
                     "rest, so a wall is not kept among its neighbours (0: the binned splits only)")};
}

BVHBuildParams bvh_params(const SchemeConfig& cfg) {
  BVHBuildParams p;
  p.bins = cfg.get_int("bins");
  p.max_leaf = cfg.get_int("leaf_size");
  p.spatial = cfg.get_bool("spatial");
  p.split_alpha = float(cfg.get_real("split_alpha"));
  p.split_budget = float(cfg.get_real("split_budget"));
  p.split_wall = float(cfg.get_real("split_wall"));
  p.split_overlap = float(cfg.get_real("split_overlap"));
  p.split_walls = cfg.get_bool("split_walls");
  // The split_* parameters steer the spatial-split build only; a value other than their default
  // (what the resolved config holds when the user gave none) would change nothing without it, so
  // it is refused (every option either works or is refused).
  if (!p.spatial && cfg.declared)
    for (const char* key : {"split_alpha", "split_overlap", "split_budget", "split_wall", "split_walls"}) {
      const ParamSpec& spec = *find_param(*cfg.declared, key);
      const bool changed = spec.type == ParamType::boolean ? cfg.get_bool(key) != param_to_bool(spec.fallback)
                                                          : cfg.get_real(key) != param_to_real(spec.fallback);
      if (changed)
        throw InputError(std::string("parameter '") + key +
                         "' only applies to spatial-split builds, and this scheme builds without them (spatial=0): "
                         "add --param spatial=1 or drop " + key);
    }
  return p;
}

}  // namespace tb
