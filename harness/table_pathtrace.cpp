// `travbench table pathtrace`: thesis §6.3-6.4, Tables 14 and 15 — the path-tracing schemes that
// keep SIMD/SIMT lanes busy (Ref, PR, DPT, SPT) and the light-sampling variants (RIS, RIS/MIS),
// error against time. Rows: traverser x method x spp (8, 16, 32 by default) with ms per frame,
// rmse against a converged image, Mrays/s, lane utilisation and efficiency 1 / (rmse^2 * s);
// beside them the thesis' ms, rmse and Mrays/s for Sponza (two GTX470s: compare shapes, not values).
//
// The converged image is rendered once with Ref at ref_spp (its own random numbers) and cached
// next to the CSV (<csv stem>_converged.bin + .json with scene hash, lighting hash, size, view,
// seed and spp); a later run reuses it only when all of those match. PNGs: each method at the
// smallest spp (<csv stem>_<method>.png) and the converged image (<csv stem>_converged.png).
// One thread traces (timings are per frame on one core; the thesis' ms are for two GPUs). Efficiency
// uses the thread's CPU time (cpu_ms; ms is wall time) and, free of timers, the rays traced.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include "harness/pathtrace.h"
#include "harness/sweep.h"
#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {
namespace {

std::string stem_of(const std::string& csv) {
  const std::string ext = ".csv";
  if (csv.size() > ext.size() && csv.compare(csv.size() - ext.size(), ext.size(), ext) == 0)
    return csv.substr(0, csv.size() - ext.size());
  return csv;
}

// "RIS/MIS" -> "ris_mis": file names.
std::string file_label(const std::string& method) {
  std::string s;
  for (char c : method) s += c == '/' ? '_' : char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The converged image: from the cache when its sidecar matches `key`, else rendered and cached.
PtImage converged_image(const std::string& stem, const nlohmann::json& key, const Scene& scene, const Traverser& t,
                        const Lighting& lighting, const PtOptions& base, bool progress, bool& reused) {
  const std::string bin = stem + "_converged.bin", side = stem + "_converged.json";
  PtImage img;
  std::ifstream in(side);
  if (in) {
    nlohmann::json have;
    try {
      in >> have;
    } catch (const nlohmann::json::exception&) {
      have = nullptr;
    }
    if (have.is_object() && have.value("key", nlohmann::json()) == key && load_pt_image(bin, img) &&
        img.width == base.width && img.height == base.height) {
      reused = true;
      return img;
    }
  }
  reused = false;
  PtOptions o = base;
  o.spp = key.at("spp").get<uint32_t>();
  o.salt = "converged";
  if (progress) std::fprintf(stderr, "rendering the converged image: Ref, %u spp, %ux%u\n", o.spp, o.width, o.height);
  PtStats st;
  img = render_pathtrace(scene, t, lighting, PtMethod::ref, o, &st);
  save_pt_image(bin, img);
  nlohmann::json meta = {{"key", key}, {"scheme", std::string(t.name())}, {"seconds", st.total_s}};
  write_file_durably(side, meta.dump(2) + "\n");
  return img;
}

}  // namespace

int pathtrace_table(const TableOptions& opt) {
  const ParamSpecs table_params = {
      int_param("min_spp", 8, 1, 4096, "smallest spp of the rows (the thesis: 8); rows double up to max_spp"),
      int_param("max_spp", 32, 1, 4096, "largest spp of the rows (the thesis: 32)"),
      int_param("ref_spp", 256, 1, 65536, "spp of the converged image (Ref, its own random numbers)"),
      int_param("ris_per_light", 2, 1, 16, "RIS candidates per light (thesis §6.4.2: two points on each light)")};
  const std::vector<std::string> names = default_schemes(opt, {"mbvh_rs"}, table_params);
  auto table_param = [&](const std::string& key) {
    const auto it = opt.run.scheme_config.params.find(key);
    return param_to_int(it != opt.run.scheme_config.params.end() ? it->second : find_param(table_params, key)->fallback);
  };
  const uint32_t min_spp = uint32_t(table_param("min_spp")), max_spp = uint32_t(table_param("max_spp"));
  const uint32_t ref_spp = uint32_t(table_param("ref_spp"));
  if (min_spp > max_spp) throw InputError("table pathtrace: min_spp must not exceed max_spp");
  if (opt.csv.empty()) throw InputError("table pathtrace needs --csv (its images and converged cache go beside it)");
  const std::string stem = stem_of(opt.csv);

  Scene scene = load_scene(table_scene(opt));
  scene.ensure_views();
  StructureCache cache(scene);
  const Lighting lighting = scene_lighting(scene);
  const std::string tscene = thesis_scene(scene.name);
  const ThesisTable thesis = load_thesis_table("table14_15_path_tracing_schemes.csv");

  PtOptions base;
  base.width = opt.run.width, base.height = opt.run.height, base.view = opt.run.view, base.seed = opt.run.seed;
  base.ris_per_light = uint32_t(table_param("ris_per_light"));

  std::vector<std::unique_ptr<Traverser>> tracers;
  for (const auto& name : names) {
    SchemeConfig cfg = config_for(name, opt.run.scheme_config);
    if (!find_scheme(name).kernels) cfg.kernel = TriKernel::watertight;
    tracers.push_back(make_scheme(name, cfg));
    tracers.back()->prepare(scene, cache);
  }
  const nlohmann::json key = {{"scene_hash", std::to_string(scene.content_hash())},
                              {"lighting_hash", std::to_string(lighting.hash())},
                              {"width", base.width},
                              {"height", base.height},
                              {"view", base.view},
                              {"seed", base.seed},
                              {"spp", ref_spp},
                              {"method", "Ref"}};
  bool reused = false;
  const PtImage conv = converged_image(stem, key, scene, *tracers.front(), lighting, base, opt.run.progress, reused);
  write_pt_png(stem + "_converged.png", conv);

  std::vector<Record> records;
  for (size_t si = 0; si < tracers.size(); ++si) {
    for (const std::string& method : pt_method_names()) {
      for (uint32_t spp = min_spp; spp <= max_spp; spp *= 2) {
        PtOptions o = base;
        o.spp = spp;
        o.salt = method;
        PtStats st;
        const PtImage img = render_pathtrace(scene, *tracers[si], lighting, parse_pt_method(method), o, &st);
        if (spp == min_spp && si == 0) write_pt_png(stem + "_" + file_label(method) + ".png", img);
        const double rmse = pt_rmse(img, conv);
        const uint64_t rays = st.ext_rays + st.shadow_rays;
        Record r;
        r.set("scene", scene.name).set("scheme", names[si]).set("method", method).set("spp", spp);
        r.set("width", base.width).set("height", base.height).set("threads", 1);
        r.set("ms", 1e3 * st.total_s).set("cpu_ms", 1e3 * st.cpu_s).set("trace_ms", 1e3 * st.trace_s).set("rmse", rmse);
        r.set("mrays", double(rays) / st.total_s * 1e-6).set("trace_mrays", double(rays) / st.trace_s * 1e-6);
        r.set("ext_rays", st.ext_rays).set("shadow_rays", st.shadow_rays);
        r.set("rays_per_sample", double(rays) / (double(spp) * base.width * base.height));
        r.set("iterations", st.iterations);
        r.set("util", st.util()).set("shadow_util", st.shadow_util()).set("warp_util", st.warp_util());
        // Efficiency 1 / (rmse^2 t) with t the frame's CPU time (a shared machine's wall time is mostly
        // the other load); efficiency_rays with the rays traced instead of time (per million rays):
        // free of timer noise, blind to what a ray costs (packet fullness, shading).
        r.set("efficiency", rmse > 0 ? 1.0 / (rmse * rmse * st.cpu_s) : 0.0);
        r.set("efficiency_rays", rmse > 0 ? 1e6 / (rmse * rmse * double(rays)) : 0.0);
        r.set("mean", pt_mean(img)).set("converged_mean", pt_mean(conv)).set("converged_spp", ref_spp);
        r.set("thesis_scene", tscene);
        for (const char* col : {"ms", "rmse", "mrays"}) {
          std::optional<double> v;
          if (!tscene.empty()) v = thesis.lookup({"scene", "method", "spp"}, {tscene, method, std::to_string(spp)}, col);
          if (v) r.set(std::string("thesis_") + col, *v);
          else r.set(std::string("thesis_") + col, "");
        }
        if (opt.run.progress)
          std::fprintf(stderr, "%-12s %-8s %4u spp %9.1f ms  rmse %7.3f  %6.2f Mrays/s  util %.3f  warp %.3f\n",
                       names[si].c_str(), method.c_str(), spp, 1e3 * st.total_s, rmse, double(rays) / st.total_s * 1e-6,
                       st.util(), st.warp_util());
        if (opt.run.cells) opt.run.cells->append(r);
        records.push_back(std::move(r));
      }
    }
  }
  // Ranks among the methods at the same (scheme, spp): 1 = the most efficient.
  for (const char* col : {"efficiency", "efficiency_rays"}) {
    std::vector<int> ranks;
    for (const Record& r : records) {
      int rank = 1;
      const double e = std::stod(*r.get(col));
      for (const Record& o : records)
        if (*o.get("scheme") == *r.get("scheme") && *o.get("spp") == *r.get("spp") && std::stod(*o.get(col)) > e) ++rank;
      ranks.push_back(rank);
    }
    for (size_t i = 0; i < records.size(); ++i) records[i].set(std::string(col) + "_rank", ranks[i]);
  }
  write_csv(opt.csv, records,
            thesis_table_meta("pathtrace", opt, tscene,
                              {{"width", base.width},
                               {"height", base.height},
                               {"lighting", lighting.source},
                               {"converged", {{"spp", ref_spp}, {"method", "Ref"}, {"reused_cache", reused}}},
                               {"threads", 1}}));
  print_table(records,
              {"scheme", "method", "spp", "ms", "cpu_ms", "rmse", "mrays", "util", "warp_util", "efficiency_rank", "efficiency_rays_rank",
               "thesis_ms", "thesis_rmse", "thesis_mrays"},
              stdout);
  return 0;
}

}  // namespace tb
