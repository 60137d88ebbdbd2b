// `travbench table cache`: thesis Table 11 (§5.4) — simulated L1/L2/L3 behaviour of RayGrid at
// ray-queue sizes 64..1024 and of MBVH/RS on bounce:2 of a 512x512 camera, hits per level in
// millions, the estimated cost and each level's share; then the same columns for every other
// scheme. The thesis' costs add up read hits x latency only (see cachesim/hierarchy.h), so the
// comparison column is read_cost_mcycles.
//
// Layout: RayGrid and MBVH/RS run the thesis' 4-wide SSE nodes (thesis_layout, harness/tables.h;
// the `layout` column) unless --param width is given. Counting unit: one access is one 64-byte
// line touched by a load or store (an access of n bytes counts every line it overlaps,
// cachesim/hierarchy.h), so a 128-byte MBVH4 node read is 2 accesses. The thesis does not state
// its unit; to measure what a finer unit gives, the thesis' cells are traced a second time through
// the same hierarchy with 4-byte lines, where every access counts the 4-byte words it reads:
// `read_lines_per_ray` (all demand reads, L1 hits + misses, 64-byte lines) beside
// `read_words_per_ray` (the same trace counted in words), against the thesis' reads per ray
// (its L1 + L2 + L3 + memory read counts over the 512 x 512 rays).
#include <algorithm>
#include <cstdio>

#include "harness/cache_columns.h"
#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {

int cache_table(const TableOptions& opt) {
  // Every repetition replays the whole cache simulation: at most 3, refused above rather than
  // capped without a word.
  if (opt.run.reps > 3)
    throw InputError("table cache takes --reps 1..3 (each repetition replays the cache simulation), not " +
                     std::to_string(opt.run.reps));
  Bench bench(load_scene(table_scene(opt)));
  TableOptions o = opt;
  o.run.width = o.run.height = 512;  // the thesis' image size for Table 11
  const WorkloadSpec spec = table_spec(o, "bounce:2");
  RunOptions run = o.run;
  run.cache = true;
  run.reps = std::max(1, run.reps);
  struct Cell {
    std::string scheme, label, thesis_col;
    SchemeConfig cfg;
    std::string layout;
  };
  std::vector<Cell> cells;
  const std::vector<std::string> names = default_schemes(opt);
  // RayGrid's M rows when the schemes include plain raygrid (the default set does; an explicit
  // --schemes without it gets none).
  const bool has_raygrid = std::find(names.begin(), names.end(), "raygrid") != names.end();
  const ThesisTable thesis = load_thesis_table("table11_cache_raygrid.csv");  // after the options' validation
  if (has_raygrid)
    for (int m : {64, 128, 256, 512, 1024}) {
      SchemeConfig c = config_for("raygrid", run.scheme_config);
      c.params["queue"] = std::to_string(m);
      const std::string layout = thesis_layout("raygrid", c);
      cells.push_back({"raygrid", "raygrid M=" + std::to_string(m), "batch" + std::to_string(m), c, layout});
    }
  // Other entries as given (mbvh_rs:stream=8192 is a row of its own, laid out as the thesis' where
  // its own parameters leave it to the layout); plain raygrid is the M rows above.
  for (const auto& name : names)
    if (name != "raygrid") {
      const std::string& scheme = find_scheme(name).name;
      SchemeConfig c = config_for(name, run.scheme_config);
      const std::string layout = thesis_layout(scheme, c);
      cells.push_back({name, name, name == "mbvh_rs" ? "mbvh_rs" : "", c, layout});
    }
  // Every demand read of a trace through `config`, per ray: L1 read hits + misses (a miss goes on
  // to L2, so the misses are L2 read hits + L2 misses, down to memory reads).
  auto reads_per_ray = [](const Record& r, double rays) {
    double m = 0;
    for (const char* k : {"l1_read_hit_m", "l2_read_hit_m", "l3_read_hit_m", "mem_read_m"})
      if (auto v = r.get(k)) m += std::stod(*v);
    return m * 1e6 / std::max(1.0, rays);
  };
  const bool conference = bench.scene().name == "conference";
  std::vector<Record> records;
  for (const Cell& c : cells) {
    auto t = make_scheme(c.scheme, c.cfg);
    t->prepare(bench.scene(), bench.cache());
    RunOptions cell = run;
    cell.scheme_config.params = c.cfg.params;  // the params column: the layout's and the entry's
    Record r = measure_cell(bench, spec, *t, cell, c.scheme);
    r.set("label", c.label).set("layout", c.layout);
    const double rays = double(bench.rays(spec).size());
    r.set("read_lines_per_ray", reads_per_ray(r, rays));
    if (!c.thesis_col.empty()) {
      Record words;
      std::vector<Hit> hits(bench.rays(spec).size());
      add_cache_columns(words, *t, bench.rays(spec), hits, "l1=32K:8:4,l2=256K:8:4,l3=2M:16:4", run.cache_policy);
      r.set("read_words_per_ray", reads_per_ray(words, rays));
    }
    if (conference && !c.thesis_col.empty()) {  // the thesis measured the Conference Room
      for (const auto& [ours, theirs] : std::vector<std::pair<std::string, std::string>>{
               {"l1_read_hit_m", "l1_read_hit"}, {"l2_read_hit_m", "l2_read_hit"}, {"l3_read_hit_m", "l3_read_hit"},
               {"mem_read_m", "mem_read"}, {"l1_write_hit_m", "l1_write_hit"}, {"read_cost_mcycles", "cost_est_gcycles"},
               {"l1_pct", "l1_pct"}, {"mem_pct", "mem_pct"}})
        if (auto v = thesis.lookup({"metric"}, {theirs}, c.thesis_col)) r.set("thesis_" + ours, *v);
    }
    std::fprintf(stderr, "%-16s L1 %s M read hits, memory %s M reads, cost %s Mcycles\n", c.label.c_str(),
                 r.get("l1_read_hit_m")->c_str(), r.get("mem_read_m")->c_str(), r.get("read_cost_mcycles")->c_str());
    records.push_back(std::move(r));
  }
  write_csv(opt.csv, records,
            {{"command", "table cache"}, {"workload", "bounce:2"}, {"image", "512x512"},
             {"access_unit", "one 64-byte line touched per access; read_words_per_ray: the same trace in 4-byte words"}});
  print_table(records, {"label", "l1_read_hit_m", "l2_read_hit_m", "l3_read_hit_m", "mem_read_m", "l1_write_hit_m",
                        "read_cost_mcycles", "l1_pct", "l2_pct", "l3_pct", "mem_pct", "thesis_read_cost_mcycles", "layout",
                        "read_lines_per_ray", "read_words_per_ray"},
              stdout);
  return 0;
}

}  // namespace tb
