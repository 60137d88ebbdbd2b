// `travbench table simt`: thesis §6.2, Tables 12 and 13, on a MODEL of a GTX470-class GPU
// (traversal/simt.h, traversal/simt_model.h, docs/SIMT.md): no GPU is involved. Rows:
//   Table 12: primary rays of divergence D = 1, 2, 4, 8, 16, 32 with the angle between rays scaled
//             per 8x8 tile (the thesis' tile, §6.2.1: workload divergence:D/8), rnd (random
//             directions from the camera) and rnd2 (random origins on surfaces);
//   Table 13: the rnd2 rays with only O = 1, 2, 4, ..., 32 lanes of each warp holding rays.
// Per row and kernel loop (while-while, if-if; --param loop=... picks one): SIMT efficiency,
// active lanes per step, load transactions (distinct 128-byte lines per step, summed) per ray and
// per step, L2 and DRAM transactions per ray, the modelled Mrays/s and its bound, % of the D = 1
// (Table 12) or O = 1 (Table 13) row, the thesis' GTX470 Mrays/s and % beside them, and the hits'
// agreement with the reference.
#include <cstdio>

#include "harness/accuracy.h"
#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"
#include "traversal/simt_model.h"

namespace tb {
namespace {

// Our scene name -> the column of table12_13_gpu_divergence_utilization.csv (the thesis prints
// Sponza, Escher, Lucy in Sibenik and Aztec in that order; we have Sponza and Sibenik+Lucy).
std::string thesis_column_of(const std::string& scene_name) {
  if (scene_name == "sponza") return "scene1";
  if (scene_name == "sibenik_lucy") return "scene3";
  return {};
}

struct Row {
  int table;             // 12 or 13
  std::string name;      // the thesis' row label: D=8, rnd2, O=4, ...
  std::string workload;  // our workload
  uint32_t lanes;        // active lanes per warp
};

std::vector<Row> simt_rows() {
  std::vector<Row> rows;
  for (int d = 1; d <= 32; d *= 2) rows.push_back({12, "D=" + std::to_string(d), "divergence:" + std::to_string(d) + "/8", 32});
  rows.push_back({12, "rnd", "rnd", 32});
  rows.push_back({12, "rnd2", "rnd2", 32});
  for (uint32_t o = 1; o <= 32; o *= 2) rows.push_back({13, "O=" + std::to_string(o), "rnd2", o});
  return rows;
}

std::string fixed(double v, int digits) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

}  // namespace

int simt_table(const TableOptions& opt) {
  const std::string scene_arg = opt.scene.empty() ? "room" : opt.scene;
  const ParamSpecs model_specs = gpu_model_param_specs();
  const std::vector<std::string> names = default_schemes(opt, {"simt_bvh"}, model_specs);
  if (names != std::vector<std::string>{"simt_bvh"})
    throw InputError("table simt models only the simt_bvh scheme (got --schemes " + [&] {
      std::string s;
      for (const auto& n : names) s += (s.empty() ? "" : ",") + n;
      return s;
    }() + ")");
  // Split --param into the model's keys and the scheme's.
  SchemeConfig model_cfg, scheme_cfg = opt.run.scheme_config;
  for (const auto& spec : model_specs) {
    auto it = scheme_cfg.params.find(spec.name);
    model_cfg.params[spec.name] = it == scheme_cfg.params.end() ? spec.fallback : it->second;
    if (it != scheme_cfg.params.end()) scheme_cfg.params.erase(it);
  }
  model_cfg.declared = &model_specs;
  const GPUModelConfig gpu = gpu_model_config(model_cfg);
  const bool loop_given = scheme_cfg.params.count("loop") != 0;
  const SchemeConfig resolved = resolve_config("simt_bvh", config_for("simt_bvh", scheme_cfg));

  Bench bench(load_scene(scene_arg));
  const std::string tcol = thesis_column_of(bench.scene().name);
  const ThesisTable thesis = load_thesis_table("table12_13_gpu_divergence_utilization.csv");
  const GPUBVHData data = fetch_gpu_bvh(bench.scene(), bench.cache(), bvh_params(resolved), resolved.kernel);

  std::vector<std::string> loops = {"while_while", "if_if"};
  if (loop_given) loops = {resolved.get_choice("loop")};
  std::vector<Record> records;
  const std::vector<Row> rows = simt_rows();
  for (const auto& loop : loops) {
    double base12 = 0, base13 = 0;
    for (const Row& row : rows) {
      SimtOptions so = simt_options(resolved);
      so.loop = loop == "if_if" ? SimtLoop::if_if : SimtLoop::while_while;
      so.lanes = row.lanes;
      const WorkloadSpec spec = table_spec(opt, row.workload);
      const RayBatch& batch = bench.rays(spec);
      std::vector<Hit> hits(batch.size());
      const GPUModelResult m = run_gpu_model(*data.gpu, *data.bvh.tris, resolved.kernel, batch, hits, so, gpu);
      const Accuracy acc = compare_hits(hits, bench.reference_hits(spec, opt.run.threads));
      const double rays = double(batch.size());
      const uint64_t steps = m.warp.total_steps();
      double& base = row.table == 12 ? base12 : base13;
      if (row.name == "D=1" || row.name == "O=1") base = m.mrays;
      Record r;
      r.set("scene", bench.scene().name).set("table", row.table).set("row", row.name).set("workload", spec.name());
      r.set("loop", loop).set("refill", resolved.get_choice("refill")).set("lanes", row.lanes).set("rays", uint64_t(batch.size()));
      r.set("kernel", std::string(kernel_name(resolved.kernel)));  // --kernel: the lanes' triangle test
      r.set("simt_efficiency", fixed(m.warp.efficiency(), 4));
      r.set("active_lanes_per_step", fixed(steps ? double(m.warp.lane_steps[0] + m.warp.lane_steps[1]) / double(steps) : 0, 2));
      r.set("steps_per_ray", fixed(double(steps) / rays, 3));
      r.set("traverse_steps", m.warp.steps[0]).set("intersect_steps", m.warp.steps[1]);
      r.set("transactions_per_ray", fixed(double(m.warp.load_lines) / rays, 2));
      r.set("transactions_per_step", fixed(steps ? double(m.warp.load_lines) / double(steps) : 0, 2));
      r.set("l2_transactions_per_ray", fixed(double(m.l2_hits + m.dram_lines) / rays, 2));
      r.set("dram_transactions_per_ray", fixed(double(m.dram_lines) / rays, 2));
      r.set("l1_hit_rate", fixed(m.warp.load_lines ? double(m.l1_hits) / double(m.warp.load_lines) : 0, 3));
      r.set("replay_ms", fixed(m.replay_cycles / double(gpu.sms) / (gpu.clock_ghz * 1e9) * 1e3, 4));
      r.set("model_mrays", fixed(m.mrays, 2)).set("model_bound", m.bound);
      r.set("issue_ms", fixed(m.issue_s * 1e3, 4)).set("latency_ms", fixed(m.latency_s * 1e3, 4)).set("dram_ms", fixed(m.dram_s * 1e3, 4));
      r.set("model_pct_of_base", base > 0 ? fixed(100.0 * m.mrays / base, 1) : "");
      std::string tm, tp;
      if (!tcol.empty()) {
        const auto v = thesis.lookup({"table", "row"}, {std::to_string(row.table), row.name}, tcol);
        const auto v1 = thesis.lookup({"table", "row"}, {std::to_string(row.table), row.table == 12 ? "D=1" : "O=1"}, tcol);
        if (v) tm = fixed(*v, 1);
        if (v && v1 && *v1 > 0) tp = fixed(100.0 * *v / *v1, 1);
      }
      r.set("thesis_mrays", tm).set("thesis_pct_of_base", tp);
      r.set("mismatch_rate", acc.mismatch_rate()).set("false_miss", acc.false_miss).set("false_hit", acc.false_hit);
      r.set("wrong_t", acc.wrong_t);
      if (opt.run.progress)
        std::fprintf(stderr, "%-11s %-5s eff %.3f  %6.2f lines/ray  model %7.2f Mrays/s (%s)\n", loop.c_str(),
                     row.name.c_str(), m.warp.efficiency(), double(m.warp.load_lines) / rays, m.mrays, m.bound.c_str());
      records.push_back(std::move(r));
    }
  }
  write_csv(opt.csv, records,
            {{"command", "table simt"},
             {"scene", scene_arg},
             {"thesis_column", tcol},
             {"width", opt.run.width},
             {"height", opt.run.height},
             {"seed", opt.run.seed},
             {"structure", data.gpu->describe()},
             {"model", "SIMT warp model of a GTX470 (docs/SIMT.md): no GPU measured"},
             {"note", "thesis: Bikker 2012 Tables 12-13, GTX470, Aila-Laine kernels; % of D=1 (Table 12) / O=1 (Table 13)"}});
  print_table(records, {"loop", "row", "simt_efficiency", "transactions_per_ray", "dram_transactions_per_ray",
                        "model_mrays", "model_bound", "model_pct_of_base", "thesis_mrays", "thesis_pct_of_base",
                        "mismatch_rate"},
              stdout);
  return 0;
}

}  // namespace tb
