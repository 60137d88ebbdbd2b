// RayOrder (traversal/ray_order.h), the batch schemes' ray sort: a stable permutation of the range
// by the Morton code of each origin's cell in a 4x4x4 grid over the range's origins, which keeps
// a batch's own order when its rays share one origin or are coherent already.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <random>

#include "harness/trace_runner.h"
#include "traversal/probe.h"
#include "traversal/ray_order.h"

namespace tb {
namespace {

std::vector<Ray> random_rays(uint32_t n, uint32_t seed) {
  std::mt19937 g(seed);
  std::uniform_real_distribution<float> u(-50.f, 50.f);
  std::vector<Ray> rays(n);
  for (Ray& r : rays) {
    r.org = Vec3{u(g), u(g) * 0.1f, u(g) + 1000.f};
    r.dir = Vec3{0.f, 0.f, 1.f};
  }
  return rays;
}

// The cell code the order is defined by, written out bit by bit.
uint32_t cell_code(const Ray& r, const AABB& box) {
  uint32_t code = 0;
  for (int a = 0; a < 3; ++a) {
    const float lo = box.lo[a], ext = box.hi[a] - box.lo[a];
    const uint32_t c = ext > 0 ? std::min<uint32_t>(3, uint32_t((r.org[a] - lo) * (4.f / ext))) : 0;
    for (int bit = 0; bit < 2; ++bit) code |= ((c >> bit) & 1u) << (3 * bit + a);
  }
  return code;
}

std::vector<uint32_t> order_of(const RayOrder& o, uint32_t n) {
  std::vector<uint32_t> v(n);
  for (uint32_t j = 0; j < n; ++j) v[j] = o.index(j);
  return v;
}

TEST(RayOrder, IsAStablePermutationByCellCode) {
  const std::vector<Ray> rays = random_rays(5000, 1);
  const uint32_t first = 37, last = 4990;
  RayOrder o;
  NullProbe p;
  o.sort(rays, first, last, 0.0, p);
  ASSERT_TRUE(o.moved());
  AABB box;
  for (uint32_t i = first; i < last; ++i) box.grow(rays[i].org);
  const std::vector<uint32_t> v = order_of(o, last - first);
  std::vector<uint32_t> sorted = v;
  std::sort(sorted.begin(), sorted.end());
  for (uint32_t j = 0; j < sorted.size(); ++j) ASSERT_EQ(sorted[j], first + j) << "not a permutation of the range";
  uint32_t cells = 1;
  for (uint32_t j = 1; j < v.size(); ++j) {
    const uint32_t a = cell_code(rays[v[j - 1]], box), b = cell_code(rays[v[j]], box);
    ASSERT_LE(a, b) << "position " << j;
    if (a == b) {
      ASSERT_LT(v[j - 1], v[j]) << "unstable at position " << j;
    }
    cells += a != b;
  }
  EXPECT_GT(cells, 32u);  // the rays spread over the grid: the test sees a real reordering
}

TEST(RayOrder, KeepsTheOrderOfRaysThatShareAnOriginOrAreCoherent) {
  NullProbe p;
  RayOrder o;
  std::vector<Ray> camera = random_rays(3000, 2);
  for (Ray& r : camera) r.org = Vec3{1.f, 2.f, 3.f};
  o.sort(camera, 0, 3000, 0.0, p);
  EXPECT_FALSE(o.moved());
  for (uint32_t j = 0; j < 3000; ++j) ASSERT_EQ(o.index(j), j);

  // Coherent: the origins in cell order already (neighbours share a cell), so fewer than half
  // the neighbours change cell: min_change 0.5 keeps the order, 0 sorts (and finds it sorted).
  std::vector<Ray> rays = random_rays(3000, 3);
  AABB box;
  for (const Ray& r : rays) box.grow(r.org);
  std::stable_sort(rays.begin(), rays.end(),
                   [&](const Ray& a, const Ray& b) { return cell_code(a, box) < cell_code(b, box); });
  o.sort(rays, 0, 3000, 0.5, p);
  EXPECT_FALSE(o.moved());
  o.sort(rays, 0, 3000, 0.0, p);
  EXPECT_TRUE(o.moved());
  for (uint32_t j = 0; j < 3000; ++j) ASSERT_EQ(o.index(j), j);

  // Incoherent: the same rays shuffled are sorted under min_change 0.5.
  std::shuffle(rays.begin(), rays.end(), std::mt19937(4));
  o.sort(rays, 0, 3000, 0.5, p);
  EXPECT_TRUE(o.moved());
}

TEST(RayOrder, EmptyAndSingleRanges) {
  const std::vector<Ray> rays = random_rays(10, 5);
  NullProbe p;
  RayOrder o;
  o.sort(rays, 4, 4, 0.0, p);
  EXPECT_FALSE(o.moved());
  o.sort(rays, 4, 5, 0.0, p);
  EXPECT_FALSE(o.moved());
  EXPECT_EQ(o.index(0), 4u);
}

// A scheme that asks for its batches in the origin order (Traverser::batch_order) and reports what
// it was handed: each hit carries its ray's origin (t = x, u = y) and the position the ray had in
// the batch given to trace (prim); calls on a batch not in its order are counted.
class OrderingTraverser final : public Traverser {
 public:
  std::string_view name() const override { return "ordering"; }
  void prepare(const Scene&, StructureCache&) override {}
  void trace(const RayBatch& b, PacketRange r, std::span<Hit> h) const override {
    if (!b.ordered) unordered_calls++;
    for (uint32_t i = b.packet_begin[r.first]; i < b.packet_begin[r.last]; ++i)
      h[i] = Hit{b.rays[i].org.x, i, b.rays[i].org.y, 0.f};
  }
  void trace(const RayBatch& b, PacketRange r, std::span<Hit> h, Probe&) const override { trace(b, r, h); }
  bool batch_order(const RayBatch& b, RayOrder& o) const override {
    NullProbe p;
    o.sort(b.rays, 0, uint32_t(b.size()), 0.0, p);
    return o.moved();
  }
  mutable std::atomic<int> unordered_calls{0};
};

// trace_batch with threads: the whole batch is ordered once, every call sees the gathered batch
// (ordered), and each hit lands on its own ray; one thread hands the scheme the batch as it is.
TEST(RayOrder, MultiThreadedTraceOrdersTheWholeBatchAndScattersTheHits) {
  RayBatch b;
  b.rays = random_rays(5003, 6);
  b.group_uniform(64);
  RayOrder expect;
  NullProbe p;
  expect.sort(b.rays, 0, uint32_t(b.size()), 0.0, p);
  ASSERT_TRUE(expect.moved());
  std::vector<uint32_t> position(b.size());
  for (uint32_t j = 0; j < b.size(); ++j) position[expect.index(j)] = j;
  for (int threads : {2, 3}) {
    for (int rep = 0; rep < 2; ++rep) {  // the second trace reuses the thread's gathered batch
      OrderingTraverser t;
      std::vector<Hit> hits(b.size());
      trace_batch(t, b, hits, threads);
      EXPECT_EQ(t.unordered_calls.load(), 0) << threads;
      for (uint32_t i = 0; i < b.size(); ++i) {
        ASSERT_EQ(hits[i].t, b.rays[i].org.x) << "ray " << i << ", " << threads << " threads";
        ASSERT_EQ(hits[i].u, b.rays[i].org.y) << "ray " << i;
        ASSERT_EQ(hits[i].prim, position[i]) << "ray " << i << " was not traced at its place in the order";
      }
    }
  }
  OrderingTraverser one;
  std::vector<Hit> hits(b.size());
  trace_batch(one, b, hits, 1);
  EXPECT_EQ(one.unordered_calls.load(), 1);
  for (uint32_t i = 0; i < b.size(); ++i) ASSERT_EQ(hits[i].prim, i);
}

}  // namespace
}  // namespace tb
