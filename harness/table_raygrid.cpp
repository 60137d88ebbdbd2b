// `travbench table raygrid`: thesis §5.4.1, Tables 9 and 10 — RayGrid against the single-ray
// MBVH baseline and MBVH/RS for the 1st to 4th diffuse bounce of a camera path (Table 9: Mrays/s
// and the % over single-ray MBVH), and the average number of rays per visited mini-MBVH interior
// node and leaf (Table 10), which is where RayGrid's gain comes from: the queues regroup rays
// that diverged, so the MBVH/RS streams inside a leaf stay full.
//
// One record per (scheme, bounce): throughput and accuracy (measure_cell), rays per visited
// interior node / leaf (its instrumented pass), pct_over_single against mbvh4_single at the same
// bounce, the thesis' Mrays/s and % for the same scene (thesis_mrays, thesis_pct_over_single;
// only for the thesis' scenes: sponza, sibenik_lucy, conference), and the thesis' rays per node
// (Table 10 for RayGrid, Table 8 for MBVH/RS; both measured on the Modern Room only, which
// thesis_rays_scene says). RayGrid rows add the queue statistics: M, octree leaves, average
// queue fill, queued leaf visits per ray, peak queue memory ((O*M + N) * 36 bytes, §5.3.5) and
// the robustness fallbacks (always 0).
//
// With --param sweep=1, a second part sweeps the queue size M (64..1024) and the octree's
// leaf_prims (1024, 4096, 16384) on bounce:3: §5.3.5 and §5.4.1 found M = 384 and 4096 triangles
// per leaf near-optimal for every scene.
#include <cstdio>
#include <map>

#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "structures/builtin_scenes.h"
#include "structures/octree.h"
#include "traversal/raygrid_stats.h"
#include "traversal/registry.h"

namespace tb {
namespace {

// Our scheme -> the thesis' row in Table 9 ("" when the thesis did not measure it).
std::string thesis_scheme9(const std::string& scheme) {
  static const std::map<std::string, std::string> m = {
      {"mbvh4_single", "mbvh_single"}, {"mbvh_rs", "mbvh_rs"}, {"raygrid", "raygrid"}};
  auto it = m.find(scheme);
  return it == m.end() ? "" : it->second;
}
std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", v);
  return buf;
}
// RayGrid's own statistics as columns (blank for other schemes, so every row has them).
void raygrid_columns(Record& r, const Traverser& t) {
  const auto s = raygrid_stats(t);
  const Octree* o = raygrid_octree(t);
  if (!s || !o) {
    for (const char* c : {"queue", "leaf_prims", "octree_leaves", "avg_fill", "leaf_visits_per_ray", "queue_mb", "fallbacks"})
      r.set(c, "");
    return;
  }
  r.set("queue", uint64_t(s->queue_size))
      .set("leaf_prims", o->params.leaf_prims)
      .set("octree_leaves", uint64_t(o->stats.leaves))
      .set("avg_fill", s->avg_fill())
      .set("leaf_visits_per_ray", s->leaf_visits_per_ray())
      .set("queue_mb", double(s->peak_bytes) / (1024.0 * 1024.0))
      .set("fallbacks", s->fallbacks);
}

}  // namespace

int raygrid_table(const TableOptions& opt) {
  Bench bench(load_scene(table_scene(opt)));
  const std::string tscene = thesis_scene(bench.scene().name);
  // The table's own parameter; the others are the schemes'.
  const ParamSpec sweep_param = bool_param("sweep", false, "also run the queue-size sweep of thesis 5.3.5 on bounce:3");
  const std::vector<std::string> names = default_schemes(opt, {"mbvh4_single", "mbvh_rs", "raygrid"}, {sweep_param}, OwnTriangleTest::keep);
  SchemeConfig base = opt.run.scheme_config;
  const bool sweep = param_to_bool(base.params.count("sweep") ? base.params.at("sweep") : sweep_param.fallback);
  base.params.erase("sweep");
  // The thesis' values after every option is validated: a refused option says only why.
  const ThesisTable t9 = load_thesis_table("table09_raygrid_by_bounce.csv");
  const ThesisRaysPerNode thesis_rays;
  RunOptions run = opt.run;
  run.scheme_config = base;
  run.stats = true;  // Table 10 needs the instrumented pass

  // Table 9 and 10: every scheme on bounce:1..4. (The thesis' Table 10 starts at primary rays;
  // Table 9, and this table, at the first bounce.)
  std::vector<Record> records;
  for (const auto& name : names) {
    // The entry as given labels the rows (raygrid and raygrid:queue=64 are rows of their own); the
    // scheme it names picks the thesis' layout and rows.
    const SchemeInfo& info = find_scheme(name);
    const std::string& scheme = info.name;
    SchemeConfig cfg = table_scheme_config(name, base, OwnTriangleTest::keep);  // Embree: its own test
    const std::string layout = thesis_layout(scheme, cfg);
    auto t = make_scheme(name, cfg);
    t->prepare(bench.scene(), bench.cache());
    RunOptions cell = run;
    cell.scheme_config.params = cfg.params;  // the params column: what the scheme ran with, the layout's included
    for (int k = 1; k <= 4; ++k) {
      raygrid_reset_stats(*t);
      Record r = measure_cell(bench, table_spec(opt, "bounce:" + std::to_string(k)), *t, cell, name);
      r.set("bounce", k).set("part", "table9").set("layout", layout);
      if (info.baseline) r.set("rays_per_node", "").set("rays_per_leaf", "");  // Embree cannot be instrumented
      const std::string ts = thesis_scheme9(scheme);
      r.set("thesis_scene", tscene).set("thesis_scheme", ts);
      const std::string col = "bounce" + std::to_string(k);
      auto v9 = tscene.empty() || ts.empty() ? std::nullopt : t9.lookup({"scene", "scheme"}, {tscene, ts}, col);
      if (v9) r.set("thesis_mrays", *v9);
      else r.set("thesis_mrays", "");
      // Table 10 (RayGrid) and Table 8 (MBVH/RS): depth k = k-th bounce; Modern Room only.
      thesis_rays.set_columns(r, scheme == "raygrid" ? "10" : scheme == "mbvh_rs" ? "8" : "", scheme,
                              "depth" + std::to_string(k));
      raygrid_columns(r, *t);
      if (opt.run.progress)
        std::fprintf(stderr, "%-14s bounce:%d %17s (thesis %s)  rays/node %s  rays/leaf %s  mismatch %s\n",
                     name.c_str(), k, speed_text(r).c_str(), r.get("thesis_mrays")->c_str(),
                     r.get("rays_per_node")->c_str(), r.get("rays_per_leaf")->c_str(), r.get("mismatch_rate")->c_str());
      records.push_back(std::move(r));
    }
  }
  // % over single-ray MBVH at the same bounce, ours and the thesis' (the "+27.6%" rows of Table 9).
  auto single_mrays = [&](const std::string& workload) {
    for (const Record& b : records)
      if (*b.get("scheme") == "mbvh4_single" && *b.get("workload") == workload) return std::stod(*b.get("mrays_median"));
    return 0.0;
  };
  for (Record& r : records) {
    const double base_mrays = single_mrays(*r.get("workload"));
    if (base_mrays > 0) r.set("pct_over_single", fmt(100.0 * (std::stod(*r.get("mrays_median")) / base_mrays - 1.0)));
    else r.set("pct_over_single", "");
    const std::string ts = *r.get("thesis_scheme");
    const std::string col = "bounce" + *r.get("bounce");
    std::optional<double> tv, tb;
    if (!tscene.empty() && !ts.empty()) {
      tv = t9.lookup({"scene", "scheme"}, {tscene, ts}, col);
      tb = t9.lookup({"scene", "scheme"}, {tscene, "mbvh_single"}, col);
    }
    if (tv && tb && *tb > 0) r.set("thesis_pct_over_single", fmt(100.0 * (*tv / *tb - 1.0)));
    else r.set("thesis_pct_over_single", "");
  }
  const size_t main_rows = records.size();

  // The parameter sweep of §5.3.5 / §5.4.1 on bounce:3.
  if (sweep) {
    const WorkloadSpec spec = table_spec(opt, "bounce:3");
    const double single = single_mrays(spec.name());
    for (int leaf_prims : {1024, 4096, 16384})
      for (int m : {64, 128, 256, 384, 512, 1024}) {
        SchemeConfig cfg = config_for("raygrid", base);
        cfg.params["queue"] = std::to_string(m);
        cfg.params["leaf_prims"] = std::to_string(leaf_prims);
        const std::string layout = thesis_layout("raygrid", cfg);
        auto t = make_scheme("raygrid", cfg);
        t->prepare(bench.scene(), bench.cache());
        RunOptions sr = run;
        sr.scheme_config = cfg;
        Record r = measure_cell(bench, spec, *t, sr, "raygrid");
        r.set("bounce", 3).set("part", "sweep").set("layout", layout);
        if (single > 0) r.set("pct_over_single", fmt(100.0 * (std::stod(*r.get("mrays_median")) / single - 1.0)));
        else r.set("pct_over_single", "");
        raygrid_columns(r, *t);
        if (opt.run.progress)
          std::fprintf(stderr, "sweep leaf_prims=%-6d M=%-5d %9s Mrays/s  %s%% over mbvh4_single  fill %s\n", leaf_prims, m,
                       r.get("mrays_median")->c_str(), r.get("pct_over_single")->c_str(), r.get("avg_fill")->c_str());
        records.push_back(std::move(r));
      }
  }

  write_csv(opt.csv, records,
            thesis_table_meta("raygrid", opt, tscene,
                              {{"note", "thesis_rays_per_node/leaf: Table 10 (raygrid) and Table 8 (mbvh_rs), measured "
                                        "on the Modern Room only; thesis_mrays: Table 9, 1 core of a 3.8 GHz Xeon (2012)"}}));
  const std::vector<Record> main(records.begin(), records.begin() + long(main_rows));
  print_table(main,
              {"scheme", "layout", "workload", "mrays_median", "pct_over_single", "thesis_mrays", "thesis_pct_over_single",
               "rays_per_node", "thesis_rays_per_node", "rays_per_leaf", "thesis_rays_per_leaf", "mismatch_rate"},
              stdout);
  if (sweep) {
    std::fprintf(stdout, "\nRayGrid parameter sweep, bounce:3 (queue size M x octree leaf_prims)\n");
    const std::vector<Record> rest(records.begin() + long(main_rows), records.end());
    print_table(rest,
                {"leaf_prims", "queue", "octree_leaves", "mrays_median", "pct_over_single", "avg_fill",
                 "leaf_visits_per_ray", "rays_per_node", "rays_per_leaf", "queue_mb", "mismatch_rate"},
                stdout);
  }
  return 0;
}

}  // namespace tb
