#include "harness/tables.h"

#include <cstdio>
#include <functional>
#include <map>

#include "harness/accuracy.h"
#include "harness/sweep.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"
#include "workloads/hard_cases.h"

namespace tb {

#define TB_TABLE(name, fn, not_taken, why) int fn(const TableOptions&);
#include "harness/tables.def"
#undef TB_TABLE

namespace {

std::vector<std::string> table_schemes(const TableOptions& opt, const std::vector<std::string>& fallback) {
  if (!opt.run.schemes.empty()) return opt.run.schemes;
  if (!fallback.empty()) {
    std::vector<std::string> known;  // keep only registered schemes (an entry may carry parameters), in the given order
    for (const auto& f : fallback)
      for (const auto& s : schemes())
        if (s.name == scheme_name_of(f)) known.push_back(f);
    return known;
  }
  std::vector<std::string> all;
  for (const auto& s : schemes())
    if (s.name != "reference") all.push_back(s.name);
  return all;
}

}  // namespace

std::vector<std::string> default_schemes(const TableOptions& opt, std::vector<std::string> fallback,
                                         const ParamSpecs& table_params, OwnTriangleTest own) {
  std::vector<std::string> names = table_schemes(opt, fallback);
  check_run_params(names, opt.run.scheme_config, table_params);
  // Every scheme's configuration as its cells will make it (--kernel included), before the first
  // cell: a table must not run for an hour and then refuse its last scheme.
  for (const auto& name : names) resolve_config(name, table_scheme_config(name, opt.run.scheme_config, own));
  return names;
}

std::string table_param(const TableOptions& opt, const ParamSpecs& table_params, const std::string& key) {
  const auto it = opt.run.scheme_config.params.find(key);
  return it != opt.run.scheme_config.params.end() ? it->second : find_param(table_params, key)->fallback;
}

SchemeConfig table_scheme_config(const std::string& entry, const SchemeConfig& run_cfg, OwnTriangleTest own) {
  SchemeConfig cfg = config_for(entry, run_cfg);
  if (own == OwnTriangleTest::keep && !find_scheme(entry).kernels) cfg.kernel = TriKernel::watertight;
  return cfg;
}

std::string thesis_layout(const std::string& scheme, SchemeConfig& cfg) {
  if (scheme != "mbvh_rs" && scheme != "raygrid") return "";
  if (!cfg.params.count("width")) {
    cfg.params.emplace("width", "4");
    if (scheme == "raygrid" && !cfg.params.count("queue")) cfg.params.emplace("queue", "384");
    // The thesis' streams: Table 8 counts rays per node "out of the original 256 rays in a 16x16
    // ray packet" (mbvh_rs's own default is longer: traversal/mbvh_rs.cpp).
    if (scheme == "mbvh_rs" && !cfg.params.count("stream")) cfg.params.emplace("stream", "256");
    // ... in the batch's order (its packets), not re-sorted by origin as mbvh_rs's default sorts.
    if (scheme == "mbvh_rs" && !cfg.params.count("sort")) cfg.params.emplace("sort", "none");
    // ... sorted by their rays' summed entry distances (Alg. 2.10; the schemes' default is the mean).
    if (!cfg.params.count("task_order")) cfg.params.emplace("task_order", "sum");
  }
  std::string label = "width=" + cfg.params["width"];
  if (scheme == "raygrid" && cfg.params.count("queue")) label += " queue=" + cfg.params["queue"];
  if (scheme == "mbvh_rs" && cfg.params.count("stream")) label += " stream=" + cfg.params["stream"];
  if (scheme == "mbvh_rs" && cfg.params.count("sort")) label += " sort=" + cfg.params["sort"];
  if (cfg.params.count("task_order")) label += " task_order=" + cfg.params["task_order"];
  return label;
}

std::string table_scene(const TableOptions& opt) { return opt.scene.empty() ? "room" : opt.scene; }

nlohmann::json thesis_table_meta(const std::string& table, const TableOptions& opt, const std::string& thesis_scene,
                                 const nlohmann::json& extra) {
  nlohmann::json meta = {{"command", "table " + table},
                         {"scene", table_scene(opt)},
                         {"thesis_scene", thesis_scene},
                         {"seed", opt.run.seed}};
  meta.update(extra);
  return meta;
}

WorkloadSpec table_spec(const TableOptions& opt, const std::string& workload, uint32_t view) {
  WorkloadSpec spec = parse_workload(workload);
  spec.width = opt.run.width;
  spec.height = opt.run.height;
  spec.seed = opt.run.seed;
  spec.view = view;
  return spec;
}

std::vector<Variant> variants_of(const SchemeInfo& info, const SchemeConfig& base) {
  std::vector<Variant> v;
  if (info.kernels) {
    for (TriKernel k : kAllTriKernels) {
      SchemeConfig c = base;
      c.kernel = k;
      v.push_back({std::string(kernel_name(k)), c});
    }
  } else if (info.name.rfind("embree", 0) == 0) {
    for (int robust : {1, 0}) {
      SchemeConfig c = base;
      c.params["robust"] = std::to_string(robust);
      v.push_back({robust ? "embree_robust" : "embree_default", c});
    }
  } else {
    // One triangle test of its own (cwbvh_single, treelet_queue: the watertight 8-wide blocks):
    // one row per cell. Without this branch those schemes had no rows at all.
    v.push_back({std::string(kernel_name(TriKernel::watertight)), base});
  }
  return v;
}

// Speed vs error (issue "Accuracy"): every scheme x kernel on ordinary and hard workloads, on the
// scene and on copies translated by ~1e5 and ~1e6 (the thesis-era failure mode of float kernels).
int accuracy_table(const TableOptions& opt) {
  const std::string base = opt.scene.empty() ? "sphere" : opt.scene;
  const std::vector<std::string> scenes = {base, base + "@148376,1234,-223423", base + "@1483760,12340,-2234230"};
  std::vector<std::string> workloads = {"primary", "rnd", "rnd2", "bounce:2", "shadow"};
  for (const auto& h : hard_case_names()) workloads.push_back(h);
  std::vector<Record> records;
  for (const auto& scene_name : scenes) {
    Bench bench(load_scene(scene_name));
    for (const auto& scheme : default_schemes(opt)) {
      const SchemeInfo& info = find_scheme(scheme);
      for (const Variant& var : variants_of(info, opt.run.scheme_config)) {
        auto t = make_scheme(scheme, config_for(scheme, var.config));
        t->prepare(bench.scene(), bench.cache());
        RunOptions cell = opt.run;
        cell.scheme_config = var.config;  // the params column: the variant's (Embree's robust=0|1 included)
        for (const auto& w : workloads) {
          WorkloadSpec spec = parse_workload(w);
          spec.width = opt.run.width, spec.height = opt.run.height, spec.seed = opt.run.seed;
          // Labelled with the entry as given: a scheme with parameters of its own is a row of its own.
          Record r = measure_cell(bench, spec, *t, cell, scheme);
          r.set("kernel", var.label).set("offset", scene_name == base ? "0" : scene_name.substr(base.size() + 1));
          r.set("must_hit", hard_case_must_hit(w) ? "yes" : "no");
          if (opt.run.progress)
            std::fprintf(stderr, "%-40s %-16s %-14s %-14s %8s Mrays/s  mismatch %s  leaks %s  ambiguous %s\n",
                         bench.scene().name.c_str(), scheme.c_str(), var.label.c_str(), w.c_str(),
                         r.get("mrays_median")->c_str(), r.get("mismatch_rate")->c_str(),
                         r.get("false_miss")->c_str(), r.get("ambiguous")->c_str());
          records.push_back(std::move(r));
        }
      }
    }
  }
  write_csv(opt.csv, records, {{"command", "table accuracy"}, {"scene", base}, {"seed", opt.run.seed}});
  print_table(records, {"offset", "scheme", "kernel", "workload", "mrays_median", "mismatch_rate", "false_miss",
                        "false_hit", "wrong_t", "ambiguous"}, stdout);
  return 0;
}

namespace {

struct TableEntry {
  std::function<int(const TableOptions&)> fn;
  std::string not_taken;  // options it has no use for, space-separated (tables.def)
  std::string why;
};

const std::map<std::string, TableEntry>& registry() {
  static const std::map<std::string, TableEntry> tables = {
#define TB_TABLE(name, fn, not_taken, why) {#name, {fn, not_taken, why}},
#include "harness/tables.def"
#undef TB_TABLE
  };
  return tables;
}

}  // namespace

std::vector<std::string> table_names() {
  std::vector<std::string> names;
  for (const auto& [name, entry] : registry()) names.push_back(name);
  return names;
}

int run_table(const std::string& name, const TableOptions& opt) {
  auto it = registry().find(name);
  if (it == registry().end()) {
    std::string known;
    for (const auto& n : table_names()) known += " " + n;
    throw InputError("unknown table '" + name + "' (available:" + known + ")");
  }
  const TableEntry& table = it->second;
  for (const auto& o : opt.given)
    if ((" " + table.not_taken + " ").find(" " + o + " ") != std::string::npos)
      throw InputError("table " + name + " does not take " + o + " (" + table.why + ")");
  if (opt.csv.empty()) return table.fn(opt);
  // Tables whose rows are not measure_cell's cells: build times structure builds, simt runs the
  // warp model; nothing of theirs reaches the CSV before the end, so there is nothing to resume.
  if (opt.resume && (name == "build" || name == "simt"))
    throw InputError("table " + name + ": --resume is not available: this table writes its CSV only when it "
                     "finishes (it does not measure ray cells one by one); run it again without --resume");
  // The sweep's identity: a resume must have the same settings (and, per scene, the same content
  // hash: CellStream::check_scene; and the same git revision, from the provenance).
  const RunOptions& r = opt.run;
  const nlohmann::json sweep = {{"scene", table_scene(opt)},
                                {"schemes", r.schemes},
                                {"seed", r.seed},
                                {"width", opt.width_given ? int(r.width) : -1},
                                {"height", opt.height_given ? int(r.height) : -1},
                                {"view", r.view + 1},
                                {"reps", r.reps},
                                {"threads", r.threads},
                                {"kernel", std::string(kernel_name(r.scheme_config.kernel))},
                                {"params", r.scheme_config.params}};
  const std::string command = "table " + name;
  // Each measured cell goes to the CSV as it finishes, so a killed table keeps them; the table's
  // own write_csv at the end replaces the file (atomically) with its finished rows. On resume the
  // constructor refuses another sweep's CSV, naming what differs.
  CellStream cells(opt.csv, {{"command", command}, {"scene", table_scene(opt)}, {"sweep", sweep}}, opt.resume,
                   {"command", "git_revision", "sweep"});
  if (opt.resume && CellStream::complete(opt.csv)) {
    // Its rows are the table's finished ones, not cells to replay: nothing is left to measure.
    std::fprintf(stderr, "%s: the table finished already (sidecar status complete); nothing to resume\n",
                 opt.csv.c_str());
    return 0;
  }
  if (cells.resumed())
    std::fprintf(stderr, "%s: resuming, %zu cells there already\n", opt.csv.c_str(), cells.resumed());
  TableOptions streamed = opt;
  streamed.run.cells = &cells;
  const int rc = table.fn(streamed);
  cells.finish_table();
  return rc;
}

}  // namespace tb
