// Compressed wide BVH (Ylitie et al. 2017; CS348K lecture 18): quantized child boxes always
// contain the true boxes (offsets up to 1e6, flat and near-zero children, flush-to-zero mode as
// in the traversal), unused slots can never be entered, the compressed tree has the MBVH8's
// topology and leaves, and its nodes take at most 0.35x the MBVH8's bytes.
#include <immintrin.h>

#include <bit>
#include <cmath>
#include <random>

#include "structures/builtin_scenes.h"
#include "structures/cwbvh.h"
#include "test_util.h"

namespace tb {
namespace {

TEST(CWBVH, QuantizationIsConservative) {
  const FlushDenormals ftz;
  std::mt19937 rng(5);
  for (float offset : {0.f, 1e-38f, 1.f, 1e5f, -1e5f, 1e6f, -1e6f, 3e7f}) {
    for (float size : {0.f, 1e-30f, 1e-6f, 1e-3f, 1.f, 100.f, 1e5f}) {
      std::uniform_real_distribution<float> U(0.f, 1.f);
      for (int k = 0; k < 200; ++k) {
        const float p = offset + size * (U(rng) - 0.5f);
        const float hi_max = p + size * U(rng);
        const int8_t e = cw_exponent(p, hi_max);
        const float s = cw_scale(e);
        ASSERT_GE(cw_decode(p, s, 255), hi_max);
        ASSERT_GT(cw_decode(p, s, 255), p) << "unused slots must decode inverted";
        float lo = p + (hi_max - p) * U(rng), hi = lo + (hi_max - lo) * U(rng);
        if (k % 5 == 0) hi = lo;        // flat child
        if (k % 7 == 0) lo = p;         // touching the grid origin
        if (k % 11 == 0) hi = hi_max;   // touching the grid's far end
        lo = std::max(lo, p), hi = std::min(std::max(hi, lo), hi_max);
        const uint8_t ql = cw_quantize_lo(p, s, lo), qh = cw_quantize_hi(p, s, hi);
        ASSERT_LE(cw_decode(p, s, ql), lo) << "offset " << offset << " size " << size;
        ASSERT_GE(cw_decode(p, s, qh), hi) << "offset " << offset << " size " << size;
        ASSERT_LE(std::min(ql, qh), qh);
        // Tight: one cell less would not contain the box.
        if (ql < 255) { ASSERT_GT(cw_decode(p, s, uint8_t(ql + 1)), lo); }
        if (qh > 0) { ASSERT_LT(cw_decode(p, s, uint8_t(qh - 1)), hi); }
      }
    }
  }
}

// cwbvh_single decodes with a packed fused multiply-add; the builder checks its quantization with
// cw_decode. They must agree bit for bit (the conservativeness proof is about the decoded floats):
// every q, every exponent, origins at zero, tiny, negative, at 1e5-1e7 offsets and near the float
// range's end (where q * 2^e overflows), in flush-to-zero mode. Where q * 2^e is finite the fused
// decode also equals the multiply then add it replaced (so every compressed tree is unchanged).
TEST(CWBVH, FusedDecodeEqualsTheBuilderDecode) {
  const FlushDenormals ftz;
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> U(-1.f, 1.f);
  for (int e = -126; e <= 127; ++e) {
    const float s = cw_scale(int8_t(e));
    for (float base : {0.f, 1e-38f, -1e-38f, 1.f, 1e5f, -1e6f, 1e7f, 3e38f, -3e38f}) {
      const float p = base * (1.f + 0.25f * U(rng)) + (base == 0.f ? U(rng) * std::ldexp(1.f, e) : 0.f);
      for (int q0 = 0; q0 < 256; q0 += 8) {
        alignas(32) float got[8];
        const __m256 q = _mm256_setr_ps(float(q0), float(q0 + 1), float(q0 + 2), float(q0 + 3), float(q0 + 4),
                                        float(q0 + 5), float(q0 + 6), float(q0 + 7));
        _mm256_store_ps(got, _mm256_fmadd_ps(q, _mm256_set1_ps(s), _mm256_set1_ps(p)));
        for (int i = 0; i < 8; ++i) {
          const float want = cw_decode(p, s, uint8_t(q0 + i));
          ASSERT_EQ(std::bit_cast<uint32_t>(got[i]), std::bit_cast<uint32_t>(want))
              << "e " << e << " p " << p << " q " << q0 + i;
          volatile float qs = float(q0 + i) * s;  // the multiply then add, rounded separately
          if (std::isfinite(qs)) {
            volatile float sum = p + qs;
            ASSERT_EQ(std::bit_cast<uint32_t>(float(sum)), std::bit_cast<uint32_t>(want)) << "e " << e << " q " << q0 + i;
          }
        }
      }
    }
  }
}

MBVH<8, 8> mbvh8_of(const Scene& s) {
  MBVHBuildParams p;
  p.sah_collapse = true;
  p.merge = 16;
  p.small = 0;
  return MBVH<8, 8>::collapse(s, BVH::build(s, p.bvh), p);
}

// Walks both trees in step: same children in the same slots, decoded boxes containing the
// MBVH8's, identical leaf blocks.
void check_same_tree(const MBVH<8, 8>& m, const CWBVH& c) {
  std::vector<std::pair<uint32_t, uint32_t>> stack{{0, 0}};
  uint32_t visited = 0;
  while (!stack.empty()) {
    const auto [mi, ci] = stack.back();
    stack.pop_back();
    ++visited;
    const MBVHNode<8>& mn = m.nodes[mi];
    for (int i = 0; i < 8; ++i) {
      if (uint32_t(i) >= mn.num_children) {
        ASSERT_FALSE(c.slot_used(ci, i));
        const AABB b = c.child_box(ci, i);
        EXPECT_TRUE(b.lo.x > b.hi.x && b.lo.y > b.hi.y && b.lo.z > b.hi.z) << "unused slot not inverted";
        continue;
      }
      ASSERT_TRUE(c.slot_used(ci, i));
      {
        const AABB cb = c.child_box(ci, i), mb = mn.child_box(i);
        ASSERT_TRUE(cb.contains(mb)) << "node " << ci << " slot " << i << " decoded " << cb.lo.x << "," << cb.lo.y << ","
                                     << cb.lo.z << " .. " << cb.hi.x << "," << cb.hi.y << "," << cb.hi.z << " true " << mb.lo.x
                                     << "," << mb.lo.y << "," << mb.lo.z << " .. " << mb.hi.x << "," << mb.hi.y << "," << mb.hi.z;
      }
      const uint32_t mr = mn.ref[i], cr = c.child_ref(ci, i);
      ASSERT_EQ(mbvh_ref::is_leaf(mr), mbvh_ref::is_leaf(cr));
      if (!mbvh_ref::is_leaf(mr)) {
        stack.push_back({mr, cr});
        continue;
      }
      ASSERT_EQ(mbvh_ref::num_tris(mr), mbvh_ref::num_tris(cr));
      for (uint32_t k = 0; k * 8 < mbvh_ref::num_tris(mr); ++k) {
        const TriBlock<8>& a = m.blocks[mbvh_ref::first_block(mr) + k];
        const TriBlock<8>& b = c.blocks[mbvh_ref::first_block(cr) + k];
        for (int l = 0; l < 8; ++l) ASSERT_EQ(a.prim[l], b.prim[l]);
        ASSERT_EQ(0, std::memcmp(a.v, b.v, sizeof a.v));
      }
    }
  }
  EXPECT_EQ(visited, c.nodes.size());
  EXPECT_EQ(m.nodes.size(), c.nodes.size());
}

Scene flat_grid(Vec3 offset) {
  Scene s;
  s.name = "flat";
  for (int i = 0; i <= 40; ++i)
    for (int j = 0; j <= 40; ++j) s.positions.push_back(offset + Vec3{float(i), 0.f, float(j) * 0.5f});
  for (uint32_t i = 0; i < 40; ++i)
    for (uint32_t j = 0; j < 40; ++j) {
      const uint32_t a = i * 41 + j;
      s.triangles.push_back({a, a + 1, a + 41});
      s.triangles.push_back({a + 1, a + 42, a + 41});
    }
  s.ensure_views();
  return s;
}

TEST(CWBVH, SameTreeConservativeBoxesAndCompressed) {
  std::vector<Scene> scenes;
  for (const char* n : {"room", "stadium", "sphere", "room@100000,-250000,1000000"}) scenes.push_back(load_scene(n));
  scenes.push_back(flat_grid({0, 0, 0}));
  scenes.push_back(flat_grid({1e6f, 1e-3f, -1e5f}));
  for (const Scene& s : scenes) {
    SCOPED_TRACE(s.name);
    const MBVH<8, 8> m = mbvh8_of(s);
    const CWBVH c = CWBVH::compress(m);
    check_same_tree(m, c);
    EXPECT_LE(double(c.stats.node_bytes), 0.35 * double(m.stats.node_bytes));
    EXPECT_EQ(c.stats.blocks, m.blocks.size());
    EXPECT_LT(c.stats.box_growth, 0.2) << "quantized boxes far larger than the true ones";
  }
}

TEST(CWBVH, RefusesLayoutsItCannotEncode) {
  const Scene s = load_scene("room");
  MBVHBuildParams p;
  p.small = 4;  // 4-wide small blocks
  EXPECT_THROW(CWBVH::compress(MBVH<8, 8>::collapse(s, BVH::build(s, p.bvh), p)), std::invalid_argument);
  p.small = 0;
  p.sah_collapse = false;
  p.merge = 32;  // greedy: every binary subtree of <= 32 triangles becomes one leaf
  p.bvh.max_leaf = 32;
  EXPECT_THROW(CWBVH::compress(MBVH<8, 8>::collapse(s, BVH::build(s, p.bvh), p)), std::invalid_argument);
}

}  // namespace
}  // namespace tb
