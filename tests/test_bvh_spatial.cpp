// Spatial-split BVH (Stich et al. 2009) invariants: every point of every triangle lies in the box
// of a leaf that references the triangle and in all of that leaf's ancestors (so no ray can miss
// it by culling), leaves respect the size limit, duplication stays within the budget, and the SAH
// cost drops on scenes with large triangles among small ones.
#include <random>

#include "structures/builtin_scenes.h"
#include "structures/bvh_spatial.h"
#include "workloads/hard_cases.h"
#include "test_util.h"

namespace tb {
namespace {

// A few huge triangles (ground quad, a wall) among many small ones: the shape spatial splits are for.
Scene small_on_large(uint32_t n, uint32_t seed, Vec3 offset = {0, 0, 0}) {
  Scene s;
  s.name = "small_on_large";
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(-1.f, 1.f), E(-0.02f, 0.02f);
  auto add = [&](Vec3 a, Vec3 b, Vec3 c) {
    const uint32_t k = uint32_t(s.positions.size());
    for (Vec3 v : {a, b, c}) s.positions.push_back(v + offset);
    s.triangles.push_back({k, k + 1, k + 2});
  };
  add({-100, 0, -100}, {100, 0, -100}, {100, 0, 100});
  add({-100, 0, -100}, {100, 0, 100}, {-100, 0, 100});
  add({-100, 0, 5}, {100, 0, 5}, {100, 50, 5});
  // Long thin diagonal slivers across the small ones.
  for (int i = 0; i < 8; ++i) add({-50, 0.1f * i, -50}, {50, 0.1f * i + 0.01f, 50}, {50, 0.1f * i, 50.1f});
  for (uint32_t i = 0; i < n; ++i) {
    Vec3 c{U(rng), std::fabs(U(rng)), U(rng)};
    add(c + Vec3{E(rng), E(rng), E(rng)}, c + Vec3{E(rng), E(rng), E(rng)}, c + Vec3{E(rng), E(rng), E(rng)});
  }
  s.ensure_views();
  return s;
}

// Leaf ancestors: for each leaf, the chain of boxes from the root.
struct Walk {
  const BVH& bvh;
  std::vector<std::vector<uint32_t>> leaves_of;  // triangle -> leaves referencing it
  std::vector<uint32_t> parent;
  explicit Walk(const BVH& b, size_t ntris) : bvh(b), leaves_of(ntris), parent(b.nodes.size(), UINT32_MAX) {
    std::vector<uint32_t> stack{0};
    while (!stack.empty()) {
      const uint32_t i = stack.back();
      stack.pop_back();
      const BVHNode& n = bvh.nodes[i];
      if (n.is_leaf()) {
        for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) leaves_of[bvh.prim_index[k]].push_back(i);
      } else {
        for (uint32_t c = n.left_first; c < n.left_first + 2; ++c) parent[c] = i, stack.push_back(c);
      }
    }
  }
  bool covered(uint32_t tri, Vec3 p) const {
    for (uint32_t leaf : leaves_of[tri]) {
      bool in = true;
      for (uint32_t i = leaf; i != UINT32_MAX && in; i = parent[i]) {
        const BVHNode& n = bvh.nodes[i];
        in = n.lo.x <= p.x && p.x <= n.hi.x && n.lo.y <= p.y && p.y <= n.hi.y && n.lo.z <= p.z && p.z <= n.hi.z;
      }
      if (in) return true;
    }
    return false;
  }
};

void check_spatial(const Scene& s, const BVH& bvh, int max_leaf, const SpatialSplitParams& sp) {
  const Walk w(bvh, s.num_triangles());
  uint32_t leaves = 0;
  for (size_t i = 0; i < bvh.nodes.size(); ++i) {
    if (i == 1) continue;
    const BVHNode& n = bvh.nodes[i];
    if (n.is_leaf()) {
      ++leaves;
      EXPECT_LE(int(n.count), max_leaf);
    } else {
      for (uint32_t c = n.left_first; c < n.left_first + 2; ++c)
        EXPECT_TRUE((AABB{n.lo, n.hi}.contains(AABB{bvh.nodes[c].lo, bvh.nodes[c].hi})));
    }
  }
  EXPECT_EQ(leaves, bvh.stats.leaves);
  // Duplicates within the budget (one spatial split may overshoot by the references it splits).
  EXPECT_LE(bvh.prim_index.size(), size_t(double(s.num_triangles()) * (1.0 + sp.budget) * 1.05 + 64));
  // Vertices, edge points and interior points of every triangle are covered.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  // Large scenes: a deterministic sample of triangles (every one is referenced, checked below).
  const uint32_t stride = std::max<uint32_t>(1, uint32_t(s.num_triangles() / 3000));
  for (uint32_t t = 0; t < s.num_triangles(); ++t) ASSERT_FALSE(w.leaves_of[t].empty()) << "triangle " << t;
  for (uint32_t t = 0; t < s.num_triangles(); t += stride) {
    ASSERT_FALSE(w.leaves_of[t].empty()) << "triangle " << t << " not referenced";
    const Vec3 a = s.vertex(t, 0), b = s.vertex(t, 1), c = s.vertex(t, 2);
    std::vector<Vec3> pts{a, b, c, (a + b) * 0.5f, (b + c) * 0.5f, (c + a) * 0.5f};
    for (int k = 0; k < 24; ++k) {
      float u = U(rng), v = U(rng);
      if (u + v > 1.f) u = 1.f - u, v = 1.f - v;
      pts.push_back(a + (b - a) * u + (c - a) * v);
      const float e = U(rng);  // a point on an edge
      pts.push_back(k % 3 == 0 ? a + (b - a) * e : k % 3 == 1 ? b + (c - b) * e : c + (a - c) * e);
    }
    for (const Vec3& p : pts) ASSERT_TRUE(w.covered(t, p)) << "triangle " << t << " point " << p.x << "," << p.y << "," << p.z;
  }
}

TEST(SpatialBVH, CoversEveryTriangleAndLowersSah) {
  const Scene s = small_on_large(4000, 11);
  BVHBuildParams p;
  p.max_leaf = 4;
  const SpatialSplitParams sp;
  const BVH plain = BVH::build(s, p);
  const BVH sbvh = build_spatial_bvh(s, p, sp);
  check_spatial(s, sbvh, p.max_leaf, sp);
  EXPECT_GT(sbvh.prim_index.size(), s.num_triangles()) << "no spatial split was made";
  EXPECT_LT(sbvh.stats.sah_cost, plain.stats.sah_cost * 0.9);
}

// SpatialSplitParams::wall: the built-in stadium is an enclosure (floor, roof and four walls of a
// 1000 x 150 x 600 box around stands and a teapot). Its triangles that span the scene on two axes
// are never clipped (one reference each); with wall = 0 (every triangle may be clipped, Stich et
// al. as published) the same build clips the enclosure. CoversEveryTriangleAndLowersSah checks
// that the default still clips the other large triangles (small_on_large's slivers).
TEST(SpatialBVH, EnclosureIsNeverClipped) {
  const Scene s = make_builtin_scene("stadium");
  const Vec3 root = s.bounds().extent();
  std::vector<uint32_t> walls;
  for (uint32_t t = 0; t < s.num_triangles(); ++t) {
    const Vec3 e = s.triangle_bounds(t).extent();
    if (int(e.x >= 0.8f * root.x) + int(e.y >= 0.8f * root.y) + int(e.z >= 0.8f * root.z) >= 2) walls.push_back(t);
  }
  ASSERT_GE(walls.size(), 12u);  // the enclosure's six faces, two triangles each
  BVHBuildParams p;
  SpatialSplitParams sp;
  ASSERT_EQ(sp.wall, 0.8f);
  const BVH b = build_spatial_bvh(s, p, sp);
  check_spatial(s, b, p.max_leaf, sp);
  const Walk w(b, s.num_triangles());
  size_t wall_refs = 0;
  for (uint32_t t : walls) {
    wall_refs += w.leaves_of[t].size();
    EXPECT_EQ(w.leaves_of[t].size(), 1u) << "enclosure triangle " << t << " was clipped";
  }
  sp.wall = 0;
  const BVH all = build_spatial_bvh(s, p, sp);
  check_spatial(s, all, p.max_leaf, sp);
  const Walk wa(all, s.num_triangles());
  size_t clipped_refs = 0;
  for (uint32_t t : walls) clipped_refs += wa.leaves_of[t].size();
  EXPECT_GT(clipped_refs, wall_refs) << "wall = 0 should clip the enclosure";
}

// SpatialSplitParams::walls_apart: the stadium's enclosure triangles (never clipped) are set apart
// near the root. The binned splits place each by its centroid among the stands, so every node
// from there to the root spans the enclosure and holds both: with the walls apart only the few
// nodes above the split do. The tree is valid, covers every triangle, and its SAH cost is lower.
TEST(SpatialBVH, WallsApartSetsTheEnclosureAside) {
  const Scene s = make_builtin_scene("stadium");
  const Vec3 root = s.bounds().extent();
  std::vector<uint8_t> wall(s.num_triangles(), 0);
  for (uint32_t t = 0; t < s.num_triangles(); ++t) {
    const Vec3 e = s.triangle_bounds(t).extent();
    wall[t] = int(e.x >= 0.8f * root.x) + int(e.y >= 0.8f * root.y) + int(e.z >= 0.8f * root.z) >= 2;
  }
  // Interior nodes whose subtree holds a wall and another triangle.
  const auto mixed_nodes = [&](const BVH& b) {
    std::vector<uint8_t> has(b.nodes.size(), 0);  // bit 0: a wall below, bit 1: another triangle
    uint32_t mixed = 0;
    const auto walk = [&](auto&& self, uint32_t i) -> uint8_t {
      const BVHNode& n = b.nodes[i];
      uint8_t m = 0;
      if (n.is_leaf()) {
        for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) m |= wall[b.prim_index[k]] ? 1 : 2;
        return m;
      }
      m = uint8_t(self(self, n.left_first) | self(self, n.left_first + 1));
      mixed += m == 3;
      return m;
    };
    walk(walk, 0);
    return mixed;
  };
  BVHBuildParams p;
  SpatialSplitParams sp;
  ASSERT_TRUE(sp.walls_apart);
  const BVH apart = build_spatial_bvh(s, p, sp);
  check_spatial(s, apart, p.max_leaf, sp);
  sp.walls_apart = false;
  const BVH binned = build_spatial_bvh(s, p, sp);
  const uint32_t m_apart = mixed_nodes(apart), m_binned = mixed_nodes(binned);
  std::printf("stadium: %u nodes hold a wall and a stand with the walls apart, %u binned; sah %.2f / %.2f\n",
              m_apart, m_binned, apart.stats.sah_cost, binned.stats.sah_cost);
  EXPECT_LE(m_apart, 4u);
  EXPECT_GT(m_binned, 2 * m_apart);
  EXPECT_LT(apart.stats.sah_cost, binned.stats.sah_cost);
  BVHBuildParams q = p;
  q.spatial = true;
  BVHBuildParams r = q;
  r.split_walls = false;
  EXPECT_NE(q.key(), r.key());
}

// SpatialSplitParams::overlap (Embree's criterion: spatial splits only where the object split's
// children overlap by more than that share of the node's own area): a valid covering tree with
// fewer duplicates than alpha alone gives, but some; overlap 1 (an overlap never exceeds the
// node's own area) leaves only object splits.
TEST(SpatialBVH, OverlapThresholdLimitsSpatialSplits) {
  const Scene s = make_builtin_scene("room");
  BVHBuildParams p;
  SpatialSplitParams sp;
  const BVH all = build_spatial_bvh(s, p, sp);
  sp.overlap = 0.2f;  // the room: 56.0 k references with alpha alone, 54.3 k with this, 52.1 k triangles
  const BVH some = build_spatial_bvh(s, p, sp);
  check_spatial(s, some, p.max_leaf, sp);
  EXPECT_LT(some.prim_index.size(), all.prim_index.size());
  EXPECT_GT(some.prim_index.size(), s.num_triangles()) << "no spatial split was made";
  sp.overlap = 1.f;
  const BVH none = build_spatial_bvh(s, p, sp);
  check_spatial(s, none, p.max_leaf, sp);
  EXPECT_EQ(none.prim_index.size(), s.num_triangles());
  BVHBuildParams q = p;
  q.spatial = true;
  BVHBuildParams r = q;
  r.split_overlap = 0.2f;
  EXPECT_NE(q.key(), r.key());
}

TEST(SpatialBVH, ZeroBudgetIsAnObjectSplitBvh) {
  const Scene s = small_on_large(1500, 5);
  BVHBuildParams p;
  SpatialSplitParams sp;
  sp.budget = 0;
  const BVH b = build_spatial_bvh(s, p, sp);
  EXPECT_EQ(b.prim_index.size(), s.num_triangles());
  check_spatial(s, b, p.max_leaf, sp);
}

TEST(SpatialBVH, HugeOffsetsAndBuiltinScenes) {
  BVHBuildParams p;
  const SpatialSplitParams sp;
  check_spatial(small_on_large(800, 2, {1.5e5f, -3e5f, 1e6f}), build_spatial_bvh(small_on_large(800, 2, {1.5e5f, -3e5f, 1e6f}), p, sp), p.max_leaf, sp);
  for (const char* name : {"room", "stadium", "sphere"}) {
    const Scene s = make_builtin_scene(name);
    check_spatial(s, build_spatial_bvh(s, p, sp), p.max_leaf, sp);
  }
}

// Coincident triangles (no object split can separate them) and a zero-area triangle.
Scene degenerate_scene() {
  Scene s;
  s.name = "degenerate";
  s.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {2, 2, 2}, {2, 2, 2}, {3, 3, 3}};
  for (int i = 0; i < 40; ++i) s.triangles.push_back({0, 1, 2});
  s.triangles.push_back({3, 4, 5});
  s.ensure_views();
  return s;
}
Scene one_triangle_scene() {
  Scene one;
  one.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  one.triangles = {{0, 1, 2}};
  one.ensure_views();
  return one;
}

TEST(SpatialBVH, DegenerateInputs) {
  BVHBuildParams p;
  const SpatialSplitParams sp;
  const Scene s = degenerate_scene();
  check_spatial(s, build_spatial_bvh(s, p, sp), p.max_leaf, sp);
  const BVH b = build_spatial_bvh(one_triangle_scene(), p, sp);
  EXPECT_EQ(b.prim_index.size(), 1u);
  EXPECT_TRUE(b.nodes[0].is_leaf());
}

}  // namespace
}  // namespace tb

namespace tb {
namespace {

// Every BVH-based scheme over a spatial-split BVH: no leak on the must-hit hard cases, and the
// ordinary workloads match the reference, as with the plain build (tests/test_schemes.cpp).
TEST(SpatialBVH, SchemesStayWatertight) {
  SchemeConfig cfg;
  cfg.params["spatial"] = "1";
  for (const char* scene : {"room", "sphere", "sphere@148376,1234,-223423", "stadium"}) {
    Bench bench(load_scene(scene));
    for (const char* scheme : {"bvh_single", "bvh_ranged", "bvh_partition", "mbvh4_single", "mbvh8_single", "mbvh_rs",
                               "cwbvh_single"}) {
      for (const std::string& w : hard_case_names()) {
        if (!hard_case_must_hit(w)) continue;
        const Accuracy a = test::accuracy_of(bench, scheme, test::small_spec(w, 48), cfg);
        EXPECT_EQ(a.false_miss, 0u) << scheme << " leaks on " << scene << " / " << w;
      }
      for (const char* w : {"primary", "bounce:2"}) {
        const Accuracy a = test::accuracy_of(bench, scheme, test::small_spec(w, 48), cfg);
        EXPECT_LE(a.mismatches, 1u) << scheme << " on " << scene << " / " << w;
        EXPECT_EQ(a.false_miss, 0u) << scheme << " on " << scene << " / " << w;
      }
    }
  }
}

}  // namespace
}  // namespace tb

namespace tb {
namespace {

// Embree's builder (BVHBuilder::embree, structures/embree_bvh.h) in travbench's layout: the same
// invariants as travbench's spatial-split builder (every point of every triangle in a leaf that
// references it and in all of that leaf's ancestors, leaf sizes, duplicates within the budget),
// plain and with spatial splits, at offsets, on the built-in scenes and on degenerate input.
TEST(EmbreeBVH, CoversEveryTriangle) {
  BVHBuildParams p;
  p.builder = BVHBuilder::embree;
  SpatialSplitParams sp;
  sp.budget = p.split_budget;
  const Scene s = small_on_large(3000, 7);
  const BVH plain = BVH::build(s, p);
  SpatialSplitParams none;
  none.budget = 0;
  check_spatial(s, plain, p.max_leaf, none);
  EXPECT_EQ(plain.prim_index.size(), s.num_triangles());
  p.spatial = true;
  const BVH split = BVH::build(s, p);
  check_spatial(s, split, p.max_leaf, sp);
  EXPECT_GT(split.prim_index.size(), s.num_triangles()) << "Embree made no spatial split";
  EXPECT_LT(split.stats.sah_cost, plain.stats.sah_cost);
  for (const Scene& o : {small_on_large(600, 3, {1.5e5f, -3e5f, 1e6f}), make_builtin_scene("room"),
                         make_builtin_scene("stadium")}) {
    check_spatial(o, BVH::build(o, p), p.max_leaf, sp);
  }
  p.max_leaf = 32;
  check_spatial(s, BVH::build(s, p), 32, sp);
  p.max_leaf = 33;
  EXPECT_THROW(BVH::build(s, p), std::invalid_argument);
}

TEST(EmbreeBVH, DegenerateAndEmptyInputs) {
  const Scene s = degenerate_scene();
  BVHBuildParams p;
  p.builder = BVHBuilder::embree;
  for (bool spatial : {false, true}) {
    p.spatial = spatial;
    SpatialSplitParams sp;
    check_spatial(s, BVH::build(s, p), p.max_leaf, sp);
    const BVH b = BVH::build(one_triangle_scene(), p);
    EXPECT_EQ(b.prim_index.size(), 1u);
    EXPECT_TRUE(b.nodes[0].is_leaf());
    Scene empty;
    empty.ensure_views();
    EXPECT_EQ(BVH::build(empty, p).prim_index.size(), 0u);
  }
}

// The schemes on Embree's tree: no leak on the must-hit hard cases, the ordinary workloads as the
// reference; and the cache keys the two builders' trees apart.
TEST(EmbreeBVH, SchemesStayWatertight) {
  for (const char* spatial : {"0", "1"}) {
    SchemeConfig cfg;
    cfg.params["builder"] = "embree";
    cfg.params["spatial"] = spatial;
    for (const char* scene : {"room", "sphere@148376,1234,-223423", "stadium"}) {
      Bench bench(load_scene(scene));
      for (const char* scheme : {"bvh_single", "bvh_ranged", "mbvh8_single", "mbvh_rs", "cwbvh_single"}) {
        for (const std::string& w : hard_case_names()) {
          if (!hard_case_must_hit(w)) continue;
          const Accuracy a = test::accuracy_of(bench, scheme, test::small_spec(w, 40), cfg);
          EXPECT_EQ(a.false_miss, 0u) << scheme << " leaks on " << scene << " / " << w << " spatial=" << spatial;
        }
        const Accuracy a = test::accuracy_of(bench, scheme, test::small_spec("bounce:2", 40), cfg);
        EXPECT_LE(a.mismatches, 1u) << scheme << " on " << scene << " spatial=" << spatial;
        EXPECT_EQ(a.false_miss, 0u) << scheme << " on " << scene << " spatial=" << spatial;
      }
    }
  }
  BVHBuildParams a, b;
  b.builder = BVHBuilder::embree;
  EXPECT_NE(a.key(), b.key());
}

}  // namespace
}  // namespace tb
