// travbench_bench: (scene, workload, scheme) cases registered at run time with a rays/s rate, so
// --benchmark_filter, --benchmark_repetitions and JSON output work as usual.
//   travbench_bench [--scene=S]... [--schemes=a,b|all] [--workloads=w1,w2] [--size=N] [benchmark flags]
// Defaults: --scene=room --schemes=all --workloads=primary,bounce:2 --size=256.
#include <benchmark/benchmark.h>

#include <cstring>
#include <memory>
#include <sstream>

#include "harness/experiment.h"
#include "harness/trace_runner.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace {

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string x; std::getline(ss, x, ',');)
    if (!x.empty()) out.push_back(x);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> scenes;
  std::string schemes = "all", workloads = "primary,bounce:2";
  uint32_t size = 256;
  std::vector<char*> rest{argv[0]};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.rfind("--scene=", 0) == 0) scenes.push_back(a.substr(8));
    else if (a.rfind("--schemes=", 0) == 0) schemes = a.substr(10);
    else if (a.rfind("--workloads=", 0) == 0) workloads = a.substr(12);
    else if (a.rfind("--size=", 0) == 0) size = uint32_t(std::stoul(a.substr(7)));
    else rest.push_back(argv[i]);
  }
  if (scenes.empty()) scenes.push_back("room");
  int rest_argc = int(rest.size());
  benchmark::Initialize(&rest_argc, rest.data());

  std::vector<std::unique_ptr<tb::Bench>> benches;
  try {
    for (const auto& scene : scenes) {
      benches.push_back(std::make_unique<tb::Bench>(tb::load_scene(scene)));
      tb::Bench& bench = *benches.back();
      for (const auto& w : split(workloads)) {
        tb::WorkloadSpec spec = tb::parse_workload(w);
        spec.width = spec.height = size;
        const tb::RayBatch& batch = bench.rays(spec);
        for (const auto& name : tb::expand_scheme_list(schemes)) {
          if (name == "reference") continue;
          std::shared_ptr<tb::Traverser> t = tb::make_scheme(name);
          t->prepare(bench.scene(), bench.cache());
          const std::string label = bench.scene().name + "/" + w + "/" + name;
          benchmark::RegisterBenchmark(label.c_str(), [t, &batch](benchmark::State& state) {
            std::vector<tb::Hit> hits(batch.size());
            tb::enable_ftz_daz();
            for (auto _ : state) t->trace(batch, tb::PacketRange::all(batch), hits);
            state.counters["rays_per_s"] =
                benchmark::Counter(double(batch.size()), benchmark::Counter::kIsIterationInvariantRate);
          })->Unit(benchmark::kMillisecond);
        }
      }
    }
  } catch (const tb::InputError& e) {
    std::fprintf(stderr, "travbench_bench: error: %s\n", e.what());
    return 2;
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
