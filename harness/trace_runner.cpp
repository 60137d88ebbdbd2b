#include "harness/trace_runner.h"

#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>

namespace tb {

void enable_ftz_daz() {
  _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
  _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
}

void trace_batch(const Traverser& t, const RayBatch& batch, std::span<Hit> hits, int threads) {
  const uint32_t packets = batch.num_packets();
  if (threads <= 1 || packets < 2) {
    enable_ftz_daz();
    t.trace(batch, PacketRange::all(batch), hits);
    return;
  }
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
  auto worker = [&] {
    enable_ftz_daz();
    for (uint32_t p; (p = next.fetch_add(chunk)) < packets;)
      t.trace(batch, {p, std::min(packets, p + chunk)}, hits);
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < threads; ++i) pool.emplace_back(worker);
  worker();
  for (auto& th : pool) th.join();
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
