// `travbench table pathtrace`: thesis §6.3-6.4, Tables 14 and 15 — the path-tracing schemes that
// keep SIMD/SIMT lanes busy (Ref, PR, DPT, SPT) and the light-sampling variants (RIS, RIS/MIS),
// error against time. Rows: traverser x method x spp (8, 16, 32 by default) with ms per frame,
// rmse against a converged image, Mrays/s, lane utilisation and efficiency 1 / (mse * s);
// beside them the thesis' ms, rmse and Mrays/s for Sponza (two GTX470s: compare shapes, not values).
//
// Statistics (docs/PATHTRACE.md): each cell is `seeds` independent renderings. rmse is their mean
// and rmse_sd their spread; rmse_corr the rms error against the true image (the converged image's
// residual removed); noise_rmse the per-rendering noise from the renderings' per-pixel spread (no
// reference needed); bias_rmse what their mean still misses. <csv stem>.depth.csv splits each
// cell's mean and noise by path vertex (kPtDepths; the first scheme only).
//
// The converged image is rendered once with Ref at ref_spp (two halves with their own random
// numbers) and cached next to the CSV (<csv stem>_converged.bin + .json with scene hash, lighting
// hash, size, view, seed, spp and residual rmse); a later run reuses it only when all of those match.
// PNGs: each method at the smallest spp (first seed; <csv stem>_<method>.png) and the converged image.
// One thread traces (timings are per frame on one core; the thesis' ms are for two GPUs). Efficiency
// uses the thread's CPU time (cpu_ms, the median over the seeds; ms is wall time) and, free of
// timers, the rays traced.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include "harness/pathtrace.h"
#include "harness/sweep.h"
#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "harness/trace_runner.h"
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
// It is rendered as two independent halves of ref_spp / 2 (salts "converged/a", "converged/b")
// and averaged: half their rmse against each other estimates its own residual rmse against the
// true image (two independent images of variance v differ by 2v; their mean has v / 2), stored in
// the sidecar and subtracted (in mse) from every cell's (rmse_corr).
PtImage converged_image(const std::string& stem, const nlohmann::json& key, const Scene& scene, const Traverser& t,
                        const Lighting& lighting, const PtOptions& base, bool progress, bool& reused,
                        double& residual) {
  const std::string bin = stem + "_converged.bin", side = stem + "_converged.json";
  PtImage img;
  // A cache is only a cache: one of other settings (another key) is rendered again silently, one
  // that is damaged (not JSON, a residual_rmse that is no rmse, an image that does not load or has
  // another size) with a warning naming the file and what is wrong, then rendered again and
  // replaced. Nothing in it is used unchecked: a NaN pixel or residual would be every cell's rmse.
  std::string damaged;
  std::ifstream in(side);
  if (in) {
    nlohmann::json have;
    try {
      in >> have;
    } catch (const nlohmann::json::exception&) {
      have = nullptr;
    }
    const nlohmann::json none;
    const nlohmann::json& res = have.is_object() && have.contains("residual_rmse") ? have["residual_rmse"] : none;
    std::string why;
    if (!have.is_object()) {
      damaged = side + ": not a JSON object";
    } else if (have.value("key", nlohmann::json()) != key) {
      // another sweep's image: not damaged, just not this one
    } else if (!res.is_number() || !std::isfinite(res.get<double>()) || res.get<double>() < 0) {
      damaged = side + ": residual_rmse " + (res.is_null() ? std::string("is missing") : res.dump() + " is not an rmse") +
                " (a finite number >= 0)";
    } else if (!load_pt_image(bin, img, &why)) {
      damaged = bin + ": " + (why.empty() ? std::string("missing") : why);
    } else if (img.width != base.width || img.height != base.height) {
      damaged = bin + ": " + std::to_string(img.width) + "x" + std::to_string(img.height) + ", the table renders " +
                std::to_string(base.width) + "x" + std::to_string(base.height);
    } else {
      reused = true;
      residual = res.get<double>();
      return img;
    }
  }
  if (!damaged.empty())
    std::fprintf(stderr, "warning: converged-image cache %s; rendering it again\n", damaged.c_str());
  reused = false;
  PtOptions o = base;
  o.spp = key.at("spp").get<uint32_t>() / 2;
  if (progress)
    std::fprintf(stderr, "rendering the converged image: Ref, 2 x %u spp, %ux%u\n", o.spp, o.width, o.height);
  double seconds = 0;
  PtImage half[2];
  for (int h = 0; h < 2; ++h) {
    o.salt = h ? "converged/b" : "converged/a";
    PtStats st;
    half[h] = render_pathtrace(scene, t, lighting, PtMethod::ref, o, &st);
    seconds += st.total_s;
  }
  residual = pt_rmse(half[0], half[1]) / 2;
  img = half[0];
  for (size_t i = 0; i < img.rgb.size(); ++i) img.rgb[i] = 0.5f * (half[0].rgb[i] + half[1].rgb[i]);
  save_pt_image(bin, img);
  nlohmann::json meta = {
      {"key", key}, {"scheme", std::string(t.name())}, {"seconds", seconds}, {"residual_rmse", residual}};
  write_file_durably(side, meta.dump(2) + "\n");
  return img;
}

// Per-pixel running sums over a cell's independent renderings (one per seed): their mean image
// and, from the spread, the per-rendering noise free of the converged image.
struct PixelMoments {
  std::vector<double> s, s2;
  uint32_t n = 0;
  void add(const PtImage& img) {
    if (s.empty()) s.assign(img.rgb.size(), 0.0), s2.assign(img.rgb.size(), 0.0);
    for (size_t i = 0; i < img.rgb.size(); ++i) s[i] += img.rgb[i], s2[i] += double(img.rgb[i]) * img.rgb[i];
    ++n;
  }
  // Mean over pixels and channels of the unbiased per-pixel variance, as an rmse (1/255 units).
  double noise_rmse() const {
    if (n < 2) return 0;
    double v = 0;
    for (size_t i = 0; i < s.size(); ++i) v += std::max(0.0, (s2[i] - s[i] * s[i] / n) / (n - 1));
    return 255.0 * std::sqrt(v / double(s.size()));
  }
  double mean() const {
    double m = 0;
    for (double x : s) m += x;
    return s.empty() ? 0 : m / double(s.size()) / n;
  }
  PtImage mean_image(uint32_t w, uint32_t h) const {
    PtImage img{w, h, std::vector<float>(s.size())};
    for (size_t i = 0; i < s.size(); ++i) img.rgb[i] = float(s[i] / n);
    return img;
  }
};

}  // namespace

int pathtrace_table(const TableOptions& opt) {
  const ParamSpecs table_params = {
      int_param("min_spp", 8, 1, 4096, "smallest spp of the rows (the thesis: 8); rows double up to max_spp"),
      int_param("max_spp", 32, 1, 4096, "largest spp of the rows (the thesis: 32)"),
      int_param("ref_spp", 1024, 2, 65536,
                "spp of the converged image (Ref, its own random numbers; two halves give its residual rmse)"),
      int_param("seeds", 3, 1, 64,
                "independent renderings per cell (rmse: their mean, rmse_sd their spread; noise_rmse needs 2)"),
      int_param("ris_per_light", 2, 1, 16, "RIS candidates per light (thesis §6.4.2: two points on each light)")};
  const std::vector<std::string> names = default_schemes(opt, {"mbvh_rs"}, table_params);
  auto table_param = [&](const std::string& key) { return param_to_int(tb::table_param(opt, table_params, key)); };
  const uint32_t min_spp = uint32_t(table_param("min_spp")), max_spp = uint32_t(table_param("max_spp"));
  const uint32_t ref_spp = uint32_t(table_param("ref_spp")), seeds = uint32_t(table_param("seeds"));
  if (ref_spp % 2) throw InputError("table pathtrace: ref_spp must be even (the converged image is two halves)");
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
  double residual = 0;
  const PtImage conv =
      converged_image(stem, key, scene, *tracers.front(), lighting, base, opt.run.progress, reused, residual);
  write_pt_png(stem + "_converged.png", conv);

  std::vector<Record> records, depth_records;
  for (size_t si = 0; si < tracers.size(); ++si) {
    for (const std::string& method : pt_method_names()) {
      for (uint32_t spp = min_spp; spp <= max_spp; spp *= 2) {
        // `seeds` independent renderings per cell: the salt names method, spp and repetition, so
        // no two cells share random numbers (an 8-spp image is not the first half of the 16-spp
        // one, whose errors would then be correlated along the spp axis).
        std::vector<double> rmses, ms, cpu_ms, trace_ms;
        PixelMoments pix;
        std::vector<PixelMoments> depth(kPtDepths);
        PtStats st;  // counters: the sum over the renderings
        for (uint32_t k = 0; k < seeds; ++k) {
          PtOptions o = base;
          o.spp = spp;
          o.salt = method + " spp=" + std::to_string(spp) + " rep=" + std::to_string(k);
          PtStats one;
          std::vector<PtImage> by_depth;
          const PtImage img = render_pathtrace(scene, *tracers[si], lighting, parse_pt_method(method), o, &one,
                                               si == 0 ? &by_depth : nullptr);
          if (spp == min_spp && si == 0 && k == 0) write_pt_png(stem + "_" + file_label(method) + ".png", img);
          rmses.push_back(pt_rmse(img, conv));
          ms.push_back(1e3 * one.total_s), cpu_ms.push_back(1e3 * one.cpu_s), trace_ms.push_back(1e3 * one.trace_s);
          pix.add(img);
          for (size_t d = 0; d < by_depth.size(); ++d) depth[d].add(by_depth[d]);
          st.ext_rays += one.ext_rays, st.shadow_rays += one.shadow_rays;
          st.ext_packets += one.ext_packets, st.shadow_packets += one.shadow_packets;
          st.warp_slots += one.warp_slots, st.warp_active += one.warp_active;
          st.iterations += one.iterations;
        }
        double rmse = 0, mse = 0, sd = 0;
        for (double e : rmses) rmse += e / seeds, mse += e * e / seeds;
        for (double e : rmses) sd += seeds > 1 ? (e - rmse) * (e - rmse) / (seeds - 1) : 0.0;
        // One rendering's rms error against the true image: the converged image's own mse removed.
        const double rmse_corr = std::sqrt(std::max(0.0, mse - residual * residual));
        const double noise = pix.noise_rmse();
        // What the mean of the renderings still misses: bias (DPT's truncation), once the noise
        // left in that mean (noise^2 / seeds) and the converged image's are removed.
        const double e_mean = pt_rmse(pix.mean_image(base.width, base.height), conv);
        const double bias = seeds > 1 ? std::sqrt(std::max(0.0, e_mean * e_mean - noise * noise / seeds -
                                                                   residual * residual))
                                      : 0.0;
        const double cpu_s = 1e-3 * median_of(cpu_ms), wall_s = 1e-3 * median_of(ms);
        const double rays = double(st.ext_rays + st.shadow_rays) / seeds;
        Record r;
        r.set("scene", scene.name).set("scheme", names[si]).set("method", method).set("spp", spp);
        r.set("width", base.width).set("height", base.height).set("threads", 1).set("seeds", seeds);
        r.set("ms", median_of(ms)).set("cpu_ms", median_of(cpu_ms)).set("trace_ms", median_of(trace_ms));
        r.set("cpu_ms_min", *std::min_element(cpu_ms.begin(), cpu_ms.end()));
        r.set("cpu_ms_max", *std::max_element(cpu_ms.begin(), cpu_ms.end()));
        r.set("rmse", rmse).set("rmse_sd", std::sqrt(sd));
        r.set("rmse_min", *std::min_element(rmses.begin(), rmses.end()));
        r.set("rmse_max", *std::max_element(rmses.begin(), rmses.end()));
        r.set("rmse_corr", rmse_corr).set("noise_rmse", noise).set("bias_rmse", bias);
        r.set("converged_residual_rmse", residual);
        r.set("mrays", rays / wall_s * 1e-6).set("trace_mrays", rays / (1e-3 * median_of(trace_ms)) * 1e-6);
        r.set("ext_rays", uint64_t(st.ext_rays / seeds)).set("shadow_rays", uint64_t(st.shadow_rays / seeds));
        r.set("rays_per_sample", rays / (double(spp) * base.width * base.height));
        r.set("iterations", uint64_t(st.iterations / seeds));
        r.set("util", st.util()).set("shadow_util", st.shadow_util()).set("warp_util", st.warp_util());
        // Efficiency 1 / (mse t) with mse = rmse_corr^2 and t the frame's median CPU time (a shared
        // machine's wall time is mostly the other load); efficiency_rays with the rays traced
        // instead of time (per million rays): free of timer noise, blind to what a ray costs.
        const double mse_corr = rmse_corr * rmse_corr;
        r.set("efficiency", mse_corr > 0 ? 1.0 / (mse_corr * cpu_s) : 0.0);
        r.set("efficiency_rays", mse_corr > 0 ? 1e6 / (mse_corr * rays) : 0.0);
        r.set("mean", pix.mean()).set("converged_mean", pt_mean(conv)).set("converged_spp", ref_spp);
        r.set("thesis_scene", tscene);
        for (const char* col : {"ms", "rmse", "mrays"}) {
          std::optional<double> v;
          if (!tscene.empty()) v = thesis.lookup({"scene", "method", "spp"}, {tscene, method, std::to_string(spp)}, col);
          if (v) r.set(std::string("thesis_") + col, *v);
          else r.set(std::string("thesis_") + col, "");
        }
        if (opt.run.progress)
          std::fprintf(stderr,
                       "%-12s %-8s %4u spp x%u  cpu %8.1f ms  rmse %7.3f +- %5.3f (corr %7.3f, noise %7.3f, bias %6.3f)  "
                       "util %.3f  warp %.3f\n",
                       names[si].c_str(), method.c_str(), spp, seeds, median_of(cpu_ms), rmse, std::sqrt(sd), rmse_corr,
                       noise, bias, st.util(), st.warp_util());
        if (opt.run.cells) opt.run.cells->append(r);
        records.push_back(std::move(r));
        // The split by path vertex (the first scheme only): energy and noise per vertex.
        for (uint32_t d = 0; si == 0 && d < kPtDepths; ++d) {
          Record dr;
          dr.set("scene", scene.name).set("scheme", names[si]).set("method", method).set("spp", spp);
          dr.set("depth", d).set("depth_or_more", d + 1 == kPtDepths ? 1 : 0).set("seeds", seeds);
          dr.set("mean", depth[d].mean()).set("share", pt_mean(conv) > 0 ? depth[d].mean() / pt_mean(conv) : 0.0);
          dr.set("noise_rmse", depth[d].noise_rmse());
          depth_records.push_back(std::move(dr));
        }
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
                               {"converged",
                                {{"spp", ref_spp}, {"method", "Ref"}, {"reused_cache", reused}, {"residual_rmse", residual}}},
                               {"seeds", seeds},
                               {"threads", 1}}));
  write_csv(stem + ".depth.csv", depth_records,
            thesis_table_meta("pathtrace", opt, tscene, {{"width", base.width}, {"height", base.height}, {"seeds", seeds}}));
  print_table(records,
              {"scheme", "method", "spp", "ms", "cpu_ms", "rmse", "rmse_sd", "rmse_corr", "bias_rmse", "mrays", "util", "warp_util", "efficiency_rank", "efficiency_rays_rank",
               "thesis_ms", "thesis_rmse", "thesis_mrays"},
              stdout);
  return 0;
}

}  // namespace tb
