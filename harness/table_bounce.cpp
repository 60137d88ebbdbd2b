// `travbench table bounce`: thesis §5.2.3, Tables 7 and 8 — how packet and stream schemes hold up
// against single-ray MBVH traversal as rays lose coherence, for primary rays and the 1st to 3rd
// diffuse bounce. Table 7 measured single-ray traversal of a 4-ary MBVH (the baseline), partition
// and ranged packet traversal (Overbeck et al. 2008) and Tsakok's MBVH/RS on one core; Table 8
// the average number of rays of the 256-ray packet that visit each interior node and leaf.
// Our 8-wide MBVH and Embree's single-ray and stream kernels are measured beside them as anchors.
//
// One record per (scheme, depth): throughput and accuracy from measure_cell, rays per visited
// interior node / leaf from its instrumented pass, the thesis' Mrays/s for the same scheme and
// scene (thesis_mrays; only for the scenes the thesis used), each scheme's speed relative to
// mbvh4_single at the same depth (vs_single) with the thesis' ratio beside it, and Table 8's
// rays per node (measured on the thesis' Modern Room only; thesis_rays_scene says so).
#include <cstdio>
#include <map>

#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {
namespace {

// Our scheme name -> the thesis' row name in Table 7 ("" when the thesis did not measure it).
std::string thesis_scheme7(const std::string& scheme) {
  static const std::map<std::string, std::string> m = {
      {"mbvh4_single", "mbvh_single"}, {"bvh_partition", "partition"}, {"bvh_ranged", "ranged"}, {"mbvh_rs", "mbvh_rs"}};
  auto it = m.find(scheme);
  return it == m.end() ? "" : it->second;
}
// Table 8 reports partition and ranged traversal together ("Ranged/partition").
std::string thesis_scheme8(const std::string& scheme) {
  if (scheme == "bvh_partition" || scheme == "bvh_ranged") return "ranged_partition";
  if (scheme == "mbvh_rs") return "mbvh_rs";
  return "";
}

}  // namespace

int bounce_table(const TableOptions& opt) {
  Bench bench(load_scene(table_scene(opt)));
  const std::string tscene = thesis_scene(bench.scene().name);
  const std::vector<std::string> workloads = {"primary", "bounce:1", "bounce:2", "bounce:3"};
  const std::vector<std::string> names =
      default_schemes(opt, {"mbvh4_single", "bvh_partition", "bvh_ranged", "mbvh_rs", "mbvh8_single", "embree_single",
                            "embree_stream"},
                      {}, OwnTriangleTest::keep);
  // The thesis' values after every option is validated: a refused option says only why.
  const ThesisTable t7 = load_thesis_table("table07_schemes_by_bounce.csv");
  const ThesisRaysPerNode thesis_rays;
  RunOptions run = opt.run;
  run.stats = true;  // Table 8 needs the instrumented pass
  std::vector<Record> records;
  for (const auto& name : names) {
    // The entry as given labels the rows; the scheme it names picks the thesis' layout and rows
    // (an entry's own parameters override the layout's: thesis_layout fills only absent keys).
    const SchemeInfo& info = find_scheme(name);
    const std::string& scheme = info.name;
    SchemeConfig cfg = table_scheme_config(name, opt.run.scheme_config, OwnTriangleTest::keep);  // Embree: its own test
    const std::string layout = thesis_layout(scheme, cfg);
    auto t = make_scheme(name, cfg);
    t->prepare(bench.scene(), bench.cache());
    RunOptions cell = run;
    cell.scheme_config.params = cfg.params;  // the params column: what the scheme ran with, the layout's included
    for (size_t depth = 0; depth < workloads.size(); ++depth) {
      Record r = measure_cell(bench, table_spec(opt, workloads[depth]), *t, cell, name);
      r.set("layout", layout);
      const std::string dcol = "depth" + std::to_string(depth);
      r.set("depth", uint64_t(depth));
      if (info.baseline) r.set("rays_per_node", "").set("rays_per_leaf", "");  // Embree cannot be instrumented
      r.set("thesis_scene", tscene).set("thesis_scheme", thesis_scheme7(scheme));
      std::optional<double> v7;
      if (!tscene.empty() && !thesis_scheme7(scheme).empty())
        v7 = t7.lookup({"scene", "scheme"}, {tscene, thesis_scheme7(scheme)}, dcol);
      if (v7) r.set("thesis_mrays", *v7);
      else r.set("thesis_mrays", "");
      thesis_rays.set_columns(r, "8", thesis_scheme8(scheme), dcol);
      if (opt.run.progress)
        std::fprintf(stderr, "%-16s %-10s %17s (thesis %s)  rays/node %s  mismatch %s\n", name.c_str(),
                     workloads[depth].c_str(), speed_text(r).c_str(), r.get("thesis_mrays")->c_str(),
                     r.get("rays_per_node")->c_str(), r.get("mismatch_rate")->c_str());
      records.push_back(std::move(r));
    }
  }
  // Relative to the thesis' baseline at the same depth, ours and the thesis' (§5.2.3: "MBVH/RS
  // achieves between 79% and 106%" of single-ray traversal after three bounces).
  for (Record& r : records) {
    const std::string depth = *r.get("depth");
    double base = 0;
    for (const Record& b : records)
      if (*b.get("scheme") == "mbvh4_single" && *b.get("depth") == depth) base = std::stod(*b.get("mrays_median"));
    if (base > 0) r.set("vs_single", std::stod(*r.get("mrays_median")) / base);
    else r.set("vs_single", "");
    const std::string ts = *r.get("thesis_scheme");
    std::optional<double> tv, tb;
    if (!tscene.empty() && !ts.empty()) {
      tv = t7.lookup({"scene", "scheme"}, {tscene, ts}, "depth" + depth);
      tb = t7.lookup({"scene", "scheme"}, {tscene, "mbvh_single"}, "depth" + depth);
    }
    if (tv && tb && *tb > 0) r.set("thesis_vs_single", *tv / *tb);
    else r.set("thesis_vs_single", "");
  }
  write_csv(opt.csv, records, thesis_table_meta("bounce", opt, tscene));
  print_table(records,
              {"scheme", "layout", "workload", "mrays_median", "thesis_mrays", "vs_single", "thesis_vs_single", "rays_per_node",
               "thesis_rays_per_node", "rays_per_leaf", "thesis_rays_per_leaf", "mismatch_rate"},
              stdout);
  return 0;
}

}  // namespace tb
