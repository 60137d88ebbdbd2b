// Compressed wide BVH (Ylitie et al. 2017; CS348K lecture 18): quantized child boxes always
// contain the true boxes (offsets up to 1e6, flat and near-zero children, flush-to-zero mode as
// in the traversal), unused slots can never be entered, the compressed tree has the MBVH8's
// topology and leaves (also with an uncompressed top), and its nodes take at most 0.35x the
// MBVH8's bytes.
#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "harness/trace_runner.h"
#include "structures/builtin_scenes.h"
#include "structures/cwbvh.h"
#include "traversal/cwbvh_traverse.h"
#include "traversal/mbvh_traverse.h"
#include "test_geometry.h"
#include "test_util.h"
#include "workloads/hard_cases.h"

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

// The decoded plane is one rounding of p + q * 2^e (a fused multiply-add): the builder checks its
// quantization with cw_decode, and the error bound of cwbvh_single's fused node test
// (traversal/cwbvh_traverse.h) assumes that single rounding. A packed fma must give the same floats:
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

// The fused node test of cwbvh_single (traversal/cwbvh_traverse.h) against long-double distances to
// the TRUE child boxes: every child whose exact interval [max(tmin, near), min(tfar, far)] is
// non-empty must be entered, with an entry distance at or below the exact one. Nodes at offsets
// 0 to 1e6 with flat children (zero extent on one or all axes) and tiny ones; origins on a child's
// plane, inside a child, near and far; directions aimed at a child's inside, faces, edges and
// corners (grazing), random ones, with components +-0, denormal (0 under DAZ) and 1e-30. The same
// rays through the UNPADDED fused formula (t = q * fl(2^e r) + fl((p - o) r), as Ylitie et al.
// compute it) must cull some entered child, or the hammer would not test the bound.
struct TestNode {
  CWNode n{};
  AABB box[8];
  int used = 0;
  float bound[3];
};

TestNode random_node(std::mt19937& rng, Vec3 center, float scale) {
  std::uniform_real_distribution<float> U(-1.f, 1.f), U01(0.f, 1.f);
  TestNode t;
  t.used = 2 + int(rng() % 7);
  AABB u;
  for (int i = 0; i < t.used; ++i) {
    Vec3 c = center + Vec3{U(rng), U(rng), U(rng)} * scale, h;
    for (int a = 0; a < 3; ++a) {
      const int k = int(rng() % 5);
      h[a] = k == 0 ? 0.f : k == 1 ? 1e-4f * scale * U01(rng) : k == 2 ? 1e-7f * scale : scale * U01(rng);
    }
    if (rng() % 8 == 0) h = {0, 0, 0};  // a point
    t.box[i].lo = c - h, t.box[i].hi = c + h;
    u.grow(t.box[i]);
  }
  for (int a = 0; a < 3; ++a) {
    t.n.p[a] = u.lo[a];
    t.n.e[a] = cw_exponent(t.n.p[a], u.hi[a]);
    const float s = cw_scale(t.n.e[a]);
    for (int i = 0; i < 8; ++i) {
      if (i >= t.used) {
        t.n.qlo[a][i] = 255, t.n.qhi[a][i] = 0;
        continue;
      }
      t.n.qhi[a][i] = cw_quantize_hi(t.n.p[a], s, t.box[i].hi[a]);
      t.n.qlo[a][i] = std::min(cw_quantize_lo(t.n.p[a], s, t.box[i].lo[a]), t.n.qhi[a][i]);
    }
    // CWBVH::compress's bound for a tree of this one node.
    const double b = std::fabs(double(t.n.p[a])) + 255.0 * double(s);
    t.bound[a] = float(b);
    if (double(t.bound[a]) < b) t.bound[a] = std::nextafter(t.bound[a], INFINITY);
  }
  return t;
}

// The unpadded fused test of one slot (for the control count only).
bool unpadded_enters(const TestNode& t, int i, Vec3 o, Vec3 d, float tmin, float tfar) {
  float n = tmin, f = tfar;
  for (int a = 0; a < 3; ++a) {
    const float r = 1.f / d[a];
    if (!std::isfinite(r)) continue;
    const float A = cw_scale(t.n.e[a]) * r, B = (t.n.p[a] - o[a]) * r;
    const bool neg = std::signbit(r);
    const float tn = std::fma(float(neg ? t.n.qhi[a][i] : t.n.qlo[a][i]), A, B);
    const float tf = std::fma(float(neg ? t.n.qlo[a][i] : t.n.qhi[a][i]), A, B);
    n = std::max(n, tn), f = std::min(f, tf);
  }
  return n <= f;
}

TEST(CWBVH, FusedNodeTestIsConservative) {
  const FlushDenormals ftz;
  std::mt19937 rng(19);
  std::uniform_real_distribution<float> U(-1.f, 1.f), U01(0.f, 1.f);
  uint64_t checked = 0, entered_exact = 0, unpadded_misses = 0, exp_add_rays = 0;
  for (float offset : {0.f, 1.f, 1e5f, -1e5f, 3e5f, 1e6f, -1e6f}) {
    for (float scale : {1e-3f, 1.f, 100.f}) {
      for (int k = 0; k < 400; ++k) {
        const TestNode t = random_node(rng, Vec3{offset, -0.5f * offset, 0.25f * offset}, scale);
        for (int j = 0; j < 40; ++j) {
          const AABB& c = t.box[rng() % uint32_t(t.used)];
          const test::HammerRay hr = test::hammer_ray(rng, c, scale);
          const Vec3 o = hr.org, d = hr.dir;
          const float tmin = hr.tmin, tfar = hr.tfar;
          Ray ray;
          ray.org = o, ray.dir = d, ray.tmin = tmin, ray.tmax = tfar;
          const RayCtx rc(ray);
          const int e_min = std::min({int(t.n.e[0]), int(t.n.e[1]), int(t.n.e[2])});
          const int e_max = std::max({int(t.n.e[0]), int(t.n.e[1]), int(t.n.e[2])});
          const CWRay r(rc, tmin, t.bound, e_min, e_max);
          __m256 tn;
          const int mask = _mm256_movemask_ps(cw_box_test(t.n, r, _mm256_set1_ps(tfar), tn));
          alignas(32) float tns[8];
          _mm256_store_ps(tns, tn);
          if (r.exp_add) {  // the exponent-add path: the same lanes and distances, bit for bit
            __m256 tn_add;
            ASSERT_EQ(_mm256_movemask_ps(cw_box_test<true>(t.n, r, _mm256_set1_ps(tfar), tn_add)), mask);
            alignas(32) float adds[8];
            _mm256_store_ps(adds, tn_add);
            ASSERT_EQ(std::memcmp(adds, tns, sizeof adds), 0);
            ++exp_add_rays;
          }
          // The same children as a full node (float boxes) under the MBVH node test with the
          // compressed ray's constants (t.bound covers the boxes' planes), as cwbvh_single's
          // uncompressed top takes them.
          MBVHNode<8> full{};
          for (int i = 0; i < 8; ++i)
            for (int a = 0; a < 3; ++a) {
              full.box[a][i] = i < t.used ? t.box[i].lo[a] : INFINITY;
              full.box[3 + a][i] = i < t.used ? t.box[i].hi[a] : -INFINITY;
            }
          __m256 ftn;
          const int fmask = _mm256_movemask_ps(box_test<8>(full, cw_full_ray(r), tfar, ftn));
          alignas(32) float ftns[8];
          _mm256_store_ps(ftns, ftn);
          for (int i = 0; i < t.used; ++i) {
            long double t0, t1;
            ++checked;
            if (!test::exact_slab_interval(t.box[i], o, d, tmin, tfar, t0, t1)) continue;
            ++entered_exact;
            ASSERT_TRUE(mask >> i & 1) << "a child the ray enters was culled: offset " << offset << " scale " << scale
                                       << " slot " << i << " exact [" << double(t0) << ", " << double(t1) << "]";
            ASSERT_LE((long double)tns[i], t0) << "entry distance above the exact one";
            ASSERT_TRUE(fmask >> i & 1) << "a full node's child the ray enters was culled: offset " << offset
                                        << " scale " << scale << " slot " << i;
            ASSERT_LE((long double)ftns[i], t0) << "full node: entry distance above the exact one";
            if (!unpadded_enters(t, i, o, d, tmin, tfar)) ++unpadded_misses;
          }
        }
      }
    }
  }
  std::printf("fused node test: %llu child tests, %llu entered exactly, unpadded formula culled %llu of them\n",
              (unsigned long long)checked, (unsigned long long)entered_exact, (unsigned long long)unpadded_misses);
  EXPECT_GT(entered_exact, checked / 20) << "the rays should enter a fair share of the children";
  EXPECT_GT(unpadded_misses, 0u) << "no ray tested the bound: the unpadded formula never culled an entered child";
  EXPECT_GT(exp_add_rays, checked / 40) << "the exponent-add path should serve most rays";
}

// CWRay::exp_add admits a ray only where adding e * 2^23 to r's bits is the product 2^e r (what the
// multiply path computes, FTZ included); rays with huge directions on fine grids take the multiply.
TEST(CWBVH, ExponentAddEqualsTheProduct) {
  const FlushDenormals ftz;
  std::mt19937 rng(23);
  uint64_t admitted = 0, refused = 0;
  for (int k = 0; k < 20000; ++k) {
    // Directions of every magnitude 2^-130 .. 2^130, signs and axes mixed.
    const auto comp = [&] {
      const float m = std::ldexp(1.f + float(rng() % 1000) / 1000.f, int(rng() % 261) - 130);
      return rng() % 2 ? -m : m;
    };
    Ray ray;
    ray.org = Vec3{1.f, -2.f, 3.f}, ray.dir = Vec3{comp(), comp(), comp()}, ray.tmin = 0, ray.tmax = INFINITY;
    const RayCtx rc(ray);
    const int e_min = int(rng() % 254) - 126, e_max = std::min(127, e_min + int(rng() % 40));  // cw_exponent's range
    const float bound[3] = {1e3f, 1e3f, 1e3f};
    const CWRay r(rc, 0.f, bound, e_min, e_max);
    alignas(16) float rs[4];
    _mm_store_ps(rs, _mm256_castps256_ps128(r.r44));
    bool exact = true;
    for (int a = 0; a < 3; ++a) {
      if (std::isnan(rs[a])) continue;
      for (int e : {e_min, e_max, (e_min + e_max) / 2}) {
        const float prod = cw_scale(int8_t(e)) * rs[a];
        const float add = std::bit_cast<float>(std::bit_cast<uint32_t>(rs[a]) + (uint32_t(e) << 23));
        exact = exact && std::bit_cast<uint32_t>(prod) == std::bit_cast<uint32_t>(add);
      }
    }
    if (r.exp_add) {
      ++admitted;
      ASSERT_TRUE(exact) << "exp_add admitted a ray whose exponent sum leaves the normal range";
    } else {
      ++refused;
    }
  }
  EXPECT_GT(admitted, 1000u);
  EXPECT_GT(refused, 1000u);
}

MBVH<8, 8> mbvh8_of(const Scene& s) {
  MBVHBuildParams p;
  p.sah_collapse = true;
  p.merge = 16;
  p.small = 0;
  return MBVH<8, 8>::collapse(s, BVH::build(s, p.bvh), p);
}

// An indexed leaf (CWLeaves::indexed) holds exactly the MBVH8 leaf's triangles, each once, with its
// vertices bit for bit: blocks of 1-8 real lanes over at most 8 table vertices, padding lanes
// repeating the last real one, `last` on the leaf's last block only.
void check_indexed_leaf(const MBVH<8, 8>& m, uint32_t mr, const CWBVH& c, uint32_t cr) {
  using Tri = std::array<uint32_t, 10>;  // prim, then corner-major vertex bits
  std::vector<Tri> want, got;
  const uint32_t n = mbvh_ref::num_tris(mr);
  for (uint32_t t = 0; t < n; ++t) {
    const TriBlock<8>& b = m.blocks[mbvh_ref::first_block(mr) + t / 8];
    Tri x{b.prim[t % 8]};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) x[size_t(1 + 3 * k + a)] = std::bit_cast<uint32_t>(b.v[k][a][t % 8]);
    want.push_back(x);
  }
  for (uint32_t bi = cw_ileaf_block(cr);; ++bi) {
    ASSERT_LT(bi, c.iblocks.size());
    const CWTriBlock& b = c.iblocks[bi];
    ASSERT_GE(b.lanes, 1);
    ASSERT_LE(b.lanes, 8);
    for (int l = 0; l < 8; ++l) {
      const int src = std::min(l, b.lanes - 1);  // padding lanes repeat the last real one
      EXPECT_EQ(b.prim[l], b.prim[src]);
      Tri x{b.prim[l]};
      for (int k = 0; k < 3; ++k) {
        ASSERT_LT(b.idx[k][l], 8);
        EXPECT_EQ(b.idx[k][l], b.idx[k][src]);
        for (int a = 0; a < 3; ++a) x[size_t(1 + 3 * k + a)] = std::bit_cast<uint32_t>(b.v[a][b.idx[k][l]]);
      }
      if (l < b.lanes) got.push_back(x);
    }
    if (b.last) break;
  }
  std::sort(want.begin(), want.end()), std::sort(got.begin(), got.end());
  EXPECT_EQ(want, got) << "an indexed leaf with other triangles than the MBVH8's";
}

// Walks both trees in step: the same children in the slots cw_slots assigns (each child in
// exactly one), decoded boxes containing the MBVH8's, identical leaf blocks.
void check_same_tree(const MBVH<8, 8>& m, const CWBVH& c, CWSlots slots) {
  std::vector<std::pair<uint32_t, uint32_t>> stack{{0, c.root}};  // (MBVH node, CWBVH reference)
  uint32_t visited = 0;
  while (!stack.empty()) {
    const auto [mi, ci] = stack.back();
    stack.pop_back();
    ++visited;
    const MBVHNode<8>& mn = m.nodes[mi];
    const std::array<int8_t, 8> slot_child = cw_slots(mn, slots);
    uint32_t seen = 0;
    for (int i = 0; i < 8; ++i) {
      const int ch = slot_child[size_t(i)];
      if (ch >= 0) {
        ASSERT_LT(uint32_t(ch), mn.num_children);
        ASSERT_FALSE(seen >> ch & 1) << "child " << ch << " in two slots";
        seen |= 1u << ch;
      }
      if (ch < 0) {
        ASSERT_FALSE(c.slot_used(ci, i));
        // The reference the traversal forms for it is a real one-triangle leaf (a padded box test
        // may let a ray into an unused slot of a tiny node).
        const uint32_t raw = (ci & kCWFull) ? c.full[ci & ~kCWFull].ref[i] : c.nodes[ci].leaf_base + c.nodes[ci].meta[i];
        ASSERT_TRUE(mbvh_ref::is_leaf(raw));
        if (c.leaves == CWLeaves::indexed) {
          EXPECT_LT(cw_ileaf_block(raw), c.iblocks.size());
        } else {
          EXPECT_EQ(mbvh_ref::num_tris(cw_leaf_to_mbvh(raw)), 1u);
          EXPECT_LT(mbvh_ref::first_block(cw_leaf_to_mbvh(raw)), c.blocks.size());
        }
        const AABB b = c.child_box(ci, i);
        EXPECT_TRUE(b.lo.x > b.hi.x && b.lo.y > b.hi.y && b.lo.z > b.hi.z) << "unused slot not inverted";
        continue;
      }
      ASSERT_TRUE(c.slot_used(ci, i));
      {
        const AABB cb = c.child_box(ci, i), mb = mn.child_box(ch);
        ASSERT_TRUE(cb.contains(mb)) << "node " << ci << " slot " << i << " decoded " << cb.lo.x << "," << cb.lo.y << ","
                                     << cb.lo.z << " .. " << cb.hi.x << "," << cb.hi.y << "," << cb.hi.z << " true " << mb.lo.x
                                     << "," << mb.lo.y << "," << mb.lo.z << " .. " << mb.hi.x << "," << mb.hi.y << "," << mb.hi.z;
      }
      const uint32_t mr = mn.ref[ch], cr = c.child_ref(ci, i);
      ASSERT_EQ(mbvh_ref::is_leaf(mr), mbvh_ref::is_leaf(cr));
      if (!mbvh_ref::is_leaf(mr)) {
        // The full nodes are a top: a compressed node has compressed children only.
        if (!(ci & kCWFull)) {
          ASSERT_FALSE(cr & kCWFull) << "a full node below a compressed one";
        }
        stack.push_back({mr, cr});
        continue;
      }
      if (c.leaves == CWLeaves::indexed) {
        check_indexed_leaf(m, mr, c, cr);
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
    ASSERT_EQ(seen, (1u << mn.num_children) - 1) << "a child without a slot";
  }
  EXPECT_EQ(visited, c.nodes.size() + c.full.size());
  EXPECT_EQ(m.nodes.size(), c.nodes.size() + c.full.size());
}

// The full nodes are the largest boxes: none of the compressed children of a full node (the
// frontier the builder stopped at) has a larger area than a full node other than the root.
void check_full_top_is_largest(const CWBVH& c) {
  float least_full = INFINITY, largest_frontier = 0;
  for (uint32_t f = 0; f < c.full.size(); ++f)
    for (int i = 0; i < 8; ++i) {
      if (!c.slot_used(kCWFull | f, i)) continue;
      const uint32_t r = c.child_ref(kCWFull | f, i);
      if (mbvh_ref::is_leaf(r)) continue;
      const float a = c.full[f].child_box(i).area();
      if (r & kCWFull) least_full = std::min(least_full, a);
      else largest_frontier = std::max(largest_frontier, a);
    }
  EXPECT_LE(largest_frontier, least_full) << "a compressed node larger than a full one";
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
    // Every node compressed, cwbvh_single's default uncompressed top (full_top = 4 percent), the
    // most the 0.35x goal allows (5%), and every node full.
    for (double share : {0.0, 0.04, 0.05, 1.0})
      for (const CWLeaves leaves : {CWLeaves::blocks, CWLeaves::indexed}) {
        SCOPED_TRACE(share);
        SCOPED_TRACE(leaves == CWLeaves::indexed ? "indexed leaves" : "block leaves");
        const CWSlots slots = share == 0.04 ? CWSlots::mbvh : CWSlots::octant;  // cwbvh_single's default: mbvh
        const CWBVH c = CWBVH::compress(m, share, slots, leaves);
        check_same_tree(m, c, slots);
        check_full_top_is_largest(c);
        EXPECT_EQ(c.full.size(), size_t(std::floor(share * double(m.nodes.size()))));
        EXPECT_EQ(c.root, c.full.empty() ? 0u : kCWFull);
        if (share <= 0.05) {
          EXPECT_LE(double(c.stats.node_bytes), 0.35 * double(m.stats.node_bytes));
        }
        EXPECT_EQ(c.stats.node_bytes, c.nodes.size() * sizeof(CWNode) + c.full.size() * sizeof(MBVHNode<8>));
        if (leaves == CWLeaves::blocks) {
          EXPECT_EQ(c.stats.blocks, m.blocks.size());
          EXPECT_EQ(c.stats.tri_bytes, m.stats.tri_bytes);
        } else {
          EXPECT_EQ(c.stats.blocks, c.iblocks.size());
          EXPECT_EQ(c.stats.tri_bytes, c.iblocks.size() * sizeof(CWTriBlock));
          EXPECT_TRUE(c.blocks.empty());
        }
        if (share < 1) {
          EXPECT_LT(c.stats.box_growth, 0.2) << "quantized boxes far larger than the true ones";
        }
      }
  }
  EXPECT_THROW(CWBVH::compress(mbvh8_of(scenes[0]), 1.5), std::invalid_argument);
}

// Octant-ordered slots (Ylitie et al. 2017 §3.2): with one child in each octant of the node,
// slot s holds the child a ray of octant s enters first (for each axis a with bit a of s set the
// ray travels towards -a, so it enters the child on the high side first), whatever order the
// MBVH node lists them in; and the traversal's table visits the slots as slot ^ octant.
TEST(CWBVH, OctantSlotsPutTheFirstEnteredChildInTheOctantsSlot) {
  const int corner_of[8] = {5, 2, 7, 0, 3, 6, 1, 4};  // child k sits in corner corner_of[k]
  MBVHNode<8> n{};
  n.num_children = 8;
  for (int k = 0; k < 8; ++k)
    for (int a = 0; a < 3; ++a) {
      const float lo = float(corner_of[k] >> a & 1) * 2.f;
      n.box[a][k] = lo, n.box[3 + a][k] = lo + 1.f;
    }
  const std::array<int8_t, 8> slot_child = cw_octant_slots(n);
  for (int s = 0; s < 8; ++s) EXPECT_EQ(corner_of[slot_child[size_t(s)]], s) << "slot " << s;
  // Fewer children: each in one slot, the rest unused.
  n.num_children = 3;
  const std::array<int8_t, 8> three = cw_octant_slots(n);
  EXPECT_EQ(std::count(three.begin(), three.end(), int8_t(-1)), 5);
  for (int8_t k = 0; k < 3; ++k) EXPECT_EQ(std::count(three.begin(), three.end(), k), 1);
  // The table lists the entered slots far to near: slot k ^ o is the (k+1)-th entered.
  for (uint32_t o = 0; o < 8; ++o) {
    for (uint32_t j = 0; j < 8; ++j) EXPECT_EQ(kCWOctantOrder[o][255] >> (8 * j) & 0xFF, (7 - j) ^ o);
    const uint32_t m = 1u << (2 ^ o) | 1u << (5 ^ o);  // entered: the 3rd and the 6th in order
    EXPECT_EQ(kCWOctantOrder[o][m] & 0xFFFF, (5 ^ o) | (2 ^ o) << 8);
  }
}

// Every child order of cwbvh_single (the registry's tests run the default, auto) changes only the
// work, never the result: as accurate as the reference allows, no leak on the must-hit hard cases,
// also at offsets.
TEST(CWBVH, EveryChildOrderIsAccurateAndWatertight) {
  // Each order on the default uncompressed top (full_top=4), and the two ends of full_top.
  // Each also with indexed leaves.
  for (const std::string variant : {"sort", "branching", "octant", "sort+prefetch", "full_top=0", "full_top=100",
                                    "octant,full_top=0", "sort,indexed", "branching,indexed", "sort+prefetch,indexed",
                                    "octant,full_top=0,indexed", "full_top=100,indexed"}) {
    SchemeConfig cfg;
    const bool indexed = variant.ends_with(",indexed");
    const std::string order = indexed ? variant.substr(0, variant.size() - 8) : variant;
    if (indexed) cfg.params["leaves"] = "indexed";
    cfg.params["order"] = order == "sort+prefetch" ? "sort" : order.starts_with("octant") ? "octant" : order;
    if (order == "sort+prefetch") cfg.params["prefetch"] = "on";  // CWOrder::sort_prefetch
    if (order.starts_with("full_top")) cfg.params.erase("order");
    if (order.ends_with("full_top=0")) cfg.params["full_top"] = "0";
    if (order.ends_with("full_top=100")) cfg.params["full_top"] = "100";
    for (const std::string scene : {"room", "sphere", "sphere@148376,1234,-223423"}) {
      Bench& bench = test::bench_for(scene);
      for (const char* w : {"primary", "rnd", "bounce:2"}) {
        const Accuracy a = test::accuracy_of(bench, "cwbvh_single", test::small_spec(w, 96), cfg);
        EXPECT_LE(a.mismatches, 1u) << variant << " on " << scene << " / " << w;
        EXPECT_EQ(a.false_miss, 0u) << variant << " leaks on " << scene << " / " << w;
      }
      // Hard cases (rays at shared vertices and edges): which triangle is reported is ambiguous
      // there (SchemeRobustness); a miss is not.
      for (const auto& w : hard_case_names()) {
        if (hard_case_must_hit(w)) {
          EXPECT_EQ(test::accuracy_of(bench, "cwbvh_single", test::small_spec(w, 96), cfg).false_miss, 0u)
              << variant << " leaks on " << scene << " / " << w;
        }
      }
    }
  }
}

// A soup of disconnected triangles: no vertex shared, so an indexed block holds at most 2 of them
// and a leaf of 16 takes 8 blocks (the most a leaf can take; a node's leaves up to 64).
Scene triangle_soup(uint32_t n, uint32_t seed) {
  Scene s;
  s.name = "soup";
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> at(-10.f, 10.f), off(-0.6f, 0.6f);
  for (uint32_t i = 0; i < n; ++i) {
    const Vec3 c{at(rng), at(rng), at(rng)};
    for (int k = 0; k < 3; ++k) s.positions.push_back(c + Vec3{off(rng), off(rng), off(rng)});
    s.triangles.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  s.ensure_views();
  return s;
}

TEST(CWBVH, IndexedLeavesPackTriangleSoupsAndMeshes) {
  for (const Scene& s : {triangle_soup(4000, 7), load_scene("sphere"), load_scene("stadium")}) {
    SCOPED_TRACE(s.name);
    MBVHBuildParams p;
    p.sah_collapse = true, p.merge = 16, p.small = 0, p.bvh.max_leaf = 16;
    const MBVH<8, 8> m = MBVH<8, 8>::collapse(s, BVH::build(s, p.bvh), p);
    const CWBVH c = CWBVH::compress(m, 0.04, CWSlots::mbvh, CWLeaves::indexed);
    check_same_tree(m, c, CWSlots::mbvh);
    // A block other than a leaf's last closes only when a triangle left does not fit: its 8
    // lanes are full, or its table holds at least 6 vertices (a triangle adds at most 3).
    uint32_t lanes = 0, blocks_of_two = 0;
    for (size_t b = 0; b < c.iblocks.size(); ++b) {
      const CWTriBlock& k = c.iblocks[b];
      lanes += k.lanes;
      blocks_of_two += k.lanes == 2;
      uint32_t used = 0;
      for (int l = 0; l < k.lanes; ++l)
        for (int q = 0; q < 3; ++q) used |= 1u << k.idx[q][l];
      EXPECT_EQ(used, (1u << std::popcount(used)) - 1) << "block " << b << ": table slots not used in order";
      if (!k.last) {
        EXPECT_TRUE(k.lanes == 8 || std::popcount(used) >= 6) << "block " << b << " closed early";
      }
    }
    EXPECT_EQ(lanes, [&] {
      uint32_t n = 0;
      for (size_t b = 0; b < m.blocks.size(); ++b)
        for (int l = 0; l < 8; ++l) n += l == 0 || m.blocks[b].prim[l] != m.blocks[b].prim[l - 1] ? 1 : 0;
      return n;
    }());
    if (s.name == "soup") {
      EXPECT_GT(blocks_of_two, c.iblocks.size() / 2) << "a soup's blocks hold two triangles";
    } else {
      EXPECT_LT(c.stats.tri_bytes, m.stats.tri_bytes * 3 / 4) << "a mesh's indexed leaves take under 0.75x the bytes";
    }
  }
}

// Indexed leaves change where a triangle is stored, never what a ray hits: the same distance as the
// MBVH8's blocks on every ray, and the same u, v bit for bit where the same triangle is reported
// (another may be where two give that distance: a ray starting on a shared vertex), on meshes, a
// soup and at offsets; on the must-hit hard cases as many leaks as the blocks (none on a mesh;
// a soup has no shared edges to be watertight across).
TEST(CWBVH, IndexedLeavesHitWhatBlockLeavesHit) {
  for (const std::string scene : {"room", "stadium", "sphere@148376,1234,-223423", "soup"}) {
    SCOPED_TRACE(scene);
    Bench& bench = scene == "soup" ? [] () -> Bench& {
      static Bench b(triangle_soup(3000, 11));
      return b;
    }() : test::bench_for(scene);
    for (const std::string order : {"auto", "branching", "sort"}) {
      SchemeConfig blocks, indexed;
      blocks.params["order"] = indexed.params["order"] = order;
      blocks.params["leaves"] = "blocks", indexed.params["leaves"] = "indexed";
      auto tb = make_scheme("cwbvh_single", blocks), ti = make_scheme("cwbvh_single", indexed);
      tb->prepare(bench.scene(), bench.cache()), ti->prepare(bench.scene(), bench.cache());
      std::vector<std::string> workloads = {"primary", "rnd", "bounce:2", "shadow"};
      for (const auto& h : hard_case_names()) workloads.push_back(h);
      for (const std::string& w : workloads) {
        const RayBatch& rays = bench.rays(test::small_spec(w, 64));
        std::vector<Hit> hb(rays.size()), hi(rays.size());
        trace_batch(*tb, rays, hb, 2), trace_batch(*ti, rays, hi, 2);
        uint32_t differ = 0;
        for (size_t i = 0; i < rays.size(); ++i) {
          // == : a ray starting on a vertex may report +0 from one triangle and -0 from another.
          differ += !(hb[i].t == hi[i].t);
          if (hb[i].prim == hi[i].prim) {
            differ += std::bit_cast<uint32_t>(hb[i].u) != std::bit_cast<uint32_t>(hi[i].u) ||
                      std::bit_cast<uint32_t>(hb[i].v) != std::bit_cast<uint32_t>(hi[i].v);
          }
        }
        EXPECT_EQ(differ, 0u) << order << " / " << w;
        if (hard_case_must_hit(w)) {  // the hits just traced, against the reference
          const std::vector<Hit>& ref = bench.reference_hits(test::small_spec(w, 64));
          EXPECT_EQ(compare_hits(hi, ref).false_miss, compare_hits(hb, ref).false_miss) << order << " / " << w;
        }
      }
    }
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
