#include "harness/experiment.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <limits>
#include <thread>
#include <cstdio>

#include "harness/accuracy.h"
#include "harness/cache_columns.h"
#include "harness/sweep.h"
#include "harness/trace_runner.h"
#include "traversal/exact.h"
#include "traversal/registry.h"

namespace tb {

std::string spec_key(const WorkloadSpec& s) {
  return s.name() + "@" + std::to_string(s.view) + ":" + std::to_string(s.width) + "x" + std::to_string(s.height) +
         ":" + std::to_string(s.seed) + (s.hfov_deg > 0 ? ":hfov" + std::to_string(s.hfov_deg) : "");
}

Bench::Bench(Scene scene) : scene_(std::move(scene)), cache_(scene_), reference_(make_scheme("reference")) {
  reference_->prepare(scene_, cache_);
}

const RayBatch& Bench::rays(const WorkloadSpec& spec) {
  const std::string key = spec_key(spec);
  auto it = batches_.find(key);
  if (it == batches_.end()) it = batches_.emplace(key, generate_workload(scene_, spec, closest_hits_of(*reference_))).first;
  return it->second;
}

const std::vector<Hit>& Bench::reference_hits(const WorkloadSpec& spec, int threads) {
  const std::string key = spec_key(spec);
  auto it = ref_hits_.find(key);
  if (it == ref_hits_.end()) {
    const RayBatch& b = rays(spec);
    std::vector<Hit> hits(b.size());
    trace_batch(*reference_, b, hits, threads);
    it = ref_hits_.emplace(key, std::move(hits)).first;
  }
  return it->second;
}

namespace {
// A row names the scheme entry as given (embree_single:robust=0 and embree_single are two rows)
// and the parameters it ran with, its own included.
void name_entry(Record& r, const std::string& entry, const SchemeConfig& cfg) {
  r.set("scheme", entry).set("params", params_text(entry, cfg));
}
}  // namespace

Record measure_cell(Bench& bench, const WorkloadSpec& spec, Traverser& scheme, const RunOptions& opt,
                    const std::string& entry) {
  const std::string label = entry.empty() ? std::string(scheme.name()) : entry;
  if (opt.cells) {  // a table's cells: `table --resume` takes those its CSV kept (harness/sweep.h)
    opt.cells->check_scene(bench.scene());
    if (const Record* kept = opt.cells->replay(bench.scene().name, spec.name(), label)) return *kept;
  }
  std::vector<Hit> hits;
  Record r = measure_rays(bench, spec.name(), bench.rays(spec), bench.reference_hits(spec, std::max(2, opt.threads)),
                          scheme, opt, hits);
  if (!entry.empty()) name_entry(r, entry, opt.scheme_config);
  if (opt.cells) opt.cells->append(r);
  return r;
}

std::string params_text(const std::string& scheme, const SchemeConfig& cfg) {
  std::string params;
  for (const auto& [k, v] : config_for(scheme, cfg).params) params += (params.empty() ? "" : ";") + k + "=" + v;
  return params;
}

std::vector<Hit> reference_hits_of(const Bench& bench, const RayBatch& batch, int threads) {
  std::vector<Hit> ref(batch.size());
  trace_batch(bench.reference(), batch, ref, std::max(2, threads));
  return ref;
}

namespace {
// The columns every row of measure_rays starts with, in this order.
Record row_head(const std::string& scene, uint64_t triangles, const std::string& workload, const std::string& scheme,
                const RunOptions& opt, uint64_t rays, const ThroughputStats& tp, const Accuracy& acc) {
  Record r;
  r.set("scene", scene)
      .set("triangles", triangles)
      .set("workload", workload)
      .set("scheme", scheme)
      .set("kernel", std::string(kernel_name(opt.scheme_config.kernel)))
      .set("view", opt.view + 1)
      .set("rays", rays)
      .set("threads", opt.threads)
      .set("reps", opt.reps)
      .set("mrays_median", tp.mrays_median)
      .set("mrays_min", tp.mrays_min)
      .set("mrays_max", tp.mrays_max)
      .set("mismatch_rate", acc.mismatch_rate())
      .set("false_miss", acc.false_miss)
      .set("false_hit", acc.false_hit)
      .set("wrong_t", acc.wrong_t)
      .set("ambiguous", acc.ambiguous);
  return r;
}
}  // namespace

std::vector<std::string> run_lead_columns(const RunOptions& opt) {
  return columns_of({row_head("", 0, "", "", opt, 0, {}, {})});
}

Record measure_rays(Bench& bench, const std::string& workload, const RayBatch& batch,
                    const std::vector<Hit>& ref, Traverser& scheme, const RunOptions& opt, std::vector<Hit>& hits) {
  hits.assign(batch.size(), Hit{});
  const ThroughputStats tp = measure(scheme, batch, hits, opt.threads, opt.reps);
  // The reference is the exact oracle; its geometry classifies the disagreeing rays (rare, except
  // for inexact kernels at large offsets), on every thread.
  const ExactOracle oracle(bench.scene(), bench.cache());
  std::vector<size_t> disagree;
  for (size_t i = 0; i < ref.size(); ++i)
    if (!hits_match(hits[i], ref[i])) disagree.push_back(i);
  std::vector<char> amb(ref.size(), 0);
  {
    std::atomic<size_t> next{0};
    std::vector<std::thread> pool;
    for (int t = 0; t < std::max(2, opt.threads); ++t)
      pool.emplace_back([&] {
        for (size_t j; (j = next.fetch_add(1)) < disagree.size();) {
          const size_t i = disagree[j];
          amb[i] = oracle.ambiguous(batch.rays[i], hits[i], kDistanceBar);
        }
      });
    for (auto& th : pool) th.join();
  }
  const Accuracy acc = compare_hits(hits, ref, [&](size_t i) { return amb[i] != 0; });
  Record r = row_head(bench.scene().name, bench.scene().num_triangles(), workload, std::string(scheme.name()), opt,
                      batch.size(), tp, acc);
  if (opt.stats) {
    TraversalCounts c;
    Probe probe;
    probe.counts = &c;
    enable_ftz_daz();
    scheme.take_stat_columns();  // drops what earlier instrumented traces (--cache of another cell) gathered
    scheme.trace(batch, PacketRange::all(batch), hits, probe);
    const double n = std::max<double>(1, double(batch.size()));
    r.set("nodes_per_ray", double(c.node_ray_visits) / n)
        .set("leaves_per_ray", double(c.leaf_ray_visits) / n)
        .set("tris_per_ray", double(c.tri_tests) / n)
        .set("rays_per_node", c.node_visits ? double(c.node_ray_visits) / double(c.node_visits) : 0.0)
        .set("rays_per_leaf", c.leaf_visits ? double(c.leaf_ray_visits) / double(c.leaf_visits) : 0.0)
        .set("bytes_per_node", c.node_visits ? double(c.node_bytes) / double(c.node_visits) : 0.0)
        // the rays the scheme scans per visit (ranged: the range width; others: rays_per_*)
        .set("range_per_node", c.node_visits ? double(c.node_range_visits) / double(c.node_visits) : 0.0)
        .set("range_per_leaf", c.leaf_visits ? double(c.leaf_range_visits) / double(c.leaf_visits) : 0.0);
    const StructureBytes b = scheme.memory();
    r.set("node_bytes", uint64_t(b.nodes)).set("prim_bytes", uint64_t(b.prims));
    for (const StatColumn& s : scheme.take_stat_columns()) r.set(s.name, s.value);
  }
  if (opt.cache) add_cache_columns(r, scheme, batch, hits, opt.cache_config, opt.cache_policy);
  // Every repetition's Mrays/s in run order, for `travbench compare`'s Mann-Whitney U test, and
  // the scheme's parameters as the run gave them, so cells of runs with different parameters
  // never match.
  std::vector<double> mrays;
  for (double sec : tp.seconds) mrays.push_back(double(batch.size()) / std::max(sec, 1e-9) * 1e-6);
  const std::string samples = samples_text(mrays);
  r.set("mrays_samples", samples).set("params", params_text(std::string(scheme.name()), opt.scheme_config));
  return r;
}

std::string samples_text(const std::vector<double>& mrays) {
  std::string samples;
  for (double v : mrays) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%s%.6g", samples.empty() ? "" : ";", v);
    samples += buf;
  }
  return samples;
}

namespace {
// A run's row: the entry's name and parameters (name_entry) and its structure's build time.
void label_entry(Record& r, const std::string& entry, const RunOptions& opt, double prepare_ms) {
  name_entry(r, entry, opt.scheme_config);
  r.set("prepare_ms", prepare_ms);
}
}  // namespace

void set_interleaved_speed(Record& r, const std::vector<double>& sec, const std::vector<double>& base_sec, size_t rays,
                           const std::string& base) {
  std::vector<double> mrays, ratio;
  for (size_t k = 0; k < sec.size(); ++k) {
    mrays.push_back(double(rays) / std::max(sec[k], 1e-9) * 1e-6);
    ratio.push_back(base_sec[k] / std::max(sec[k], 1e-9));
  }
  r.set("reps", int(sec.size()))
      .set("mrays_median", median_of(mrays))
      .set("mrays_min", *std::min_element(mrays.begin(), mrays.end()))
      .set("mrays_max", *std::max_element(mrays.begin(), mrays.end()))
      .set("mrays_samples", samples_text(mrays))
      .set("speed_base", base);
  if (rays == 0) {
    // A batch without rays (bounce:k of a view whose rays all escaped before bounce k) has no speed
    // to compare: its rounds time the calls' overhead, so the ratio columns say nan, not a number
    // a goal table would read as a result.
    const double nan = std::numeric_limits<double>::quiet_NaN();
    r.set("speed_ratio_median", nan).set("speed_ratio_min", nan).set("speed_ratio_max", nan);
    return;
  }
  r.set("speed_ratio_median", median_of(ratio))
      .set("speed_ratio_min", *std::min_element(ratio.begin(), ratio.end()))
      .set("speed_ratio_max", *std::max_element(ratio.begin(), ratio.end()));
}

std::vector<Record> run_experiment(Bench& bench, const RunOptions& opt) {
  std::vector<Record> out;
  std::vector<std::unique_ptr<Traverser>> schemes;
  std::vector<double> prepare_ms;
  check_run_params(opt.schemes, opt.scheme_config);
  for (const auto& name : opt.schemes) {
    auto t = make_scheme(name, config_for(name, opt.scheme_config));
    const auto t0 = std::chrono::steady_clock::now();
    t->prepare(bench.scene(), bench.cache());
    prepare_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    schemes.push_back(std::move(t));
  }
  const size_t total = opt.workloads.size() * schemes.size();
  size_t done = 0;
  RunOptions cell_opt = opt;
  cell_opt.cells = nullptr;  // appended below, once prepare_ms is in the row
  for (const auto& w : opt.workloads) {
    WorkloadSpec spec = parse_workload(w);
    spec.width = opt.width;
    spec.height = opt.height;
    spec.view = opt.view;
    spec.seed = opt.seed;
    if (opt.interleave) {  // every scheme of this workload at once (apps refuse --resume with it)
      RunOptions once = cell_opt;
      once.reps = 1;  // accuracy, --stats and --cache per cell; the timing is the rounds below
      std::vector<Record> rows;
      std::vector<const Traverser*> ts;
      for (size_t s = 0; s < schemes.size(); ++s) {
        rows.push_back(measure_cell(bench, spec, *schemes[s], once));
        label_entry(rows.back(), opt.schemes[s], opt, prepare_ms[s]);
        ts.push_back(schemes[s].get());
      }
      const RayBatch& batch = bench.rays(spec);
      std::vector<Hit> hits(batch.size());
      const auto sec = measure_interleaved(ts, batch, hits, opt.threads, opt.reps);
      for (size_t s = 0; s < schemes.size(); ++s) {
        set_interleaved_speed(rows[s], sec[s], sec[0], batch.size(), opt.schemes[0]);
        if (opt.cells) opt.cells->append(rows[s]);
        if (opt.progress)
          std::fprintf(stderr, "[%zu/%zu] %-16s %-14s %16s  %s x %s  mismatch %s\n", ++done, total,
                       opt.schemes[s].c_str(), spec.name().c_str(), speed_text(rows[s]).c_str(),
                       rows[s].get("speed_ratio_median")->c_str(), opt.schemes[0].c_str(),
                       rows[s].get("mismatch_rate")->c_str());
        out.push_back(std::move(rows[s]));
      }
      continue;
    }
    for (size_t s = 0; s < schemes.size(); ++s) {
      const std::string& name = opt.schemes[s];  // the entry, with its own parameters if any
      if (opt.cells && opt.cells->has(run_cell_key(opt, spec.name(), name))) {
        if (opt.progress)
          std::fprintf(stderr, "[%zu/%zu] %-16s %-14s (in the CSV already)\n", ++done, total, name.c_str(),
                       spec.name().c_str());
        continue;
      }
      Record r = measure_cell(bench, spec, *schemes[s], cell_opt);
      label_entry(r, name, opt, prepare_ms[s]);
      if (opt.cells) opt.cells->append(r);
      if (opt.progress)
        std::fprintf(stderr, "[%zu/%zu] %-16s %-14s %16s  mismatch %s\n", ++done, total,
                     name.c_str(), spec.name().c_str(), speed_text(r).c_str(),
                     r.get("mismatch_rate")->c_str());
      out.push_back(std::move(r));
    }
  }
  return opt.cells ? opt.cells->records() : out;
}

}  // namespace tb
