// `travbench table bandwidth` (issue 19; CS348K lecture 18: incoherent rays are bandwidth bound,
// answered by compression and by reordering): per scheme the bytes of a node fetch and of the
// node array, the simulated memory reads per ray (the --cache hierarchy, default
// l1=32K:8,l2=256K:8,l3=2M:16, thesis §5.4) and the speed, for primary rays and bounce:2. On a
// scene whose nodes exceed the simulated L3 the memory reads show what the compressed nodes
// (cwbvh_single) and the treelet queues (treelet_queue) save against mbvh8_single, mbvh_rs and
// raygrid.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>

#include "harness/tables.h"
#include "harness/trace_runner.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {

namespace {

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

// Speed, interleaved: the schemes are timed in the same process, round by round (each round
// traces the whole batch once with every scheme, the order rotated by one each round, after one
// warm-up trace each), so a shared machine's slow phases fall on all schemes alike. Per cell the
// median, min and max Mrays/s over the rounds (mrays_median, _min, _max, mrays_samples; `reps` =
// rounds), and per round the speed ratio to the first scheme of the table (mbvh8_single by
// default): speed_ratio_median, _min, _max, the ratio columns to read (a ratio of one round is
// two traces seconds apart, not two runs minutes apart).
int bandwidth_table(const TableOptions& opt) {
  Bench bench(load_scene(table_scene(opt)));
  RunOptions run = opt.run;
  run.stats = run.cache = true;
  const int rounds = std::max(1, run.reps);
  run.reps = 1;  // measure_cell's own timing is replaced by the interleaved rounds below
  const std::vector<std::string> names =
      default_schemes(opt, {"mbvh8_single", "cwbvh_single", "treelet_queue", "mbvh_rs", "raygrid"});
  const std::vector<std::string> workloads = {"primary", "bounce:2"};
  std::vector<std::unique_ptr<Traverser>> schemes;
  for (const auto& name : names) {
    schemes.push_back(make_scheme(name, config_for(name, run.scheme_config)));
    schemes.back()->prepare(bench.scene(), bench.cache());
  }
  std::vector<Record> records;  // scheme-major: records[s * workloads + w]
  for (auto& t : schemes) {
    for (const std::string& w : workloads) {
      Record r = measure_cell(bench, table_spec(opt, w, run.view), *t, run);
      // Columns a scheme gathers only under the cache (treelet_queue's memory-read split): the
      // --stats columns were taken before measure_cell's --cache trace.
      for (const StatColumn& s : t->take_stat_columns())
        if (s.name.find("_mem_") != std::string::npos) r.set(s.name, s.value);
      // Memory reads are whole lines of the simulated hierarchy (64 bytes).
      const double rays = std::max(1.0, std::stod(*r.get("rays")));
      r.set("mem_reads_per_ray", std::stod(*r.get("mem_read_m")) * 1e6 / rays);
      records.push_back(std::move(r));
    }
  }
  for (size_t w = 0; w < workloads.size(); ++w) {
    const RayBatch& batch = bench.rays(table_spec(opt, workloads[w], run.view));
    std::vector<Hit> hits(batch.size());
    for (auto& t : schemes) trace_batch(*t, batch, hits, run.threads);  // warm-up
    std::vector<std::vector<double>> sec(schemes.size());
    for (int round = 0; round < rounds; ++round)
      for (size_t k = 0; k < schemes.size(); ++k) {
        const size_t s = (size_t(round) + k) % schemes.size();
        const auto t0 = std::chrono::steady_clock::now();
        trace_batch(*schemes[s], batch, hits, run.threads);
        sec[s].push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      }
    for (size_t s = 0; s < schemes.size(); ++s) {
      Record& r = records[s * workloads.size() + w];
      std::vector<double> mrays, ratio;
      std::string samples;
      for (int k = 0; k < rounds; ++k) {
        mrays.push_back(double(batch.size()) / std::max(sec[s][k], 1e-9) * 1e-6);
        ratio.push_back(sec[0][k] / std::max(sec[s][k], 1e-9));
        char buf[32];
        std::snprintf(buf, sizeof buf, "%s%.6g", samples.empty() ? "" : ";", mrays.back());
        samples += buf;
      }
      r.set("reps", rounds)
          .set("mrays_median", median_of(mrays))
          .set("mrays_min", *std::min_element(mrays.begin(), mrays.end()))
          .set("mrays_max", *std::max_element(mrays.begin(), mrays.end()))
          .set("mrays_samples", samples)
          .set("speed_base", names[0])
          .set("speed_ratio_median", median_of(ratio))
          .set("speed_ratio_min", *std::min_element(ratio.begin(), ratio.end()))
          .set("speed_ratio_max", *std::max_element(ratio.begin(), ratio.end()));
      std::fprintf(stderr, "%-14s %-9s %7s B/node  %10s node bytes  %8.2f memory reads/ray  %8.4g Mrays/s  %.3fx %s\n",
                   names[s].c_str(), workloads[w].c_str(), r.get("bytes_per_node")->c_str(),
                   r.get("node_bytes")->c_str(), std::stod(*r.get("mem_reads_per_ray")), median_of(mrays),
                   median_of(ratio), names[0].c_str());
    }
  }
  write_csv(opt.csv, records,
            {{"command", "table bandwidth"}, {"scene", bench.scene().name}, {"cache", run.cache_config},
             {"policy", run.cache_policy}, {"rounds", rounds}});
  print_table(records, {"scheme", "workload", "bytes_per_node", "node_bytes", "prim_bytes", "mem_reads_per_ray",
                        "mem_read_m", "mrays_median", "speed_ratio_median", "speed_ratio_min", "speed_ratio_max",
                        "mismatch_rate", "false_miss"},
              stdout);
  return 0;
}

}  // namespace tb
