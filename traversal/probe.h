// Instrumentation as a compile-time policy (DESIGN.md): every kernel is a template on a probe.
// NullProbe compiles to nothing, so the timed path pays nothing; Probe counts visits and tests
// (thesis Table 8/10 "rays per visited node") and can feed a cache simulator.
#pragma once
#include <cstdint>

namespace tb {
namespace cachesim { class Hierarchy; }

struct TraversalCounts {
  uint64_t rays = 0;             // rays traced
  uint64_t node_visits = 0;      // interior node visits (a packet or stream visit counts once)
  uint64_t node_ray_visits = 0;  // sum over interior visits of the active rays at that visit
  uint64_t leaf_visits = 0;
  uint64_t leaf_ray_visits = 0;
  // Sum over visits of the rays the scheme iterates over there: the range [first, last] of ranged
  // traversal, which also holds rays that miss the node; equal to the *_ray_visits elsewhere.
  uint64_t node_range_visits = 0, leaf_range_visits = 0;
  uint64_t tri_tests = 0;        // ray-triangle tests (per ray-triangle pair)
  uint64_t node_bytes = 0;       // bytes the interior node visits read (a visit reads its node once)
  void add(const TraversalCounts& o) {
    rays += o.rays; node_visits += o.node_visits; node_ray_visits += o.node_ray_visits; node_bytes += o.node_bytes;
    leaf_visits += o.leaf_visits; leaf_ray_visits += o.leaf_ray_visits; tri_tests += o.tri_tests;
    node_range_visits += o.node_range_visits; leaf_range_visits += o.leaf_range_visits;
  }
};

struct NullProbe {
  static constexpr bool enabled = false;
  void node(const void*, uint32_t, uint32_t = 1) {}
  void leaf(const void*, uint32_t, uint32_t = 1) {}
  void node_range(const void*, uint32_t, uint32_t, uint32_t) {}
  void leaf_range(const void*, uint32_t, uint32_t, uint32_t) {}
  void tris(const void*, uint32_t, uint32_t = 1) {}
  void read(const void*, uint32_t) {}
  void write(const void*, uint32_t) {}
};

// The instrumented path's probe. Either sink may be null.
class Probe {
 public:
  static constexpr bool enabled = true;
  TraversalCounts* counts = nullptr;
  cachesim::Hierarchy* cache = nullptr;

  // An interior node of `bytes` bytes at `p` visited by `active` rays at once.
  void node(const void* p, uint32_t bytes, uint32_t active = 1) { node_range(p, bytes, active, active); }
  void leaf(const void* p, uint32_t bytes, uint32_t active = 1) { leaf_range(p, bytes, active, active); }
  // The same when the scheme iterates over `range` rays of which `active` intersect the node
  // (ranged traversal: thesis Table 8 counts the rays that intersect, §5.2.3).
  void node_range(const void* p, uint32_t bytes, uint32_t active, uint32_t range) {
    if (counts) {
      counts->node_visits++; counts->node_ray_visits += active; counts->node_range_visits += range;
      counts->node_bytes += bytes;
    }
    if (cache) read(p, bytes);
  }
  void leaf_range(const void* p, uint32_t bytes, uint32_t active, uint32_t range) {
    if (counts) { counts->leaf_visits++; counts->leaf_ray_visits += active; counts->leaf_range_visits += range; }
    if (cache) read(p, bytes);
  }
  // Triangle data of `bytes` bytes read and tested against `tests` rays.
  void tris(const void* p, uint32_t bytes, uint32_t tests = 1) {
    if (counts) counts->tri_tests += tests;
    if (cache) read(p, bytes);
  }
  void read(const void* p, uint32_t bytes);   // rays, hits, stacks, queues
  void write(const void* p, uint32_t bytes);
};

}  // namespace tb
