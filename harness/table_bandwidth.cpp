// `travbench table bandwidth` (issue 19; CS348K lecture 18: incoherent rays are bandwidth bound,
// answered by compression and by reordering): per scheme the bytes of a node fetch and of the
// node array, the simulated memory reads per ray (the --cache hierarchy, default
// l1=32K:8,l2=256K:8,l3=2M:16, thesis §5.4) and the speed, for primary rays and bounce:2. On a
// scene whose nodes exceed the simulated L3 the memory reads show what the compressed nodes
// (cwbvh_single) and the treelet queues (treelet_queue, on the compressed tree by default, and
// `treelet_queue:tree=mbvh8`, the reordering alone on mbvh8_single's tree) save against
// mbvh8_single, mbvh_rs and raygrid.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>

#include "harness/tables.h"
#include "harness/trace_runner.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {

// Speed, interleaved (measure_interleaved: --reps rounds, every scheme once per round, as `run
// --interleave` times them): per cell the Mrays/s over the rounds and the per-round speed ratio
// to the first scheme of the table (mbvh8_single by default), speed_ratio_median, _min, _max, the
// ratio columns to read (set_interleaved_speed).
int bandwidth_table(const TableOptions& opt) {
  Bench bench(load_scene(table_scene(opt)));
  RunOptions run = opt.run;
  run.stats = run.cache = true;
  const int rounds = std::max(1, run.reps);
  run.reps = 1;  // measure_cell's own timing is replaced by the interleaved rounds below
  const std::vector<std::string> names =
      default_schemes(opt, {"mbvh8_single", "cwbvh_single", "treelet_queue", "treelet_queue:tree=mbvh8", "mbvh_rs", "raygrid"});
  const std::vector<std::string> workloads = {"primary", "bounce:2"};
  std::vector<std::unique_ptr<Traverser>> schemes;
  for (const auto& name : names) {
    schemes.push_back(make_scheme(name, config_for(name, run.scheme_config)));
    schemes.back()->prepare(bench.scene(), bench.cache());
  }
  std::vector<Record> records;  // scheme-major: records[s * workloads + w]
  for (size_t k = 0; k < schemes.size(); ++k) {
    Traverser* t = schemes[k].get();
    for (const std::string& w : workloads) {
      // Labelled with the entry: cwbvh_single and cwbvh_single:full_top=0 are two rows.
      Record r = measure_cell(bench, table_spec(opt, w, run.view), *t, run, names[k]);
      // Columns a scheme gathers only under the cache (treelet_queue's memory-read split): the
      // --stats columns were taken before measure_cell's --cache trace.
      for (const StatColumn& s : t->take_stat_columns())
        if (s.name.find("_mem_") != std::string::npos) r.set(s.name, s.value);
      // Memory reads are whole lines of the simulated hierarchy (64 bytes).
      const double rays = std::max(1.0, std::stod(*r.get("rays")));
      r.set("mem_reads_per_ray", std::stod(*r.get("mem_read_m")) * 1e6 / rays);
      r.set("cold_reads_per_ray", std::stod(*r.get("mem_read_cold_m")) * 1e6 / rays);
      records.push_back(std::move(r));
    }
  }
  for (size_t w = 0; w < workloads.size(); ++w) {
    const RayBatch& batch = bench.rays(table_spec(opt, workloads[w], run.view));
    std::vector<Hit> hits(batch.size());
    std::vector<const Traverser*> ts;
    for (auto& t : schemes) ts.push_back(t.get());
    const auto sec = measure_interleaved(ts, batch, hits, run.threads, rounds);
    for (size_t s = 0; s < schemes.size(); ++s) {
      Record& r = records[s * workloads.size() + w];
      set_interleaved_speed(r, sec[s], sec[0], batch.size(), names[0]);
      if (batch.size() == 0) {  // nothing traced: no reads or speed to print (the CSV says nan)
        std::fprintf(stderr, "%-14s %-9s (no rays)\n", names[s].c_str(), workloads[w].c_str());
        continue;
      }
      std::fprintf(stderr, "%-14s %-9s %7s B/node  %10s node bytes  %8.2f memory reads/ray  %8.4g Mrays/s  %.3fx %s\n",
                   names[s].c_str(), workloads[w].c_str(), r.get("bytes_per_node")->c_str(),
                   r.get("node_bytes")->c_str(), std::stod(*r.get("mem_reads_per_ray")),
                   std::stod(*r.get("mrays_median")), std::stod(*r.get("speed_ratio_median")), names[0].c_str());
    }
  }
  write_csv(opt.csv, records,
            {{"command", "table bandwidth"}, {"scene", bench.scene().name}, {"cache", run.cache_config},
             {"policy", run.cache_policy}, {"rounds", rounds}});
  print_table(records, {"scheme", "workload", "bytes_per_node", "node_bytes", "prim_bytes", "mem_reads_per_ray",
                        "cold_reads_per_ray", "mem_read_m", "mrays_median", "speed_ratio_median", "speed_ratio_min",
                        "speed_ratio_max", "mismatch_rate", "false_miss"},
              stdout);
  return 0;
}

}  // namespace tb
