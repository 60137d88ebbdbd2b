// A memory and throughput MODEL of GPU traversal (thesis §6.2, Tables 12-13), not a GPU and not a
// cycle-accurate simulator. Many warps (traversal/simt.h) run round-robin, one step each per
// round, on `sms` streaming multiprocessors with `warps_per_sm` warps each, all fetching rays
// from one pool. Every step's distinct 128-byte lines go through the cache simulator (cachesim/:
// one L1 per SM, one shared L2), and the run's time is the largest of three bounds:
//   issue:   per SM, the warp instructions of its steps / issue rate (warp steps x instructions
//            per step: a step costs the same however many lanes are active: SIMT), plus the
//            replays of loads whose lanes touch several lines (uncoalesced loads),
//   latency: per SM, its slowest warp's serial time: per step, its instructions x the dependent
//            issue interval, plus the latency of the slowest level that served one of its lines
//            (a warp waits for all of its lanes' loads),
//   DRAM:    lines missing the L2 x 128 bytes / DRAM bandwidth.
// Modelled Mrays/s = rays / (largest bound). Every constant is in GPUModelConfig with its source;
// those marked "assumed" are not published for the GTX470 and are our choice (docs/SIMT.md says
// what the model leaves out: L2 and interconnect bandwidth, texture path, stack traffic in local
// memory, instruction cache, warp scheduling detail, the real register-limited occupancy).
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "traversal/params.h"
#include "traversal/simt.h"

namespace tb {

struct GPUModelConfig {
  // GTX470 (GF100, NVIDIA GeForce GTX 470 specifications): 14 SMs x 32 cores, 1215 MHz shader
  // clock, 133.9 GB/s memory bandwidth (the thesis quotes it, §6.2.4), 640 KB of L2 (5 of GF100's
  // 6 x 128 KB memory-partition slices), 128-byte lines (NVIDIA Fermi Compute Architecture
  // Whitepaper 2009; CUDA C Programming Guide 3.2 §G.4.2).
  uint32_t sms = 14;
  double clock_ghz = 1.215;
  double dram_gbs = 133.9;
  // The cache simulator takes power-of-two sizes (cachesim/cache_level.h), so the GTX470's 640 KB
  // L2 is modelled as 512 KB, and Fermi's 16 or 48 KB L1 (64 KB split with shared memory;
  // cudaFuncCachePreferL1 selects 48 KB) as 32 KB, between the two.
  uint64_t l2_bytes = 512 * 1024;
  uint32_t l2_assoc = 16;     // assumed (not published)
  uint64_t l1_bytes = 32 * 1024;
  uint32_t l1_assoc = 4;      // assumed (not published)
  // Latencies in shader cycles. DRAM: "400 to 600 clock cycles" (CUDA C Programming Guide 3.2,
  // §5.3.2); L1 and L2 hit latencies are assumed (L2 at half the DRAM latency, L1 an order of
  // magnitude below DRAM; not measured here, and not published by NVIDIA for the GTX470).
  uint32_t l1_latency = 40;
  uint32_t l2_latency = 250;
  uint32_t dram_latency = 500;
  // Issue: a Fermi SM's two schedulers each issue one warp instruction per two cycles on 16 lanes
  // (Fermi whitepaper), one warp instruction per cycle per SM. A dependent instruction of the same
  // warp waits about 22 cycles for its operands (CUDA C Programming Guide 3.2, §5.2.3); `ilp`
  // independent instructions per step cover part of that (assumed 2: the two child slab tests).
  double issue_per_cycle = 1.0;
  uint32_t dependent_latency = 22;
  double ilp = 2.0;
  // Warp instructions per step (assumed: counted from A&L's kernels' loop bodies: traversal = two
  // children's 3-axis slab tests with min/max, compare, order, push or pop, node loads; intersect
  // = Woop's unit-triangle test, compare, pop at the leaf's end). Watertight costs more; the ratio
  // matters more than the level.
  uint32_t traverse_instructions = 40;
  uint32_t intersect_instructions = 30;
  // Coalescing cost: a load instruction whose active lanes touch L distinct 128-byte lines is
  // replayed until every line is served, one line per L1 access (CUDA C Programming Guide 3.2,
  // §G.4.2: "one memory transaction per cache line"; NVIDIA's profilers count these replays as
  // issued instructions). A&L fetch a 64-byte node as four float4 loads and a Woop triangle as
  // three; so a step costs loads x (L - 1) x replay_cycles extra issue cycles (1 cycle per line,
  // assumed). This is how the model makes divergent rays cost more than their steps.
  uint32_t traverse_loads = 4;
  uint32_t intersect_loads = 3;
  double replay_cycles = 1.0;
  // Warps resident per SM (assumed: A&L's kernels use ~32-40 registers per thread; 32768
  // registers per SM give ~24 warps of 32 threads; Fermi's maximum is 48).
  uint32_t warps_per_sm = 24;
};

// The binary BVH (and its leaf-ordered triangles for `kernel`) converted to the GPU layout, both
// from the structure cache (the GPU layout under the BVH's key + ":gpu").
struct GPUBVHData {
  BVHData bvh;
  std::shared_ptr<const GPUBVH> gpu;
};
GPUBVHData fetch_gpu_bvh(const Scene& scene, StructureCache& cache, const BVHBuildParams& params, TriKernel kernel);

// The model's parameters as --param keys (table simt) and the config they make.
ParamSpecs gpu_model_param_specs();
GPUModelConfig gpu_model_config(const SchemeConfig& cfg);
SimtOptions simt_options(const SchemeConfig& cfg);  // loop, refill, lanes
ParamSpecs simt_option_specs();

struct GPUModelResult {
  WarpCounters warp;
  uint64_t l1_hits = 0, l2_hits = 0, dram_lines = 0;  // load lines by the level that served them
  uint64_t store_lines = 0;                           // hit stores (to L2; Fermi's L1 does not cache stores)
  double replay_cycles = 0;                           // issue cycles of load replays (all SMs)
  double issue_s = 0, latency_s = 0, dram_s = 0;      // the three bounds (seconds)
  double seconds = 0, mrays = 0;
  std::string bound;  // "issue", "latency" or "dram"
};

// Traces every ray of `batch` into hits through the modelled GPU.
GPUModelResult run_gpu_model(const GPUBVH& bvh, const TriangleSet& tris, TriKernel kernel, const RayBatch& batch,
                             std::span<Hit> hits, const SimtOptions& opt, const GPUModelConfig& cfg);

}  // namespace tb
