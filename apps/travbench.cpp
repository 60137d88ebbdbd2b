// travbench command line (DESIGN.md "Command line"): parses and dispatches, nothing more.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>
#include <sstream>

#include "cachesim/din_trace.h"
#include "harness/experiment.h"
#include "harness/tables.h"
#include "harness/trace_runner.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"
#include "workloads/ray_file.h"

using namespace tb;

namespace {

void print_list(const std::string& what, bool headed) {
  auto section = [&](const char* title, const std::vector<std::string>& names) {
    if (headed) std::printf("%s:\n", title);
    for (const auto& n : names) std::printf("%s%s\n", headed ? "  " : "", n.c_str());
  };
  std::vector<std::string> names;
  if (what == "schemes" || what.empty()) {
    names.clear();
    for (const auto& s : schemes()) names.push_back(s.name);
    section("schemes", names);
  }
  if (what == "scenes" || what.empty()) section("scenes", builtin_scene_names());
  if (what == "workloads" || what.empty()) section("workloads", workload_names());
  if (what == "tables") section("tables", table_names());
}

// Parses repeated --param key=value options into the scheme config.
void apply_params(SchemeConfig& cfg, const std::vector<std::string>& params, const std::string& kernel) {
  cfg.kernel = parse_kernel(kernel);
  for (const auto& p : params) {
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0) throw InputError("--param '" + p + "' is not key=value");
    cfg.params[p.substr(0, eq)] = p.substr(eq + 1);
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"travbench: ray-traversal benchmark suite (Bikker 2012 experiments)"};
  app.require_subcommand(1);

  std::string list_what;
  auto* list = app.add_subcommand("list", "List schemes, scenes, workloads (one per line) or tables");
  list->add_option("what", list_what, "schemes | scenes | workloads | tables")
      ->check(CLI::IsMember({"schemes", "scenes", "workloads", "tables"}));

  RunOptions ro;
  std::string scene_arg, schemes_arg = "all", workloads_arg = "primary", csv_path, kernel = "watertight";
  std::vector<std::string> params;
  auto add_common = [&](CLI::App* c, bool need_schemes) {
    c->add_option("--scene", scene_arg, "built-in scene name or scene file path")->required();
    if (need_schemes) c->add_option("--schemes", schemes_arg, "comma-separated scheme names or 'all'");
    c->add_option("--threads", ro.threads, "tracing threads")->check(CLI::Range(1, 256));
    c->add_option("--reps", ro.reps, "timed repetitions (after one warm-up)")->check(CLI::Range(1, 1000));
    c->add_option("--width", ro.width, "image width for camera workloads")->check(CLI::Range(16, 16384));
    c->add_option("--height", ro.height, "image height for camera workloads")->check(CLI::Range(16, 16384));
    c->add_option("--seed", ro.seed, "workload seed");
    c->add_option("--kernel", kernel, "triangle kernel: watertight | moller | plane | plane_rcp");
    c->add_option("--param", params, "scheme parameter key=value (repeatable), e.g. leaf_size=4");
    c->add_option("--csv", csv_path, "output CSV (a .json provenance sidecar is written beside it)");
  };
  auto* run = app.add_subcommand("run", "Measure schemes x workloads on one scene -> CSV");
  add_common(run, true);
  run->add_option("--workloads", workloads_arg, "comma-separated workloads, e.g. primary,bounce:2");
  run->add_option("--view", ro.view, "camera view (1-3)")->check(CLI::Range(1, 3));
  run->add_flag("--stats", ro.stats, "add node/leaf/triangle counts per ray and rays per visited node");
  run->add_flag("--cache", ro.cache, "add simulated L1/L2/L3 hits, memory accesses and estimated cycles");
  run->add_option("--cache-config", ro.cache_config, "cache levels, e.g. l1=32K:8,l2=256K:8,l3=2M:16");
  run->add_option("--cache-policy", ro.cache_policy, "lru | plru | bitplru");
  run->get_option("--csv")->required();

  std::string table_name;
  auto* table = app.add_subcommand("table", "Reproduce a thesis table -> CSV + terminal table");
  table->add_option("name", table_name, "table name (travbench list tables)")->required();
  add_common(table, true);
  table->get_option("--scene")->required(false);
  table->get_option("--csv")->required();

  std::string rays_out, workload_arg;
  auto* rays = app.add_subcommand("rays", "Generate a workload and write it as a ray file");
  add_common(rays, false);
  rays->add_option("--workload", workload_arg, "workload name")->required();
  rays->add_option("--view", ro.view, "camera view (1-3)")->check(CLI::Range(1, 3));
  rays->add_option("--out", rays_out, "ray file to write")->required();

  std::string scheme_arg, rays_in, hits_out;
  auto* trace = app.add_subcommand("trace", "Trace a ray file with one scheme and write a hit file");
  add_common(trace, false);
  trace->add_option("--scheme", scheme_arg, "scheme name")->required();
  trace->add_option("--rays", rays_in, "ray file to read")->required();
  trace->add_option("--hits", hits_out, "hit file to write")->required();

  std::string cache_config = "l1=32K:8,l2=256K:8,l3=2M:16", policy = "plru", trace_path;
  auto* cachesim = app.add_subcommand("cachesim", "Replay a Dinero IV din trace through the cache simulator");
  cachesim->add_option("--config", cache_config, "cache levels, e.g. l1=32K:8,l2=256K:8,l3=2M:16");
  cachesim->add_option("--policy", policy, "lru | plru | bitplru");
  cachesim->add_option("--trace", trace_path, "din trace file")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  try {
    if (ro.view > 0) ro.view -= 1;  // the CLI counts views from 1
    if (*list) {
      print_list(list_what, list_what.empty());
      return 0;
    }
    if (*cachesim) return cachesim::run_cachesim_command(cache_config, policy, trace_path, std::cout);
    apply_params(ro.scheme_config, params, kernel);
    if (*table) {
      TableOptions to;
      to.scene = scene_arg;
      to.run = ro;
      to.run.schemes = schemes_arg == "all" ? std::vector<std::string>{} : expand_scheme_list(schemes_arg);
      to.csv = csv_path;
      return run_table(table_name, to);
    }
    Bench bench(load_scene(scene_arg));
    if (*run) {
      ro.schemes = expand_scheme_list(schemes_arg);
      ro.workloads.clear();
      std::stringstream ss(workloads_arg);
      for (std::string w; std::getline(ss, w, ',');)
        if (!w.empty()) ro.workloads.push_back(parse_workload(w).name());
      if (ro.workloads.empty()) throw InputError("--workloads is empty");
      const auto records = run_experiment(bench, ro);
      write_csv(csv_path, records,
                {{"command", "run"}, {"scene", scene_arg}, {"scene_hash", bench.scene().content_hash()},
                 {"seed", ro.seed}, {"width", ro.width}, {"height", ro.height}});
      std::fprintf(stderr, "wrote %s\n", csv_path.c_str());
      return 0;
    }
    if (*rays) {
      WorkloadSpec spec = parse_workload(workload_arg);
      spec.width = ro.width, spec.height = ro.height, spec.view = ro.view, spec.seed = ro.seed;
      write_rays(rays_out, bench.rays(spec));
      return 0;
    }
    if (*trace) {
      RayBatch batch = read_rays(rays_in);
      auto t = make_scheme(scheme_arg, ro.scheme_config);
      t->prepare(bench.scene(), bench.cache());
      std::vector<Hit> hits(batch.size());
      trace_batch(*t, batch, hits, ro.threads);
      write_hits(hits_out, hits);
      return 0;
    }
  } catch (const InputError& e) {
    std::fprintf(stderr, "travbench: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "travbench: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
