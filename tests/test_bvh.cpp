// BVH builder invariants: every triangle in exactly one leaf, boxes nest, leaves respect the
// size limit, refit restores tight boxes after a move; the build over a span of references (an
// index subset with clipped boxes, as the RayGrid octree's mini-BVHs) is the scene build's code.
#include <algorithm>
#include <cstring>
#include <random>

#include "structures/bvh.h"
#include "structures/clip.h"
#include "test_geometry.h"
#include "test_util.h"

namespace tb {
namespace {

using test::random_triangles;

// Every expected primitive exactly once (no other), boxes nested, each leaf's box holding its
// primitives' boxes, leaves within the size limit. `box_of(id)` is the box the build was given.
template <class BoxOf>
void check_tree(const BVH& bvh, int max_leaf, const std::vector<uint32_t>& ids, BoxOf&& box_of) {
  ASSERT_FALSE(bvh.nodes.empty());
  std::vector<int> seen(ids.empty() ? 0 : *std::max_element(ids.begin(), ids.end()) + 1, 0);
  std::vector<uint32_t> stack{0};
  uint32_t leaves = 0;
  size_t slots = 0;
  while (!stack.empty()) {
    const BVHNode& n = bvh.nodes[stack.back()];
    stack.pop_back();
    const AABB box{n.lo, n.hi};
    if (n.is_leaf()) {
      ++leaves;
      EXPECT_LE(int(n.count), max_leaf);
      for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) {
        ASSERT_LT(k, bvh.prim_index.size());
        const uint32_t t = bvh.prim_index[k];
        ASSERT_LT(t, seen.size()) << "primitive " << t << " was not given";
        seen[t]++;
        ++slots;
        EXPECT_TRUE(box.contains(box_of(t))) << "primitive " << t << " outside its leaf";
      }
    } else {
      for (uint32_t c = n.left_first; c < n.left_first + 2; ++c) {
        EXPECT_TRUE(box.contains(AABB{bvh.nodes[c].lo, bvh.nodes[c].hi})) << "child box outside parent";
        stack.push_back(c);
      }
    }
  }
  std::vector<int> want(seen.size(), 0);
  for (uint32_t t : ids) want[t] = 1;
  for (size_t t = 0; t < seen.size(); ++t) EXPECT_EQ(seen[t], want[t]) << "primitive " << t;
  EXPECT_EQ(slots, ids.size());
  EXPECT_EQ(bvh.prim_index.size(), ids.size());
  EXPECT_EQ(leaves, bvh.stats.leaves);
}

void check_invariants(const Scene& s, const BVH& bvh, int max_leaf) {
  std::vector<uint32_t> all(s.num_triangles());
  for (uint32_t t = 0; t < all.size(); ++t) all[t] = t;
  check_tree(bvh, max_leaf, all, [&](uint32_t t) { return s.triangle_bounds(t); });
}

// vmin / vmax (structures/vec3.h) are minss / maxss intrinsics so that no compiler profile turns
// them into branches (docs/PERFORMANCE.md, session 34); they must still be std::min / std::max bit
// for bit, NaNs and signed zeros included, since every box of every builder goes through them.
TEST(Vec3, MinMaxAreStdMinMaxBitForBit) {
  const float v[] = {0.f, -0.f, 1.f, -1.f, 1e-40f, -1e-40f, 3e38f, -3e38f, INFINITY, -INFINITY, NAN, -NAN, 0.5f};
  const auto bits = [](float x) {
    uint32_t u;
    std::memcpy(&u, &x, sizeof u);
    return u;
  };
  for (float a : v)
    for (float b : v) {
      const Vec3 lo = vmin({a, b, a}, {b, a, a}), hi = vmax({a, b, a}, {b, a, a});
      EXPECT_EQ(bits(lo.x), bits(std::min(a, b))) << a << " " << b;
      EXPECT_EQ(bits(lo.y), bits(std::min(b, a))) << a << " " << b;
      EXPECT_EQ(bits(lo.z), bits(std::min(a, a))) << a;
      EXPECT_EQ(bits(hi.x), bits(std::max(a, b))) << a << " " << b;
      EXPECT_EQ(bits(hi.y), bits(std::max(b, a))) << a << " " << b;
      EXPECT_EQ(bits(hi.z), bits(std::max(a, a))) << a;
    }
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
    if (!n.is_leaf() && &n != &bvh.nodes[1]) {
      EXPECT_EQ(n.left_first % 2, 0u);
    }
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

// The octree's use: an index subset of the scene (the triangles that touch a region), each box
// clipped to the region. Every chosen triangle once, the leaves holding the clipped boxes, and
// the root box their union: the region's geometry bounds, inside the region.
TEST(BVH, SpanOfClippedBoxesOnAnIndexSubset) {
  Scene s = random_triangles(4000, 21);
  for (uint32_t i = 0; i < 40; ++i) {  // long triangles that cross the region's faces
    const Vec3 a{-12.f + i * 0.6f, -11.f, 9.f - i * 0.4f}, b{11.f, 10.5f - i * 0.5f, -12.f}, c{-11.f, 12.f, 0.3f * i};
    const uint32_t v = uint32_t(s.positions.size());
    s.positions.insert(s.positions.end(), {a, b, c});
    s.triangles.push_back({v, v + 1, v + 2});
  }
  const AABB region{{-3.f, -6.f, -2.f}, {5.f, 2.5f, 7.f}};
  for (int leaf : {1, 4, 7}) {
    for (int threads : {1, 2}) {
      SCOPED_TRACE(::testing::Message() << "max_leaf " << leaf << " threads " << threads);
      std::vector<PrimRef> refs;
      std::vector<uint32_t> ids;
      std::vector<AABB> clipped(s.num_triangles());
      for (uint32_t t = 1; t < s.num_triangles(); t += 2) {  // every other triangle: a subset
        clipped[t] = clip_triangle_bounds(s.vertex(t, 0), s.vertex(t, 1), s.vertex(t, 2), region);
        if (clipped[t].empty()) continue;
        refs.emplace_back(clipped[t], t);
        ids.push_back(t);
      }
      ASSERT_GT(ids.size(), 200u);
      BVHBuildParams p;
      p.max_leaf = leaf;
      p.threads = threads;
      const BVH bvh = BVH::build(std::span<PrimRef>(refs), p);
      check_tree(bvh, leaf, ids, [&](uint32_t t) { return clipped[t]; });
      AABB all;
      for (uint32_t t : ids) all.grow(clipped[t]);
      EXPECT_EQ(bvh.nodes[0].lo, all.lo);
      EXPECT_EQ(bvh.nodes[0].hi, all.hi);
      EXPECT_TRUE(region.contains(all));
      EXPECT_GT(bvh.stats.sah_cost, 0);
      // The span was partitioned in place: it now lists the ids in leaf order.
      for (size_t k = 0; k < refs.size(); ++k) EXPECT_EQ(refs[k].id(), bvh.prim_index[k]);
    }
  }
}

// One builder: the scene build is the span build over the scene's triangle boxes, node for node.
TEST(BVH, SceneBuildIsTheSpanBuild) {
  for (const char* name : {"room", "spheres:5000"}) {
    const Scene s = make_builtin_scene(name);
    std::vector<PrimRef> refs;
    for (uint32_t t = 0; t < s.num_triangles(); ++t) refs.emplace_back(s.triangle_bounds(t), t);
    const BVH a = BVH::build(s), b = BVH::build(std::span<PrimRef>(refs));
    ASSERT_EQ(a.nodes.size(), b.nodes.size()) << name;
    EXPECT_EQ(std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BVHNode)), 0) << name;
    EXPECT_EQ(a.prim_index, b.prim_index) << name;
    EXPECT_EQ(a.stats.sah_cost, b.stats.sah_cost) << name;
  }
}

// BVHSubtreeBuilder (the spatial-split builder's hand-off of small subtrees): each subtree built
// in place under a node of a tree under construction is the span build of the same references,
// node for node, its nodes and leaf ranges renumbered into the host tree; one builder serves many
// subtrees in turn (its bins kept), of one, two and many references.
TEST(BVH, SubtreeBuiltInPlaceIsTheSpanBuildRenumbered) {
  const Scene s = make_builtin_scene("spheres:3000");
  const BVHBuildParams p;
  BVH host;
  host.nodes.reserve(4 * s.num_triangles() + 8);
  host.nodes.resize(2);
  BVHSubtreeBuilder sub(p);
  uint32_t t = 0;
  for (uint32_t n : {1u, 2u, 3u, 40u, 63u, 500u, 7u}) {
    std::vector<PrimRef> refs, copy;
    AABB box;
    for (uint32_t k = 0; k < n; ++k, ++t) refs.emplace_back(s.triangle_bounds(t), t), box.grow(s.triangle_bounds(t));
    copy = refs;
    const BVH expect = BVH::build(std::span<PrimRef>(copy), p);
    // A host node holding the references, as a split leaves it (its box their bounds).
    const uint32_t node = uint32_t(host.nodes.size());
    host.nodes.push_back({box.lo, 0, box.hi, n});
    const uint32_t node_off = uint32_t(host.nodes.size()), prim_off = uint32_t(host.prim_index.size());
    const uint32_t depth = sub.build(host, node, refs);
    EXPECT_EQ(depth, expect.stats.max_depth) << n;
    ASSERT_EQ(host.nodes.size() - node_off, expect.nodes.size() - 2) << n;
    const auto renumbered = [&](BVHNode e) {
      e.left_first += e.is_leaf() ? prim_off : node_off - 2;
      return e;
    };
    const auto same = [](const BVHNode& a, const BVHNode& b) {
      return a.lo == b.lo && a.hi == b.hi && a.left_first == b.left_first && a.count == b.count;
    };
    EXPECT_TRUE(same(host.nodes[node], renumbered(expect.nodes[0]))) << n;
    for (size_t i = 2; i < expect.nodes.size(); ++i)
      EXPECT_TRUE(same(host.nodes[node_off + i - 2], renumbered(expect.nodes[i]))) << n << " node " << i;
    ASSERT_EQ(host.prim_index.size(), prim_off + n);
    EXPECT_TRUE(std::equal(expect.prim_index.begin(), expect.prim_index.end(), host.prim_index.begin() + prim_off)) << n;
  }
}

TEST(BVH, SpanOfOneOrNoReferences) {
  std::vector<PrimRef> one{PrimRef(AABB{{1, 2, 3}, {4, 5, 6}}, 77)};
  const BVH b = BVH::build(std::span<PrimRef>(one));
  ASSERT_TRUE(b.nodes[0].is_leaf());
  EXPECT_EQ(b.nodes[0].count, 1u);
  EXPECT_EQ(b.prim_index, std::vector<uint32_t>{77});
  EXPECT_EQ(b.nodes[0].lo, (Vec3{1, 2, 3}));
  EXPECT_EQ(b.nodes[0].hi, (Vec3{4, 5, 6}));
  EXPECT_EQ(one[0].box().lo, (Vec3{1, 2, 3}));
  std::vector<PrimRef> none;
  const BVH e = BVH::build(std::span<PrimRef>(none));
  EXPECT_TRUE(e.prim_index.empty());
  EXPECT_EQ(e.stats.leaves, 0u);
}

}  // namespace
}  // namespace tb
