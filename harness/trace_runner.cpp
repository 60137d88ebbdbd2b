#include "harness/trace_runner.h"

#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>
#include <utility>

#include "traversal/ray_order.h"

namespace tb {

void enable_ftz_daz() {
  _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
  _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
}

namespace {

// Runs f(k) for k = 0 .. threads-1, k = 0 on the calling thread, each with FTZ/DAZ set.
template <class F>
void on_threads(int threads, F&& f) {
  std::vector<std::thread> pool;
  for (int k = 1; k < threads; ++k)
    pool.emplace_back([&f, k] {
      enable_ftz_daz();
      f(k);
    });
  enable_ftz_daz();
  f(0);
  for (auto& th : pool) th.join();
}

// Thread k's share [lo, hi) of n items cut into `threads` parts.
std::pair<uint32_t, uint32_t> share(uint32_t n, int threads, int k) {
  return {uint32_t(uint64_t(n) * uint32_t(k) / uint32_t(threads)), uint32_t(uint64_t(n) * uint32_t(k + 1) / uint32_t(threads))};
}

// The packets of `batch` traced by `threads` threads pulling chunks of packets.
void trace_chunks(const Traverser& t, const RayBatch& batch, std::span<Hit> hits, int threads) {
  const uint32_t packets = batch.num_packets();
  // Small chunks keep both cores busy to the end even when packets differ in cost — unless the
  // scheme needs many rays per call (RayGrid's queues fill from the whole call: with 16-packet
  // chunks it scaled only 1.6x on 2 threads, Sponza bounce:2); then chunks grow towards its
  // preferred size, but never beyond a quarter of each thread's share (half measured no better).
  uint32_t chunk = std::max<uint32_t>(1, std::min<uint32_t>(16, packets / (8 * threads)));
  if (const uint32_t pref = t.preferred_chunk_rays(); pref > 0) {
    const uint64_t rays_per_packet = std::max<uint64_t>(1, batch.size() / packets);
    const uint32_t want = uint32_t(std::min<uint64_t>(packets, (pref + rays_per_packet - 1) / rays_per_packet));
    chunk = std::max(chunk, std::min(want, std::max<uint32_t>(1, packets / (4 * threads))));
  }
  std::atomic<uint32_t> next{0};
  on_threads(threads, [&](int) {
    for (uint32_t p; (p = next.fetch_add(chunk)) < packets;) t.trace(batch, {p, std::min(packets, p + chunk)}, hits);
  });
}

// A batch gathered into a scheme's order (Traverser::batch_order) and its hits: kept between the
// traces of a thread, so that repeated timed traces do not allocate and fault in the copy anew.
struct OrderedBatch {
  RayOrder order;
  RayBatch batch;
  std::vector<Hit> hits;
};

}  // namespace

void trace_batch(const Traverser& t, const RayBatch& batch, std::span<Hit> hits, int threads) {
  const uint32_t packets = batch.num_packets();
  if (threads <= 1 || packets < 2) {
    enable_ftz_daz();
    t.trace(batch, PacketRange::all(batch), hits);
    return;
  }
  // A scheme that orders the batch (mbvh_rs's sort) orders all of it here, once, rather than each
  // thread's chunk: the threads gather their shares of the rays into the order, trace chunks of
  // the gathered batch, and scatter their shares of the hits back. Timed, as the single-threaded
  // trace's sort inside the scheme is.
  static thread_local OrderedBatch mine;
  OrderedBatch& ob = mine;  // named in the lambdas below: a thread_local there is the worker's own
  if (!batch.ordered && t.batch_order(batch, ob.order)) {
    const uint32_t n = ob.order.size();
    RayBatch& g = ob.batch;
    g.rays.resize(n);
    ob.hits.resize(n);
    // Packets of the scheme's preferred call (mbvh_rs: one stream each), so that the chunks cut
    // the order where a single-threaded trace's streams do.
    const uint32_t packet = t.preferred_chunk_rays() > 0 ? t.preferred_chunk_rays() : batch.packet_size;
    if (g.packet_size != packet || g.packet_begin.back() != n) g.group_uniform(packet);
    g.ordered = true;
    g.depth = batch.depth;
    NullProbe probe;
    on_threads(threads, [&](int k) {
      const auto [lo, hi] = share(n, threads, k);
      gather_rays(ob.order, batch.rays, lo, hi, g.rays.data() + lo, probe);
    });
    trace_chunks(t, g, ob.hits, threads);
    on_threads(threads, [&](int k) {
      const auto [lo, hi] = share(n, threads, k);
      scatter_hits(ob.order, ob.hits.data() + lo, lo, hi, hits, probe);
    });
    return;
  }
  trace_chunks(t, batch, hits, threads);
}

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n == 0 ? 0 : n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::vector<std::vector<double>> measure_interleaved(std::span<const Traverser* const> schemes, const RayBatch& batch,
                                                     std::span<Hit> hits, int threads, int rounds) {
  for (const Traverser* t : schemes) trace_batch(*t, batch, hits, threads);  // warm-up
  std::vector<std::vector<double>> sec(schemes.size());
  for (int round = 0; round < rounds; ++round)
    for (size_t k = 0; k < schemes.size(); ++k) {
      const size_t s = (size_t(round) + k) % schemes.size();
      const auto t0 = std::chrono::steady_clock::now();
      trace_batch(*schemes[s], batch, hits, threads);
      sec[s].push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
  return sec;
}

ThroughputStats measure(const Traverser& t, const RayBatch& batch, std::span<Hit> hits, int threads, int reps) {
  ThroughputStats s;
  trace_batch(t, batch, hits, threads);  // warm-up: caches, page faults, lazy allocations
  std::vector<double> mrays;
  for (int r = 0; r < reps; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    trace_batch(t, batch, hits, threads);
    const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    s.seconds.push_back(sec);
    mrays.push_back(double(batch.size()) / std::max(sec, 1e-9) * 1e-6);
  }
  s.mrays_min = *std::min_element(mrays.begin(), mrays.end());
  s.mrays_max = *std::max_element(mrays.begin(), mrays.end());
  s.mrays_median = median_of(mrays);
  return s;
}

}  // namespace tb
