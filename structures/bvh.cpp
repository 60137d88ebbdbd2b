#include "structures/bvh.h"

#include <algorithm>
#include <atomic>
#include <thread>
#include <chrono>
#include <cstdio>

namespace tb {

std::string BVHBuildParams::key() const {
  char buf[96];
  std::snprintf(buf, sizeof buf, "bvh:bins=%d:leaf=%d:ct=%g:ci=%g", bins, max_leaf, cost_traversal, cost_intersect);  // threads do not change the tree
  return buf;
}

std::string BVHStats::describe() const {
  char buf[200];
  std::snprintf(buf, sizeof buf, "nodes=%u leaves=%u max_depth=%u sah=%.2f build_ms=%.1f bytes=%zu", nodes, leaves,
                max_depth, sah_cost, build_ms, bytes);
  return buf;
}

namespace {

struct Bin {
  AABB box;
  uint32_t count = 0;
};

struct BuildTask {
  uint32_t node, depth;
};

}  // namespace

namespace {

// The binned SAH sweep over one subtree at a time. Threads share the node array (pairs are
// claimed with an atomic counter) and work on disjoint ranges of prim_index.
struct Builder {
  const BVHBuildParams& p;
  BVH& bvh;
  const std::vector<AABB>& tri_box;
  const std::vector<Vec3>& centroid;
  std::atomic<uint32_t> next_node{2};
  std::atomic<uint32_t> max_depth{0};
  uint32_t defer_below = 0;  // subtrees smaller than this are left for the thread pool
  std::vector<BuildTask> deferred;

  void run(std::vector<BuildTask> stack, bool may_defer) {
    const int nbins = std::clamp(p.bins, 2, 256);
    const uint32_t max_leaf = uint32_t(std::max(1, p.max_leaf));
    std::vector<Bin> bins(size_t(3) * nbins);
    std::vector<float> right_area(nbins);
    std::vector<uint32_t> right_count(nbins);
    uint32_t local_depth = 0;
    while (!stack.empty()) {
      BuildTask task = stack.back();
      stack.pop_back();
      BVHNode& node = bvh.nodes[task.node];
      const uint32_t first = node.left_first, count = node.count;
      if (may_defer && count < defer_below) {
        deferred.push_back(task);
        continue;
      }
      AABB box, cbox;
      for (uint32_t i = first; i < first + count; ++i) {
        box.grow(tri_box[bvh.prim_index[i]]);
        cbox.grow(centroid[bvh.prim_index[i]]);
      }
      node.lo = box.lo;
      node.hi = box.hi;
      local_depth = std::max(local_depth, task.depth);
      if (count <= 1) continue;

      // Binned SAH over the centroid bounds on all three axes.
      int best_axis = -1, best_split = 0;
      float best_cost = INFINITY;
      const Vec3 cext = cbox.extent();
      for (int a = 0; a < 3; ++a) {
        if (!(cext[a] > 0.f)) continue;
        Bin* b = &bins[size_t(a) * nbins];
        std::fill(b, b + nbins, Bin{});
        const float scale = nbins / cext[a];
        for (uint32_t i = first; i < first + count; ++i) {
          uint32_t t = bvh.prim_index[i];
          int k = std::min(nbins - 1, int((centroid[t][a] - cbox.lo[a]) * scale));
          b[k].count++;
          b[k].box.grow(tri_box[t]);
        }
        AABB acc;
        uint32_t cnt = 0;
        for (int k = nbins - 1; k > 0; --k) {
          acc.grow(b[k].box);
          cnt += b[k].count;
          right_area[k] = acc.area();
          right_count[k] = cnt;
        }
        acc = AABB{};
        cnt = 0;
        for (int k = 0; k < nbins - 1; ++k) {
          acc.grow(b[k].box);
          cnt += b[k].count;
          if (cnt == 0 || right_count[k + 1] == 0) continue;
          float c = acc.area() * cnt + right_area[k + 1] * right_count[k + 1];
          if (c < best_cost) { best_cost = c; best_axis = a; best_split = k + 1; }
        }
      }
      const float parent_area = box.area();
      const float split_cost = p.cost_traversal + p.cost_intersect * best_cost / std::max(parent_area, 1e-30f);
      const float leaf_cost = p.cost_intersect * count;
      if (count <= max_leaf && (best_axis < 0 || split_cost >= leaf_cost)) continue;

      uint32_t mid;
      if (best_axis >= 0) {
        const float scale = nbins / cext[best_axis];
        auto* it = std::partition(bvh.prim_index.data() + first, bvh.prim_index.data() + first + count,
                                  [&](uint32_t t) {
                                    return std::min(nbins - 1, int((centroid[t][best_axis] - cbox.lo[best_axis]) *
                                                                   scale)) < best_split;
                                  });
        mid = uint32_t(it - bvh.prim_index.data());
      } else {
        mid = first + count / 2;  // all centroids coincide: split the list to respect max_leaf
      }
      const uint32_t left = next_node.fetch_add(2);
      bvh.nodes[left] = {{}, first, {}, mid - first};
      bvh.nodes[left + 1] = {{}, mid, {}, first + count - mid};
      node.left_first = left;
      node.count = 0;
      stack.push_back({left + 1, task.depth + 1});
      stack.push_back({left, task.depth + 1});
    }
    for (uint32_t d = max_depth.load(); local_depth > d && !max_depth.compare_exchange_weak(d, local_depth);) {
    }
  }
};

}  // namespace

BVH BVH::build(const Scene& scene, const BVHBuildParams& p) {
  auto t0 = std::chrono::steady_clock::now();
  const uint32_t n = uint32_t(scene.num_triangles());
  BVH bvh;
  bvh.prim_index.resize(n);
  std::vector<AABB> tri_box(n);
  std::vector<Vec3> centroid(n);
  for (uint32_t i = 0; i < n; ++i) {
    bvh.prim_index[i] = i;
    tri_box[i] = scene.triangle_bounds(i);
    centroid[i] = tri_box[i].centre();
  }
  bvh.nodes.resize(size_t(2) * std::max(n, 1u) + 2);  // a binary tree over n leaves has < 2n nodes
  bvh.nodes[0] = {{}, 0, {}, n};
  bvh.nodes[1] = {{0, 0, 0}, 0, {0, 0, 0}, 0};

  Builder b{p, bvh, tri_box, centroid};
  const int threads = std::max(1, p.threads);
  if (threads == 1) {
    b.run({{0, 0}}, false);
  } else {
    // Top levels on this thread until the subtrees are small enough to balance across threads,
    // then the deferred subtrees in parallel, each thread pulling the next from a shared index.
    b.defer_below = std::max(n / (8 * uint32_t(threads)), 1024u);
    b.run({{0, 0}}, true);
    std::atomic<size_t> next{0};
    auto worker = [&] {
      for (size_t i; (i = next.fetch_add(1)) < b.deferred.size();) b.run({b.deferred[i]}, false);
    };
    std::vector<std::thread> pool;
    for (int i = 1; i < threads; ++i) pool.emplace_back(worker);
    worker();
    for (auto& t : pool) t.join();
  }
  bvh.nodes.resize(b.next_node.load());
  bvh.stats.max_depth = b.max_depth.load();
  bvh.stats.nodes = uint32_t(bvh.nodes.size() - 1);
  for (size_t i = 0; i < bvh.nodes.size(); ++i)
    if (i != 1 && bvh.nodes[i].is_leaf()) bvh.stats.leaves++;
  bvh.stats.bytes = bvh.nodes.size() * sizeof(BVHNode) + bvh.prim_index.size() * sizeof(uint32_t);
  bvh.stats.sah_cost = bvh.compute_sah_cost(p);
  bvh.stats.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return bvh;
}

void BVH::refit(const Scene& scene, int threads) {
  // Post-order over the tree; the top levels fork so `threads` subtrees refit at once.
  int fork_levels = 0;
  while ((1 << fork_levels) < threads) ++fork_levels;
  auto rec = [&](auto&& self, uint32_t i, int depth) -> void {
    BVHNode& nd = nodes[i];
    AABB b;
    if (nd.is_leaf()) {
      for (uint32_t k = nd.left_first; k < nd.left_first + nd.count; ++k) b.grow(scene.triangle_bounds(prim_index[k]));
    } else {
      if (depth < fork_levels) {
        std::thread left([&] { self(self, nd.left_first, depth + 1); });
        self(self, nd.left_first + 1, depth + 1);
        left.join();
      } else {
        self(self, nd.left_first, depth + 1);
        self(self, nd.left_first + 1, depth + 1);
      }
      const BVHNode &l = nodes[nd.left_first], &r = nodes[nd.left_first + 1];
      b.grow(AABB{l.lo, l.hi});
      b.grow(AABB{r.lo, r.hi});
    }
    nd.lo = b.lo;
    nd.hi = b.hi;
  };
  if (!nodes.empty()) rec(rec, 0, 0);
}

double BVH::compute_sah_cost(const BVHBuildParams& p) const {
  if (nodes.empty()) return 0;
  const double root = std::max(AABB{nodes[0].lo, nodes[0].hi}.area(), 1e-30f);
  double cost = 0;
  for (size_t i = 0; i < nodes.size(); ++i) {
    if (i == 1) continue;
    const double a = AABB{nodes[i].lo, nodes[i].hi}.area() / root;
    cost += nodes[i].is_leaf() ? a * p.cost_intersect * nodes[i].count : a * p.cost_traversal;
  }
  return cost;
}

}  // namespace tb
