// RayGrid (thesis §5.3): the octree's invariants checked by brute force — leaves tile the root,
// every triangle is referenced by every leaf it overlaps, neighbour links lead to the adjacent
// same-size-or-larger node — and the scheme against the reference on every workload with tiny,
// default and big queues and deep octrees, and on rays built to run along the octree's seams:
// from outside the bounds, from origins on faces, edges and corners of leaves, axis-parallel
// along shared faces (+0 and -0), through leaf corners, with tmin > 0 and short tmax.
#include <cstring>
#include <map>
#include <random>

#include "structures/bvh_spatial.h"
#include "structures/clip.h"
#include "structures/octree.h"
#include "test_geometry.h"
#include "traversal/raygrid_stats.h"
#include "workloads/hard_cases.h"
#include "test_util.h"

namespace tb {
namespace {

using test::sat_overlap;

// Small and huge triangles mixed: the huge ones cross many leaves.
Scene random_soup(uint32_t n, uint32_t seed) { return test::random_triangles(n, seed, {.huge_every = 50}); }

AABB box_of(const OctreeNode& n) { return {n.lo, n.hi}; }

void check_octree(const Scene& scene, const Octree& o, const std::string& what) {
  SCOPED_TRACE(what);
  ASSERT_FALSE(o.nodes.empty());
  const OctreeNode& root = o.nodes[0];
  EXPECT_TRUE(box_of(root).contains(scene.bounds())) << "root does not hold the scene";
  // Structure: children are the exact octants of their parent (sharing the split floats), so
  // the leaves tile the root without gaps or overlaps.
  double leaf_volume = 0;
  uint32_t leaves = 0;
  for (uint32_t i = 0; i < o.nodes.size(); ++i) {
    const OctreeNode& n = o.nodes[i];
    if (n.is_leaf()) {
      ++leaves;
      ASSERT_LT(n.leaf, o.leaves.size());
      EXPECT_EQ(o.leaves[n.leaf].node, i);
      leaf_volume += (double(n.hi.x) - n.lo.x) * (double(n.hi.y) - n.lo.y) * (double(n.hi.z) - n.lo.z);
      EXPECT_LE(n.depth, uint32_t(o.params.max_depth));
      continue;
    }
    for (uint32_t c = 0; c < 8; ++c) {
      const OctreeNode& k = o.nodes[n.child + c];
      EXPECT_EQ(k.parent, i);
      EXPECT_EQ(k.depth, n.depth + 1);
      for (int a = 0; a < 3; ++a) {
        const bool up = (c >> a) & 1;
        EXPECT_EQ(k.lo[a], up ? n.mid[a] : n.lo[a]);
        EXPECT_EQ(k.hi[a], up ? n.hi[a] : n.mid[a]);
        EXPECT_GE(n.mid[a], n.lo[a]);
        EXPECT_LE(n.mid[a], n.hi[a]);
      }
    }
  }
  EXPECT_EQ(leaves, o.leaves.size());
  const Vec3 re = root.hi - root.lo;
  const double root_volume = (double(root.hi.x) - root.lo.x) * (double(root.hi.y) - root.lo.y) * (double(root.hi.z) - root.lo.z);
  EXPECT_NEAR(leaf_volume, root_volume, 1e-12 * root_volume);

  // Point location: a random point lies in the closed box of the leaf found, and a point
  // strictly inside a leaf lies strictly inside no other.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  for (int k = 0; k < 300; ++k) {
    const Vec3 p = root.lo + Vec3{U(rng) * re.x, U(rng) * re.y, U(rng) * re.z};
    const Vec3 d{U(rng) - .5f, U(rng) - .5f, U(rng) - .5f};
    const uint32_t l = o.locate(0, p, d);
    ASSERT_TRUE(o.nodes[l].is_leaf());
    for (int a = 0; a < 3; ++a) EXPECT_TRUE(p[a] >= o.nodes[l].lo[a] && p[a] <= o.nodes[l].hi[a]);
    if (o.strictly_inside(l, p)) {
      int inside = 0;
      for (const OctreeLeaf& lf : o.leaves) inside += o.strictly_inside(lf.node, p);
      EXPECT_EQ(inside, 1);
    }
  }

  // Every triangle is referenced by every leaf whose closed box it overlaps (brute force over
  // leaf x triangle with the independent SAT test), and only by leaves it comes close to.
  std::vector<AABB> tb(scene.num_triangles());
  for (uint32_t t = 0; t < scene.num_triangles(); ++t) tb[t] = scene.triangle_bounds(t);
  size_t missing = 0, spurious = 0;
  for (uint32_t l = 0; l < o.leaves.size(); ++l) {
    const OctreeNode& n = o.nodes[o.leaves[l].node];
    const AABB box = box_of(n);
    const std::vector<uint32_t> refs = o.leaf_triangles(l);
    EXPECT_EQ(refs.size(), o.leaves[l].empty() ? 0u : size_t(o.leaves[l].refs));
    for (uint32_t t = 0; t < scene.num_triangles(); ++t) {
      const AABB& b = tb[t];
      if (b.lo.x > box.hi.x || b.hi.x < box.lo.x || b.lo.y > box.hi.y || b.hi.y < box.lo.y || b.lo.z > box.hi.z ||
          b.hi.z < box.lo.z)
        continue;
      if (sat_overlap(scene.vertex(t, 0), scene.vertex(t, 1), scene.vertex(t, 2), box) &&
          !std::binary_search(refs.begin(), refs.end(), t))
        ++missing;
    }
    const AABB near{box.lo - Vec3{2 * o.pad, 2 * o.pad, 2 * o.pad}, box.hi + Vec3{2 * o.pad, 2 * o.pad, 2 * o.pad}};
    for (uint32_t t : refs)
      if (!sat_overlap(scene.vertex(t, 0), scene.vertex(t, 1), scene.vertex(t, 2), near)) ++spurious;
    // The mini-MBVH's bounds lie within the padded leaf.
    if (!o.leaves[l].empty()) {
      EXPECT_TRUE(near.contains(o.leaves[l].cull));
    }
  }
  EXPECT_EQ(missing, 0u) << "triangles missing from leaves they overlap";
  EXPECT_EQ(spurious, 0u) << "triangles referenced by leaves they do not touch";

  // Neighbour links: across each face, the same-size node sharing it, else the larger leaf
  // that covers it, else (scene boundary) none.
  for (uint32_t i = 0; i < o.nodes.size(); ++i) {
    const OctreeNode& n = o.nodes[i];
    for (int a = 0; a < 3; ++a)
      for (int s = 0; s < 2; ++s) {
        const float plane = s ? n.hi[a] : n.lo[a];
        const int b1 = (a + 1) % 3, b2 = (a + 2) % 3;
        uint32_t same = kNoNode, larger = kNoNode;
        for (uint32_t j = 0; j < o.nodes.size(); ++j) {
          const OctreeNode& m = o.nodes[j];
          if ((s ? m.lo[a] : m.hi[a]) != plane) continue;  // must lie across the face
          if (m.depth == n.depth && m.lo[b1] == n.lo[b1] && m.hi[b1] == n.hi[b1] && m.lo[b2] == n.lo[b2] &&
              m.hi[b2] == n.hi[b2])
            same = j;
          if (m.is_leaf() && m.depth < n.depth && m.lo[b1] <= n.lo[b1] && m.hi[b1] >= n.hi[b1] && m.lo[b2] <= n.lo[b2] &&
              m.hi[b2] >= n.hi[b2])
            larger = j;
        }
        const uint32_t want = same != kNoNode ? same : larger;
        EXPECT_EQ(n.nbr[face_of(a, s)], want) << "node " << i << " face " << face_of(a, s);
        if (plane == (s ? root.hi[a] : root.lo[a])) {
          EXPECT_EQ(n.nbr[face_of(a, s)], kNoNode);
        }
      }
  }
}

TEST(Octree, InvariantsByBruteForce) {
  struct Case {
    std::string scene;
    int leaf_prims, max_depth;
  };
  for (const Case& c : std::vector<Case>{{"sphere", 64, 10},
                                         {"spheres:2000", 16, 10},
                                         {"room", 2048, 10},
                                         {"sphere@1483760,12340,-2234230", 64, 10},
                                         {"stadium", 4096, 8}}) {
    const Scene s = load_scene(c.scene);
    OctreeParams p;
    p.leaf_prims = c.leaf_prims, p.max_depth = c.max_depth;
    check_octree(s, Octree::build(s, p), c.scene + " leaf_prims=" + std::to_string(c.leaf_prims));
  }
  const Scene soup = random_soup(1500, 3);
  OctreeParams p;
  p.leaf_prims = 32;
  check_octree(soup, Octree::build(soup, p), "soup");
}

// leaf_prims = 1 with a deep max_depth (both in range) split every node of two triangles: 5.7 GB
// and a minute on room before the process was killed. The build now stops at a budget of nodes and
// references with an error that names the two parameters; the thesis' settings stay far below it.
TEST(Octree, ExplodingParametersAreRefusedNamingThem) {
  const Scene s = load_scene("sphere");
  OctreeParams p;
  p.leaf_prims = 1, p.max_depth = 12;
  try {
    (void)Octree::build(s, p);
    ADD_FAILURE() << "leaf_prims=1 max_depth=12 built";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("leaf_prims=1 with max_depth=12"), std::string::npos) << e.what();
  }
  p.leaf_prims = 8, p.max_depth = 10;
  EXPECT_NO_THROW((void)Octree::build(s, p));
}

TEST(Octree, AdaptsToComplexity) {
  const Scene s = load_scene("stadium");  // a dense teapot in a huge, nearly empty box
  OctreeParams p;
  p.leaf_prims = 512;
  const Octree o = Octree::build(s, p);
  EXPECT_GT(o.stats.max_depth, 4u);
  EXPECT_LT(o.stats.avg_leaf_depth, double(o.stats.max_depth));  // shallow where the stadium is empty
  EXPECT_GT(o.stats.empty_leaves, 0u);
  // Without enough triangles to split, the root is the only leaf.
  p.leaf_prims = 1 << 30;
  EXPECT_EQ(Octree::build(s, p).stats.leaves, 1u);
}

// The mini-MBVHs (octree.h): each leaf's wide tree lies in its own node and block ranges, its
// child boxes nest and hold the leaf's triangles clipped to the padded leaf (the boxes the binary
// builder was given), every referenced triangle sits in exactly one of its leaf slots — and the
// tree is exactly what the one builder path makes of those references: BVH::build over the span
// of clipped boxes, then MBVH::collapse, placed by MBVH::concat.
template <int N>
void check_minis(const Scene& scene, const Octree& o, const MBVH<N, 4>& mini) {
  ASSERT_EQ(mini.stats.nodes, mini.nodes.size());
  MBVHBuildParams mp;
  mp.bvh = o.params.bvh;
  mp.merge = o.params.merge;
  mp.sah_collapse = N == 8;
  mp.small = 0;
  uint32_t next_node = 0, next_block = 0;
  for (uint32_t l = 0; l < o.leaves.size(); ++l) {
    const OctreeLeaf& lf = o.leaves[l];
    if (lf.empty()) continue;
    SCOPED_TRACE(::testing::Message() << "leaf " << l);
    EXPECT_EQ(lf.first_node, next_node) << "leaves are laid out one after another";
    EXPECT_EQ(lf.first_block, next_block);
    next_node += lf.num_nodes, next_block += lf.num_blocks;
    const OctreeNode& on = o.nodes[lf.node];
    const AABB padded{on.lo - Vec3{o.pad, o.pad, o.pad}, on.hi + Vec3{o.pad, o.pad, o.pad}};
    const std::vector<uint32_t> tris = o.leaf_triangles(l);  // ascending: the build's order
    std::vector<PrimRef> refs;
    std::map<uint32_t, AABB> clipped;
    for (uint32_t t : tris) {
      const AABB b = clip_triangle_bounds(scene.vertex(t, 0), scene.vertex(t, 1), scene.vertex(t, 2), padded);
      ASSERT_FALSE(b.empty()) << "triangle " << t << " does not touch the leaf that references it";
      clipped[t] = padded.contains(scene.triangle_bounds(t)) ? scene.triangle_bounds(t) : b;
      refs.emplace_back(clipped[t], t);
    }
    // Walk: ranges, nesting, the clipped boxes in their slots, each triangle once.
    std::map<uint32_t, int> seen;
    std::vector<std::pair<uint32_t, AABB>> stack{{lf.mbvh_root, lf.cull}};
    while (!stack.empty()) {
      const auto [ni, parent] = stack.back();
      stack.pop_back();
      ASSERT_TRUE(ni >= lf.first_node && ni < lf.first_node + lf.num_nodes) << "node outside its leaf's range";
      const MBVHNode<N>& n = mini.nodes[ni];
      for (uint32_t i = 0; i < n.num_children; ++i) {
        const AABB b = n.child_box(int(i));
        EXPECT_TRUE(parent.contains(b)) << "child box outside its parent";
        const uint32_t r = n.ref[i];
        if (!mbvh_ref::is_leaf(r)) {
          stack.push_back({r, b});
          continue;
        }
        const uint32_t first = mbvh_ref::first_block(r), cnt = mbvh_ref::num_tris(r);
        ASSERT_TRUE(first >= lf.first_block && first + (cnt + 3) / 4 <= lf.first_block + lf.num_blocks);
        for (uint32_t k = 0; k < cnt; ++k) {
          const uint32_t t = mini.blocks[first + k / 4].prim[k % 4];
          ASSERT_TRUE(clipped.count(t)) << "triangle " << t << " not referenced by the leaf";
          seen[t]++;
          // With spatial splits a slot holds the part of the triangle its binary leaf was given
          // (clipped again by the builder); its box need not hold the whole leaf-clipped one.
          if (!mp.bvh.spatial) EXPECT_TRUE(b.contains(clipped[t])) << "clipped box of " << t << " outside its slot";
        }
      }
    }
    EXPECT_EQ(seen.size(), tris.size());
    // Once each; a spatial-split build may reference a triangle from several of its leaves.
    for (const auto& [t, c] : seen) {
      if (mp.bvh.spatial) EXPECT_GE(c, 1) << "triangle " << t;
      else EXPECT_EQ(c, 1) << "triangle " << t;
    }
    // The one builder path, node for node and block for block (rebased by the leaf's offsets).
    BVH bvh;
    if (mp.bvh.spatial) {
      std::vector<SpatialRef> srefs;
      for (const PrimRef& r : refs) srefs.push_back({r.box(), r.id()});
      bvh = build_spatial_bvh(scene, std::move(srefs), mp.bvh, spatial_split_params(mp.bvh));
    } else {
      bvh = BVH::build(std::span<PrimRef>(refs), mp.bvh);
    }
    EXPECT_EQ(lf.cull.lo, bvh.nodes[0].lo);
    EXPECT_EQ(lf.cull.hi, bvh.nodes[0].hi);
    const MBVH<N, 4> own = MBVH<N, 4>::collapse(scene, bvh, mp);
    ASSERT_EQ(own.nodes.size(), lf.num_nodes);
    ASSERT_EQ(own.blocks.size(), lf.num_blocks);
    EXPECT_EQ(own.stats.max_depth, lf.mbvh_depth);
    for (uint32_t k = 0; k < lf.num_nodes; ++k) {
      const MBVHNode<N>& a = own.nodes[k];
      const MBVHNode<N>& b = mini.nodes[lf.first_node + k];
      EXPECT_EQ(std::memcmp(a.box, b.box, sizeof a.box), 0) << "node " << k;
      ASSERT_EQ(a.num_children, b.num_children);
      for (uint32_t i = 0; i < a.num_children; ++i) {
        const uint32_t r = a.ref[i];
        EXPECT_EQ(b.ref[i], mbvh_ref::is_leaf(r) ? mbvh_ref::make_leaf(mbvh_ref::first_block(r) + lf.first_block,
                                                                       mbvh_ref::num_tris(r))
                                                 : r + lf.first_node);
      }
    }
    for (uint32_t k = 0; k < lf.num_blocks; ++k)
      EXPECT_EQ(std::memcmp(&own.blocks[k], &mini.blocks[lf.first_block + k], sizeof(TriBlock<4>)), 0) << "block " << k;
  }
  EXPECT_EQ(next_node, mini.nodes.size());
  EXPECT_EQ(next_block, mini.blocks.size());
}

TEST(Octree, MiniMBVHsComeFromTheOneBuilder) {
  const Scene soup = random_soup(3000, 9);
  for (int width : {4, 8})
  for (bool spatial : {false, true}) {
    SCOPED_TRACE(::testing::Message() << "width " << width << " spatial " << spatial);
    OctreeParams p;
    p.leaf_prims = 300;
    p.width = width;
    p.bvh.spatial = spatial;
    const Octree o = Octree::build(soup, p);
    ASSERT_GT(o.leaves.size(), 8u);
    if (width == 8) {
      EXPECT_TRUE(o.mini.nodes.empty());
      check_minis(soup, o, o.mini8);
    } else {
      EXPECT_TRUE(o.mini8.nodes.empty());
      check_minis(soup, o, o.mini);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// The scheme against the reference

SchemeConfig config(std::initializer_list<std::pair<const char*, int>> kv) {
  SchemeConfig c;
  for (const auto& [k, v] : kv) c.params[k] = std::to_string(v);
  return c;
}

using test::bench_for;

// A conventional traversal with raygrid's float watertight kernel (the same float operations,
// the hit distance from the same double-precision plane equation): the two must agree ray for
// ray, so any difference is a triangle the octree walk failed to offer — a stricter check than
// the comparison with the double-precision reference, which differs from every float kernel on
// a few grazing and vertex rays.
const Traverser& twin(Bench& bench) {
  // Keyed by the scene too: a bench that lives on the stack may reuse an address.
  static std::map<std::pair<const Bench*, std::string>, std::unique_ptr<Traverser>> twins;
  auto& t = twins[{&bench, bench.scene().name}];
  if (!t) {
    bool mbvh = false;
    for (const auto& s : schemes()) mbvh |= s.name == "mbvh4_single";
    t = make_scheme(mbvh ? "mbvh4_single" : "bvh_single");
    t->prepare(bench.scene(), bench.cache());
  }
  return *t;
}

// Traces `batch` with raygrid (2 threads over the packets, as the harness does) and the twin.
struct Outcome {
  Accuracy vs_twin;
  RayGridStats stats;
};
Outcome trace_against_twin(Bench& bench, const SchemeConfig& cfg, const RayBatch& batch, int threads = 2) {
  auto t = make_scheme("raygrid", cfg);
  t->prepare(bench.scene(), bench.cache());
  std::vector<Hit> hits(batch.size()), tw(batch.size());
  trace_batch(*t, batch, hits, threads);
  trace_batch(twin(bench), batch, tw, 2);
  return {compare_hits(hits, tw), *raygrid_stats(*t)};
}

const std::vector<std::pair<std::string, SchemeConfig>>& configs() {
  static const std::vector<std::pair<std::string, SchemeConfig>> c = {
      {"default", {}},
      {"queue=1", config({{"queue", 1}})},
      {"queue=7", config({{"queue", 7}})},
      {"queue=1024", config({{"queue", 1024}})},
      {"leaf_prims=64", config({{"leaf_prims", 64}, {"max_depth", 8}})},
      {"leaf_prims=64,queue=7", config({{"leaf_prims", 64}, {"max_depth", 8}, {"queue", 7}})},
      // The thesis' 4-wide mini-MBVHs (the default is 8 wide).
      {"width=4", config({{"width", 4}})},
      // Spatial splits in the mini-BVHs (issue 17: every BVH-based scheme takes them).
      {"spatial=1", config({{"spatial", 1}})},
      {"spatial=1,width=4,leaf_prims=64", config({{"spatial", 1}, {"width", 4}, {"leaf_prims", 64}, {"max_depth", 8}})},
      {"width=4,leaf_prims=64,queue=7", config({{"width", 4}, {"leaf_prims", 64}, {"max_depth", 8}, {"queue", 7}})},
  };
  return c;
}

TEST(RayGrid, MatchesReferenceOnEveryWorkloadAndParameter) {
  std::vector<std::string> workloads = {"primary", "divergence:8", "rnd", "rnd2", "bounce:1", "bounce:3", "shadow"};
  for (const auto& h : hard_case_names()) workloads.push_back(h);
  for (const std::string scene : {"room", "sphere", "stadium", "spheres:2000"}) {
    Bench& bench = bench_for(scene);
    for (const auto& [label, cfg] : configs()) {
      auto t = make_scheme("raygrid", cfg);
      t->prepare(bench.scene(), bench.cache());
      for (const auto& w : workloads) {
        const WorkloadSpec spec = test::small_spec(w, 64);
        const RayBatch& b = bench.rays(spec);
        std::vector<Hit> hits(b.size()), tw(b.size());
        trace_batch(*t, b, hits, 2);
        trace_batch(twin(bench), b, tw, 2);
        const Accuracy a = compare_hits(hits, bench.reference_hits(spec)), at = compare_hits(hits, tw);
        if (w.rfind("hard:", 0) != 0) {
          // The suite's bar against the reference (test_schemes.cpp), and hit for hit with the twin.
          EXPECT_LE(a.mismatches, 1u) << scene << " " << label << " " << w;
          EXPECT_EQ(a.false_miss, 0u) << scene << " " << label << " " << w;
          EXPECT_EQ(at.mismatches, 0u) << scene << " " << label << " " << w << " vs twin";
          continue;
        }
        // Hard cases: float kernels disagree with the double-precision reference on rays through
        // vertices and edges, and box culling decides which of those near-misses a float kernel
        // sees, so the twin may differ on a handful; leaks are what must not happen.
        EXPECT_LE(at.mismatches, std::max<uint64_t>(3, b.size() / 500)) << scene << " " << label << " " << w << " vs twin";
        const Accuracy twin_ref = compare_hits(tw, bench.reference_hits(spec));
        if (hard_case_must_hit(w)) {
          EXPECT_LE(a.false_miss, twin_ref.false_miss) << scene << " " << label << " " << w;
          if (scene != "spheres:2000") {  // the others are closed around the interior point
            EXPECT_EQ(a.false_miss, 0u) << scene << " " << label << " " << w;
          }
        }
        if (w == "hard:tmin_tmax") {
          EXPECT_EQ(a.false_hit, 0u) << scene << " " << label;
        }
      }
      const RayGridStats s = *raygrid_stats(*t);
      EXPECT_EQ(s.fallbacks, 0u) << scene << " " << label << ": the walk hit its step limit";
      EXPECT_GT(s.queues, 0u);
      EXPECT_LE(s.avg_fill(), double(s.queue_size));
    }
  }
}

TEST(RayGrid, NoLeaksWithHugeOffsets) {
  for (const std::string scene : {"sphere@148376,1234,-223423", "sphere@1483760,12340,-2234230",
                                  "room@-250000,100000,730000"}) {
    Bench& bench = bench_for(scene);
    for (const auto& [label, cfg] : configs()) {
      for (const auto& w : hard_case_names()) {
        if (!hard_case_must_hit(w)) continue;
        const Accuracy a = test::accuracy_of(bench, "raygrid", test::small_spec(w, 64), cfg);
        EXPECT_EQ(a.false_miss, 0u) << "leaks on " << scene << " " << label << " " << w;
      }
    }
  }
}

// Rays built to stress the octree walk: every seam of a deep octree.
RayBatch seam_rays(const Octree& o, uint32_t seed) {
  RayBatch b;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  const OctreeNode& root = o.nodes[0];
  const Vec3 re = root.hi - root.lo, rc = (root.lo + root.hi) * 0.5f;
  auto interior = [&] { return root.lo + Vec3{U(rng) * re.x, U(rng) * re.y, U(rng) * re.z}; };
  auto random_dir = [&] {
    Vec3 d;
    do d = Vec3{U(rng) - .5f, U(rng) - .5f, U(rng) - .5f};
    while (length(d) < 0.05f);
    return normalize(d);
  };
  auto add = [&](Vec3 org, Vec3 dir, float tmin = 0.f, float tmax = INFINITY) {
    if (length(dir) > 0.f) b.rays.push_back({org, tmin, dir, tmax});
  };
  // Axis-parallel directions with +0 and -0 in the other components.
  auto axis_dir = [](int a, bool neg, int zeros) {
    Vec3 d{zeros & 1 ? -0.f : 0.f, zeros & 2 ? -0.f : 0.f, zeros & 4 ? -0.f : 0.f};
    d[a] = neg ? -1.f : 1.f;
    return d;
  };
  std::vector<uint32_t> leaves;
  for (uint32_t l = 0; l < o.leaves.size(); l += std::max<uint32_t>(1, uint32_t(o.leaves.size()) / 150)) leaves.push_back(l);
  for (uint32_t l : leaves) {
    const OctreeNode& n = o.nodes[o.leaves[l].node];
    const Vec3 c = (n.lo + n.hi) * 0.5f;
    // Origins on the leaf's corners, edge midpoints and face centres; random and axis directions.
    for (int k = 0; k < 27; ++k) {
      Vec3 p;
      for (int a = 0; a < 3; ++a) {
        const int s = (k / (a == 0 ? 1 : a == 1 ? 3 : 9)) % 3;
        p[a] = s == 0 ? n.lo[a] : s == 1 ? c[a] : n.hi[a];
      }
      add(p, random_dir());
      add(p, axis_dir(k % 3, k & 1, k % 8));
    }
    // From a random interior point exactly through the leaf's corners (exits through edges and
    // corners of the octree).
    for (int k = 0; k < 8; ++k) {
      const Vec3 corner{k & 1 ? n.hi.x : n.lo.x, k & 2 ? n.hi.y : n.lo.y, k & 4 ? n.hi.z : n.lo.z};
      const Vec3 from = interior();
      add(from, normalize(corner - from));
    }
    // Axis-parallel along the leaf's faces (which are shared with its neighbours): the origin
    // on the face plane, the direction inside that plane.
    for (int a = 0; a < 3; ++a)
      for (int s = 0; s < 2; ++s) {
        Vec3 p = c;
        p[a] = s ? n.hi[a] : n.lo[a];
        for (int b2 = 0; b2 < 3; ++b2)
          if (b2 != a)
            for (int zeros = 0; zeros < 8; zeros += 3) {
              add(p, axis_dir(b2, false, zeros));
              add(p, axis_dir(b2, true, zeros));
            }
        // ... and along the face's edges.
        Vec3 e = p;
        const int b1 = (a + 1) % 3;
        e[b1] = n.lo[b1];
        add(e, axis_dir((a + 2) % 3, s, 5));
      }
  }
  // From outside the bounds: aimed at interior points, at octree corners, and away.
  for (int k = 0; k < 400; ++k) {
    const Vec3 dir = random_dir();
    const Vec3 from = rc - dir * (length(re) * (0.6f + 2.f * U(rng)));
    const OctreeNode& n = o.nodes[o.leaves[k % o.leaves.size()].node];
    add(from, normalize(interior() - from));
    add(from, normalize(n.lo - from));
    add(from, -dir);
  }
  // From outside along the axes, grazing the bounds' faces.
  for (int a = 0; a < 3; ++a)
    for (int k = 0; k < 30; ++k) {
      Vec3 p = interior();
      p[a] = root.lo[a] - re[a];
      const int b1 = (a + 1) % 3;
      if (k % 3 == 0) p[b1] = root.lo[b1];
      if (k % 3 == 1) p[b1] = root.hi[b1];
      add(p, axis_dir(a, false, k % 8));
    }
  // Interval variants: tmin > 0 and short tmax.
  const size_t base = b.rays.size();
  for (size_t i = 0; i < base; i += 3) {
    const Ray r = b.rays[i];
    add(r.org, r.dir, 0.25f * length(re) * U(rng));
    add(r.org, r.dir, 0.f, 0.3f * length(re) * U(rng));
  }
  b.group_uniform(256);
  return b;
}

TEST(RayGrid, SeamRays) {
  for (const std::string scene : {"room", "sphere", "stadium", "sphere@1483760,12340,-2234230"}) {
    Bench& bench = bench_for(scene);
    for (const auto& [label, cfg] : configs()) {
      auto t = make_scheme("raygrid", cfg);
      t->prepare(bench.scene(), bench.cache());
      const RayBatch batch = seam_rays(*raygrid_octree(*t), 11);
      ASSERT_GT(batch.size(), 1000u);
      // Many of these rays start on the scene's walls (the root's faces are the bounds), where
      // float and double kernels disagree about hits at t ~ 0: the twin with the same float
      // kernel is the yardstick, and it must match ray for ray.
      const Outcome out = trace_against_twin(bench, cfg, batch);
      EXPECT_EQ(out.vs_twin.mismatches, 0u) << scene << " " << label << " of " << batch.size();
      EXPECT_EQ(out.stats.fallbacks, 0u) << scene << " " << label;
    }
  }
}

// Flat and tiny scenes: a single triangle, and a flat quad grid (zero extent on one axis, so
// the root is widened and rays run inside the plane of every triangle). Rays in the plane of a
// triangle are edge-on — never a hit for the float kernels, while the double-precision reference
// decides some of them otherwise — so the twin is the yardstick here.
TEST(RayGrid, DegenerateScenes) {
  std::vector<Scene> scenes(2);
  scenes[0].name = "one";
  scenes[0].positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  scenes[0].triangles = {{0, 1, 2}};
  scenes[1].name = "flat";
  for (int y = 0; y <= 20; ++y)
    for (int x = 0; x <= 20; ++x) scenes[1].positions.push_back({float(x), float(y), 0.f});
  for (uint32_t y = 0; y < 20; ++y)
    for (uint32_t x = 0; x < 20; ++x) {
      const uint32_t a = y * 21 + x;
      scenes[1].triangles.push_back({a, a + 1, a + 22});
      scenes[1].triangles.push_back({a, a + 22, a + 21});
    }
  for (Scene& sc : scenes) {
    sc.ensure_views();
    Bench bench(sc);
    RayBatch b;
    std::mt19937 rng(9);
    std::uniform_real_distribution<float> U(-1.f, 1.f);
    const AABB box = bench.scene().bounds();
    const Vec3 c = box.centre(), e = box.extent();
    for (int k = 0; k < 4000; ++k) {
      const Vec3 from = c + Vec3{U(rng) * 2 * e.x, U(rng) * 2 * e.y, U(rng) * 3};
      const Vec3 to = c + Vec3{U(rng) * e.x, U(rng) * e.y, 0.f};
      if (length(to - from) > 0.f) b.rays.push_back({from, 0.f, normalize(to - from), INFINITY});
      // In the plane z = 0, axis-parallel (+0 and -0 in z).
      Vec3 d{k & 1 ? 1.f : -1.f, 0.f, k & 2 ? -0.f : 0.f};
      if (k & 4) std::swap(d.x, d.y);
      b.rays.push_back({Vec3{c.x + U(rng) * e.x, c.y + U(rng) * e.y, 0.f}, 0.f, d, INFINITY});
    }
    b.group_uniform(256);
    for (const auto& [label, cfg] : configs()) {
      const Outcome out = trace_against_twin(bench, cfg, b);
      EXPECT_EQ(out.vs_twin.mismatches, 0u) << sc.name << " " << label;
      EXPECT_EQ(out.stats.fallbacks, 0u) << sc.name << " " << label;
    }
  }
}

TEST(RayGrid, QueuesAndMemory) {
  Bench& bench = bench_for("room");
  const WorkloadSpec spec = test::small_spec("bounce:2", 96);
  const RayBatch& b = bench.rays(spec);
  for (int m : {1, 7, 64, 384, 1024}) {
    SchemeConfig cfg = config({{"queue", m}, {"leaf_prims", 512}});
    auto t = make_scheme("raygrid", cfg);
    t->prepare(bench.scene(), bench.cache());
    std::vector<Hit> hits(b.size());
    t->trace(b, PacketRange::all(b), hits);  // one call: every ray fed at once
    const RayGridStats s = *raygrid_stats(*t);
    const Octree& o = *raygrid_octree(*t);
    EXPECT_EQ(s.calls, 1u);
    EXPECT_EQ(s.rays, b.size());
    EXPECT_EQ(s.queues, s.full_queues + s.partial_queues);
    EXPECT_GE(s.queued_rays, s.rays - s.outside);  // every ray visits at least one leaf ...
    EXPECT_LE(s.avg_fill(), double(m));
    EXPECT_EQ(s.queue_size, uint32_t(m));
    // ... and the queues never need more than (O * M + N) records (§5.3.5).
    EXPECT_LE(s.peak_queues, (b.size() + m - 1) / m + o.leaves.size() + 2);
    EXPECT_EQ(s.peak_bytes, s.peak_queues * uint64_t(m) * 36);
    if (m == 1) {
      EXPECT_EQ(s.partial_queues, 0u);  // a queue of one is full at once
    }
    EXPECT_EQ(s.fallbacks, 0u);
    const Accuracy a = compare_hits(hits, bench.reference_hits(spec));
    EXPECT_LE(a.mismatches, 1u) << "queue=" << m;
  }
}

TEST(RayGrid, CountsForTheTables) {
  Bench& bench = bench_for("room");
  auto t = make_scheme("raygrid");
  t->prepare(bench.scene(), bench.cache());
  const RayBatch& b = bench.rays(test::small_spec("bounce:1", 64));
  std::vector<Hit> hits(b.size());
  TraversalCounts c;
  Probe probe;
  probe.counts = &c;
  t->trace(b, PacketRange::all(b), hits, probe);
  EXPECT_EQ(c.rays, b.size());
  EXPECT_GT(c.node_visits, 0u);
  EXPECT_GT(c.leaf_visits, 0u);
  EXPECT_GT(c.tri_tests, 0u);
  // Streams: more than one ray per visited node on average (Table 10).
  EXPECT_GT(double(c.node_ray_visits) / double(c.node_visits), 1.0);
  EXPECT_FALSE(t->structure_info().empty());
  EXPECT_GT(t->structure_bytes(), 0u);
  EXPECT_FALSE(raygrid_stats(bench.reference()).has_value());
}

// The scalar kernels (--kernel) run on the triangle set in the mini-MBVHs' lane order; they
// decide exactly as in a conventional traversal with the same kernel.
TEST(RayGrid, OtherKernelsMatchTheirTwin) {
  Bench& bench = bench_for("room");
  bool mbvh = false;
  for (const auto& s : schemes()) mbvh |= s.name == "mbvh4_single";
  for (TriKernel k : {TriKernel::moller, TriKernel::plane, TriKernel::plane_rcp}) {
    SchemeConfig cfg;
    cfg.kernel = k;
    auto t = make_scheme("raygrid", cfg);
    auto tw = make_scheme(mbvh ? "mbvh4_single" : "bvh_single", cfg);
    t->prepare(bench.scene(), bench.cache());
    tw->prepare(bench.scene(), bench.cache());
    for (const std::string w : {"primary", "bounce:2"}) {
      const RayBatch& b = bench.rays(test::small_spec(w, 64));
      std::vector<Hit> h1(b.size()), h2(b.size());
      trace_batch(*t, b, h1, 2);
      trace_batch(*tw, b, h2, 2);
      // plane_rcp's 12-bit reciprocal puts t off by ~1e-4, beyond the 1e-5 match tolerance, so
      // which of two nearly equal hits wins depends on the order triangles are met in.
      const uint64_t allowed = k == TriKernel::plane_rcp ? b.size() / 200 : 1;
      EXPECT_LE(compare_hits(h1, h2).mismatches, allowed) << kernel_name(k) << " " << w;
    }
  }
}

TEST(RayGrid, RejectsBadParameters) {
  for (const auto& [k, v] : std::vector<std::pair<const char*, int>>{
           {"queue", 0}, {"queue", 70000}, {"leaf_prims", 0}, {"max_depth", 21}, {"leaf_size", 0}, {"merge", 65},
           {"feed", 0}})
    EXPECT_THROW(make_scheme("raygrid", config({{k, v}})), InputError) << k << "=" << v;
}

}  // namespace
}  // namespace tb
