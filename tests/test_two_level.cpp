// Two-level BVH (structures/two_level.h, traversal/two_level.h): a top-level BVH over instances of
// objects with their own BVHs. The traversal's hits are checked against the exact oracle on the
// flattened scene (every instance's triangles transformed to world space, global prim ids), after
// building, after rigid motion (top refit and top rebuild), after deformation (object refit), with
// spatial-split object BVHs and with threaded object builds.
#include "structures/two_level.h"

#include "structures/builtin_scenes.h"
#include "traversal/exact.h"
#include "traversal/two_level.h"
#include "test_util.h"

namespace tb {
namespace {

Scene sphere_mesh() {
  Scene s;
  s.name = "sphere_obj";
  MeshBuilder(s).sphere({0, 0, 0}, 1.f, 24, 12);
  return s;
}
Scene torus_mesh() {
  Scene s;
  s.name = "torus_obj";
  MeshBuilder(s).torus({0, 0, 0}, 1.f, 0.35f, 32, 12);
  return s;
}

// Four instances of two objects, one of them rotated and scaled: the thesis' "group of 4 objects".
TwoLevelBVH group(const BVHBuildParams& p = {}, int threads = 1) {
  TwoLevelBVH tl;
  const uint32_t sphere = tl.add_object(sphere_mesh()), torus = tl.add_object(torus_mesh());
  tl.add_instance(sphere, Affine::translate({-1.5f, 0, 0}));
  tl.add_instance(torus, Affine::rotate_y_scale_translate(30.f, 1.25f, {1.5f, 0.2f, 0.3f}));
  tl.add_instance(sphere, Affine::rotate_y_scale_translate(-75.f, 0.5f, {0, 1.2f, -0.4f}));
  tl.add_instance(torus, Affine::rotate_y_scale_translate(110.f, 0.8f, {0.1f, -1.1f, 0.6f}));
  tl.build_objects(p, threads);
  tl.build_top();
  return tl;
}

// Hits of the two-level traversal against the exact oracle on the flattened scene.
Accuracy check(const TwoLevelBVH& tl, const std::string& workload, std::vector<Hit>* out = nullptr) {
  Bench bench(tl.flatten());
  const WorkloadSpec spec = test::small_spec(workload, 48);
  const RayBatch& rays = bench.rays(spec);
  std::vector<Hit> hits(rays.size());
  trace_two_level(tl, rays, hits);
  const ExactOracle oracle(bench.scene(), bench.cache());
  const Accuracy a = compare_hits(hits, bench.reference_hits(spec), [&](size_t i) {
    return oracle.ambiguous(rays.rays[i], hits[i], kDistanceBar);
  });
  size_t hit = 0;
  for (const Hit& h : bench.reference_hits(spec)) hit += h.hit();
  EXPECT_GT(hit, rays.size() / 50) << workload << ": the rays must see the group";
  if (out) *out = hits;
  return a;
}

void expect_exact(const TwoLevelBVH& tl, const std::string& what) {
  for (const char* w : {"primary", "rnd", "bounce:1"}) {
    const Accuracy a = check(tl, w);
    EXPECT_EQ(a.non_ambiguous(), 0u) << what << " " << w << ": " << a.false_miss << " leaks, " << a.false_hit
                                     << " false hits, " << a.wrong_t << " wrong t of " << a.rays;
  }
}

TEST(TwoLevel, AffineInverse) {
  const Affine m = Affine::rotate_y_scale_translate(37.f, 1.7f, {3, -2, 5});
  const Affine inv = m.inverse();
  for (Vec3 p : {Vec3{0, 0, 0}, Vec3{1, 2, 3}, Vec3{-4, 0.5f, 9}}) {
    const Vec3 q = inv.point(m.point(p));
    EXPECT_NEAR(q.x, p.x, 1e-5f);
    EXPECT_NEAR(q.y, p.y, 1e-5f);
    EXPECT_NEAR(q.z, p.z, 1e-5f);
  }
  Affine singular;
  singular.l = {1, 0, 0, 0, 0, 0, 0, 0, 1};
  EXPECT_THROW(singular.inverse(), InputError);
}

TEST(TwoLevel, StructureCoversTheGroup) {
  const TwoLevelBVH tl = group();
  EXPECT_EQ(tl.instances().size(), 4u);
  EXPECT_EQ(tl.num_triangles(), 2 * sphere_mesh().num_triangles() + 2 * torus_mesh().num_triangles());
  EXPECT_EQ(tl.top().prim_index.size(), 4u);
  // The top root holds every transformed vertex of every instance.
  const AABB root{tl.top().nodes[0].lo, tl.top().nodes[0].hi};
  const Scene flat = tl.flatten();
  for (const Vec3& p : flat.positions) EXPECT_TRUE(root.contains(AABB{p, p}));
  EXPECT_EQ(flat.num_triangles(), tl.num_triangles());
}

TEST(TwoLevel, TraversalMatchesFlattenedExactReference) { expect_exact(group(), "built"); }

TEST(TwoLevel, RigidMotionRefitAndRebuildTop) {
  TwoLevelBVH tl = group();
  tl.set_transform(0, Affine::rotate_y_scale_translate(45.f, 1.1f, {-1.2f, 0.5f, 0.2f}));
  tl.set_transform(3, Affine::translate({0.4f, -0.9f, 0.9f}));
  tl.refit_top();
  expect_exact(tl, "top refit");
  std::vector<Hit> refit_hits, rebuilt_hits;
  check(tl, "primary", &refit_hits);
  tl.build_top();
  expect_exact(tl, "top rebuilt");
  check(tl, "primary", &rebuilt_hits);
  ASSERT_EQ(refit_hits.size(), rebuilt_hits.size());
  for (size_t i = 0; i < refit_hits.size(); ++i) EXPECT_EQ(refit_hits[i].prim, rebuilt_hits[i].prim) << i;
}

TEST(TwoLevel, DeformedObjectRefit) {
  TwoLevelBVH tl = group();
  // Deform the sphere object (both its instances): stretch along x, bulge in y.
  for (Vec3& p : tl.object_mesh(0).positions) p = {p.x * 1.6f, p.y * (1.f + 0.3f * p.x * p.x), p.z};
  tl.refit_objects(2);
  tl.refit_top();
  expect_exact(tl, "object refit");
}

TEST(TwoLevel, SpatialSplitObjectsAndThreads) {
  BVHBuildParams sp;
  sp.spatial = true;
  expect_exact(group(sp), "spatial");
  // Threaded object builds make the same trees: bit-identical hits.
  std::vector<Hit> one, four;
  check(group({}, 1), "rnd", &one);
  check(group({}, 4), "rnd", &four);
  ASSERT_EQ(one.size(), four.size());
  for (size_t i = 0; i < one.size(); ++i) {
    EXPECT_EQ(one[i].prim, four[i].prim) << i;
    EXPECT_EQ(one[i].t, four[i].t) << i;
  }
}

TEST(TwoLevel, BadInput) {
  TwoLevelBVH tl;
  EXPECT_THROW(tl.add_instance(0, Affine{}), InputError);
  EXPECT_THROW(tl.build_top(), InputError);
  tl.add_object(sphere_mesh());
  tl.add_instance(0, Affine{});
  EXPECT_THROW(tl.build_top(), InputError) << "top level before the object BVHs";
  EXPECT_THROW(tl.refit_top(), InputError);
}

}  // namespace
}  // namespace tb
