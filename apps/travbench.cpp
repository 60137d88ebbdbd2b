// travbench command line (DESIGN.md "Command line"): parses and dispatches, nothing more.
//
// Every option value is checked while parsing (CLI11 validators), so a bad value fails at once, before
// any scene is built, with one line that names the option: "travbench: error: --workloads: ...".
// Problems found later (a scene file that does not load, a ray file that is cut short) are one line
// too, "travbench: error: <file>: <what>". Exit status: 0 on success, 2 for bad input (CLI11's
// parse errors included), 1 for anything else; never a signal.
#include <CLI/CLI.hpp>

#include <charconv>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <limits>
#include <new>
#include <sstream>

#include "cachesim/din_trace.h"
#include "harness/compare.h"
#include "harness/experiment.h"
#include "harness/image.h"
#include "harness/pathtrace.h"
#include "harness/records.h"
#include "harness/sweep.h"
#include "harness/tables.h"
#include "harness/trace_runner.h"
#include "structures/builtin_scenes.h"
#include "structures/scene_loader.h"
#include "traversal/kernels.h"
#include "traversal/registry.h"
#include "workloads/ray_file.h"

using namespace tb;

namespace {

// The contract is one line per error: fold any line breaks a library put into its message.
std::string one_line(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

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

// `list params [SCHEME]`: each scheme's declared --param keys (traversal/params.h).
void print_params(const std::string& scheme) {
  for (const auto& s : schemes()) {
    if (!scheme.empty() && s.name != scheme) continue;
    if (scheme.empty()) std::printf("%s:%s\n", s.name.c_str(), s.params.empty() ? " (no parameters)" : "");
    for (const auto& p : s.params)
      std::printf("%s%-15s %-26s default %-7s %s\n", scheme.empty() ? "  " : "", p.name.c_str(), p.type_text().c_str(),
                  p.fallback.empty() ? "auto" : p.fallback.c_str(), p.doc.c_str());
    if (!scheme.empty() && s.params.empty()) std::printf("(%s takes no parameters)\n", s.name.c_str());
  }
}

// Parses repeated --param key=value options into the scheme config; a key given twice is refused
// (the last value would silently win).
void apply_params(SchemeConfig& cfg, const std::vector<std::string>& params, const std::string& kernel) {
  cfg.kernel = parse_kernel(kernel);
  for (const auto& p : params) {
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0) throw InputError("--param '" + p + "' is not key=value");
    if (!cfg.params.emplace(p.substr(0, eq), p.substr(eq + 1)).second)
      throw InputError("--param: parameter '" + p.substr(0, eq) + "' is given twice");
  }
}

// Every file a command reads and writes, checked together before any work: each output must be
// writable as a file (the sidecar of a --csv too), and none may be an input or another output.
void check_files(const std::vector<FileArg>& inputs, const std::vector<FileArg>& outputs) {
  for (const FileArg& o : outputs) {
    try {
      if (!o.path.empty()) check_output_file(o.path);
    } catch (const InputError& e) {
      throw InputError(o.what + ": " + e.what());
    }
  }
  check_distinct_files(inputs, outputs);
}

// --view on a workload whose rays no camera view changes would label its rows with a view that
// was not used: refused, naming the workload.
void check_view_applies(const WorkloadSpec& spec) {
  if (!uses_view(spec))
    throw InputError("--view: workload '" + spec.name() +
                     "' does not use a camera view (its rays are the same for every view): run it without --view");
}

// The files loading a --scene argument reads (none for a built-in scene).
std::vector<FileArg> scene_inputs(const std::string& scene_arg) {
  std::vector<FileArg> in;
  if (const std::string file = scene_file_of(scene_arg); !file.empty())
    for (const SceneFileInput& f : scene_file_inputs(file))
      in.push_back({f.role == SceneFileInput::Role::scene   ? "--scene"
                    : f.role == SceneFileInput::Role::views ? "the scene's views file"
                                                            : "the scene's external file",
                    f.path});
  return in;
}

// A --csv output and its provenance sidecar.
std::vector<FileArg> csv_outputs(const std::string& csv) {
  if (csv.empty()) return {};
  return {{"--csv", csv}, {"the sidecar of --csv", sidecar_path(csv)}};
}

// ---- validators: each runs the parser the value is meant for, so the CLI and the library can
// never disagree about what is valid; CLI11 prefixes the message with the option name.

CLI::Validator checked_by(const std::string& desc, std::function<void(const std::string&)> parse) {
  return CLI::Validator(
      [parse](std::string& value) -> std::string {
        try {
          parse(value);
          return {};
        } catch (const std::exception& e) {
          return one_line(e.what());
        }
      },
      desc);
}

void for_each_item(const std::string& list, const std::function<void(const std::string&)>& fn) {
  std::stringstream ss(list);
  bool any = false;
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) fn(item), any = true;
  if (!any) throw InputError("empty list");
}

const CLI::Validator kWorkloads = checked_by("WORKLOAD[,WORKLOAD...]", [](const std::string& v) {
  for_each_item(v, [](const std::string& w) { parse_workload(w); });
});
const CLI::Validator kWorkload = checked_by("WORKLOAD", [](const std::string& v) { parse_workload(v); });
const CLI::Validator kSchemes = checked_by("SCHEME[,SCHEME...]|all", [](const std::string& v) { expand_scheme_list(v); });
// A scheme entry, NAME[:KEY=VALUE...]: the name and the entry's own parameters (config_for).
const CLI::Validator kScheme = checked_by("SCHEME", [](const std::string& v) { config_for(v, {}); });
const CLI::Validator kKernel = checked_by("KERNEL", [](const std::string& v) { parse_kernel(v); });
const CLI::Validator kParam = checked_by("KEY=VALUE", [](const std::string& v) {
  const auto eq = v.find('=');
  if (eq == std::string::npos || eq == 0) throw InputError("'" + v + "' is not key=value");
});
const CLI::Validator kCacheConfig = checked_by("LEVELS", [](const std::string& v) {
  cachesim::validate_config(cachesim::parse_config(v));
});
const CLI::Validator kPolicy = checked_by("POLICY", [](const std::string& v) { cachesim::parse_policy(v); });
// A seed is a uint64_t: a larger number must not be clamped to 2^64-1 by the conversion.
const CLI::Validator kSeed = checked_by("UINT", [](const std::string& v) {
  if (v.empty() || v.find_first_not_of("0123456789") != std::string::npos)
    throw InputError("'" + v + "' is not a non-negative integer");
  uint64_t seed = 0;
  if (std::from_chars(v.data(), v.data() + v.size(), seed).ec != std::errc())
    throw InputError("'" + v + "' is out of range (at most " +
                     std::to_string(std::numeric_limits<uint64_t>::max()) + ")");
});
// A scene: the name is valid and a scene file exists and is readable, before any work (its
// contents are read when it loads).
const CLI::Validator kScene = checked_by("SCENE", [](const std::string& v) { check_scene_arg(v); });
// An output file (records.h check_output_file: the rule write_file_durably applies too), so that
// a typo fails before a long run rather than when its results are written.
const CLI::Validator kOutputFile = checked_by("FILE", [](const std::string& v) { check_output_file(v); });

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"travbench: ray-traversal benchmark suite (Bikker 2012 experiments)"};
  app.require_subcommand(1);
  app.failure_message([](const CLI::App*, const CLI::Error& e) {
    std::string what = one_line(e.what());
    // Some CLI11 messages already end in "Run with --help for more information.": one hint is enough.
    for (const std::string hint : {"Run with --help for more information.", "(see travbench --help)"})
      if (const size_t at = what.find(hint); at != std::string::npos) what = one_line(what.erase(at, hint.size()));
    return "travbench: error: " + what + " (see travbench --help)\n";
  });

  std::string list_what, list_scheme;
  auto* list = app.add_subcommand("list", "List schemes, scenes, workloads (one per line), tables, or params [SCHEME]");
  list->add_option("what", list_what, "schemes | scenes | workloads | tables | params")
      ->check(CLI::IsMember({"schemes", "scenes", "workloads", "tables", "params"}));
  list->add_option("scheme", list_scheme, "with params: only this scheme's")->check(kScheme);

  // Each subcommand gets only the options it uses (issue 15, part 6).
  RunOptions ro;
  std::string scene_arg, schemes_arg = "all", workloads_arg = "primary", csv_path, kernel = "watertight";
  std::vector<std::string> params;
  auto add_scene = [&](CLI::App* c) {
    c->add_option("--scene", scene_arg, "built-in scene name or scene file path")->required()->check(kScene);
  };
  auto add_tracing = [&](CLI::App* c) {  // whatever traces with a scheme and times it
    c->add_option("--threads", ro.threads, "tracing threads")->check(CLI::Range(1, 256));
    c->add_option("--reps", ro.reps, "timed repetitions (after one warm-up)")->check(CLI::Range(1, 1000));
    c->add_option("--kernel", kernel, "triangle kernel: watertight | moller | plane | plane_rcp")->check(kKernel);
    c->add_option("--param", params, "scheme parameter key=value (repeatable; travbench list params)")->check(kParam);
    c->add_option("--csv", csv_path, "output CSV (a .json provenance sidecar is written beside it)")->check(kOutputFile);
  };
  auto add_image = [&](CLI::App* c) {  // whatever generates workloads
    c->add_option("--width", ro.width, "image width for camera workloads")->check(CLI::Range(16, 16384));
    c->add_option("--height", ro.height, "image height for camera workloads")->check(CLI::Range(16, 16384));
    c->add_option("--seed", ro.seed, "workload seed")->check(kSeed);
  };
  auto add_cache = [&](CLI::App* c, const char* flag_doc) {  // the cache simulator's columns
    auto* flag = c->add_flag("--cache", ro.cache, flag_doc);
    c->add_option("--cache-config", ro.cache_config, "with --cache: cache levels, e.g. l1=32K:8,l2=256K:8,l3=2M:16")
        ->check(kCacheConfig)->needs(flag);
    c->add_option("--cache-policy", ro.cache_policy, "with --cache: lru | plru | bitplru")->check(kPolicy)->needs(flag);
  };
  auto add_common = [&](CLI::App* c) {
    add_scene(c);
    c->add_option("--schemes", schemes_arg, "comma-separated scheme names or 'all'")->check(kSchemes);
    add_tracing(c);
    add_image(c);
  };
  // Views: the scene's (scenes.json may list any number; derived views are 3); checked against the
  // loaded scene below, this range only catches nonsense early.
  const auto view_range = CLI::Range(1, 64);
  auto* run = app.add_subcommand("run", "Measure schemes x workloads on one scene -> CSV");
  add_common(run);
  run->add_option("--workloads", workloads_arg, "comma-separated workloads, e.g. primary,bounce:2")->check(kWorkloads);
  run->add_option("--view", ro.view, "camera view (1-3, or as many as scenes.json lists)")->check(view_range);
  run->add_flag("--stats", ro.stats, "add node/leaf/triangle counts per ray and rays per visited node");
  add_cache(run, "add simulated L1/L2/L3 hits, memory accesses and estimated cycles");
  run->get_option("--csv")->required();
  bool resume = false;
  run->add_flag("--resume", resume,
                "keep the cells --csv holds from an interrupted run of the same sweep and measure only the rest");
  run->add_flag("--interleave", ro.interleave,
                "time each workload's schemes round by round (--reps rounds, every scheme once a round, the order "
                "rotated) and add speed_ratio columns: each round's speed over the first scheme's");

  std::string table_name;
  auto* table = app.add_subcommand("table", "Reproduce a thesis table -> CSV + terminal table");
  table->add_option("name", table_name, "table name (travbench list tables)")->required()->check(CLI::IsMember(table_names()));
  add_common(table);
  table->get_option("--scene")->required(false);
  table->get_option("--csv")->required();
  table->add_flag("--resume", resume,
                  "keep the cells --csv holds from an interrupted table of the same settings and measure only the rest");

  std::string rays_out, workload_arg, pt_method;
  uint32_t pt_spp = 1;
  auto* rays = app.add_subcommand("rays", "Generate a workload and write it as a ray file");
  add_scene(rays);
  add_image(rays);
  auto* rays_workload = rays->add_option("--workload", workload_arg, "workload name")->check(kWorkload);
  // Every ray one path-traced frame traces (harness/pathtrace.h), so a scheme, the cache simulator
  // or callgrind can replay a frame (scripts/pathtrace_reads.sh); the frame is rendered with the
  // reference traverser, and stdout gets the rays per iteration and kind as CSV.
  auto* rays_pt = rays->add_option("--pathtrace", pt_method,
                                    "instead of --workload: one frame of this path tracer (Ref, PR, DPT, ...)")
                      ->check(checked_by("METHOD", [](const std::string& v) { parse_pt_method(v); }))
                      ->excludes(rays_workload);
  rays->add_option("--spp", pt_spp, "samples per pixel of --pathtrace")->check(CLI::Range(1, 4096))->needs(rays_pt);
  rays->add_option("--view", ro.view, "camera view (1-3, or as many as scenes.json lists)")->check(view_range);
  // The camera `table divergence` traces by default (thesis Tables 2-4), for a ray file of the same
  // rays (scripts/divergence_counts.sh counts them under callgrind), built-in scenes included.
  std::string rays_camera = "view";
  rays->add_option("--camera", rays_camera,
                   "view = the view's own field of view; thesis = the camera of thesis Tables 2-4 (adjacent rays "
                   "0.034 deg apart at 1280 pixels wide: `table divergence`'s default)")
      ->check(CLI::IsMember({"view", "thesis"}))
      ->excludes(rays_pt);
  rays->add_option("--out", rays_out, "ray file to write")->required()->check(kOutputFile);

  std::string scheme_arg, rays_in, hits_out;
  auto* trace = app.add_subcommand(
      "trace", "Trace a ray file with one scheme: write its hits (--hits) and/or time it against the reference (--csv)");
  add_scene(trace);
  add_tracing(trace);
  trace->add_option("--scheme", scheme_arg, "scheme name")->required()->check(kScheme);
  trace->add_option("--rays", rays_in, "ray file to read")->required();
  trace->add_option("--hits", hits_out, "hit file to write")->check(kOutputFile);
  add_cache(trace, "with --csv: add run's simulated cache columns (one instrumented trace)");
  trace->add_flag("--stats", ro.stats, "with --csv: add run's node/leaf/triangle counts per ray and rays per visited node");

  ImageOptions io;
  auto* image = app.add_subcommand("image", "Per-pixel heat map of one scheme's traversal cost on a workload -> PNG");
  add_scene(image);
  image->add_option("--scheme", io.scheme, "scheme name")->required()->check(kScheme);
  image->add_option("--workload", io.workload, "camera workload: primary, divergence:D, bounce:k, shadow")->check(kWorkload);
  image->add_option("--metric", io.metric, "nodes | leaves | tris (per ray) | time (ns per ray) | shade (|n.d|)")
      ->check(CLI::IsMember(image_metrics()));
  image->add_option("--view", ro.view, "camera view (1-3, or as many as the scene lists)")->check(view_range);
  image->add_option("--width", io.width, "image width")->check(CLI::Range(16, 4096));
  image->add_option("--height", io.height, "image height")->check(CLI::Range(16, 4096));
  image->add_option("--packet", io.packet, "0: the workload's packets; N: packets of N rays (1: per ray)")
      ->check(CLI::Range(0, 65536));
  image->add_option("--kernel", kernel, "triangle kernel: watertight | moller | plane | plane_rcp")->check(kKernel);
  image->add_option("--param", params, "scheme parameter key=value (repeatable)")->check(kParam);
  image->add_option("--out", io.out, "PNG file to write")->required()->check(kOutputFile);

  std::string cache_config = "l1=32K:8,l2=256K:8,l3=2M:16", policy = "plru", trace_path;
  auto* cachesim = app.add_subcommand("cachesim", "Replay a Dinero IV din trace through the cache simulator");
  cachesim->add_option("--config", cache_config, "cache levels, e.g. l1=32K:8,l2=256K:8,l3=2M:16")->check(kCacheConfig);
  cachesim->add_option("--policy", policy, "lru | plru | bitplru")->check(kPolicy);
  cachesim->add_option("--trace", trace_path, "din trace file (- for standard input)")->required();

  std::string base_csv, new_csv, compare_csv;
  CompareOptions co;
  auto* compare = app.add_subcommand(
      "compare", "Compare two run CSVs cell by cell: speed ratio, Mann-Whitney U over the repetitions, accuracy deltas");
  compare->add_option("base", base_csv, "the baseline run CSV")->required()->check(CLI::ExistingFile);
  compare->add_option("new", new_csv, "the new run CSV")->required()->check(CLI::ExistingFile);
  compare->add_option("--alpha", co.alpha, "false discovery rate of the U tests (Benjamini-Hochberg over the cells)")
      ->check(CLI::Range(1e-6, 0.5));
  compare->add_option("--min-effect", co.min_effect_pct,
                      "a cell is faster/slower only when its ratio differs from 1 by at least PCT percent (default 10: "
                      "twice the drift between runs of one binary on a quiet machine, README; 0: off)")
      ->check(CLI::Range(0.0, 100.0));
  compare->add_option("--fail-on-regression", co.fail_on_regression_pct,
                      "exit 3 when a cell is slower by more than PCT percent (or beyond it without a verdict)")
      ->check(CLI::Range(0.0, 100.0));
  compare->add_option("--csv", compare_csv, "also write the comparison as CSV")->check(kOutputFile);

  // A first word that is no subcommand is named as such (CLI11 would say only that a subcommand
  // is required).
  if (argc > 1 && argv[1][0] != '-') {
    std::string names;
    bool known = false;
    for (const CLI::App* sub : app.get_subcommands({})) {
      names += (names.empty() ? "" : ", ") + sub->get_name();
      known |= sub->get_name() == argv[1];
    }
    if (!known) {
      std::fprintf(stderr, "travbench: error: unknown subcommand '%s' (one of: %s; see travbench --help)\n", argv[1],
                   names.c_str());
      return 2;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every usage error exits 2, whichever CLI11 code it carries
    // (105 for a value a validator refused, 106 for a missing option, ...).
    return app.exit(e) == 0 ? 0 : 2;
  }

  try {
    const bool view_given = ro.view > 0;
    if (view_given) ro.view -= 1;  // the CLI counts views from 1
    if (*list) {
      if (!list_scheme.empty() && list_what != "params")
        throw InputError("list: a scheme name only goes with 'list params SCHEME'");
      if (list_what == "params") print_params(list_scheme);
      else print_list(list_what, list_what.empty());
      return 0;
    }
    if (*cachesim) return cachesim::run_cachesim_command(cache_config, policy, trace_path, std::cout);
    // Outputs that would destroy an input or each other, and sidecars that cannot be written, are
    // refused before any work.
    if (*compare) check_files({{"base", base_csv}, {"new", new_csv}}, csv_outputs(compare_csv));
    if (*run || *table) check_files(scene_inputs(scene_arg), csv_outputs(csv_path));
    if (*rays) check_files(scene_inputs(scene_arg), {{"--out", rays_out}});
    if (*image) check_files(scene_inputs(scene_arg), {{"--out", io.out}});
    if (*trace) {
      if (ro.stats && csv_path.empty()) throw InputError("trace: --stats needs --csv (its columns go there)");
      std::vector<FileArg> in = scene_inputs(scene_arg), out = csv_outputs(csv_path);
      in.push_back({"--rays", rays_in});
      out.insert(out.begin(), {"--hits", hits_out});
      check_files(in, out);
    }
    if (*compare) {
      const CompareResult r = compare_runs(read_csv(base_csv), read_csv(new_csv), co);
      print_comparison(r, co, stdout);
      if (!compare_csv.empty()) write_csv(compare_csv, comparison_records(r), {{"command", "compare"}, {"base", base_csv}, {"new", new_csv}});
      return r.failed ? 3 : 0;
    }
    apply_params(ro.scheme_config, params, kernel);
    // Parameters are checked before any scene is loaded (tables check theirs against their schemes).
    if (*run) check_run_params(expand_scheme_list(schemes_arg), ro.scheme_config);
    if (*image) {
      io.scheme_config = ro.scheme_config;
      check_image_options(io);
    }
    if (*rays && workload_arg.empty() && pt_method.empty()) throw InputError("rays: give --workload or --pathtrace");
    if (*trace) {
      check_run_params({scheme_arg}, ro.scheme_config);
      if (ro.cache && csv_path.empty()) throw InputError("trace: --cache needs --csv (its columns go there)");
      if (hits_out.empty() && csv_path.empty())
        throw InputError("trace: nothing to write: give --hits FILE and/or --csv FILE");
    }
    if (*table) {
      TableOptions to;
      to.scene = scene_arg;
      to.run = ro;
      to.run.schemes = schemes_arg == "all" ? std::vector<std::string>{} : expand_scheme_list(schemes_arg);
      to.csv = csv_path;
      to.width_given = table->count("--width") > 0, to.height_given = table->count("--height") > 0;
      to.resume = resume;
      for (const CLI::Option* o : table->get_options())
        if (o->count() > 0) to.given.push_back(o->get_name());
      return run_table(table_name, to);
    }
    Scene scene;
    try {
      scene = load_scene(scene_arg);
    } catch (const InputError& e) {
      throw InputError("--scene: " + std::string(e.what()));
    }
    if (view_given && ro.view >= scene.views.size())
      throw InputError("--view " + std::to_string(ro.view + 1) + ": scene '" + scene.name + "' has " +
                       std::to_string(scene.views.size()) + " camera views");
    Bench bench(std::move(scene));
    if (*run) {
      ro.schemes = expand_scheme_list(schemes_arg);
      ro.workloads.clear();
      std::stringstream ss(workloads_arg);
      for (std::string w; std::getline(ss, w, ',');)
        if (!w.empty()) {
          const WorkloadSpec spec = parse_workload(w);
          if (view_given) check_view_applies(spec);
          ro.workloads.push_back(spec.name());
        }
      if (ro.workloads.empty()) throw InputError("--workloads is empty");
      if (ro.interleave && resume)
        throw InputError("--interleave times a workload's schemes together: it cannot --resume a run that kept some");
      run_sweep(bench, ro, scene_arg, csv_path, resume);
      std::fprintf(stderr, "wrote %s\n", csv_path.c_str());
      return 0;
    }
    if (*image) {
      io.view = ro.view;
      run_image(bench, io, bench.scene().name);
      return 0;
    }
    if (*rays && !pt_method.empty()) {
      PtOptions o;
      o.width = ro.width, o.height = ro.height, o.view = ro.view, o.spp = pt_spp, o.seed = ro.seed;
      std::vector<RayBatch> traced;
      o.traced = &traced;
      render_pathtrace(bench.scene(), bench.reference(), scene_lighting(bench.scene()), parse_pt_method(pt_method), o);
      RayBatch all;
      std::printf("iteration,kind,rays,packets\n");
      for (const RayBatch& b : traced) {
        std::printf("%u,%s,%zu,%u\n", b.depth, b.workload.c_str(), b.size(), b.num_packets());
        all.append(b);
      }
      write_rays(rays_out, all);
      return 0;
    }
    if (*rays) {
      WorkloadSpec spec = parse_workload(workload_arg);
      if (view_given) check_view_applies(spec);
      if (rays_camera == "thesis") {
        if (!from_camera_pixels(spec))
          throw InputError("--camera thesis: workload '" + spec.name() +
                           "' is not traced through the camera's pixels: run it without --camera");
        spec.hfov_deg = thesis_hfov_deg();
      }
      spec.width = ro.width, spec.height = ro.height, spec.view = ro.view, spec.seed = ro.seed;
      write_rays(rays_out, bench.rays(spec));
      return 0;
    }
    if (*trace) {
      RayBatch batch = read_rays(rays_in);
      auto t = make_scheme(scheme_arg, ro.scheme_config);
      const auto t0 = std::chrono::steady_clock::now();
      t->prepare(bench.scene(), bench.cache());
      const double prepare_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      std::vector<Hit> hits(batch.size());
      if (csv_path.empty() && trace->count("--reps") == 0) {
        trace_batch(*t, batch, hits, ro.threads);  // hits only: one untimed trace
      } else {
        // Timed as `run` times a cell: warm-up, --reps repetitions, accuracy against the reference.
        const std::vector<Hit> ref = reference_hits_of(bench, batch, ro.threads);
        const std::string label = "file:" + std::filesystem::path(rays_in).filename().string();
        Record r = measure_rays(bench, label, batch, ref, *t, ro, hits);
        r.set("prepare_ms", prepare_ms).set("view", "");  // the rays came from a file, not a camera view
        std::fprintf(stderr, "%-16s %-14s %8s Mrays/s (min %s, max %s)  mismatch %s\n", scheme_arg.c_str(),
                     label.c_str(), r.get("mrays_median")->c_str(), r.get("mrays_min")->c_str(),
                     r.get("mrays_max")->c_str(), r.get("mismatch_rate")->c_str());
        if (!csv_path.empty()) {
          write_csv(csv_path, {r},
                    {{"command", "trace"}, {"scene", scene_arg}, {"scene_hash", bench.scene().content_hash()},
                     {"rays_file", rays_in}});
          std::fprintf(stderr, "wrote %s\n", csv_path.c_str());
        }
      }
      if (!hits_out.empty()) write_hits(hits_out, hits);
      return 0;
    }
  } catch (const InputError& e) {
    std::fprintf(stderr, "travbench: error: %s\n", one_line(e.what()).c_str());
    return 2;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "travbench: error: out of memory (a smaller scene or --width/--height may fit)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "travbench: error: %s\n", one_line(e.what()).c_str());
    return 1;
  } catch (...) {
    std::fprintf(stderr, "travbench: error: unknown exception\n");
    return 1;
  }
  return 0;
}
