// MBVH::concat (structures/mbvh.h): wide trees collapsed on their own, laid out part after part in
// one node array and one block array with their references rebased — how the RayGrid octree
// stores its per-leaf mini-MBVHs. Each part, read from its placement, must be the part itself.
#include <gtest/gtest.h>

#include <cstring>

#include "structures/builtin_scenes.h"
#include "structures/mbvh.h"

namespace tb {
namespace {

// Part `p` read at placement `w` in `all` equals `p` node for node and block for block.
template <int N, int W>
void expect_placed(const MBVH<N, W>& p, const MBVH<N, W>& all, const typename MBVH<N, W>::Placement& w) {
  ASSERT_LE(size_t(w.root) + p.nodes.size(), all.nodes.size());
  for (size_t k = 0; k < p.nodes.size(); ++k) {
    const MBVHNode<N>& a = p.nodes[k];
    const MBVHNode<N>& b = all.nodes[w.root + k];
    EXPECT_EQ(std::memcmp(a.box, b.box, sizeof a.box), 0);
    ASSERT_EQ(a.num_children, b.num_children);
    for (uint32_t i = 0; i < a.num_children; ++i) {
      const uint32_t r = a.ref[i], nt = mbvh_ref::num_tris(r);
      const uint32_t base = nt <= p.small_leaf ? w.first_small : w.first_block;
      EXPECT_EQ(b.ref[i], mbvh_ref::is_leaf(r) ? mbvh_ref::make_leaf(mbvh_ref::first_block(r) + base, nt) : r + w.root);
    }
  }
  for (size_t k = 0; k < p.blocks.size(); ++k)
    EXPECT_EQ(std::memcmp(&p.blocks[k], &all.blocks[w.first_block + k], sizeof(TriBlock<W>)), 0);
  for (size_t k = 0; k < p.small.size(); ++k)
    EXPECT_EQ(std::memcmp(&p.small[k], &all.small[w.first_small + k], sizeof(TriBlock<4>)), 0);
}

template <int N, int W>
void check_concat(bool sah) {
  SCOPED_TRACE(::testing::Message() << "N=" << N << " W=" << W << (sah ? " sah" : " greedy"));
  const Scene room = make_builtin_scene("room"), spheres = make_builtin_scene("spheres:3000");
  MBVHBuildParams mp;
  mp.sah_collapse = sah;
  mp.merge = 4;
  std::vector<MBVH<N, W>> parts;
  parts.push_back(MBVH<N, W>::collapse(room, BVH::build(room, mp.bvh), mp));
  parts.emplace_back();  // an empty part (an empty octree leaf) takes no space
  // A subset over another scene, through the span build.
  std::vector<PrimRef> refs;
  for (uint32_t t = 0; t < spheres.num_triangles(); t += 3) refs.emplace_back(spheres.triangle_bounds(t), t);
  parts.push_back(MBVH<N, W>::collapse(spheres, BVH::build(std::span<PrimRef>(refs), mp.bvh), mp));
  // Two parts of blocks over different scenes is fine for the layout; the prims say which.
  const std::vector<MBVH<N, W>> copy = parts;
  std::vector<typename MBVH<N, W>::Placement> where;
  const MBVH<N, W> all = MBVH<N, W>::concat(std::move(parts), &where);
  ASSERT_EQ(where.size(), 3u);
  EXPECT_EQ(where[0].root, 0u);
  EXPECT_EQ(where[1].root, copy[0].nodes.size());
  EXPECT_EQ(where[2].root, copy[0].nodes.size());
  EXPECT_EQ(where[2].first_block, copy[0].blocks.size());
  EXPECT_EQ(where[2].first_small, copy[0].small.size());
  for (size_t k = 0; k < copy.size(); ++k) expect_placed(copy[k], all, where[k]);
  EXPECT_EQ(all.nodes.size(), copy[0].nodes.size() + copy[2].nodes.size());
  EXPECT_EQ(all.stats.nodes, all.nodes.size());
  EXPECT_EQ(all.stats.blocks, all.blocks.size() + all.small.size());
  EXPECT_EQ(all.stats.leaves, copy[0].stats.leaves + copy[2].stats.leaves);
  EXPECT_EQ(all.stats.triangles, copy[0].stats.triangles + copy[2].stats.triangles);
  EXPECT_EQ(all.stats.max_depth, std::max(copy[0].stats.max_depth, copy[2].stats.max_depth));
  EXPECT_EQ(all.stats.node_bytes, all.nodes.size() * sizeof(MBVHNode<N>));
  EXPECT_EQ(all.small_leaf, copy[0].small_leaf);
  const double depth = (copy[0].stats.avg_leaf_depth * copy[0].stats.leaves +
                        copy[2].stats.avg_leaf_depth * copy[2].stats.leaves) / all.stats.leaves;
  EXPECT_NEAR(all.stats.avg_leaf_depth, depth, 1e-9);
  EXPECT_GE(copy[0].stats.avg_leaf_depth, 1.0);
  EXPECT_LE(copy[0].stats.avg_leaf_depth, double(copy[0].stats.max_depth));
  EXPECT_TRUE(all.small.empty() == (W == 4));
}

TEST(MBVHConcat, PartsKeepTheirTreesAndOrder) {
  check_concat<4, 4>(false);
  check_concat<8, 4>(true);
  check_concat<8, 8>(true);  // small 4-wide leaf blocks rebased into their own array
}

TEST(MBVHConcat, NothingToConcatenate) {
  std::vector<MBVH<4, 4>> none(3);
  std::vector<MBVH<4, 4>::Placement> where;
  const MBVH<4, 4> all = MBVH<4, 4>::concat(std::move(none), &where);
  EXPECT_TRUE(all.nodes.empty());
  EXPECT_EQ(where.size(), 3u);
  EXPECT_EQ(all.stats.leaves, 0u);
}

}  // namespace
}  // namespace tb
