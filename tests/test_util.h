// Shared helpers of the test suites.
#pragma once
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include "harness/accuracy.h"
#include "harness/experiment.h"
#include "harness/trace_runner.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb::test {

// The Bench of a scene (a load_scene spec), made on first use and kept for the process: its
// structures, rays and reference hits are what the traversal tests spend their time on.
inline Bench& bench_for(const std::string& scene) {
  static std::map<std::string, std::unique_ptr<Bench>> benches;
  auto& b = benches[scene];
  if (!b) b = std::make_unique<Bench>(load_scene(scene));
  return *b;
}

inline WorkloadSpec small_spec(const std::string& workload, uint32_t size = 64, uint32_t view = 0) {
  WorkloadSpec s = parse_workload(workload);
  s.width = size;
  s.height = size;
  s.view = view;
  return s;
}

// Traces `spec` with `scheme` and compares with the reference.
inline Accuracy accuracy_of(Bench& bench, const std::string& scheme, const WorkloadSpec& spec,
                            const SchemeConfig& cfg = {}) {
  auto t = make_scheme(scheme, cfg);
  t->prepare(bench.scene(), bench.cache());
  const RayBatch& b = bench.rays(spec);
  std::vector<Hit> hits(b.size());
  trace_batch(*t, b, hits, 2);
  return compare_hits(hits, bench.reference_hits(spec));
}

// How many rays of `b` get a hit from `b_scheme` (traced on 2 threads) that is not bit for bit the
// one `a_scheme` (1 thread) gives: 0 for two schemes that make the same visits in the same order.
inline size_t differing_hits(const Traverser& a_scheme, const Traverser& b_scheme, const RayBatch& b) {
  std::vector<Hit> a(b.size()), q(b.size());
  trace_batch(a_scheme, b, a, 1);
  trace_batch(b_scheme, b, q, 2);
  size_t differ = 0;
  for (size_t i = 0; i < b.size(); ++i) differ += std::memcmp(&a[i], &q[i], sizeof(Hit)) != 0;
  return differ;
}

// Every registered scheme but the reference itself (baselines too, unless `ours_only`).
inline std::vector<std::string> schemes_under_test(bool ours_only = false) {
  std::vector<std::string> names;
  for (const auto& s : schemes())
    if (s.name != "reference" && !(ours_only && s.baseline)) names.push_back(s.name);
  return names;
}

inline std::filesystem::path temp_dir(const std::string& name) {
  auto p = std::filesystem::temp_directory_path() / ("travbench_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::create_directories(p);
  return p;
}

}  // namespace tb::test
