// `travbench table bandwidth` (issue 19; CS348K lecture 18: incoherent rays are bandwidth bound,
// answered by compression and by reordering): per scheme the bytes of a node fetch and of the
// node array, the simulated memory reads per ray (the --cache hierarchy, default
// l1=32K:8,l2=256K:8,l3=2M:16, thesis §5.4) and the speed, for primary rays and bounce:2. On a
// scene whose nodes exceed the simulated L3 the memory reads show what the compressed nodes
// (cwbvh_single) and the treelet queues (treelet_queue) save against mbvh8_single, mbvh_rs and
// raygrid.
#include <cstdio>

#include "harness/tables.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {

int bandwidth_table(const TableOptions& opt) {
  Bench bench(load_scene(table_scene(opt)));
  RunOptions run = opt.run;
  run.stats = run.cache = true;
  const std::vector<std::string> names =
      default_schemes(opt, {"mbvh8_single", "cwbvh_single", "treelet_queue", "mbvh_rs", "raygrid"});
  std::vector<Record> records;
  for (const auto& name : names) {
    auto t = make_scheme(name, config_for(name, run.scheme_config));
    t->prepare(bench.scene(), bench.cache());
    for (const std::string w : {"primary", "bounce:2"}) {
      Record r = measure_cell(bench, table_spec(opt, w, run.view), *t, run);
      // Columns a scheme gathers only under the cache (treelet_queue's memory-read split): the
      // --stats columns were taken before measure_cell's --cache trace.
      for (const StatColumn& s : t->take_stat_columns())
        if (s.name.find("_mem_") != std::string::npos) r.set(s.name, s.value);
      // Memory reads are whole lines of the simulated hierarchy (64 bytes).
      const double rays = std::max(1.0, std::stod(*r.get("rays")));
      r.set("mem_reads_per_ray", std::stod(*r.get("mem_read_m")) * 1e6 / rays);
      std::fprintf(stderr, "%-14s %-9s %7s B/node  %10s node bytes  %8.2f memory reads/ray  %8s Mrays/s\n",
                   name.c_str(), w.c_str(), r.get("bytes_per_node")->c_str(), r.get("node_bytes")->c_str(),
                   std::stod(*r.get("mem_read_m")) * 1e6 / rays, r.get("mrays_median")->c_str());
      records.push_back(std::move(r));
    }
  }
  write_csv(opt.csv, records,
            {{"command", "table bandwidth"}, {"scene", bench.scene().name}, {"cache", run.cache_config},
             {"policy", run.cache_policy}});
  print_table(records, {"scheme", "workload", "bytes_per_node", "node_bytes", "prim_bytes", "mem_reads_per_ray",
                        "mem_read_m", "mrays_median", "mismatch_rate", "false_miss"},
              stdout);
  return 0;
}

}  // namespace tb
