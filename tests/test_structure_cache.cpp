// The structure cache (structures/structure_cache.h): typed keys, one build per key, builds
// outside the global lock so nested and concurrent fetches neither deadlock nor repeat work.
#include <atomic>
#include <condition_variable>
#include <thread>

#include "test_util.h"
#include "traversal/bvh_common.h"
#include "traversal/mbvh_fetch.h"

namespace tb {
namespace {

TEST(StructureCache, KeysAreTypedSoOneStringNeverReadsBackAsAnotherType) {
  const Scene s = make_builtin_scene("sphere");
  StructureCache cache(s);
  auto i = cache.get<int>("k", [] { return 7; });
  auto d = cache.get<double>("k", [] { return 2.5; });
  EXPECT_EQ(*i, 7);
  EXPECT_EQ(*d, 2.5);
  EXPECT_EQ(cache.get<int>("k", [] { return 8; }), i) << "second fetch returns the cached object";
  EXPECT_EQ(cache.size(), 2u);
}

TEST(StructureCache, NestedFetchBuildsBothWithoutDeadlock) {
  const Scene s = make_builtin_scene("sphere");
  StructureCache cache(s);
  auto outer = cache.get<std::string>("outer", [&] {
    auto inner = cache.get<int>("inner", [] { return 41; });
    // The same key again from inside the builder of another: already built, returned at once.
    return std::to_string(*cache.get<int>("inner", [] { return 0; }) + 1) + "/" + std::to_string(*inner);
  });
  EXPECT_EQ(*outer, "42/41");
  EXPECT_EQ(cache.size(), 2u);
}

// fetch_mbvh builds the binary BVH inside the MBVH's builder: the BVH is cached and shared with
// the binary-BVH schemes' fetch_bvh.
TEST(StructureCache, MBVHFetchSharesItsNestedBVH) {
  const Scene s = make_builtin_scene("room");
  StructureCache cache(s);
  const MBVHBuildParams p = mbvh_params(resolve_config("mbvh4_single", {}), MBVHDefaults{});
  const MBVHData<4, 4> m = fetch_mbvh<4, 4>(s, cache, p, TriKernel::watertight);
  ASSERT_TRUE(m.mbvh);
  EXPECT_EQ(cache.size(), 2u);  // the MBVH and the BVH it collapsed
  const BVHData b = fetch_bvh(s, cache, p.bvh, TriKernel::watertight);
  EXPECT_EQ(cache.size(), 3u) << "the BVH came from the cache; only its triangle set is new";
  EXPECT_EQ(m.mbvh->stats.triangles, s.num_triangles());
  EXPECT_GT(cache.build_ms<BVH>(p.bvh.key()), 0.0);
  EXPECT_EQ(cache.build_ms<BVH>("no such key"), 0.0);
}

TEST(StructureCache, ConcurrentFetchOfOneKeyBuildsOnce) {
  const Scene s = make_builtin_scene("sphere");
  StructureCache cache(s);
  std::atomic<int> builds{0};
  std::vector<std::shared_ptr<const std::vector<int>>> got(8);
  std::vector<std::thread> pool;
  for (size_t t = 0; t < got.size(); ++t)
    pool.emplace_back([&, t] {
      got[t] = cache.get<std::vector<int>>("big", [&] {
        builds++;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));  // let the others arrive meanwhile
        return std::vector<int>(1000, 3);
      });
    });
  for (auto& th : pool) th.join();
  EXPECT_EQ(builds.load(), 1);
  for (const auto& g : got) EXPECT_EQ(g, got[0]);
}

// Two different structures build at the same time: each builder waits until the other has
// started, which could never happen if a build held the cache's global lock. (The wait has a
// generous timeout so a regression fails instead of hanging the suite.)
TEST(StructureCache, DifferentKeysBuildConcurrently) {
  const Scene s = make_builtin_scene("sphere");
  StructureCache cache(s);
  std::mutex m;
  std::condition_variable cv;
  int started = 0;
  auto builder = [&](int v) {
    return [&, v] {
      std::unique_lock lock(m);
      ++started;
      cv.notify_all();
      const bool both = cv.wait_for(lock, std::chrono::seconds(30), [&] { return started == 2; });
      return both ? v : -1;
    };
  };
  int a = 0, b = 0;
  std::thread ta([&] { a = *cache.get<int>("a", builder(1)); });
  std::thread tb([&] { b = *cache.get<int>("b", builder(2)); });
  ta.join();
  tb.join();
  EXPECT_EQ(a, 1) << "builder a never saw b start";
  EXPECT_EQ(b, 2) << "builder b never saw a start";
}

TEST(StructureCache, AFailedBuildIsRetriedByTheNextFetch) {
  const Scene s = make_builtin_scene("sphere");
  StructureCache cache(s);
  EXPECT_THROW(cache.get<int>("k", []() -> int { throw InputError("boom"); }), InputError);
  EXPECT_EQ(cache.size(), 0u);
  EXPECT_EQ(*cache.get<int>("k", [] { return 5; }), 5);
}

}  // namespace
}  // namespace tb
