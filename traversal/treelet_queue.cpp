// treelet_queue: ray reordering by treelets (Aila & Karras 2010, "Architecture considerations for
// tracing incoherent rays"; CS348K lecture 18: "partition BVH into treelets sized for L1 or L2
// cache; when a ray enters a treelet, add it to the treelet's queue; intersect all enqueued rays
// with the treelet, amortising its load").
//
// The structure is mbvh8_single's cached MBVH8 (same build parameters and defaults), cut into
// treelets of at most `treelet_bytes` (structures/treelet.h). A pool of `rays_in_flight` rays
// each keeps its whole traversal state — the pending stack of (reference, entry distance), the
// reference it visits next, its closest hit so far — in memory while it waits. Every ray starts
// in the root's queue; the scheduler repeatedly takes the fullest queue and runs each of its rays
// with mbvh8_single's loop (mbvh_traverse_from: box_test, the bitonic child order, block_intersect)
// until the next reference it would visit lies in another treelet; the ray then goes to that
// treelet's queue. A finished ray frees its slot for the next ray of the call. Because a ray is
// only suspended between two visits and resumes with the same stack, it visits exactly the nodes
// and leaves mbvh8_single visits, in the same order: its hits are bit-identical (tested).
//
// Statistics (`run --stats`, from the instrumented traces): treelet_rays_per_visit (rays run per
// queue taken), treelet_queues_nonempty (non-empty queues when the scheduler takes one),
// treelet_queue_rays (rays waiting per non-empty queue then), treelet_switches_per_ray (times a
// ray moved to another treelet's queue), treelets (how many the tree was cut into).
#include <atomic>
#include <memory>
#include <queue>

#include "structures/treelet.h"
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"

namespace tb {
namespace {

class TreeletQueue final : public TraverserBase<TreeletQueue> {
 public:
  explicit TreeletQueue(const SchemeConfig& cfg)
      : params_(mbvh_params(cfg, kMBVH8Defaults)),
        budget_(size_t(cfg.get_int("treelet_bytes"))),
        flight_(uint32_t(cfg.get_int("rays_in_flight"))) {}
  std::string_view name() const override { return "treelet_queue"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    data_ = fetch_mbvh<8, 8>(scene, cache, params_, TriKernel::watertight);
    tl_ = cache.get<Treelets>(params_.key(8, 8) + ":treelets:" + std::to_string(budget_),
                              [&] { return Treelets::partition(*data_.mbvh, budget_); });
  }
  std::string structure_info() const override {
    return data_.mbvh->stats.describe() + " " + tl_->stats.describe();
  }
  // The MBVH8's nodes plus the treelet map the scheduler reads; its triangle blocks.
  StructureBytes memory() const override {
    return {data_.mbvh->stats.node_bytes + tl_->map_bytes(), mbvh_prim_bytes(data_, TriKernel::watertight)};
  }
  // Queues fill from the rays of one call (as RayGrid's).
  uint32_t preferred_chunk_rays() const override { return 65536; }
  std::vector<StatColumn> take_stat_columns() const override {
    const double visits = double(std::max<uint64_t>(1, visits_.exchange(0)));
    const double nonempty = double(nonempty_.exchange(0)), waiting = double(waiting_.exchange(0));
    const double rays = double(std::max<uint64_t>(1, rays_.exchange(0)));
    return {{"treelet_rays_per_visit", double(run_rays_.exchange(0)) / visits},
            {"treelet_queues_nonempty", nonempty / visits},
            {"treelet_queue_rays", nonempty > 0 ? waiting / nonempty : 0.0},
            {"treelet_switches_per_ray", double(switches_.exchange(0)) / rays},
            {"treelets", double(tl_->count())}};
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const MBVH<8, 8>& m = *data_.mbvh;
    const Treelets& tl = *tl_;
    const uint32_t end = batch.packet_begin[range.last];
    uint32_t next = batch.packet_begin[range.first];
    if (next >= end) return;
    const uint32_t flight = std::min(flight_, end - next);
    const size_t cap = size_t(7) * m.stats.max_depth + 10;  // mbvh_traverse's bound for N = 8
    // The waiting rays' state, one cache line per ray: a copy of the ray (a resumed ray reads no
    // second line from the batch), where it resumes, its index and closest hit. Stacks apart,
    // uninitialised (only the used part is ever touched).
    struct alignas(64) Slot {
      Ray r;
      MBVHCursor at;
      uint32_t ray;
      Hit hit;
    };
    static_assert(sizeof(Slot) == 64);
    std::vector<Slot> slots(flight);
    std::unique_ptr<MBVHStackEntry[]> stacks(new MBVHStackEntry[flight * cap]);
    std::vector<std::vector<uint32_t>> queues(tl.count());
    // The scheduler's max-heap of (queue size, treelet), one entry per enqueue: an entry is current
    // when the queue still has that size, and every queue has a current entry, so the first current
    // entry on top is a fullest queue; stale ones are skipped.
    std::priority_queue<std::pair<uint32_t, uint32_t>> heap;
    uint64_t nonempty = 0, waiting = 0;  // live: non-empty queues, rays queued
    uint64_t st_visits = 0, st_run = 0, st_nonempty = 0, st_waiting = 0, st_switches = 0, st_rays = 0;
    auto enqueue = [&](uint32_t slot, uint32_t t) {
      auto& q = queues[t];
      if (q.empty()) ++nonempty;
      q.push_back(slot);
      probe.write(&q.back(), sizeof(uint32_t));
      ++waiting;
      heap.push({uint32_t(q.size()), t});
    };
    auto start = [&](uint32_t slot) {
      const uint32_t i = next++;
      const Ray& ray = batch.rays[i];
      probe.read(&ray, sizeof(Ray));
      if constexpr (P::enabled) {
        if (probe.counts) probe.counts->rays++;
        ++st_rays;
      }
      slots[slot] = {ray, {0, 0}, i, initial_hit(ray)};
      probe.write(&slots[slot], sizeof(Slot));
      enqueue(slot, tl.of(0));
    };
    for (uint32_t s = 0; s < flight; ++s) start(s);
    std::vector<uint32_t> work;
    while (!heap.empty()) {
      const uint32_t size = heap.top().first, t = heap.top().second;
      heap.pop();
      if (queues[t].size() != size) continue;
      if constexpr (P::enabled) ++st_visits, st_run += size, st_nonempty += nonempty, st_waiting += waiting;
      work.clear();
      work.swap(queues[t]);
      --nonempty, waiting -= size;
      for (const uint32_t& slot : work) {
        probe.read(&slot, sizeof(uint32_t));
        Slot& s = slots[slot];
        probe.read(&s, sizeof(Slot));
        const Ray& ray = s.r;
        const RayCtx rc(ray);
        const bool done = mbvh_traverse_from<8, 8, TriKernel::watertight, ChildOrder::sort_always>(
            m, nullptr, NodeRay<8>(rc, ray.tmin), TriRay<8>(rc, ray.tmin), &rc, s.at, s.hit, &stacks[slot * cap], probe,
            [&](uint32_t ref) {
              const uint32_t& e = tl.entry(ref);
              probe.read(&e, sizeof(uint32_t));
              return e != t;
            });
        probe.write(&s, sizeof(Slot));
        if (done) {
          hits[s.ray] = finish_hit(s.hit);
          probe.write(&hits[s.ray], sizeof(Hit));
          if (next < end) start(slot);
        } else {
          if constexpr (P::enabled) ++st_switches;
          enqueue(slot, tl.of(s.at.cur));
        }
      }
    }
    if constexpr (P::enabled) {
      visits_ += st_visits, run_rays_ += st_run, nonempty_ += st_nonempty, waiting_ += st_waiting;
      switches_ += st_switches, rays_ += st_rays;
    }
  }

 private:
  MBVHBuildParams params_;
  size_t budget_;
  uint32_t flight_;
  MBVHData<8, 8> data_;
  std::shared_ptr<const Treelets> tl_;
  mutable std::atomic<uint64_t> visits_{0}, run_rays_{0}, nonempty_{0}, waiting_{0}, switches_{0}, rays_{0};
};

}  // namespace

std::unique_ptr<Traverser> make_treelet_queue(const SchemeConfig& cfg) { return std::make_unique<TreeletQueue>(cfg); }
ParamSpecs params_treelet_queue() {
  return mbvh_param_specs(kMBVH8Defaults) +
         ParamSpecs{int_param("treelet_bytes", 262144, 256, 1 << 30,
                              "treelet byte budget (nodes + their leaves' blocks): 262144 = a 256 KiB L2; 32768 for L1"),
                    int_param("rays_in_flight", 8192, 1, 1 << 20,
                              "rays whose traversal state waits in the queues at once (the ray pool)")};
}

}  // namespace tb
