// The interface every traversal scheme implements (DESIGN.md core types). A new scheme is one
// file plus one line: the file derives from TraverserBase and defines
//   std::unique_ptr<Traverser> make_<name>(const SchemeConfig&);  // reads only declared parameters
//   ParamSpecs params_<name>();                                     // what --param keys it takes
// and the line `TB_SCHEME(<name>, "description", honours --kernel, baseline)` goes in
// traversal/schemes.def (registry.cpp expands it; tests/test_schemes.cpp checks that name()
// returns <name> and that every declared default is valid). README "Adding a scheme".
#pragma once
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "structures/scene.h"
#include "structures/structure_cache.h"
#include "traversal/kernels.h"
#include "traversal/params.h"
#include "traversal/probe.h"
#include "workloads/ray_batch.h"

namespace tb {

class RayOrder;  // traversal/ray_order.h

// Per-scheme options: the triangle kernel (--kernel) and parameters (--param k=v), e.g.
// `leaf_size=4`, `stream=512`, `queue=384`. As the user gives them, `params` holds text;
// make_scheme (traversal/registry.h) checks every key and value against the scheme's declared
// ParamSpecs and hands the scheme a resolved copy: `declared` set, defaults filled in. The getters
// read that copy; reading a parameter the scheme did not declare is a programming error
// (std::logic_error), which tests/test_schemes.cpp catches by making every scheme.
struct SchemeConfig {
  TriKernel kernel = TriKernel::watertight;
  std::map<std::string, std::string> params;
  const ParamSpecs* declared = nullptr;

  int get_int(const std::string& key) const;
  bool get_bool(const std::string& key) const;
  double get_real(const std::string& key) const;
  const std::string& get_choice(const std::string& key) const;
  // For parameters whose default depends on others (ParamSpec::fallback empty): nullopt when not given.
  std::optional<int> find_int(const std::string& key) const;
  std::optional<std::string> find_choice(const std::string& key) const;
  std::optional<bool> find_bool(const std::string& key) const;
  // Whether the user set `key` to something other than its declared default (a parameter without
  // a fixed default: whether it was given at all). For refusing a parameter that changes nothing
  // under the values of the others: every option either works or is refused.
  bool changed(const std::string& key) const;
  // Throws InputError "parameter 'KEY' ...WHY" when `key` was changed (see changed()).
  void refuse_if_changed(const std::string& key, const std::string& why) const;

 private:
  const std::string* value(const std::string& key) const;
};

// Bytes of a scheme's structure, split as a traversal reads them (`run --stats` columns node_bytes
// and prim_bytes): `nodes` the tree (interior nodes, leaf records and reference lists), `prims`
// the triangle data its leaves test (leaf-ordered triangle sets, SIMD triangle blocks).
struct StructureBytes {
  size_t nodes = 0, prims = 0;
  size_t total() const { return nodes + prims; }
};

// A named statistic a scheme adds to `run --stats` rows (treelet_queue's queue statistics).
struct StatColumn {
  std::string name;
  double value;
};

class Traverser {
 public:
  virtual ~Traverser() = default;
  virtual std::string_view name() const = 0;
  // Builds or fetches the scheme's structure. Not timed as trace time.
  virtual void prepare(const Scene& scene, StructureCache& cache) = 0;
  // The timed path: packets [range.first, range.last) of `batch`; hits[i] belongs to batch.rays[i].
  // Must be safe to call concurrently on disjoint ranges.
  virtual void trace(const RayBatch& batch, PacketRange range, std::span<Hit> hits) const = 0;
  // The instrumented path: same result, with counters and/or cache simulation.
  virtual void trace(const RayBatch& batch, PacketRange range, std::span<Hit> hits, Probe& probe) const = 0;
  // One line describing the built structure (nodes, bytes, ...), for logs and the build table.
  virtual std::string structure_info() const { return {}; }
  // Bytes of the scheme's acceleration structure and triangle data (Embree: from its memory monitor).
  virtual StructureBytes memory() const { return {}; }
  size_t structure_bytes() const { return memory().total(); }
  // Scheme-specific statistics gathered by the instrumented traces since the last call (which
  // resets them); `run --stats` appends them to the row. Most schemes have none.
  virtual std::vector<StatColumn> take_stat_columns() const { return {}; }
  // Rays per trace() call below which the scheme loses efficiency (batch schemes that queue rays
  // by region need many rays per call); multi-threaded runs hand out chunks of at least this size
  // while keeping every thread busy. 0: any chunk size is fine.
  virtual uint32_t preferred_chunk_rays() const { return 0; }
  // The order a scheme traces `batch`'s rays in when it reorders a batch before forming its work
  // (mbvh_rs's sort of incoherent rays by origin, traversal/ray_order.h), for multi-threaded
  // traces: harness/trace_runner.h's trace_batch asks once per batch, inside the timed trace,
  // gathers the rays into that order (a batch with `ordered` set, which the scheme does not
  // reorder again), hands the threads chunks of it and scatters the hits back; so the order does
  // not depend on how the batch is cut among threads. False (the default): the batch's own order,
  // or the scheme orders within each call. A single-threaded trace makes one call, in which a
  // scheme may order the whole batch itself.
  virtual bool batch_order(const RayBatch& batch, RayOrder& order) const { return false; }
};

// Implements both trace entry points with one template: Derived provides
//   template <class P> void run(const RayBatch&, PacketRange, std::span<Hit>, P& probe) const;
template <class Derived>
class TraverserBase : public Traverser {
 public:
  void trace(const RayBatch& b, PacketRange r, std::span<Hit> h) const final {
    NullProbe p;
    static_cast<const Derived&>(*this).run(b, r, h, p);
  }
  void trace(const RayBatch& b, PacketRange r, std::span<Hit> h, Probe& p) const final {
    static_cast<const Derived&>(*this).run(b, r, h, p);
  }
};

// Seeds a hit record: the search interval is [ray.tmin, ray.tmax).
inline Hit initial_hit(const Ray& r) { return Hit{r.tmax, kNoHit, 0.f, 0.f}; }
// Turns a search record into the reported hit: misses carry t = +inf.
inline Hit finish_hit(Hit h) {
  if (h.prim == kNoHit) h.t = INFINITY;
  return h;
}

// The per-ray loop of every single-ray scheme: each ray of the packets in `range` is read
// (probe), counted, and handed to `trace(ray, hit)` with `hit` seeded by initial_hit; the finished
// hit is written to hits[i]. Inlined, so the timed path pays nothing for the lambda.
template <class P, class F>
[[gnu::always_inline]] inline void for_each_ray(const RayBatch& batch, PacketRange range, std::span<Hit> hits,
                                                P& probe, F&& trace) {
  for (uint32_t i = batch.packet_begin[range.first]; i < batch.packet_begin[range.last]; ++i) {
    const Ray& ray = batch.rays[i];
    probe.read(&ray, sizeof(Ray));
    if constexpr (P::enabled)
      if (probe.counts) probe.counts->rays++;
    Hit hit = initial_hit(ray);
    trace(ray, hit);
    hits[i] = finish_hit(hit);
    probe.write(&hits[i], sizeof(Hit));
  }
}

// A traverser as the closest-hit function that workload generation takes (workloads/workload.h).
inline auto closest_hits_of(const Traverser& t) {
  return [&t](const RayBatch& b, std::span<Hit> hits) { t.trace(b, PacketRange::all(b), hits); };
}

}  // namespace tb
