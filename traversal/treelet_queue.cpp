// treelet_queue: ray reordering by treelets (Aila & Karras 2010, "Architecture considerations for
// tracing incoherent rays"; CS348K lecture 18: "partition BVH into treelets sized for L1 or L2
// cache; when a ray enters a treelet, add it to the treelet's queue; intersect all enqueued rays
// with the treelet, amortising its load").
//
// The structure (`tree`) is cwbvh_single's compressed BVH (structures/cwbvh.h, its defaults: 4% of
// the nodes uncompressed, indexed leaves) or mbvh8_single's MBVH8, built with mbvh8_single's
// parameters and defaults, and cut into treelets of at most `treelet_bytes` of that tree's own
// bytes (structures/treelet.h). A pool of `rays_in_flight` rays
// each keeps its whole traversal state — the pending stack of (reference, entry distance), the
// reference it visits next, its closest hit so far — in memory while it waits. The scheduler
// repeatedly takes the fullest queue and runs each of its rays with the single-ray loop of that
// tree's scheme (cw_traverse_from with CWOrder::sort, or mbvh_traverse_from with the bitonic child
// order) until the next node it would visit lies in another treelet; the ray then goes to that
// treelet's queue. A leaf is tested where the ray is (see run_ray). The default is the compressed
// tree, both answers of the lecture together: on bounce:2 of spheres:2M at 1024x1024 it reads
// 0.39x mbvh8_single's memory lines where the MBVH8's treelets read 0.50x (node bytes 0.34x,
// triangle bytes 0.63x, so a budget holds more of the tree); `tree=mbvh8` isolates the
// reordering (the same visits as mbvh8_single). docs/PERFORMANCE.md, session 33.
// Rays not yet started count towards the root treelet's queue (up to the free slots) and start
// there, from the batch, when it is visited; a finished ray frees its slot for the next one. The
// default pool holds a whole 262144-ray chunk and the default treelet 128 KiB (half the simulated
// 256 KiB L2, which the treelet shares with the lines of the rays it runs): on the compressed tree
// (bounce:2, reads per ray against mbvh8_single's) they give spheres:500k at 2048x2048 0.44x and
// spheres:2M at 1024x1024 0.39x, where 256 KiB and 131072 rays gave 0.51x and 0.44x, at the cost
// of crytek_sponza_partial 512x512 (0.81x against 0.73x; its rays stay in the room they bounce in,
// and no setting reaches 0.5x there). On the MBVH8's treelets 8192 rays had read 8.4 lines per
// ray on crytek, 65536 6.5 (docs/PERFORMANCE.md, Bandwidth; session 33 for the rest).
// Because a ray is only suspended between two visits and resumes with the same stack, it visits
// exactly the nodes and leaves cwbvh_single (mbvh8_single) visits with `order=sort` (their order
// for all but common-origin batches), in the same order: its hits are bit-identical (tested).
//
// Statistics (`run --stats`, from the instrumented traces): treelet_rays_per_visit (rays run per
// queue taken), treelet_queues_nonempty (non-empty queues when the scheduler takes one),
// treelet_queue_rays (rays waiting per non-empty queue then), treelet_switches_per_ray (times a
// ray moved to another treelet's queue), treelets (how many the tree was cut into); with --cache
// also where the simulated memory reads go, per ray: treelet_mem_slots and treelet_mem_stacks (the
// suspended rays' state), treelet_mem_nodes, treelet_mem_tris (the tree's node and triangle-block arrays) and
// treelet_mem_other (the ray batch, the queues, the treelet map), summing to mem_read_m.
#include <atomic>
#include <memory>
#include <queue>

#include "structures/treelet.h"
#include "traversal/cwbvh_traverse.h"
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"

#include "cachesim/hierarchy.h"

namespace tb {
namespace {

// The cache probe of one traced call with its simulated memory reads split by the array an access
// falls in (the SplitProbe::Part ranges); forwards everything to the harness' Probe.
struct SplitProbe {
  static constexpr bool enabled = true;
  enum Part { state_slots, state_stacks, node_array, full_array, block_array, small_array, parts };
  Probe& p;
  TraversalCounts* counts = p.counts;
  const char* lo[parts] = {};
  const char* hi[parts] = {};
  uint64_t reads[parts + 1] = {};  // the last: anything else
  template <class T>
  void range(Part k, const T* first, size_t n) {
    lo[k] = reinterpret_cast<const char*>(first), hi[k] = reinterpret_cast<const char*>(first + n);
  }
  template <class F>
  void split(const void* a, F&& f) {
    const uint64_t before = p.cache->memory_reads();
    f();
    const char* c = static_cast<const char*>(a);
    int k = 0;
    while (k < parts && !(c >= lo[k] && c < hi[k])) ++k;
    reads[k] += p.cache->memory_reads() - before;
  }
  void node(const void* a, uint32_t b, uint32_t n = 1) { split(a, [&] { p.node(a, b, n); }); }
  void leaf(const void* a, uint32_t b, uint32_t n = 1) { split(a, [&] { p.leaf(a, b, n); }); }
  void tris(const void* a, uint32_t b, uint32_t n = 1) { split(a, [&] { p.tris(a, b, n); }); }
  void read(const void* a, uint32_t b) { split(a, [&] { p.read(a, b); }); }
  void write(const void* a, uint32_t b) { split(a, [&] { p.write(a, b); }); }
};

class TreeletQueue final : public TraverserBase<TreeletQueue> {
 public:
  explicit TreeletQueue(const SchemeConfig& cfg)
      : params_(mbvh_params(cfg, kMBVH8Defaults)),
        budget_(size_t(cfg.get_int("treelet_bytes"))),
        flight_(uint32_t(cfg.get_int("rays_in_flight"))),
        compressed_(cfg.get_choice("tree") == "cwbvh") {
    if (compressed_) check_cwbvh_params(params_, "tree=cwbvh: ");
  }
  std::string_view name() const override { return "treelet_queue"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    const std::string budget = std::to_string(budget_);
    if (compressed_) {
      cw_ = fetch_cwbvh(scene, cache, params_, kCWFullTop, CWSlots::mbvh, CWLeaves::indexed);
      tl_ = cache.get<Treelets>(params_.key(8, 8) + ":cwbvh_treelets:" + budget, [&] { return Treelets::partition(*cw_, budget_); });
    } else {
      data_ = fetch_mbvh<8, 8>(scene, cache, params_, TriKernel::watertight);
      tl_ = cache.get<Treelets>(params_.key(8, 8) + ":treelets:" + budget, [&] { return Treelets::partition(*data_.mbvh, budget_); });
    }
  }
  std::string structure_info() const override {
    return (compressed_ ? cw_->stats.describe() : data_.mbvh->stats.describe()) + " " + tl_->stats.describe();
  }
  // The tree's nodes plus the treelet map the scheduler reads; its triangle blocks.
  StructureBytes memory() const override {
    if (compressed_) return {cw_->stats.node_bytes + tl_->map_bytes(), cw_->stats.tri_bytes};
    return {data_.mbvh->stats.node_bytes + tl_->map_bytes(), mbvh_prim_bytes(data_, TriKernel::watertight)};
  }
  // Queues fill from the rays of one call (as RayGrid's).
  uint32_t preferred_chunk_rays() const override { return std::max<uint32_t>(65536, flight_); }
  std::vector<StatColumn> take_stat_columns() const override {
    const double visits = double(std::max<uint64_t>(1, visits_.exchange(0)));
    const double nonempty = double(nonempty_.exchange(0)), waiting = double(waiting_.exchange(0));
    const double rays = double(std::max<uint64_t>(1, rays_.exchange(0)));
    std::vector<StatColumn> cols = {{"treelet_rays_per_visit", double(run_rays_.exchange(0)) / visits},
            {"treelet_queues_nonempty", nonempty / visits},
            {"treelet_queue_rays", nonempty > 0 ? waiting / nonempty : 0.0},
            {"treelet_switches_per_ray", double(switches_.exchange(0)) / rays},
            {"treelets", double(tl_->count())}};
    // Only after a traced call with a cache (the harness takes --stats columns before its --cache
    // trace: `table bandwidth` takes them again after it).
    if (mem_split_.exchange(false))
      cols.insert(cols.end(), {{"treelet_mem_slots", double(mem_slots_.exchange(0)) / rays},
                               {"treelet_mem_stacks", double(mem_stacks_.exchange(0)) / rays},
                               {"treelet_mem_nodes", double(mem_nodes_.exchange(0)) / rays},
                               {"treelet_mem_tris", double(mem_tris_.exchange(0)) / rays},
                               {"treelet_mem_other", double(mem_other_.exchange(0)) / rays}});
    return cols;
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    if constexpr (std::is_same_v<P, Probe>) {
      if (probe.cache) {
        SplitProbe split{probe};
        schedule(batch, range, hits, split);
        mem_slots_ += split.reads[SplitProbe::state_slots];
        mem_stacks_ += split.reads[SplitProbe::state_stacks];
        mem_nodes_ += split.reads[SplitProbe::node_array] + split.reads[SplitProbe::full_array];
        mem_tris_ += split.reads[SplitProbe::block_array] + split.reads[SplitProbe::small_array];
        mem_other_ += split.reads[SplitProbe::parts];
        mem_split_ = true;
        return;
      }
    }
    schedule(batch, range, hits, probe);
  }

 private:
  template <class P>
  void schedule(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const Treelets& tl = *tl_;
    const uint32_t end = batch.packet_begin[range.last];
    uint32_t next = batch.packet_begin[range.first];
    if (next >= end) return;
    if (compressed_ && cw_->stats.blocks == 0) {  // an empty scene (cwbvh_single's guard): every ray misses
      for (; next < end; ++next) hits[next] = finish_hit(initial_hit(batch.rays[next]));
      return;
    }
    const uint32_t flight = std::min(flight_, end - next);
    const size_t cap = mbvh_stack_entries(8, compressed_ ? cw_->stats.max_depth : data_.mbvh->stats.max_depth);
    const uint32_t root_ref = compressed_ ? cw_->root : 0;
    // The treelet a reference belongs to, as the entry the leave test reads.
    const auto entry = [&](uint32_t ref) -> const uint32_t& { return compressed_ ? tl.cw_entry(ref) : tl.entry(ref); };
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
    if constexpr (std::is_same_v<P, SplitProbe>) {
      probe.range(SplitProbe::state_slots, slots.data(), slots.size());
      probe.range(SplitProbe::state_stacks, stacks.get(), flight * cap);
      if (compressed_) {
        probe.range(SplitProbe::node_array, cw_->nodes.data(), cw_->nodes.size());
        probe.range(SplitProbe::full_array, cw_->full.data(), cw_->full.size());
        probe.range(SplitProbe::block_array, cw_->iblocks.data(), cw_->iblocks.size());
      } else {
        const MBVH<8, 8>& m = *data_.mbvh;
        probe.range(SplitProbe::node_array, m.nodes.data(), m.nodes.size());
        probe.range(SplitProbe::block_array, m.blocks.data(), m.blocks.size());
        probe.range(SplitProbe::small_array, m.small.data(), m.small.size());
      }
    }
    // Rays not yet started wait in no queue: the root's treelet counts them (as many as there are
    // free slots) and starts them from the batch when it is visited, so a new ray's first visit
    // reads the batch and a slot line it has just written, not a slot written a whole round before
    // (at 262144 rays in flight on crytek_sponza_partial 512x512 bounce:2 that slot read was
    // about one memory read per ray).
    const uint32_t root_t = entry(root_ref);
    std::vector<uint32_t> free_slots(flight);
    for (uint32_t k = 0; k < flight; ++k) free_slots[k] = flight - 1 - k;  // slot 0 first
    auto size_of = [&](uint32_t t) {
      size_t n = queues[t].size();
      if (t == root_t) n += std::min<size_t>(free_slots.size(), end - next);
      return uint32_t(n);
    };
    // The scheduler's max-heap of (queue size, treelet), one entry each time a size grows: an
    // entry is current when the queue still has that size, and every non-empty queue has a current
    // entry, so the first current entry on top is a fullest queue; stale ones are skipped.
    std::priority_queue<std::pair<uint32_t, uint32_t>> heap;
    uint64_t nonempty = 0, waiting = 0;  // live: non-empty queues, rays queued
    uint64_t st_visits = 0, st_run = 0, st_nonempty = 0, st_waiting = 0, st_switches = 0, st_rays = 0;
    auto enqueue = [&](uint32_t slot, uint32_t t) {
      auto& q = queues[t];
      if (q.empty()) ++nonempty;
      q.push_back(slot);
      probe.write(&q.back(), sizeof(uint32_t));
      ++waiting;
      heap.push({size_of(t), t});
    };
    // Runs the ray of `slot` in treelet t until it finishes (its slot is freed) or leaves: the
    // single-ray loop of mbvh8_single (ChildOrder::sort_always) or of cwbvh_single (CWOrder::sort,
    // indexed leaves), suspended where the next reference lies in another treelet.
    const RayCtx::ShearAxes axes = RayCtx::axes_for(batch.common_origin);  // a resumed ray rebuilds its RayCtx
    auto run_ray = [&](uint32_t slot, uint32_t t) {
      Slot& s = slots[slot];
      probe.read(&s, sizeof(Slot));
      const Ray& ray = s.r;
      const RayCtx rc(ray, axes);
      MBVHStackEntry* stack = &stacks[slot * cap];
      // A leaf is tested where the ray is: one reached from its parent is in this treelet (its
      // parent is), and one popped from the stack reads its blocks here instead of a switch (the
      // slot and stack lines again) - and no leaf reads the block map (4 bytes per block: 2 MB on
      // spheres:2M, a memory read at most leaf visits; docs/PERFORMANCE.md, session 33).
      const auto leave = [&](uint32_t ref) {
        if (mbvh_ref::is_leaf(ref)) return false;
        const uint32_t& e = entry(ref);
        probe.read(&e, sizeof(uint32_t));
        return e != t;
      };
      bool done;
      if (compressed_) {
        const CWBVH& c = *cw_;
        const CWRay cr(rc, ray.tmin, c.coord_bound, c.e_min, c.e_max);
        const TriRay<8> tr(rc, ray.tmin);
        done = cr.exp_add ? cw_traverse_from<CWOrder::sort, true, true>(c, cr, tr, s.at, s.hit, stack, probe, leave)
                          : cw_traverse_from<CWOrder::sort, false, true>(c, cr, tr, s.at, s.hit, stack, probe, leave);
      } else {
        const MBVH<8, 8>& m = *data_.mbvh;
        done = mbvh_traverse_from<8, 8, TriKernel::watertight, ChildOrder::sort_always>(
            m, nullptr, NodeRay<8>(rc, ray.tmin, m.coord_bound), TriRay<8>(rc, ray.tmin), &rc, s.at, s.hit, stack, probe, leave);
      }
      probe.write(&s, sizeof(Slot));
      if (done) {
        hits[s.ray] = finish_hit(s.hit);
        probe.write(&hits[s.ray], sizeof(Hit));
        free_slots.push_back(slot);
        if (t != root_t && next < end) heap.push({size_of(root_t), root_t});
      } else {
        if constexpr (P::enabled) ++st_switches;
        enqueue(slot, entry(s.at.cur));
      }
    };
    heap.push({size_of(root_t), root_t});
    std::vector<uint32_t> work;
    while (!heap.empty()) {
      const uint32_t size = heap.top().first, t = heap.top().second;
      heap.pop();
      if (size == 0 || size_of(t) != size) continue;
      if constexpr (P::enabled) ++st_visits, st_nonempty += nonempty, st_waiting += waiting;
      work.clear();
      work.swap(queues[t]);
      if (!work.empty()) --nonempty, waiting -= work.size();
      for (const uint32_t& slot : work) {
        probe.read(&slot, sizeof(uint32_t));
        run_ray(slot, t);
      }
      if constexpr (P::enabled) st_run += work.size();
      // The root's treelet starts new rays while slots are free (a ray that finishes here frees
      // its slot for the next one at once).
      while (t == root_t && next < end && !free_slots.empty()) {
        const uint32_t slot = free_slots.back(), i = next++;
        free_slots.pop_back();
        const Ray& ray = batch.rays[i];
        probe.read(&ray, sizeof(Ray));
        if constexpr (P::enabled) {
          if (probe.counts) probe.counts->rays++;
          ++st_rays, ++st_run;
        }
        slots[slot] = {ray, {root_ref, 0}, i, initial_hit(ray)};
        probe.write(&slots[slot], sizeof(Slot));
        run_ray(slot, t);
      }
    }
    if constexpr (P::enabled) {
      visits_ += st_visits, run_rays_ += st_run, nonempty_ += st_nonempty, waiting_ += st_waiting;
      switches_ += st_switches, rays_ += st_rays;
    }
  }

  MBVHBuildParams params_;
  size_t budget_;
  uint32_t flight_;
  bool compressed_;                    // tree=cwbvh
  MBVHData<8, 8> data_;                // tree=mbvh8
  std::shared_ptr<const CWBVH> cw_;    // tree=cwbvh
  std::shared_ptr<const Treelets> tl_;
  mutable std::atomic<uint64_t> visits_{0}, run_rays_{0}, nonempty_{0}, waiting_{0}, switches_{0}, rays_{0};
  mutable std::atomic<uint64_t> mem_slots_{0}, mem_stacks_{0}, mem_nodes_{0}, mem_tris_{0}, mem_other_{0};
  mutable std::atomic<bool> mem_split_{false};
};

}  // namespace

std::unique_ptr<Traverser> make_treelet_queue(const SchemeConfig& cfg) { return std::make_unique<TreeletQueue>(cfg); }
ParamSpecs params_treelet_queue() {
  return mbvh_param_specs(kMBVH8Defaults) +
         ParamSpecs{int_param("treelet_bytes", 131072, 256, 1 << 30,
                              "treelet byte budget (nodes + their leaves' blocks): 131072 = half a 256 KiB L2; 32768 for L1"),
                    int_param("rays_in_flight", 262144, 1, 1 << 20,
                              "rays whose traversal state waits in the queues at once (the ray pool)"),
                    choice_param("tree", "cwbvh", {"cwbvh", "mbvh8"},
                                 "the tree cut into treelets: mbvh8 = mbvh8_single's MBVH8 and loop; cwbvh = "
                                 "cwbvh_single's compressed BVH (its defaults: full_top=4, indexed leaves) and loop")};
}

}  // namespace tb
