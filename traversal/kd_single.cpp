// kd_single: one ray at a time through the SAH kD-tree (thesis §2.2.2, Alg. 2.2), made iterative
// with a (node, tnear, tfar) stack as the thesis notes ("typically expressed as an iterative
// algorithm by using a simple stack mechanism"): front to back, near child first, the far child
// pushed with its interval, and an early exit as soon as a hit lies inside the current cell.
//
// Robustness (DESIGN.md "Correctness"): the near/far order comes from the sign bit of the
// direction component, so d = (split - org) * (1/dir) = +-inf for dir = +-0 culls the right child
// by itself; d = NaN (origin exactly on the plane of a zero component: 0 * inf, the ray runs
// inside the plane) visits both children over the whole interval, and since both then share
// that interval, a hit in the near child ends the search only after the far child has been
// searched too (a ray along the edge of a box hits its corner from either cell); every interval is widened by kKdPad (structures/kdtree.h) so
// a ray touching a cell's closed box visits it. Leaves test their triangles over the ray's whole
// [tmin, closest hit) range, so a triangle that extends beyond the cell is still found; the hit
// only ends the search once it lies inside the cell.
#include "structures/kdtree.h"
#include "traversal/bvh_common.h"
#include "traversal/kd_common.h"

namespace tb {
namespace {

class KDSingle final : public KDScheme<KDSingle> {
 public:
  using TreeScheme::TreeScheme;
  std::string_view name() const override { return "kd_single"; }

  template <TriKernel K, class P>
  void run_kernel(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const KDTree& kd = *data_.tree;
    const TriangleSet& tris = *data_.tris;
    const KDNode* nodes = kd.nodes.data();
    // Each push is followed by a descent, so the stack never holds more than the depth.
    Entry stack[KDTree::kMaxDepth + 2];
    const RayCtx::ShearAxes axes = RayCtx::axes_for(batch.common_origin);
    for_each_ray(batch, range, hits, probe, [&](const Ray& ray, Hit& hit) {
      const RayCtx rc(ray, axes);
      float tn, tf;
      if (!kd.nodes.empty() && kd_clip_ray(kd.bounds, rc.org, rc.dir, rc.inv, ray.tmin, ray.tmax, tn, tf)) {
        const float org[3] = {rc.org.x, rc.org.y, rc.org.z};
        const float inv[3] = {rc.inv.x, rc.inv.y, rc.inv.z};
        const uint32_t neg[3] = {uint32_t(rc.near_x), uint32_t(rc.near_y), uint32_t(rc.near_z)};
        uint32_t sp = 0;
        uint32_t node = 0;
        // Pending cells pushed for a ray inside their split plane share the t-interval of the
        // cell being searched, so a hit "inside the current cell" does not end the search while
        // any of them is on the stack (rays along the edge of a box hit its corner in either cell).
        uint32_t in_plane = 0;
        for (;;) {
          const KDNode* n = &nodes[node];
          bool leaf_reached = true;
          while (!n->is_leaf()) {
            probe.node(n, sizeof(KDNode));
            const int a = n->axis();
            const float d = (n->split() - org[a]) * inv[a];
            const uint32_t near = n->left() + neg[a], far = n->left() + (neg[a] ^ 1u);
            // std::min(tf, NaN) = tf and std::max(tn, NaN) = tn: a NaN distance keeps both
            // children over the whole interval (ray inside the split plane).
            const float tf_near = std::min(tf, kd_pad_up(d));
            const float tn_far = std::max(tn, kd_pad_down(d));
            const bool go_near = tn <= tf_near;
            const bool go_far = tn_far <= tf && tn_far <= hit.t;
            if (go_near) {
              if (go_far) {
                const uint32_t nan = d != d;
                in_plane += nan;
                stack[sp++] = {far, tn_far, tf, nan};
                probe.write(&stack[sp - 1], sizeof(Entry));
              }
              node = near;
              tf = tf_near;
            } else if (go_far) {
              node = far;
              tn = tn_far;
            } else {
              leaf_reached = false;
              break;
            }
            n = &nodes[node];
          }
          if (leaf_reached) {
            probe.leaf(n, sizeof(KDNode));
            const uint32_t first = n->first(), end = first + n->count();
            for (uint32_t k = first; k < end; ++k) {
              probe.tris(tris.data_at(k, K), TriangleSet::bytes(K));
              intersect_tri<K>(rc, tris, k, ray.tmin, hit);
            }
            // Early exit (Alg. 2.2 "if t <= d return"): a hit inside this cell (whose interval
            // is already padded outward) cannot be beaten by any later cell.
            if (hit.prim != kNoHit && hit.t <= tf && in_plane == 0) break;
          }
          // Pop the nearest pending cell that may still hold a closer hit.
          bool popped = false;
          while (sp > 0) {
            const Entry e = stack[--sp];
            probe.read(&stack[sp], sizeof(Entry));
            in_plane -= e.in_plane;
            if (e.tn <= hit.t) {
              node = e.node;
              tn = e.tn;
              tf = e.tf;
              popped = true;
              break;
            }
          }
          if (!popped) break;
        }
      }
    });
  }

 private:
  struct Entry {
    uint32_t node;
    float tn, tf;
    uint32_t in_plane;  // pushed for a ray inside the split plane (NaN distance)
  };
};

}  // namespace

std::unique_ptr<Traverser> make_kd_single(const SchemeConfig& cfg) { return std::make_unique<KDSingle>(cfg); }
ParamSpecs params_kd_single() { return kd_param_specs(); }

}  // namespace tb
