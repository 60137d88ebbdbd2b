#include "structures/octree.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <thread>

namespace tb {

std::string OctreeParams::key() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, "octree:leaf_prims=%d:max_depth=%d:mbvh_leaf=%d:merge=%d:bins=%d:width=%d",
                leaf_prims, max_depth, mbvh_leaf, merge, bins, width);  // threads do not change the structure
  return buf;
}

std::string OctreeStats::describe() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "octree_nodes=%u leaves=%u empty_leaves=%u max_depth=%u avg_leaf_depth=%.2f refs=%llu "
                "dup=%.2f avg_prims_per_leaf=%.1f avg_mbvh_nodes=%.1f avg_mbvh_leaf_depth=%.2f "
                "mbvh_max_depth=%u bytes=%zu build_ms=%.1f",
                nodes, leaves, empty_leaves, max_depth, avg_leaf_depth, (unsigned long long)refs,
                triangles ? double(refs) / double(triangles) : 0.0, avg_prims_per_leaf, avg_mbvh_nodes,
                avg_mbvh_leaf_depth, mbvh_max_depth, bytes, build_ms);
  return buf;
}

// ---------------------------------------------------------------------------------------------
// Triangle / box clipping

namespace {

struct P3 {
  double x[3];
};

// Keeps the part of polygon in[0..n) with x[axis] >= c (keep_ge) or x[axis] <= c. Points on the
// plane are inside: the boxes are closed.
int clip_plane(const P3* in, int n, P3* out, int axis, double c, bool keep_ge) {
  int m = 0;
  for (int i = 0; i < n; ++i) {
    const P3& A = in[i];
    const P3& B = in[(i + 1) % n];
    const double da = keep_ge ? A.x[axis] - c : c - A.x[axis];
    const double db = keep_ge ? B.x[axis] - c : c - B.x[axis];
    const bool ina = da >= 0, inb = db >= 0;
    if (ina) out[m++] = A;
    if (ina != inb) {
      const double t = da / (da - db);
      P3 p;
      for (int k = 0; k < 3; ++k) p.x[k] = A.x[k] + (B.x[k] - A.x[k]) * t;
      p.x[axis] = c;
      out[m++] = p;
    }
  }
  return m;
}

float round_down(double d) {
  float f = float(d);
  if (double(f) > d) f = std::nextafter(f, -INFINITY);
  return f;
}
float round_up(double d) {
  float f = float(d);
  if (double(f) < d) f = std::nextafter(f, INFINITY);
  return f;
}

float ulp_of(float x) {
  x = std::fabs(x);
  return std::nextafter(x, INFINITY) - x;
}

}  // namespace

bool clip_triangle_to_box(Vec3 a, Vec3 b, Vec3 c, const AABB& box, AABB* bounds) {
  // A triangle has at most 3 + 6 vertices after six planes; 16 leaves room.
  P3 buf0[16], buf1[16];
  buf0[0] = {{a.x, a.y, a.z}}, buf0[1] = {{b.x, b.y, b.z}}, buf0[2] = {{c.x, c.y, c.z}};
  int n = 3;
  P3* in = buf0;
  P3* out = buf1;
  for (int axis = 0; axis < 3 && n > 0; ++axis) {
    n = clip_plane(in, n, out, axis, box.lo[axis], true);
    std::swap(in, out);
    if (n == 0) break;
    n = clip_plane(in, n, out, axis, box.hi[axis], false);
    std::swap(in, out);
  }
  if (n == 0) return false;
  if (bounds) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], in[i].x[k]), hi[k] = std::max(hi[k], in[i].x[k]);
    AABB r;
    for (int k = 0; k < 3; ++k) {
      r.lo[k] = std::max(round_down(lo[k]), box.lo[k]);
      r.hi[k] = std::min(round_up(hi[k]), box.hi[k]);
      if (r.lo[k] > r.hi[k]) r.lo[k] = r.hi[k] = std::clamp(float(lo[k]), box.lo[k], box.hi[k]);
    }
    *bounds = r;
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// Mini-MBVH builder: binned SAH over an index subset with clipped boxes, then the SAH-aware
// collapse to 4 wide of structures/mbvh.cpp (open the interior child of largest area until there
// are four), with small subtrees merged into one leaf.

namespace {

struct Item {
  AABB box;
  Vec3 centre;
  uint32_t tri;
};

struct BNode {
  AABB box;
  uint32_t first = 0, count = 0;
  uint32_t left = 0;  // interior: children left, left + 1
  bool leaf = true;
};

template <int N>
struct LocalMBVH {
  std::vector<MBVHNode<N>> nodes;
  std::vector<TriBlock<4>> blocks;
  uint32_t max_depth = 0, leaves = 0;
  double leaf_depth_sum = 0;
  AABB bounds;
};

class MiniBuilder {
 public:
  MiniBuilder(const Scene& scene, const OctreeParams& p) : scene_(scene), p_(p) {}

  void build(std::vector<Item>& items, LocalMBVH<4>& out) {
    items_ = &items;
    out_ = &out;
    start(items);
    for (const Item& it : items) out.bounds.grow(it.box);
    out.nodes.emplace_back();
    std::vector<uint32_t> kids;
    if (as_leaf(0)) kids.push_back(0);
    else kids = {bnodes_[0].left, bnodes_[0].left + 1};
    fill(0, std::move(kids), 1);
  }

  // Width 8: the same binary tree over clipped boxes, handed to structures/mbvh.cpp's SAH-optimal
  // collapse (Ylitie, Karras, Laine 2017, §3.2) as a BVH in its layout, so the 8-wide mini-MBVHs
  // are built exactly like mbvh8_single's tree. Its 4-wide triangle blocks keep RayGrid's
  // two-rays-per-AVX2-pass leaf test.
  void build8(std::vector<Item>& items, LocalMBVH<8>& out) {
    items_ = &items;
    start(items);
    for (const Item& it : items) out.bounds.grow(it.box);
    // BVH layout: root 0, slot 1 unused, siblings adjacent; binary node i > 0 moves to i + 1.
    BVH bvh;
    bvh.nodes.resize(bnodes_.size() + 1);
    for (size_t i = 0; i < bnodes_.size(); ++i) {
      const BNode& b = bnodes_[i];
      BVHNode& n = bvh.nodes[i == 0 ? 0 : i + 1];
      n.lo = b.box.lo, n.hi = b.box.hi;
      n.left_first = b.leaf ? b.first : b.left + 1;
      n.count = b.leaf ? b.count : 0;
    }
    bvh.prim_index.resize(items.size());
    for (size_t i = 0; i < items.size(); ++i) bvh.prim_index[i] = items[i].tri;
    MBVHBuildParams mp;
    mp.sah_collapse = true;
    mp.merge = p_.merge;
    mp.small = 0;
    MBVH<8, 4> m = MBVH<8, 4>::collapse(scene_, bvh, mp);
    out.nodes.assign(m.nodes.begin(), m.nodes.end());
    out.blocks.assign(m.blocks.begin(), m.blocks.end());
    out.max_depth = m.stats.max_depth;
    out.leaves = m.stats.leaves;
    // Leaf depths (root = 1) for the statistics.
    std::vector<std::pair<uint32_t, uint32_t>> stack{{0u, 1u}};
    while (!stack.empty()) {
      const auto [ni, d] = stack.back();
      stack.pop_back();
      const MBVHNode<8>& nd = out.nodes[ni];
      for (uint32_t c = 0; c < nd.num_children; ++c) {
        if (mbvh_ref::is_leaf(nd.ref[c])) out.leaf_depth_sum += d;
        else stack.push_back({nd.ref[c], d + 1});
      }
    }
  }

 private:
  void start(std::vector<Item>& items) {
    bnodes_.clear();
    bnodes_.reserve(2 * items.size() + 1);
    BNode root;
    root.first = 0;
    root.count = uint32_t(items.size());
    bnodes_.push_back(root);
    binary();
  }

  void binary() {
    std::vector<Item>& items = *items_;
    const int nbins = std::clamp(p_.bins, 2, 256);
    const uint32_t max_leaf = uint32_t(std::max(1, p_.mbvh_leaf));
    struct Bin {
      AABB box;
      uint32_t count = 0;
    };
    std::vector<Bin> bins(nbins);
    std::vector<float> right_area(nbins);
    std::vector<uint32_t> right_count(nbins);
    std::vector<uint32_t> stack = {0};
    while (!stack.empty()) {
      const uint32_t ni = stack.back();
      stack.pop_back();
      const uint32_t first = bnodes_[ni].first, count = bnodes_[ni].count;
      AABB box, cbox;
      for (uint32_t i = first; i < first + count; ++i) box.grow(items[i].box), cbox.grow(items[i].centre);
      bnodes_[ni].box = box;
      if (count <= 1) continue;
      int best_axis = -1, best_split = 0;
      float best_cost = INFINITY;
      const Vec3 cext = cbox.extent();
      for (int a = 0; a < 3; ++a) {
        if (!(cext[a] > 0.f)) continue;
        std::fill(bins.begin(), bins.end(), Bin{});
        const float scale = nbins / cext[a];
        for (uint32_t i = first; i < first + count; ++i) {
          const int k = std::min(nbins - 1, int((items[i].centre[a] - cbox.lo[a]) * scale));
          bins[k].count++;
          bins[k].box.grow(items[i].box);
        }
        AABB acc;
        uint32_t cnt = 0;
        for (int k = nbins - 1; k > 0; --k) {
          acc.grow(bins[k].box);
          cnt += bins[k].count;
          right_area[k] = acc.area();
          right_count[k] = cnt;
        }
        acc = AABB{};
        cnt = 0;
        for (int k = 0; k < nbins - 1; ++k) {
          acc.grow(bins[k].box);
          cnt += bins[k].count;
          if (cnt == 0 || right_count[k + 1] == 0) continue;
          const float cst = acc.area() * cnt + right_area[k + 1] * right_count[k + 1];
          if (cst < best_cost) best_cost = cst, best_axis = a, best_split = k + 1;
        }
      }
      const float split_cost = 1.f + best_cost / std::max(box.area(), 1e-30f);
      if (count <= max_leaf && (best_axis < 0 || split_cost >= float(count))) continue;
      uint32_t mid;
      if (best_axis >= 0) {
        const float scale = nbins / cext[best_axis];
        auto it = std::partition(items.begin() + first, items.begin() + first + count, [&](const Item& t) {
          return std::min(nbins - 1, int((t.centre[best_axis] - cbox.lo[best_axis]) * scale)) < best_split;
        });
        mid = uint32_t(it - items.begin());
      } else {
        mid = first + count / 2;  // coincident centroids: split the list to respect mbvh_leaf
      }
      const uint32_t left = uint32_t(bnodes_.size());
      BNode l, r;
      l.first = first, l.count = mid - first;
      r.first = mid, r.count = first + count - mid;
      bnodes_.push_back(l);
      bnodes_.push_back(r);
      bnodes_[ni].leaf = false;
      bnodes_[ni].left = left;
      stack.push_back(left + 1);
      stack.push_back(left);
    }
  }

  bool as_leaf(uint32_t b) const {
    return bnodes_[b].leaf || (p_.merge > 0 && bnodes_[b].count <= uint32_t(p_.merge));
  }

  void fill(uint32_t idx, std::vector<uint32_t> kids, uint32_t depth) {
    out_->max_depth = std::max(out_->max_depth, depth);
    while (kids.size() < 4) {
      int best = -1;
      float best_area = -1.f;
      for (size_t i = 0; i < kids.size(); ++i) {
        if (as_leaf(kids[i])) continue;
        const float a = bnodes_[kids[i]].box.area();
        if (a > best_area) best_area = a, best = int(i);
      }
      if (best < 0) break;
      const uint32_t open = kids[size_t(best)];
      kids[size_t(best)] = bnodes_[open].left;
      kids.insert(kids.begin() + best + 1, bnodes_[open].left + 1);
    }
    MBVHNode<4> node;
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < 4; ++i) node.box[a][i] = INFINITY, node.box[3 + a][i] = -INFINITY;
    for (int i = 0; i < 4; ++i) node.ref[i] = 0;
    node.num_children = uint32_t(kids.size());
    for (size_t i = 0; i < kids.size(); ++i) {
      const AABB& b = bnodes_[kids[i]].box;
      for (int a = 0; a < 3; ++a) node.box[a][i] = b.lo[a], node.box[3 + a][i] = b.hi[a];
    }
    for (size_t i = 0; i < kids.size(); ++i)
      if (as_leaf(kids[i])) {
        node.ref[i] = make_leaf(bnodes_[kids[i]].first, bnodes_[kids[i]].count);
        out_->leaves++;
        out_->leaf_depth_sum += depth;
      }
    std::vector<std::pair<size_t, uint32_t>> interior;
    for (size_t i = 0; i < kids.size(); ++i)
      if (!as_leaf(kids[i])) {
        node.ref[i] = uint32_t(out_->nodes.size());
        interior.push_back({i, node.ref[i]});
        out_->nodes.emplace_back();
      }
    out_->nodes[idx] = node;
    for (const auto& [slot, child] : interior) {
      const uint32_t b = kids[slot];
      fill(child, {bnodes_[b].left, bnodes_[b].left + 1}, depth + 1);
    }
  }

  // A leaf's triangles as SIMD blocks of four, the last padded with copies of the leaf's last
  // triangle (mbvh.h: every lane is a real triangle, a duplicate never reports another hit).
  uint32_t make_leaf(uint32_t first, uint32_t count) {
    if (count == 0 || count > mbvh_ref::kMaxLeafTris)
      throw std::runtime_error("octree: mini-MBVH leaf of " + std::to_string(count) + " triangles");
    const uint32_t block0 = uint32_t(out_->blocks.size());
    for (uint32_t k = 0; k * 4 < count; ++k) {
      TriBlock<4> blk;
      for (uint32_t l = 0; l < 4; ++l) {
        const uint32_t tri = (*items_)[first + std::min(k * 4 + l, count - 1)].tri;
        for (int c = 0; c < 3; ++c) {
          const Vec3 v = scene_.vertex(tri, c);
          blk.v[c][0][l] = v.x, blk.v[c][1][l] = v.y, blk.v[c][2][l] = v.z;
        }
        blk.prim[l] = tri;
      }
      out_->blocks.push_back(blk);
    }
    return mbvh_ref::make_leaf(block0, count);  // block index relative to this leaf; rebased later
  }

  const Scene& scene_;
  const OctreeParams& p_;
  std::vector<Item>* items_ = nullptr;
  LocalMBVH<4>* out_ = nullptr;
  std::vector<BNode> bnodes_;
};

AABB grown(const AABB& b, float pad) {
  return {b.lo - Vec3{pad, pad, pad}, b.hi + Vec3{pad, pad, pad}};
}

}  // namespace

// Mini-MBVHs, leaves in parallel (each builds into its own arrays), then concatenated into
// `mini` (leaf after leaf: a leaf's nodes and blocks are contiguous).
template <int N>
void build_minis(const Scene& scene, const OctreeParams& p, const std::vector<AABB>& tbox,
                 const std::vector<std::vector<uint32_t>>& leaf_refs, Octree& o, MBVH<N, 4>& mini) {
  const float pad = o.pad;
  OctreeStats& s = o.stats;
  const uint32_t nl = uint32_t(o.leaves.size());
  std::vector<LocalMBVH<N>> local(nl);
  {
    std::atomic<uint32_t> next{0};
    auto worker = [&] {
      MiniBuilder mb(scene, p);
      std::vector<Item> items;
      for (uint32_t l; (l = next.fetch_add(1)) < nl;) {
        const std::vector<uint32_t>& refs = leaf_refs[l];
        if (refs.empty()) continue;
        const OctreeNode& nd = o.nodes[o.leaves[l].node];
        const AABB e = grown(AABB{nd.lo, nd.hi}, pad);
        items.clear();
        for (uint32_t t : refs) {
          Item it;
          it.tri = t;
          if (e.contains(tbox[t])) it.box = tbox[t];
          else if (!clip_triangle_to_box(scene.vertex(t, 0), scene.vertex(t, 1), scene.vertex(t, 2), e, &it.box))
            continue;  // cannot happen: the same test admitted it
          it.centre = it.box.centre();
          items.push_back(it);
        }
        if (items.empty()) continue;
        if constexpr (N == 8) mb.build8(items, local[l]);
        else mb.build(items, local[l]);
      }
    };
    const int threads = std::clamp(p.threads, 1, 64);
    std::vector<std::thread> pool;
    for (int t = 1; t < threads && uint32_t(t) < nl; ++t) pool.emplace_back(worker);
    worker();
    for (auto& t : pool) t.join();
  }
  size_t total_nodes = 0, total_blocks = 0;
  for (const auto& l : local) total_nodes += l.nodes.size(), total_blocks += l.blocks.size();
  if (total_blocks > mbvh_ref::kMaxBlocks) throw std::runtime_error("octree: too many triangle blocks");
  mini.nodes.reserve(total_nodes);
  mini.blocks.reserve(total_blocks);
  double leaf_depth_sum = 0, mbvh_leaf_depth_sum = 0;
  uint64_t mbvh_leaves = 0, mbvh_nodes_nonempty = 0;
  for (uint32_t l = 0; l < nl; ++l) {
    OctreeLeaf& lf = o.leaves[l];
    LocalMBVH<N>& m = local[l];
    leaf_depth_sum += o.nodes[lf.node].depth;
    s.max_depth = std::max(s.max_depth, o.nodes[lf.node].depth);
    if (m.nodes.empty()) {
      s.empty_leaves++;
      continue;
    }
    const uint32_t nb = uint32_t(mini.nodes.size()), bb = uint32_t(mini.blocks.size());
    for (MBVHNode<N> nd : m.nodes) {
      for (uint32_t i = 0; i < nd.num_children; ++i) {
        const uint32_t r = nd.ref[i];
        nd.ref[i] = mbvh_ref::is_leaf(r) ? mbvh_ref::make_leaf(mbvh_ref::first_block(r) + bb, mbvh_ref::num_tris(r))
                                         : r + nb;
      }
      mini.nodes.push_back(nd);
    }
    mini.blocks.insert(mini.blocks.end(), m.blocks.begin(), m.blocks.end());
    lf.mbvh_root = nb;
    lf.first_node = nb, lf.num_nodes = uint32_t(m.nodes.size());
    lf.first_block = bb, lf.num_blocks = uint32_t(m.blocks.size());
    lf.refs = uint32_t(leaf_refs[l].size());
    lf.mbvh_depth = m.max_depth;
    lf.mbvh_leaf_depth = m.leaves ? m.leaf_depth_sum / m.leaves : 0.0;
    lf.cull = m.bounds;
    {
      const Vec3 ce = m.bounds.extent(), le = o.nodes[lf.node].hi - o.nodes[lf.node].lo;
      lf.cull_tight = double(ce.x) * ce.y * ce.z < 0.5 * double(le.x) * le.y * le.z;
    }
    s.refs += lf.refs;
    s.mbvh_max_depth = std::max(s.mbvh_max_depth, m.max_depth);
    mbvh_leaf_depth_sum += m.leaf_depth_sum;
    mbvh_leaves += m.leaves;
    mbvh_nodes_nonempty += m.nodes.size();
    m = LocalMBVH<N>{};
  }
  mini.stats.width = N, mini.stats.tri_width = 4;
  mini.stats.nodes = uint32_t(mini.nodes.size());
  mini.stats.blocks = uint32_t(mini.blocks.size());
  mini.stats.leaves = uint32_t(mbvh_leaves);
  mini.stats.max_depth = s.mbvh_max_depth;
  mini.stats.triangles = uint32_t(s.refs);
  mini.stats.node_bytes = mini.nodes.size() * sizeof(MBVHNode<N>);
  mini.stats.tri_bytes = mini.blocks.size() * sizeof(TriBlock<4>);
  s.leaves = nl;
  const uint32_t nonempty = nl - s.empty_leaves;
  s.avg_leaf_depth = nl ? leaf_depth_sum / nl : 0.0;
  s.avg_prims_per_leaf = nonempty ? double(s.refs) / nonempty : 0.0;
  s.avg_mbvh_nodes = nonempty ? double(mbvh_nodes_nonempty) / nonempty : 0.0;
  s.avg_mbvh_leaf_depth = mbvh_leaves ? mbvh_leaf_depth_sum / double(mbvh_leaves) : 0.0;
}

// ---------------------------------------------------------------------------------------------

Octree Octree::build(const Scene& scene, const OctreeParams& p) {
  const auto t0 = std::chrono::steady_clock::now();
  if (p.leaf_prims < 1) throw InputError("octree: leaf_prims must be >= 1");
  if (p.max_depth < 0 || p.max_depth > 20) throw InputError("octree: max_depth must be in [0, 20]");
  if (p.mbvh_leaf < 1 || p.mbvh_leaf > 64) throw InputError("octree: mbvh_leaf must be in [1, 64]");
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
          if (ebox[c].contains(b) ||
              clip_triangle_to_box(scene.vertex(t, 0), scene.vertex(t, 1), scene.vertex(t, 2), ebox[c]))
            kids[c].push_back(t);
        }
      }
      for (const auto& k : kids) total += k.size();
      // Subdivide unless references explode: when the triangles overlap (nearly) every child, as
      // a fan around a vertex does, splitting separates nothing. (A child that keeps all the
      // parent's triangles is fine: the others are empty space, and the next level separates.)
      if (total > 4 * w.refs.size()) split = false;
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
  s.bytes = o.nodes.size() * sizeof(OctreeNode) + o.leaves.size() * sizeof(OctreeLeaf) +
            o.mini.stats.node_bytes + o.mini.stats.tri_bytes + o.mini8.stats.node_bytes + o.mini8.stats.tri_bytes;
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
