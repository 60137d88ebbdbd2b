// `travbench table divergence`: the experiment of thesis §3.4 (Tables 2-4). For the scene's three
// camera views, primary rays from one origin whose angle between adjacent rays is scaled by
// D = 1, 2, 4, 8, 16, 32 about each tile's top-left corner (the tiles overlap, so every level sees
// the same geometry). As the thesis measured it unless --width/--height/--param say otherwise:
// 1280x800, a camera whose adjacent rays are 0.034 degrees apart at D = 1 (so `deg_per_ray`, the
// angle between adjacent rays at a tile's corner, is 0.034 D), 16x16 tiles (--param tile=8: the
// 8x8 tiles of chapter 6, §6.2.1); --param camera=view keeps the views' own fields of view. Plus fully
// incoherent rnd (random directions from the camera) and rnd2 (random origins and directions),
// traced by every packet scheme, the single-ray baseline and Embree's packet kernel. The thesis
// measured its ranged BVH packets (Arauna) at D = 1..8 on Modern Room, Sponza and Sibenik+Lucy;
// its Mrays/s stand in `thesis_mrays` beside our bvh_ranged rows when the scene is one of those
// (mapped by file name). `pct_of_d1` is the throughput relative to D = 1 for the same view and
// scheme, the percentage the thesis prints in parentheses.
#include <cstdio>
#include <filesystem>
#include <map>

#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {
namespace {

// Our scene name -> the thesis' scene key in table02-04_packet_divergence_cpu.csv. The built-in
// `room` is a procedural stand-in for Modern Room, not the same geometry, so it gets no column.
std::string thesis_scene_of(const std::string& scene_name) {
  if (scene_name == "sponza") return "sponza";
  if (scene_name == "sibenik_lucy") return "sibenik_lucy";
  return {};
}

}  // namespace

int divergence_table(const TableOptions& table_opt) {
  TableOptions opt = table_opt;
  if (!opt.width_given) opt.run.width = kThesisWidth;
  if (!opt.height_given) opt.run.height = kThesisHeight;
  const ParamSpecs table_params = {
      int_choice_param("tile", 16, {16, 8}, "tile side D scales about: 16 = the CPU packets of §3.4, 8 = chapter 6's tiles (§6.2.1)"),
      choice_param("camera", "thesis", {"thesis", "view"},
                   "thesis: the horizontal fov that puts adjacent rays 0.034 deg apart at 1280 px; view: the views' vfov")};
  const std::vector<std::string> scheme_names = default_schemes(
      opt, {"bvh_single", "bvh_masked", "bvh_ranged", "bvh_partition", "kd_packet", "mbvh4_single", "mbvh8_single",
            "mbvh_rs", "embree_packet8"}, table_params);
  const int tile = param_to_int(table_param(opt, table_params, "tile"));
  const bool thesis_camera = table_param(opt, table_params, "camera") == "thesis";
  Bench bench(load_scene(table_scene(opt)));
  const std::string thesis_scene = thesis_scene_of(bench.scene().name);
  const ThesisTable thesis = load_thesis_table("table02-04_packet_divergence_cpu.csv");
  const std::vector<std::string> workloads = {"divergence:1",  "divergence:2",  "divergence:4", "divergence:8",
                                              "divergence:16", "divergence:32", "rnd",          "rnd2"};
  const uint32_t views = uint32_t(std::min<size_t>(3, bench.scene().views.size()));

  std::vector<std::unique_ptr<Traverser>> schemes;
  for (const auto& name : scheme_names) {
    schemes.push_back(make_scheme(name, config_for(name, opt.run.scheme_config)));
    schemes.back()->prepare(bench.scene(), bench.cache());
  }

  std::vector<Record> records;
  std::map<std::pair<uint32_t, std::string>, double> d1;  // (view, scheme) -> Mrays/s at D = 1
  const size_t total = size_t(views) * workloads.size() * schemes.size();
  size_t done = 0;
  for (uint32_t view = 0; view < views; ++view) {
    RunOptions run = opt.run;
    run.view = view;  // measure_cell records the view from here
    for (const auto& w : workloads) {
      WorkloadSpec spec = table_spec(opt, w, view);
      if (spec.kind == "divergence") spec.tile = uint32_t(tile);
      if (thesis_camera) spec.hfov_deg = thesis_hfov_deg();
      for (size_t s = 0; s < schemes.size(); ++s) {
        Record r = measure_cell(bench, spec, *schemes[s], run, scheme_names[s]);
        const double mrays = std::stod(*r.get("mrays_median"));
        const std::string& scheme = scheme_names[s];
        const std::string level = spec.kind == "divergence" ? std::to_string(spec.param) : spec.kind;
        if (spec.kind == "divergence" && spec.param == 1) d1[{view, scheme}] = mrays;
        r.set("divergence", level);
        if (spec.kind == "divergence") r.set("deg_per_ray", spec.param * centre_pixel_deg(bench.scene(), spec));
        else r.set("deg_per_ray", "");
        if (auto it = d1.find({view, scheme}); it != d1.end() && it->second > 0)
          r.set("pct_of_d1", 100.0 * mrays / it->second);
        else
          r.set("pct_of_d1", "");
        // The thesis measured its ranged packets (Arauna), D = 1..8, 1280x800, one Xeon core.
        std::string tm, tp;
        if (!thesis_scene.empty() && tile == 16 && scheme == "bvh_ranged" && spec.kind == "divergence") {
          const std::string col = "view" + std::to_string(view + 1) + "_mrays";
          const auto v = thesis.lookup({"scene", "divergence"}, {thesis_scene, std::to_string(spec.param)}, col);
          const auto v1 = thesis.lookup({"scene", "divergence"}, {thesis_scene, "1"}, col);
          if (v) {
            char buf[32];
            std::snprintf(buf, sizeof buf, "%.2f", *v);
            tm = buf;
            if (v1 && *v1 > 0) std::snprintf(buf, sizeof buf, "%.0f", 100.0 * *v / *v1), tp = buf;
          }
        }
        r.set("thesis_mrays", tm).set("thesis_pct_of_d1", tp);
        if (opt.run.progress)
          std::fprintf(stderr, "[%zu/%zu] view %u %-14s %-16s %8.3f Mrays/s  mismatch %s\n", ++done, total, view + 1,
                       w.c_str(), scheme.c_str(), mrays, r.get("mismatch_rate")->c_str());
        records.push_back(std::move(r));
      }
    }
  }
  write_csv(opt.csv, records,
            thesis_table_meta("divergence", opt, thesis_scene,
                              {{"width", opt.run.width},
                               {"height", opt.run.height},
                               {"tile", tile},
                               {"camera", thesis_camera ? "thesis" : "view"},
                               {"hfov_deg", thesis_camera ? thesis_hfov_deg() : 0.0},
                               {"reps", opt.run.reps},
                               {"note", "thesis: Bikker 2012 Tables 2-4, ranged BVH packets, 1280x800, 1 core Xeon 3.4 GHz"}}));
  print_table(records, {"view", "divergence", "deg_per_ray", "scheme", "mrays_median", "pct_of_d1", "thesis_mrays", "thesis_pct_of_d1",
                        "mismatch_rate", "false_miss", "false_hit"},
              stdout);
  return 0;
}

}  // namespace tb
