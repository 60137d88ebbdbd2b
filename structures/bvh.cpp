#include "structures/bvh.h"

#include <algorithm>
#include <chrono>
#include <cstdio>

namespace tb {

std::string BVHBuildParams::key() const {
  char buf[96];
  std::snprintf(buf, sizeof buf, "bvh:bins=%d:leaf=%d:ct=%g:ci=%g", bins, max_leaf, cost_traversal, cost_intersect);
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

BVH BVH::build(const Scene& scene, const BVHBuildParams& p) {
  auto t0 = std::chrono::steady_clock::now();
  const uint32_t n = uint32_t(scene.num_triangles());
  const int nbins = std::clamp(p.bins, 2, 256);
  const uint32_t max_leaf = uint32_t(std::max(1, p.max_leaf));
  BVH bvh;
  bvh.prim_index.resize(n);
  std::vector<AABB> tri_box(n);
  std::vector<Vec3> centroid(n);
  for (uint32_t i = 0; i < n; ++i) {
    bvh.prim_index[i] = i;
    tri_box[i] = scene.triangle_bounds(i);
    centroid[i] = tri_box[i].centre();
  }
  bvh.nodes.reserve(n > 0 ? 2 * n : 2);
  bvh.nodes.resize(2);
  bvh.nodes[0] = {{}, 0, {}, n};
  bvh.nodes[1] = {{0, 0, 0}, 0, {0, 0, 0}, 0};

  std::vector<BuildTask> stack{{0, 0}};
  std::vector<Bin> bins(size_t(3) * nbins);
  std::vector<float> right_area(nbins);
  std::vector<uint32_t> right_count(nbins);
  while (!stack.empty()) {
    BuildTask task = stack.back();
    stack.pop_back();
    BVHNode& node = bvh.nodes[task.node];
    const uint32_t first = node.left_first, count = node.count;
    AABB box, cbox;
    for (uint32_t i = first; i < first + count; ++i) {
      box.grow(tri_box[bvh.prim_index[i]]);
      cbox.grow(centroid[bvh.prim_index[i]]);
    }
    node.lo = box.lo;
    node.hi = box.hi;
    bvh.stats.max_depth = std::max(bvh.stats.max_depth, task.depth);
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
      auto* it = std::partition(bvh.prim_index.data() + first, bvh.prim_index.data() + first + count, [&](uint32_t t) {
        return std::min(nbins - 1, int((centroid[t][best_axis] - cbox.lo[best_axis]) * scale)) < best_split;
      });
      mid = uint32_t(it - bvh.prim_index.data());
    } else {
      mid = first + count / 2;  // all centroids coincide: split the list to respect max_leaf
    }
    const uint32_t left = uint32_t(bvh.nodes.size());
    bvh.nodes.push_back({{}, first, {}, mid - first});
    bvh.nodes.push_back({{}, mid, {}, first + count - mid});
    BVHNode& parent = bvh.nodes[task.node];  // push_back may have moved the array
    parent.left_first = left;
    parent.count = 0;
    stack.push_back({left + 1, task.depth + 1});
    stack.push_back({left, task.depth + 1});
  }
  bvh.stats.nodes = uint32_t(bvh.nodes.size() - 1);
  for (size_t i = 0; i < bvh.nodes.size(); ++i)
    if (i != 1 && bvh.nodes[i].is_leaf()) bvh.stats.leaves++;
  bvh.stats.bytes = bvh.nodes.size() * sizeof(BVHNode) + bvh.prim_index.size() * sizeof(uint32_t);
  bvh.stats.sah_cost = bvh.compute_sah_cost(p);
  bvh.stats.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return bvh;
}

void BVH::refit(const Scene& scene) {
  // Children always have higher indices than their parent, so one reverse sweep suffices.
  for (size_t i = nodes.size(); i-- > 0;) {
    if (i == 1) continue;
    BVHNode& nd = nodes[i];
    AABB b;
    if (nd.is_leaf()) {
      for (uint32_t k = nd.left_first; k < nd.left_first + nd.count; ++k) b.grow(scene.triangle_bounds(prim_index[k]));
    } else {
      const BVHNode &l = nodes[nd.left_first], &r = nodes[nd.left_first + 1];
      b.grow(AABB{l.lo, l.hi});
      b.grow(AABB{r.lo, r.hi});
    }
    nd.lo = b.lo;
    nd.hi = b.hi;
  }
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
