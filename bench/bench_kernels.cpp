// Microbenchmarks of the kernels every scheme shares: ray/box and ray/triangle tests, and the
// builders. Rates are tests (or triangles) per second.
#include <benchmark/benchmark.h>

#include <random>

#include "structures/builtin_scenes.h"
#include "structures/bvh.h"
#include "traversal/kernels.h"

namespace tb {
namespace {

struct Data {
  std::vector<Ray> rays;
  std::vector<TriVerts> tris;
  std::vector<PlaneTri> planes;
  std::vector<AABB> boxes;
  Data() {
    std::mt19937 rng(42);
    std::uniform_real_distribution<float> U(-1.f, 1.f);
    for (int i = 0; i < 4096; ++i) {
      const Vec3 o{U(rng) * 4, U(rng) * 4, -5}, target{U(rng), U(rng), U(rng)};
      rays.push_back({o, 0.f, normalize(target - o), INFINITY});
      const Vec3 c{U(rng), U(rng), U(rng)};
      tris.push_back({c, c + Vec3{U(rng), U(rng), 0} * 0.5f, c + Vec3{0, U(rng), U(rng)} * 0.5f});
      planes.push_back(make_plane_tri(tris.back()));
      AABB b;
      b.grow(c);
      b.grow(c + Vec3{0.3f, 0.3f, 0.3f});
      boxes.push_back(b);
    }
  }
};
const Data& data() {
  static Data d;
  return d;
}

void BM_BoxEntry(benchmark::State& state) {
  const Data& d = data();
  std::vector<RayCtx> ctx;
  for (const Ray& r : d.rays) ctx.emplace_back(r);
  size_t i = 0;
  for (auto _ : state) {
    const RayCtx& r = ctx[i & 4095];
    const AABB& b = d.boxes[(i * 7) & 4095];
    benchmark::DoNotOptimize(box_entry(r, b.lo, b.hi, 0.f, INFINITY));
    ++i;
  }
  state.SetItemsProcessed(int64_t(state.iterations()));
}
BENCHMARK(BM_BoxEntry);

template <TriKernel K>
void BM_Triangle(benchmark::State& state) {
  const Data& d = data();
  TriangleSet ts;
  ts.verts.assign(d.tris.begin(), d.tris.end());
  ts.planes.assign(d.planes.begin(), d.planes.end());
  ts.prim_id.resize(d.tris.size());
  std::vector<RayCtx> ctx;
  for (const Ray& r : d.rays) ctx.emplace_back(r);
  size_t i = 0, hits = 0;
  for (auto _ : state) {
    Hit h;
    hits += intersect_tri<K>(ctx[i & 4095], ts, uint32_t((i * 13) & 4095), 0.f, h);
    ++i;
  }
  benchmark::DoNotOptimize(hits);
  state.SetItemsProcessed(int64_t(state.iterations()));
  state.counters["hit_rate"] = double(hits) / double(std::max<size_t>(1, i));
}
BENCHMARK(BM_Triangle<TriKernel::watertight>)->Name("BM_Triangle/watertight");
BENCHMARK(BM_Triangle<TriKernel::moller>)->Name("BM_Triangle/moller");
BENCHMARK(BM_Triangle<TriKernel::plane>)->Name("BM_Triangle/plane");
BENCHMARK(BM_Triangle<TriKernel::plane_rcp>)->Name("BM_Triangle/plane_rcp");

void BM_BuildBVH(benchmark::State& state) {
  const Scene s = make_builtin_scene("spheres:" + std::to_string(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(BVH::build(s).nodes.size());
  state.SetItemsProcessed(int64_t(state.iterations() * s.num_triangles()));
}
BENCHMARK(BM_BuildBVH)->Arg(100000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace tb
