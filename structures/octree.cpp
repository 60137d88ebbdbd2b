#include "structures/octree.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>

#include "structures/bvh_spatial.h"
#include "structures/clip.h"

namespace tb {

std::string OctreeParams::key() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, "octree:leaf_prims=%d:max_depth=%d:merge=%d:width=%d:", leaf_prims, max_depth, merge,
                width);  // threads do not change the structure
  return buf + bvh.key();
}

std::string OctreeStats::describe() const {
  // The octree's part, then its mini-MBVHs' (the same keys as ever: table columns read them).
  const double dup = triangles ? double(refs) / double(triangles) : 0.0;
  char tree[240], minis[160];
  std::snprintf(tree, sizeof tree,
                "octree_nodes=%u leaves=%u empty_leaves=%u max_depth=%u avg_leaf_depth=%.2f refs=%llu dup=%.2f "
                "avg_prims_per_leaf=%.1f",
                nodes, leaves, empty_leaves, max_depth, avg_leaf_depth, (unsigned long long)refs, dup, avg_prims_per_leaf);
  std::snprintf(minis, sizeof minis, "avg_mbvh_nodes=%.1f avg_mbvh_leaf_depth=%.2f mbvh_max_depth=%u bytes=%zu build_ms=%.1f",
                avg_mbvh_nodes, avg_mbvh_leaf_depth, mbvh_max_depth, bytes, build_ms);
  return std::string(tree) + " " + minis;
}

namespace {

float ulp_of(float x) {
  x = std::fabs(x);
  return std::nextafter(x, INFINITY) - x;
}

AABB grown(const AABB& b, float pad) {
  return {b.lo - Vec3{pad, pad, pad}, b.hi + Vec3{pad, pad, pad}};
}

// Whether the leaf or child box `box` references triangle t, and the bounds of the part of t
// inside it (empty: not referenced). A box that holds t's whole box needs no clipping.
AABB clipped_box(const Scene& scene, const std::vector<AABB>& tbox, uint32_t t, const AABB& box) {
  if (box.contains(tbox[t])) return tbox[t];
  return clip_triangle_bounds(scene.vertex(t, 0), scene.vertex(t, 1), scene.vertex(t, 2), box);
}

}  // namespace

// Mini-MBVHs (octree.h), leaves in parallel: each leaf's triangles, boxes clipped to the padded
// leaf, go to the one binary builder (BVH::build over a span of references) and the one collapse
// (MBVH::collapse: greedy for width 4, the SAH-optimal programme for width 8), each into arrays
// of its own; MBVH::concat then lays them out leaf after leaf in `mini`.
template <int N>
void build_minis(const Scene& scene, const OctreeParams& p, const std::vector<AABB>& tbox,
                 const std::vector<std::vector<uint32_t>>& leaf_refs, Octree& o, MBVH<N, 4>& mini) {
  MBVHBuildParams mp;
  mp.bvh = p.bvh;
  mp.bvh.threads = 1;  // the leaves are the parallelism
  const SpatialSplitParams sp = spatial_split_params(p.bvh);
  mp.merge = p.merge;
  mp.sah_collapse = N == 8;
  mp.small = 0;  // 4-wide blocks throughout: RayGrid tests two rays per AVX2 pass
  const uint32_t nl = uint32_t(o.leaves.size());
  std::vector<MBVH<N, 4>> parts(nl);
  std::vector<AABB> cull(nl);
  {
    std::atomic<uint32_t> next{0};
    auto worker = [&] {
      std::vector<PrimRef> refs;
      std::vector<SpatialRef> srefs;
      for (uint32_t l; (l = next.fetch_add(1)) < nl;) {
        if (leaf_refs[l].empty()) continue;
        const OctreeNode& nd = o.nodes[o.leaves[l].node];
        const AABB e = grown(AABB{nd.lo, nd.hi}, o.pad);
        refs.clear();
        for (uint32_t t : leaf_refs[l]) {
          const AABB b = clipped_box(scene, tbox, t, e);
          if (!b.empty()) refs.emplace_back(b, t);  // always: the same test admitted t
        }
        if (refs.empty()) continue;
        BVH bvh;
        if (mp.bvh.spatial) {
          srefs.clear();
          for (const PrimRef& r : refs) srefs.push_back({r.box(), r.id()});
          bvh = build_spatial_bvh(scene, std::move(srefs), mp.bvh, sp);
        } else {
          bvh = BVH::build(std::span<PrimRef>(refs), mp.bvh);
        }
        cull[l] = AABB{bvh.nodes[0].lo, bvh.nodes[0].hi};
        parts[l] = MBVH<N, 4>::collapse(scene, bvh, mp);
      }
    };
    const int threads = std::clamp(p.threads, 1, 64);
    std::vector<std::thread> pool;
    for (int t = 1; t < threads && uint32_t(t) < nl; ++t) pool.emplace_back(worker);
    worker();
    for (auto& t : pool) t.join();
  }
  OctreeStats& s = o.stats;
  double leaf_depth_sum = 0;
  uint64_t mbvh_nodes_nonempty = 0;
  for (uint32_t l = 0; l < nl; ++l) {
    OctreeLeaf& lf = o.leaves[l];
    const MBVHStats& m = parts[l].stats;
    leaf_depth_sum += o.nodes[lf.node].depth;
    s.max_depth = std::max(s.max_depth, o.nodes[lf.node].depth);
    if (parts[l].nodes.empty()) {
      s.empty_leaves++;
      continue;
    }
    lf.num_nodes = uint32_t(parts[l].nodes.size());
    lf.num_blocks = uint32_t(parts[l].blocks.size());
    lf.refs = uint32_t(leaf_refs[l].size());
    lf.mbvh_depth = m.max_depth;
    lf.mbvh_leaf_depth = m.avg_leaf_depth;
    lf.cull = cull[l];
    {
      const Vec3 ce = cull[l].extent(), le = o.nodes[lf.node].hi - o.nodes[lf.node].lo;
      lf.cull_tight = double(ce.x) * ce.y * ce.z < 0.5 * double(le.x) * le.y * le.z;
    }
    s.refs += lf.refs;
    mbvh_nodes_nonempty += lf.num_nodes;
  }
  std::vector<typename MBVH<N, 4>::Placement> where;
  mini = MBVH<N, 4>::concat(std::move(parts), &where);
  for (uint32_t l = 0; l < nl; ++l) {
    OctreeLeaf& lf = o.leaves[l];
    if (lf.num_nodes == 0) continue;
    lf.mbvh_root = lf.first_node = where[l].root;
    lf.first_block = where[l].first_block;
  }
  s.leaves = nl;
  s.mbvh_max_depth = mini.stats.max_depth;
  const uint32_t nonempty = nl - s.empty_leaves;
  s.avg_leaf_depth = nl ? leaf_depth_sum / nl : 0.0;
  s.avg_prims_per_leaf = nonempty ? double(s.refs) / nonempty : 0.0;
  s.avg_mbvh_nodes = nonempty ? double(mbvh_nodes_nonempty) / nonempty : 0.0;
  s.avg_mbvh_leaf_depth = mini.stats.avg_leaf_depth;
}

// ---------------------------------------------------------------------------------------------

Octree Octree::build(const Scene& scene, const OctreeParams& p) {
  const auto t0 = std::chrono::steady_clock::now();
  if (p.leaf_prims < 1) throw InputError("octree: leaf_prims must be >= 1");
  if (p.max_depth < 0 || p.max_depth > 20) throw InputError("octree: max_depth must be in [0, 20]");
  if (p.bvh.max_leaf < 1 || p.bvh.max_leaf > 64) throw InputError("octree: the mini-BVHs' max_leaf must be in [1, 64]");
  if (p.bvh.builder != BVHBuilder::travbench) throw InputError("octree: the mini-BVHs are built by travbench's builder");
  if (p.merge < 0 || p.merge > 64) throw InputError("octree: merge must be in [0, 64]");
  if (p.width != 4 && p.width != 8) throw InputError("octree: width must be 4 or 8");
  Octree o;
  o.params = p;
  const uint32_t n = uint32_t(scene.num_triangles());
  std::vector<AABB> tbox(n);
  AABB root;
  for (uint32_t i = 0; i < n; ++i) {
    tbox[i] = scene.triangle_bounds(i);
    root.grow(tbox[i]);
  }
  if (root.empty()) root = AABB{{0, 0, 0}, {0, 0, 0}};
  // A flat scene would make every split along its thin axis produce two identical children:
  // give each axis at least 2^-10 of the largest extent (empty space costs nothing).
  {
    const Vec3 e = root.extent();
    const float emax = std::max(std::max(e.x, e.y), std::max(e.z, 1e-30f));
    for (int a = 0; a < 3; ++a) {
      const float need = emax * 0x1p-10f;
      if (e[a] < need) {
        const float c = root.lo[a] + e[a] * 0.5f;
        root.lo[a] = std::min(root.lo[a], c - need * 0.5f);
        root.hi[a] = std::max(root.hi[a], c + need * 0.5f);
      }
    }
  }
  // The pad (see octree.h): a walk position p = org + dir * t carries a few rounding errors of
  // the magnitudes involved — the coordinates (ulp of the largest one) and the distance travelled
  // (ulp of the extent, up to a few extents for rays from outside). 2^-16 of the extent and 16
  // ulps of the largest coordinate cover that with a wide margin; the cost is a few duplicated
  // references of triangles that lie within that distance of a face.
  {
    const Vec3 e = root.extent();
    const float emax = std::max(std::max(e.x, e.y), e.z);
    float maxabs = 0.f;
    for (int a = 0; a < 3; ++a) maxabs = std::max({maxabs, std::fabs(root.lo[a]), std::fabs(root.hi[a])});
    o.pad = std::max(emax * 0x1p-16f + 16.f * ulp_of(maxabs), 1e-30f);
  }

  OctreeNode rn;
  rn.lo = root.lo, rn.hi = root.hi;
  o.nodes.push_back(rn);
  std::vector<std::vector<uint32_t>> leaf_refs;
  struct Work {
    uint32_t node;
    std::vector<uint32_t> refs;
  };
  std::vector<Work> stack;
  {
    Work w{0, std::vector<uint32_t>(n)};
    for (uint32_t i = 0; i < n; ++i) w.refs[i] = i;
    stack.push_back(std::move(w));
  }
  const float pad = o.pad;
  // References made by all splits together: a scene's triangles are referenced a few times per
  // level over up to ten levels at the thesis' settings (§5.4.1), but leaf_prims near 1 with a deep
  // max_depth keeps splitting nodes that every triangle of a fan overlaps, up to 4x the references
  // per level (the explosion guard below) — gigabytes, then an out-of-memory error that blamed the
  // image size.
  // Nodes likewise: leaf_prims = 1 splits every node of two triangles, and each leaf gets a
  // mini-BVH of its own.
  const uint64_t ref_budget = std::max<uint64_t>(256ull * n, 1ull << 24);
  const uint64_t node_budget = std::max<uint64_t>(16ull * n, 1ull << 16);
  uint64_t refs_made = 0;
  while (!stack.empty()) {
    Work w = std::move(stack.back());
    stack.pop_back();
    const OctreeNode nd = o.nodes[w.node];
    bool split = w.refs.size() > size_t(p.leaf_prims) && nd.depth < uint32_t(p.max_depth);
    std::array<std::vector<uint32_t>, 8> kids;
    std::array<AABB, 8> kbox;
    Vec3 mid;
    if (split) {
      for (int a = 0; a < 3; ++a) mid[a] = std::clamp(nd.lo[a] + (nd.hi[a] - nd.lo[a]) * 0.5f, nd.lo[a], nd.hi[a]);
      // Too small to halve in float on every axis: stop.
      bool any = false;
      for (int a = 0; a < 3; ++a) any |= mid[a] > nd.lo[a] && mid[a] < nd.hi[a];
      split = any;
    }
    if (split) {
      for (uint32_t c = 0; c < 8; ++c)
        for (int a = 0; a < 3; ++a) {
          const bool up = (c >> a) & 1;
          kbox[c].lo[a] = up ? mid[a] : nd.lo[a];
          kbox[c].hi[a] = up ? nd.hi[a] : mid[a];
        }
      std::array<AABB, 8> ebox;
      for (int c = 0; c < 8; ++c) ebox[c] = grown(kbox[c], pad);
      size_t total = 0;  // references over all children
      for (uint32_t t : w.refs) {
        const AABB& b = tbox[t];
        // Octants the box can touch: per axis the lower half if it reaches below mid + pad, the
        // upper half if it reaches above mid - pad.
        uint32_t lower = 0, upper = 0;
        for (int a = 0; a < 3; ++a) {
          if (b.lo[a] <= ebox[0].hi[a]) lower |= 1u << a;
          if (b.hi[a] >= ebox[7].lo[a]) upper |= 1u << a;
        }
        for (uint32_t c = 0; c < 8; ++c) {
          if (((c & upper) != c) || ((~c & 7u & lower) != (~c & 7u))) continue;
          if (!clipped_box(scene, tbox, t, ebox[c]).empty()) kids[c].push_back(t);
        }
      }
      for (const auto& k : kids) total += k.size();
      // Subdivide unless references explode: when the triangles overlap (nearly) every child, as
      // a fan around a vertex does, splitting separates nothing. (A child that keeps all the
      // parent's triangles is fine: the others are empty space, and the next level separates.)
      if (total > 4 * w.refs.size()) split = false;
      if (split && ((refs_made += total) > ref_budget || o.nodes.size() + 8 > node_budget))
        throw InputError("octree: leaf_prims=" + std::to_string(p.leaf_prims) + " with max_depth=" +
                         std::to_string(p.max_depth) + " makes more than " +
                         (refs_made > ref_budget ? std::to_string(ref_budget) + " triangle references made by its splits (256"
                                                 : std::to_string(node_budget) + " nodes (16") +
                         " per triangle of the scene, or 2^16 nodes, 2^24 references if more); raise leaf_prims or "
                         "lower max_depth");
    }
    if (split) {
      const uint32_t first = uint32_t(o.nodes.size());
      o.nodes[w.node].child = first;
      o.nodes[w.node].mid = mid;
      for (uint32_t c = 0; c < 8; ++c) {
        OctreeNode cn;
        cn.lo = kbox[c].lo, cn.hi = kbox[c].hi;
        cn.parent = w.node;
        cn.depth = nd.depth + 1;
        o.nodes.push_back(cn);
      }
      for (int c = 7; c >= 0; --c) stack.push_back({first + uint32_t(c), std::move(kids[size_t(c)])});
    } else {
      o.nodes[w.node].leaf = uint32_t(o.leaves.size());
      OctreeLeaf lf;
      lf.node = w.node;
      o.leaves.push_back(lf);
      leaf_refs.push_back(std::move(w.refs));
    }
  }

  // Neighbour links, top-down (a parent's index is below its children's): across an internal
  // face the sibling; across the parent's face the parent's neighbour if it is a leaf (larger),
  // else its child mirrored across that face (same size).
  for (uint32_t i = 0; i < o.nodes.size(); ++i) {
    const OctreeNode pn = o.nodes[i];
    if (pn.is_leaf()) continue;
    for (uint32_t c = 0; c < 8; ++c) {
      OctreeNode& cn = o.nodes[pn.child + c];
      for (int a = 0; a < 3; ++a)
        for (int s = 0; s < 2; ++s) {
          const int f = face_of(a, s);
          const uint32_t bit = (c >> a) & 1u;
          if (bit != uint32_t(s)) {
            cn.nbr[f] = pn.child + (c ^ (1u << a));
          } else {
            const uint32_t nb = pn.nbr[f];
            if (nb == kNoNode) cn.nbr[f] = kNoNode;
            else if (o.nodes[nb].is_leaf()) cn.nbr[f] = nb;
            else cn.nbr[f] = o.nodes[nb].child + (c ^ (1u << a));
          }
        }
    }
  }

  if (p.width == 8) build_minis<8>(scene, p, tbox, leaf_refs, o, o.mini8);
  else build_minis<4>(scene, p, tbox, leaf_refs, o, o.mini);
  OctreeStats& s = o.stats;
  s.nodes = uint32_t(o.nodes.size());
  s.triangles = n;
  s.tri_bytes = o.mini.stats.tri_bytes + o.mini8.stats.tri_bytes;
  s.bytes = o.nodes.size() * sizeof(OctreeNode) + o.leaves.size() * sizeof(OctreeLeaf) + o.mini.stats.node_bytes +
            o.mini8.stats.node_bytes + s.tri_bytes;
  s.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return o;
}

std::vector<uint32_t> Octree::leaf_triangles(uint32_t leaf) const {
  const OctreeLeaf& lf = leaves[leaf];
  std::vector<uint32_t> out;
  const auto& blocks = mini_blocks();
  for (uint32_t b = lf.first_block; b < lf.first_block + lf.num_blocks; ++b)
    for (int l = 0; l < 4; ++l) out.push_back(blocks[b].prim[l]);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace tb
