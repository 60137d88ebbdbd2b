// A SIMT warp executor: 32 lanes running GPU BVH traversal in lock-step, as a GTX470-class GPU
// would (thesis ch. 6, §6.2; Aila & Laine 2009, "Understanding the efficiency of ray traversal on
// GPUs", §2-§4). One ray per lane, one per-lane stack of child references (A&L keep it in local
// memory), the binary BVH in the GPU node layout (structures/gpu_bvh.h: both children's boxes in
// the parent), persistent threads: a warp keeps fetching rays from a shared pool (A&L §4, a global
// atomic counter) until the pool is empty.
//
// A "step" is one issue of a loop body by the warp: every lane whose control flow is in that body
// executes it, the others idle (masked off). SIMT efficiency = active lane-steps / (32 x steps),
// A&L's "SIMD efficiency" (§3) and the thesis' "utilization" (§6.2). The two kernels of A&L §3:
//  - while-while: `while (ray alive) { while (node is interior) traverse one node;
//                                      while (leaf has untested triangles) test one triangle; }`
//    A lane that reaches a leaf waits until every lane has left the traversal loop.
//  - if-if: `while (ray alive) { if (node is interior) traverse one node;
//                                if (in a leaf) test one triangle; }`
// Refill (`SimtRefill`): `lanes` replaces each finished lane's ray at the top of every outer
// iteration (A&L's Fermi/Kepler kernels, 2012 addendum: ballot + popc + one atomicAdd per warp);
// `warp` fetches a new batch of rays only when all lanes have finished (A&L 2009 §4 persistent
// threads). `lanes < 32` lets only that many lanes ever hold rays (thesis Table 13's O).
//
// Not modelled: A&L's speculative traversal and leaf postponing (§5), the shared-memory stack
// top, instruction-level detail inside a step (a step is one unit; the throughput model in
// simt_model.h gives it a cost). Hits equal bvh_single's on the same BVH (same slab and triangle
// kernels, traversal/kernels.h); the order of the tests differs.
//
// The executor reports memory operations and steps to an observer policy, as traversal/probe.h
// does for the CPU schemes: NullWarpObserver compiles to nothing (the scheme's timed path),
// LineObserver collects the distinct 128-byte lines of each step (coalescing) and counts.
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "structures/gpu_bvh.h"
#include "traversal/bvh_common.h"
#include "traversal/kernels.h"

namespace tb {

inline constexpr uint32_t kWarpSize = 32;  // threads per warp on every NVIDIA GPU (CUDA C Programming Guide 3.2, §4.1)
// Fermi's global-memory transaction unit: the loads of a warp are served in as many transactions
// as there are distinct 128-byte L1 lines among the addresses its active threads touch (CUDA C
// Programming Guide 3.2, §G.4.2, compute capability 2.x "cached" loads).
inline constexpr uint32_t kGpuLineBytes = 128;

enum class SimtLoop : uint8_t { while_while, if_if };
enum class SimtRefill : uint8_t { lanes, warp };
enum class StepKind : uint8_t { traverse = 0, intersect = 1, done = 2 };

struct SimtOptions {
  SimtLoop loop = SimtLoop::while_while;
  SimtRefill refill = SimtRefill::lanes;
  uint32_t lanes = kWarpSize;  // lanes that ever hold a ray (1..32; Table 13's O)
};

// Rays [next, end) of a batch, handed out in order: A&L's global ray counter shared by all warps.
struct RayPool {
  uint32_t next = 0, end = 0;
  bool empty() const { return next >= end; }
};

// Per-step observer that does nothing: the timed path.
struct NullWarpObserver {
  static constexpr bool enabled = false;
  void node(const void*, uint32_t) {}
  void tri(const void*, uint32_t) {}
  void ray(const void*, uint32_t) {}
  void store(const void*, uint32_t) {}
  void step(StepKind, uint32_t /*active lanes*/) {}
};

// Warp counters of a run (summed over warps).
struct WarpCounters {
  uint64_t steps[2] = {0, 0};       // issued steps by kind (traverse, intersect)
  uint64_t lane_steps[2] = {0, 0};  // active lanes summed over those steps
  uint64_t load_lines = 0;          // distinct 128-byte lines loaded, summed over steps (transactions)
  uint64_t load_requests = 0;       // lane loads (node, triangle, ray), before coalescing
  uint64_t store_lines = 0;         // distinct lines stored (hits)
  uint64_t rays = 0;
  uint64_t total_steps() const { return steps[0] + steps[1]; }
  // Active lane-steps / (32 x steps): A&L's SIMD efficiency, the thesis' utilization.
  double efficiency() const {
    const uint64_t s = total_steps();
    return s ? double(lane_steps[0] + lane_steps[1]) / (double(kWarpSize) * double(s)) : 0.0;
  }
  void add(const WarpCounters& o) {
    for (int k = 0; k < 2; ++k) steps[k] += o.steps[k], lane_steps[k] += o.lane_steps[k];
    load_lines += o.load_lines, load_requests += o.load_requests, store_lines += o.store_lines, rays += o.rays;
  }
};

// Collects the distinct lines of the current step (loads and stores apart) and counts every
// step. The caller reads lines()/store_lines() after Warp::step() and calls clear() before the
// next step.
class LineObserver {
 public:
  static constexpr bool enabled = true;
  WarpCounters counters;

  void node(const void* p, uint32_t bytes) { load(p, bytes); }
  void tri(const void* p, uint32_t bytes) { load(p, bytes); }
  void ray(const void* p, uint32_t bytes) { load(p, bytes), counters.rays++; }
  void store(const void* p, uint32_t bytes) { add_lines(stores_, p, bytes); }
  void step(StepKind k, uint32_t active) {
    counters.steps[int(k)]++;
    counters.lane_steps[int(k)] += active;
  }
  // Ends the step: its distinct lines join the counters. Called once per step, after step().
  void clear() {
    counters.load_lines += loads_.size();
    counters.store_lines += stores_.size();
    loads_.clear(), stores_.clear();
  }
  std::span<const uint64_t> lines() const { return loads_; }
  std::span<const uint64_t> store_lines() const { return stores_; }
  // Maps the host array [base, base + bytes) to its own 128-byte-aligned region of a virtual GPU
  // address space, so lines (coalescing, cache sets) do not depend on where the host allocator put
  // it and runs are reproducible. Addresses outside every region are used as they are.
  void add_region(const void* base, size_t bytes) {
    const uint64_t vbase = (uint64_t(regions_.size()) + 1) << 40;
    regions_.push_back({reinterpret_cast<uintptr_t>(base), bytes, vbase});
  }

 private:
  struct Region {
    uint64_t base, bytes, vbase;
  };
  uint64_t address(const void* p) const {
    const uint64_t a = reinterpret_cast<uintptr_t>(p);
    for (const Region& r : regions_)
      if (a - r.base < r.bytes) return r.vbase + (a - r.base);
    return a;
  }
  void load(const void* p, uint32_t bytes) {
    counters.load_requests++;
    add_lines(loads_, p, bytes);
  }
  // Line addresses (byte address / 128) of [p, p + bytes), each once per step.
  void add_lines(std::vector<uint64_t>& v, const void* p, uint32_t bytes) const {
    const uint64_t a = address(p);
    for (uint64_t l = a / kGpuLineBytes; l <= (a + bytes - 1) / kGpuLineBytes; ++l)
      if (std::find(v.begin(), v.end(), l) == v.end()) v.push_back(l);
  }
  std::vector<uint64_t> loads_, stores_;
  std::vector<Region> regions_;
};

// One warp. step() issues exactly one step (at least one active lane) and returns its kind, or
// StepKind::done once every lane has finished and the pool is empty. Hits go to hits[ray index].
template <TriKernel K, class Obs>
class Warp {
 public:
  Warp(const GPUBVH& bvh, const TriangleSet& tris, const RayBatch& batch, std::span<Hit> hits, RayPool& pool,
       const SimtOptions& opt, Obs& obs)
      : nodes_(bvh.nodes.data()), tris_(tris), batch_(batch), hits_(hits), pool_(pool), opt_(opt), obs_(obs),
        depth_(bvh.max_depth + 2), stack_(size_t(kWarpSize) * depth_) {}

  StepKind step() {
    for (;;) {
      if (phase_ == Phase::top) {
        if (!refill()) return StepKind::done;
        phase_ = Phase::traverse;
      }
      if (phase_ == Phase::traverse) {
        // while-while stays in the traversal loop while any lane is at an interior node; if-if
        // runs the traversal body once per outer iteration.
        const uint32_t m = mask_interior();
        if (opt_.loop == SimtLoop::if_if) phase_ = Phase::intersect;
        if (m) return issue(StepKind::traverse, m);
        phase_ = Phase::intersect;
      }
      const uint32_t m = mask_leaf();
      if (opt_.loop == SimtLoop::if_if) phase_ = Phase::top;
      if (m) return issue(StepKind::intersect, m);
      phase_ = Phase::top;
    }
  }

 private:
  enum class Phase : uint8_t { top, traverse, intersect };
  struct Lane {
    bool alive = false;
    uint32_t ray = 0;
    GPUChild cur;            // the node being traversed or the leaf being intersected
    uint32_t tri = 0;        // next triangle of the current leaf
    uint32_t sp = 0;         // stack depth
    float tmin = 0.f;
    Hit hit;
    RayCtx rc{Ray{}};
  };

  uint32_t mask_interior() const {
    uint32_t m = 0;
    for (uint32_t l = 0; l < opt_.lanes; ++l) m |= uint32_t(lanes_[l].alive && !lanes_[l].cur.is_leaf()) << l;
    return m;
  }
  uint32_t mask_leaf() const {
    uint32_t m = 0;
    for (uint32_t l = 0; l < opt_.lanes; ++l) m |= uint32_t(lanes_[l].alive && lanes_[l].cur.is_leaf()) << l;
    return m;
  }

  StepKind issue(StepKind k, uint32_t m) {
    obs_.step(k, uint32_t(std::popcount(m)));
    for (uint32_t mm = m; mm; mm &= mm - 1) {
      const uint32_t l = uint32_t(std::countr_zero(mm));
      if (k == StepKind::traverse) traverse(l);
      else intersect(l);
    }
    return k;
  }

  // The top of the outer loop: finished lanes fetch rays. False when no lane holds a ray.
  bool refill() {
    bool any_alive = false;
    for (uint32_t l = 0; l < opt_.lanes; ++l) any_alive |= lanes_[l].alive;
    if (opt_.refill == SimtRefill::lanes || !any_alive)
      for (uint32_t l = 0; l < opt_.lanes && !pool_.empty(); ++l)
        if (!lanes_[l].alive) start(l, pool_.next++), any_alive = true;
    return any_alive;
  }

  void start(uint32_t l, uint32_t ray) {
    Lane& s = lanes_[l];
    const Ray& r = batch_.rays[ray];
    obs_.ray(&r, sizeof(Ray));
    s.alive = true, s.ray = ray, s.cur = {0, 0}, s.sp = 0, s.tmin = r.tmin;
    s.hit = initial_hit(r);
    s.rc = RayCtx(r);
  }

  void enter(Lane& s, GPUChild c) {
    s.cur = c;
    if (c.is_leaf()) s.tri = c.index;
  }
  void pop(Lane& s, uint32_t l) {
    if (s.sp == 0) {  // traversal done: write the hit, the lane is free for a new ray
      hits_[s.ray] = finish_hit(s.hit);
      obs_.store(&hits_[s.ray], sizeof(Hit));
      s.alive = false;
      return;
    }
    enter(s, stack_[size_t(l) * depth_ + --s.sp]);
  }

  // One node: test both children (A&L's node test), go to the nearer hit child and push the
  // other, or pop when neither is hit.
  void traverse(uint32_t l) {
    Lane& s = lanes_[l];
    const GPUNode& n = nodes_[s.cur.index];
    obs_.node(&n, sizeof(GPUNode));
    const float d0 = box_entry(s.rc, n.lo[0], n.hi[0], s.tmin, s.hit.t);
    const float d1 = box_entry(s.rc, n.lo[1], n.hi[1], s.tmin, s.hit.t);
    if (d0 == INFINITY && d1 == INFINITY) return pop(s, l);
    if (d1 == INFINITY) return enter(s, n.child[0]);
    if (d0 == INFINITY) return enter(s, n.child[1]);
    const int near = d1 < d0;
    stack_[size_t(l) * depth_ + s.sp++] = n.child[1 - near];
    enter(s, n.child[near]);
  }

  // One triangle of the current leaf; the leaf's last one pops.
  void intersect(uint32_t l) {
    Lane& s = lanes_[l];
    obs_.tri(tris_.data_at(s.tri, K), TriangleSet::bytes(K));
    intersect_tri<K>(s.rc, tris_, s.tri, s.tmin, s.hit);
    if (++s.tri == s.cur.index + s.cur.count) pop(s, l);
  }

  const GPUNode* nodes_;
  const TriangleSet& tris_;
  const RayBatch& batch_;
  std::span<Hit> hits_;
  RayPool& pool_;
  SimtOptions opt_;
  Obs& obs_;
  uint32_t depth_;
  std::vector<GPUChild> stack_;  // lane l's stack: [l * depth_, (l + 1) * depth_)
  Lane lanes_[kWarpSize];
  Phase phase_ = Phase::top;
};

// Runs one warp over the whole pool with a LineObserver and returns its counters (tests, tools).
template <TriKernel K>
WarpCounters run_one_warp(const GPUBVH& bvh, const TriangleSet& tris, const RayBatch& batch, std::span<Hit> hits,
                          RayPool pool, const SimtOptions& opt) {
  LineObserver obs;
  Warp<K, LineObserver> w(bvh, tris, batch, hits, pool, opt, obs);
  while (w.step() != StepKind::done) obs.clear();
  obs.clear();
  return obs.counters;
}

}  // namespace tb
