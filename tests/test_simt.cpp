// The SIMT warp executor and GPU model (traversal/simt.h, simt_model.h; thesis ch. 6): hits equal
// the reference, the warp counters on hand-checkable cases, refill, and the model's bookkeeping.
// (The registry tests run simt_bvh on every workload and hard case as every other scheme.)
#include <cmath>
#include <vector>

#include "test_util.h"
#include "traversal/simt_model.h"
#include "workloads/hard_cases.h"

namespace tb {
namespace {

Bench& room() {
  static Bench b(load_scene("room"));
  return b;
}

GPUBVHData room_gpu() { return fetch_gpu_bvh(room().scene(), room().cache(), BVHBuildParams{}, TriKernel::watertight); }

WarpCounters counters_of(const RayBatch& b, const SimtOptions& opt, std::vector<Hit>& hits) {
  const GPUBVHData d = room_gpu();
  hits.assign(b.size(), Hit{});
  return run_one_warp<TriKernel::watertight>(*d.gpu, *d.bvh.tris, b, hits, RayPool{0, uint32_t(b.size())}, opt);
}

TEST(SimtLayout, ConversionKeepsEveryInteriorNodeAndLeaf) {
  const GPUBVHData d = room_gpu();
  const BVH& bvh = *d.bvh.tree;
  EXPECT_EQ(d.gpu->nodes.size(), size_t(bvh.stats.nodes - bvh.stats.leaves));
  uint64_t leaf_tris = 0;
  for (const GPUNode& n : d.gpu->nodes)
    for (const GPUChild& c : n.child) leaf_tris += c.count;
  EXPECT_EQ(leaf_tris, d.bvh.tris->size());  // each leaf referenced once
  EXPECT_EQ(reinterpret_cast<uintptr_t>(d.gpu->nodes.data()) % 128, 0u);
}

// Every loop and refill policy, and a narrow warp, returns the reference's hits on ordinary
// workloads and the same hits as bvh_single (same BVH, same kernels) on the hard cases, where
// the reference also differs from every scheme on ambiguous rays (docs/ACCURACY.md).
TEST(SimtExecutor, HitsEqualTheReferenceForEveryLoopAndRefill) {
  auto single = make_scheme("bvh_single");
  single->prepare(room().scene(), room().cache());
  for (const char* loop : {"while_while", "if_if"})
    for (const char* refill : {"lanes", "warp"})
      for (const char* lanes : {"32", "5"}) {
        SchemeConfig cfg;
        cfg.params = {{"loop", loop}, {"refill", refill}, {"lanes", lanes}};
        auto simt = make_scheme("simt_bvh", cfg);
        simt->prepare(room().scene(), room().cache());
        for (const std::string w : {"divergence:4/8", "rnd2", "bounce:1", "hard:edges", "hard:inside", "hard:tmin_tmax"}) {
          const WorkloadSpec spec = test::small_spec(w, 48);
          const RayBatch& b = room().rays(spec);
          std::vector<Hit> hits(b.size()), expected(b.size());
          trace_batch(*simt, b, hits, 2);
          trace_batch(*single, b, expected, 1);
          EXPECT_EQ(compare_hits(hits, expected).mismatches, 0u) << loop << "/" << refill << "/" << lanes << " on " << w;
          if (w.rfind("hard:", 0) != 0) {
            EXPECT_LE(compare_hits(hits, room().reference_hits(spec)).mismatches, 1u) << loop << "/" << refill << " on " << w;
          }
        }
      }
}

// 32 identical rays: every lane does the same thing at every step, so every step has 32 active
// lanes (efficiency 1) and every node or triangle fetch is one address (one or two lines).
TEST(SimtExecutor, IdenticalRaysRunAtFullEfficiencyAndCoalesce) {
  const RayBatch& src = room().rays(test::small_spec("primary", 32));
  RayBatch b;
  b.rays.assign(32, src.rays[src.size() / 2 + 16]);
  b.packet_begin = {0, 32};
  for (SimtLoop loop : {SimtLoop::while_while, SimtLoop::if_if}) {
    std::vector<Hit> hits;
    const WarpCounters c = counters_of(b, {loop, SimtRefill::lanes, 32}, hits);
    EXPECT_DOUBLE_EQ(c.efficiency(), 1.0);
    EXPECT_EQ(c.rays, 32u);
    EXPECT_GT(c.steps[0], 0u);
    // Rays: 32 x 32 bytes = 8 lines; each step one node (64 bytes in one line) or one triangle.
    EXPECT_LE(c.load_lines, 8 + c.steps[0] + 2 * c.steps[1]);
    EXPECT_GE(c.load_lines, 8 + c.steps[0] + c.steps[1]);
    EXPECT_EQ(c.load_requests, 32 * (1 + c.total_steps()));
    for (const Hit& h : hits) EXPECT_EQ(h.prim, hits[0].prim);
  }
}

TEST(SimtExecutor, LineObserverCountsDistinctLinesPerStep) {
  alignas(128) static float data[64 * 32];
  LineObserver obs;
  for (int lane = 0; lane < 32; ++lane) obs.node(&data[0], 64);  // one address: one line
  EXPECT_EQ(obs.lines().size(), 1u);
  obs.clear();
  for (int lane = 0; lane < 32; ++lane) obs.ray(&data[lane * 8], 32);  // 32 x 32 consecutive bytes: 8 lines
  EXPECT_EQ(obs.lines().size(), 8u);
  obs.clear();
  for (int lane = 0; lane < 32; ++lane) obs.tri(&data[lane * 64], 48);  // one line each (stride 256)
  EXPECT_EQ(obs.lines().size(), 32u);
  obs.node(&data[24], 64);  // bytes 96..159 straddle two lines
  obs.clear();
  EXPECT_EQ(obs.counters.load_lines, 1u + 8u + 32u + 1u);
  obs.node(&data[24], 64);
  EXPECT_EQ(obs.lines().size(), 2u);
}

// One lane of 32: efficiency exactly 1/32.
TEST(SimtExecutor, OneActiveLaneHasEfficiencyOneIn32) {
  std::vector<Hit> hits;
  const WarpCounters c = counters_of(room().rays(test::small_spec("rnd2", 16)), {SimtLoop::while_while, SimtRefill::lanes, 1}, hits);
  EXPECT_DOUBLE_EQ(c.efficiency(), 1.0 / 32);
}

// Refilling finished lanes at every outer iteration keeps more lanes busy than waiting for the
// whole warp (A&L 2009 §4 vs their Fermi kernels), with the same hits; coherent rays keep more
// lanes busy than incoherent ones.
TEST(SimtExecutor, RefillKeepsLanesBusyAndCoherenceRaisesEfficiency) {
  const RayBatch& rnd2 = room().rays(test::small_spec("rnd2", 32));
  std::vector<Hit> h_lanes, h_warp;
  const WarpCounters lanes = counters_of(rnd2, {SimtLoop::while_while, SimtRefill::lanes, 32}, h_lanes);
  const WarpCounters warp = counters_of(rnd2, {SimtLoop::while_while, SimtRefill::warp, 32}, h_warp);
  EXPECT_GT(lanes.efficiency(), warp.efficiency());
  EXPECT_LT(lanes.total_steps(), warp.total_steps());
  for (size_t i = 0; i < h_lanes.size(); ++i) EXPECT_EQ(h_lanes[i].prim, h_warp[i].prim);
  std::vector<Hit> h;
  const WarpCounters d1 = counters_of(room().rays(test::small_spec("divergence:1/8", 32)), {SimtLoop::while_while, SimtRefill::lanes, 32}, h);
  EXPECT_GT(d1.efficiency(), lanes.efficiency());
}

// The model: every load line is served by exactly one level, the hits are the reference's, and
// the throughput is the rays over the largest bound.
TEST(SimtModel, AccountsEveryLineAndReturnsTheReferenceHits) {
  const GPUBVHData d = room_gpu();
  const WorkloadSpec spec = test::small_spec("rnd2", 48);
  const RayBatch& b = room().rays(spec);
  std::vector<Hit> hits(b.size());
  GPUModelConfig cfg;
  cfg.sms = 2, cfg.warps_per_sm = 3;
  const GPUModelResult r = run_gpu_model(*d.gpu, *d.bvh.tris, TriKernel::watertight, b, hits, SimtOptions{}, cfg);
  EXPECT_EQ(compare_hits(hits, room().reference_hits(spec)).non_ambiguous(), 0u);
  EXPECT_EQ(r.l1_hits + r.l2_hits + r.dram_lines, r.warp.load_lines);
  EXPECT_EQ(r.warp.rays, b.size());
  EXPECT_DOUBLE_EQ(r.seconds, std::max({r.issue_s, r.latency_s, r.dram_s}));
  EXPECT_NEAR(r.mrays, double(b.size()) / r.seconds * 1e-6, 1e-9 * r.mrays);
  EXPECT_FALSE(r.bound.empty());
}

TEST(SimtModel, RefusesACacheSizeThatIsNotAPowerOfTwo) {
  const GPUBVHData d = room_gpu();
  const RayBatch& b = room().rays(test::small_spec("rnd2", 8));
  std::vector<Hit> hits(b.size());
  GPUModelConfig cfg;
  cfg.l1_bytes = 48 * 1024;  // Fermi's 48 KB: not a power of two, which the simulator needs
  EXPECT_THROW(run_gpu_model(*d.gpu, *d.bvh.tris, TriKernel::watertight, b, hits, SimtOptions{}, cfg), InputError);
}

TEST(SimtWorkload, DivergenceTileParameter) {
  const WorkloadSpec s = parse_workload("divergence:8/8");
  EXPECT_EQ(s.param, 8);
  EXPECT_EQ(s.tile, 8u);
  EXPECT_EQ(s.name(), "divergence:8/8");
  EXPECT_EQ(parse_workload("divergence:8").name(), "divergence:8");
  EXPECT_THROW(parse_workload("divergence:8/3"), InputError);
  EXPECT_THROW(parse_workload("divergence:8/"), InputError);
  // D = 1 is the plain camera whatever the tile.
  const RayBatch& a = room().rays(test::small_spec("divergence:1/8", 32));
  const RayBatch& c = room().rays(test::small_spec("divergence:1", 32));
  ASSERT_EQ(a.size(), c.size());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a.rays[i].dir.x, c.rays[i].dir.x);
}

}  // namespace
}  // namespace tb
