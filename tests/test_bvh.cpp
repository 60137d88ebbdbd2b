// BVH builder invariants: every triangle in exactly one leaf, boxes nest, leaves respect the
// size limit, refit restores tight boxes after a move.
#include <random>

#include "structures/bvh.h"
#include "test_util.h"

namespace tb {
namespace {

Scene random_triangles(uint32_t n, uint32_t seed) {
  Scene s;
  s.name = "random";
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(-10.f, 10.f), E(-0.5f, 0.5f);
  for (uint32_t i = 0; i < n; ++i) {
    Vec3 c{U(rng), U(rng), U(rng)};
    for (int k = 0; k < 3; ++k) s.positions.push_back(c + Vec3{E(rng), E(rng), E(rng)});
    s.triangles.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  s.ensure_views();
  return s;
}

void check_invariants(const Scene& s, const BVH& bvh, int max_leaf) {
  std::vector<int> seen(s.num_triangles(), 0);
  std::vector<uint32_t> stack{0};
  uint32_t leaves = 0;
  while (!stack.empty()) {
    const BVHNode& n = bvh.nodes[stack.back()];
    stack.pop_back();
    const AABB box{n.lo, n.hi};
    if (n.is_leaf()) {
      ++leaves;
      EXPECT_LE(int(n.count), max_leaf);
      for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) {
        const uint32_t t = bvh.prim_index[k];
        seen[t]++;
        EXPECT_TRUE(box.contains(s.triangle_bounds(t))) << "triangle " << t << " outside its leaf";
      }
    } else {
      for (uint32_t c = n.left_first; c < n.left_first + 2; ++c) {
        EXPECT_TRUE(box.contains(AABB{bvh.nodes[c].lo, bvh.nodes[c].hi})) << "child box outside parent";
        stack.push_back(c);
      }
    }
  }
  for (size_t t = 0; t < seen.size(); ++t) EXPECT_EQ(seen[t], 1) << "triangle " << t;
  EXPECT_EQ(leaves, bvh.stats.leaves);
}

TEST(BVH, InvariantsOnRandomTriangles) {
  for (int leaf : {1, 4, 8}) {
    Scene s = random_triangles(3000, 7);
    BVHBuildParams p;
    p.max_leaf = leaf;
    BVH bvh = BVH::build(s, p);
    check_invariants(s, bvh, leaf);
    EXPECT_GT(bvh.stats.sah_cost, 0);
  }
}

TEST(BVH, InvariantsOnBuiltinScenes) {
  for (const char* name : {"room", "sphere", "spheres:5000"}) {
    Scene s = make_builtin_scene(name);
    BVH bvh = BVH::build(s);
    check_invariants(s, bvh, 4);
  }
}

TEST(BVH, CoincidentCentroidsStillRespectLeafSize) {
  Scene s;
  s.name = "stack";
  for (uint32_t i = 0; i < 100; ++i) {  // 100 identical triangles: SAH cannot separate them
    s.positions.insert(s.positions.end(), {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    s.triangles.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  BVH bvh = BVH::build(s);
  check_invariants(s, bvh, 4);
}

TEST(BVH, SiblingPairsShareACacheLine) {
  Scene s = random_triangles(500, 3);
  BVH bvh = BVH::build(s);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(bvh.nodes.data()) % 64, 0u);
  for (const BVHNode& n : bvh.nodes)
    if (!n.is_leaf() && &n != &bvh.nodes[1]) EXPECT_EQ(n.left_first % 2, 0u);
}

TEST(BVH, RefitTracksMovedGeometry) {
  Scene s = random_triangles(800, 11);
  BVH bvh = BVH::build(s);
  for (auto& p : s.positions) p = p * 1.5f + Vec3{3, 0, -2};
  bvh.refit(s);
  check_invariants(s, bvh, 4);
  BVH fresh = BVH::build(s);
  EXPECT_FLOAT_EQ(bvh.nodes[0].lo.x, fresh.nodes[0].lo.x);
  EXPECT_FLOAT_EQ(bvh.nodes[0].hi.z, fresh.nodes[0].hi.z);
}

}  // namespace
}  // namespace tb

namespace tb {
namespace {

TEST(BVH, ParallelBuildAndRefitMatchSerial) {
  Scene s = make_builtin_scene("spheres:60000");
  BVHBuildParams p;
  BVH serial = BVH::build(s, p);
  p.threads = 2;
  BVH parallel = BVH::build(s, p);
  check_invariants(s, parallel, 4);
  EXPECT_EQ(parallel.stats.nodes, serial.stats.nodes);
  EXPECT_EQ(parallel.stats.leaves, serial.stats.leaves);
  EXPECT_NEAR(parallel.stats.sah_cost, serial.stats.sah_cost, 1e-6 * serial.stats.sah_cost);
  for (auto& v : s.positions) v = v * 0.5f;
  parallel.refit(s, 2);
  check_invariants(s, parallel, 4);
}

}  // namespace
}  // namespace tb
