#include "traversal/simt_model.h"

#include <algorithm>
#include <memory>
#include <vector>

#include "cachesim/cache_level.h"

namespace tb {

GPUBVHData fetch_gpu_bvh(const Scene& scene, StructureCache& cache, const BVHBuildParams& params, TriKernel kernel) {
  GPUBVHData d;
  d.bvh = fetch_bvh(scene, cache, params, kernel);
  d.gpu = cache.get<GPUBVH>(params.key() + ":gpu", [&] { return GPUBVH::from_bvh(*d.bvh.tree); });
  return d;
}

ParamSpecs simt_option_specs() {
  return {choice_param("loop", "while_while", {"while_while", "if_if"},
                       "Aila & Laine 2009 §3 kernel: while-while (traversal loop, then intersection loop) or if-if "
                       "(one node and one triangle per outer iteration)"),
          choice_param("refill", "lanes", {"lanes", "warp"},
                       "persistent threads: each finished lane fetches a new ray at the top of every outer iteration "
                       "(lanes, A&L's Fermi kernels) or the warp fetches 32 rays when all lanes are done (warp, A&L §4)"),
          int_param("lanes", int(kWarpSize), 1, int(kWarpSize),
                    "lanes of a warp that ever hold a ray (thesis Table 13's O active threads per warp)")};
}

SimtOptions simt_options(const SchemeConfig& cfg) {
  SimtOptions o;
  o.loop = cfg.get_choice("loop") == "if_if" ? SimtLoop::if_if : SimtLoop::while_while;
  o.refill = cfg.get_choice("refill") == "warp" ? SimtRefill::warp : SimtRefill::lanes;
  o.lanes = uint32_t(cfg.get_int("lanes"));
  return o;
}

ParamSpecs gpu_model_param_specs() {
  const GPUModelConfig d;
  return {int_param("sms", int(d.sms), 1, 128, "modelled streaming multiprocessors (GTX470: 14)"),
          int_param("warps_per_sm", int(d.warps_per_sm), 1, 64, "warps resident per SM (assumed 24; Fermi max 48)"),
          int_choice_param("l1_kb", int(d.l1_bytes / 1024), {8, 16, 32, 64, 128},
                           "L1 per SM in KB (Fermi: 16 or 48; the simulator takes powers of two)"),
          int_param("l1_assoc", int(d.l1_assoc), 1, 64, "L1 ways (assumed 4)"),
          int_choice_param("l2_kb", int(d.l2_bytes / 1024), {128, 256, 512, 1024, 2048, 4096},
                           "shared L2 in KB (GTX470: 640; the simulator takes powers of two)"),
          int_param("l2_assoc", int(d.l2_assoc), 1, 64, "L2 ways (assumed 16)"),
          int_param("l1_latency", int(d.l1_latency), 1, 10000, "L1 hit latency, shader cycles (assumed)"),
          int_param("l2_latency", int(d.l2_latency), 1, 10000, "L2 hit latency, shader cycles (assumed)"),
          int_param("dram_latency", int(d.dram_latency), 1, 10000,
                    "DRAM latency, shader cycles (CUDA C Programming Guide 3.2: 400-600)"),
          real_param("dram_gbs", d.dram_gbs, 1, 10000, "DRAM bandwidth, GB/s (GTX470: 133.9)"),
          real_param("clock_ghz", d.clock_ghz, 0.1, 10, "shader clock, GHz (GTX470: 1.215)"),
          int_param("traverse_instructions", int(d.traverse_instructions), 1, 1000,
                    "warp instructions per traversal step (assumed, docs/SIMT.md)"),
          int_param("intersect_instructions", int(d.intersect_instructions), 1, 1000,
                    "warp instructions per intersection step (assumed, docs/SIMT.md)"),
          real_param("replay_cycles", d.replay_cycles, 0, 100,
                     "issue cycles per extra 128-byte line a load's lanes touch (uncoalesced replay; assumed 1; 0 = free)")};
}

GPUModelConfig gpu_model_config(const SchemeConfig& cfg) {
  GPUModelConfig c;
  c.sms = uint32_t(cfg.get_int("sms"));
  c.warps_per_sm = uint32_t(cfg.get_int("warps_per_sm"));
  c.l1_bytes = uint64_t(cfg.get_int("l1_kb")) * 1024;
  c.l1_assoc = uint32_t(cfg.get_int("l1_assoc"));
  c.l2_bytes = uint64_t(cfg.get_int("l2_kb")) * 1024;
  c.l2_assoc = uint32_t(cfg.get_int("l2_assoc"));
  c.l1_latency = uint32_t(cfg.get_int("l1_latency"));
  c.l2_latency = uint32_t(cfg.get_int("l2_latency"));
  c.dram_latency = uint32_t(cfg.get_int("dram_latency"));
  c.dram_gbs = cfg.get_real("dram_gbs");
  c.clock_ghz = cfg.get_real("clock_ghz");
  c.traverse_instructions = uint32_t(cfg.get_int("traverse_instructions"));
  c.intersect_instructions = uint32_t(cfg.get_int("intersect_instructions"));
  c.replay_cycles = cfg.get_real("replay_cycles");
  return c;
}

namespace {

template <TriKernel K>
GPUModelResult run_model(const GPUBVH& bvh, const TriangleSet& tris, const RayBatch& batch, std::span<Hit> hits,
                         const SimtOptions& opt, const GPUModelConfig& cfg) {
  using cachesim::CacheLevel;
  // Replacement is not published for Fermi; LRU is the neutral choice. The geometry checks
  // (power-of-two sets) raise InputError naming the level.
  std::vector<CacheLevel> l1;
  for (uint32_t s = 0; s < cfg.sms; ++s)
    l1.emplace_back(cfg.l1_bytes, cfg.l1_assoc, kGpuLineBytes, cachesim::Policy::LRU);
  CacheLevel l2(cfg.l2_bytes, cfg.l2_assoc, kGpuLineBytes, cachesim::Policy::LRU);

  RayPool pool{0, uint32_t(batch.size())};
  const size_t nwarps = size_t(cfg.sms) * cfg.warps_per_sm;
  std::vector<LineObserver> obs(nwarps);
  for (LineObserver& o : obs) {  // the arrays a warp reads and writes, at fixed virtual addresses
    o.add_region(bvh.nodes.data(), bvh.bytes());
    o.add_region(tris.verts.data(), tris.verts.size() * sizeof(TriVerts));
    o.add_region(tris.planes.data(), tris.planes.size() * sizeof(PlaneTri));
    o.add_region(batch.rays.data(), batch.rays.size() * sizeof(Ray));
    o.add_region(hits.data(), hits.size_bytes());
  }
  std::vector<std::unique_ptr<Warp<K, LineObserver>>> warps;
  for (size_t w = 0; w < nwarps; ++w)
    warps.push_back(std::make_unique<Warp<K, LineObserver>>(bvh, tris, batch, hits, pool, opt, obs[w]));
  std::vector<double> serial(nwarps, 0.0), issue(cfg.sms, 0.0);
  std::vector<bool> done(nwarps, false);
  const double per_instr = double(cfg.dependent_latency) / cfg.ilp;  // serial cycles per instruction of one warp
  GPUModelResult r;
  size_t live = nwarps;
  // Round robin: warp w runs on SM w % sms, so the SMs start their warps at the same time, as a
  // persistent-threads launch does.
  while (live) {
    for (size_t w = 0; w < nwarps; ++w) {
      if (done[w]) continue;
      const StepKind k = warps[w]->step();
      const uint32_t sm = uint32_t(w % cfg.sms);
      uint32_t latency = 0;
      const size_t n_lines = obs[w].lines().size();
      for (const uint64_t line : obs[w].lines()) {
        if (l1[sm].access(line, false, false).hit) ++r.l1_hits, latency = std::max(latency, cfg.l1_latency);
        else if (l2.access(line, false, false).hit) ++r.l2_hits, latency = std::max(latency, cfg.l2_latency);
        else ++r.dram_lines, latency = std::max(latency, cfg.dram_latency);
      }
      // Stores go to L2 (Fermi's L1 does not keep global stores) and do not stall the warp.
      for (const uint64_t line : obs[w].store_lines()) l2.access(line, true, true), ++r.store_lines;
      obs[w].clear();
      if (k == StepKind::done) {
        done[w] = true, --live;
        continue;
      }
      const bool trav = k == StepKind::traverse;
      const double instr = trav ? cfg.traverse_instructions : cfg.intersect_instructions;
      const double replays = double(trav ? cfg.traverse_loads : cfg.intersect_loads) *
                             double(n_lines > 1 ? n_lines - 1 : 0) * cfg.replay_cycles;
      r.replay_cycles += replays;
      issue[sm] += instr / cfg.issue_per_cycle + replays;
      serial[w] += instr * per_instr + replays + latency;
    }
  }
  for (const auto& o : obs) r.warp.add(o.counters);
  double issue_cycles = 0, latency_cycles = 0;
  for (uint32_t s = 0; s < cfg.sms; ++s) issue_cycles = std::max(issue_cycles, issue[s]);
  for (size_t w = 0; w < nwarps; ++w) latency_cycles = std::max(latency_cycles, serial[w]);
  const double hz = cfg.clock_ghz * 1e9;
  r.issue_s = issue_cycles / hz;
  r.latency_s = latency_cycles / hz;
  r.dram_s = double(r.dram_lines) * kGpuLineBytes / (cfg.dram_gbs * 1e9);
  r.seconds = std::max({r.issue_s, r.latency_s, r.dram_s});
  r.bound = r.seconds == r.issue_s ? "issue" : r.seconds == r.latency_s ? "latency" : "dram";
  r.mrays = r.seconds > 0 ? double(batch.size()) / r.seconds * 1e-6 : 0.0;
  return r;
}

}  // namespace

GPUModelResult run_gpu_model(const GPUBVH& bvh, const TriangleSet& tris, TriKernel kernel, const RayBatch& batch,
                             std::span<Hit> hits, const SimtOptions& opt, const GPUModelConfig& cfg) {
  return dispatch_kernel(kernel, [&](auto k) { return run_model<decltype(k)::value>(bvh, tris, batch, hits, opt, cfg); });
}

}  // namespace tb
