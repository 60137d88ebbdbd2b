#include "traversal/kd_common.h"

namespace tb {

ParamSpecs kd_param_specs() {
  const KDBuildParams p;
  return {real_param("kd_ct", p.cost_traversal, 1e-6, 1e6, "SAH cost of a traversal step (Wald & Havran 2006: 15)"),
          real_param("kd_ci", p.cost_intersect, 1e-6, 1e6, "SAH cost of a triangle test (Wald & Havran 2006: 20)"),
          real_param("kd_empty_bonus", p.empty_bonus, 0.0, 0.99,
                     "cost reduction of a split that cuts off empty space (Hurley et al. 2002)"),
          int_param("kd_max_depth", p.max_depth, 0, KDTree::kMaxDepth, "tree depth limit (0: 8 + 1.3 log2 N)"),
          int_param("kd_min_leaf", p.min_leaf, 0, 1 << 20, "nodes with at most this many triangles become leaves"),
          int_param("kd_max_leaf", p.max_leaf, 1, 1 << 30,
                    "nodes with more triangles are split even when the SAH prefers a leaf (within the depth limit and the "
                    "reference cap, KDTree::reference_cap)"),
          bool_param("kd_planar_both", p.planar_both, "triangles in a split plane go to both children")};
}

KDBuildParams kd_params(const SchemeConfig& cfg) {
  KDBuildParams p;
  p.cost_traversal = float(cfg.get_real("kd_ct"));
  p.cost_intersect = float(cfg.get_real("kd_ci"));
  p.empty_bonus = float(cfg.get_real("kd_empty_bonus"));
  p.max_depth = cfg.get_int("kd_max_depth");
  p.min_leaf = cfg.get_int("kd_min_leaf");
  p.max_leaf = cfg.get_int("kd_max_leaf");
  p.planar_both = cfg.get_bool("kd_planar_both");
  return p;
}

}  // namespace tb
