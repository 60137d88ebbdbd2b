// cwbvh_single: single-ray traversal of the compressed 8-wide BVH (structures/cwbvh.h; Ylitie,
// Karras and Laine 2017; CS348K lecture 18, "compression" as the first answer to incoherent rays
// being bandwidth bound). Each node is 80 bytes instead of the MBVH8's 256. The node test
// computes the child planes' distances straight from the 8-bit offsets, one fused multiply-add per
// plane row (Ylitie et al. §3.1), with a proven error bound in place of Ize's padding: every
// computed near distance is a lower bound and every far one an upper bound of the exact distance,
// so a child the ray really enters is never culled (traversal/cwbvh_traverse.h has the bound; the
// builder's quantization guarantees the decoded box contains the true one).
// Children are ordered by `order` (the values of mbvh8_single's, plus octant): branching enters a
// single entered child directly and compares two, and sorts three or more with the bitonic
// network on distance keys; sort takes the network for every node; auto (default, as
// mbvh8_single's) is branching for common-origin batches and sort otherwise. Session 9 measured
// branching faster on bounce:2 too (spheres:2M 0.522 -> 0.562 Mrays/s, crytek 1.065 -> 1.081) and
// on primary rays (callgrind, crytek 128x128: 2431 -> 2168 instructions per ray); after the
// branch-free node and leaf changes since, sort is the faster on bounce:2: sort / branching 1.03 to
// 1.08 on crytek, sibenik, bunny, conference and dragon_100k (session 22, one interleaved process
// per scene, 2 rounds), and with `prefetch` (the second-nearest child fetched early on structures
// beyond llc_mib, as mbvh8_single) 1.07-1.11 on spheres:1M and 2M (docs/PERFORMANCE.md, session 22).
// octant takes the builder's octant-ordered slots (Ylitie et al. 2017 §3.2/§4; structures/cwbvh.h):
// the entered slots, read in the order slot ^ ray octant, are approximately near to far, so one
// table lookup (kCWOctantOrder) gives the push order and the child to enter, no sort. Not the
// default: the approximate order enters far children first often enough that
// crytek's primary rays test 3.01 leaves instead of 1.80 (bounce:2 4.21 instead of 3.19) and take
// more instructions than sort (2629 vs 2431; docs/PERFORMANCE.md, session 9). Whatever the order,
// popped children whose entry distance is not below the closest hit are skipped, so the order
// changes the work, never the hits' distances.
// Leaves (`leaves`): indexed by default (structures/cwbvh.h, CWTriBlock: up to 8 triangles over a
// table of up to 8 distinct vertices, 160 bytes; Benthin et al. 2018 compress leaves as well as
// nodes), tested by indexed_block_intersect (the watertight test on the table, permuted to the
// corners: the same values as on the MBVH8's blocks); `blocks` keeps the MBVH8's 8-wide blocks
// (320 bytes). The triangles are most of the structure (spheres:2M: 122 MB of blocks against 16 MB
// of MBVH8 nodes), so node compression alone left most of the bytes: indexed leaves take
// 0.59-0.66x the triangle bytes and, beyond the last-level cache, cwbvh_single / mbvh8_single on
// bounce:2 rays rose from 1.04 to 1.11 (spheres:2M) and on primary rays from 0.99 to 1.01
// (spheres:10M); on cached scenes whose blocks split (quads: conference, 18% more blocks) 2-7%
// below `blocks` (docs/PERFORMANCE.md, session 32).
// The tree is the SAH-collapsed MBVH8 (same parameters as mbvh8_single, leaves of at most 16
// triangles), re-laid out and quantized; `full_top` percent of its nodes, those of largest box
// area, stay MBVH8 nodes (structures/cwbvh.h, "Uncompressed top"; Benthin et al. 2018's
// compressed-leaf BVH keeps full-precision nodes where the visits are). Default 4: 0.340x the
// MBVH8's node bytes (the bound is 0.35x), and 69-83% of the node visits on crytek,
// sponza and spheres:2M take the MBVH8's one-fma-per-plane test instead of widening and converting
// 8-bit rows: cwbvh_single / mbvh8_single on primary rays crytek 0.83 -> 0.92-0.95, spheres:2M
// 0.85-0.88 -> 0.96-1.00, bunny 0.85 -> 0.91-0.92 (interleaved, 3 rounds; docs/PERFORMANCE.md,
// session 23). full_top=0 is the plain compressed layout.
#include <cstddef>
#include <cstring>

#include "structures/cwbvh.h"
#include "traversal/cwbvh_traverse.h"
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"

namespace tb {
namespace {

constexpr MBVHDefaults kDefaults = kMBVH8Defaults;  // compresses mbvh8_single's cached tree

class CWBVHSingle final : public TraverserBase<CWBVHSingle> {
 public:
  explicit CWBVHSingle(const SchemeConfig& cfg)
      : cfg_(cfg),
        params_(mbvh_params(cfg, kDefaults)),
        order_(parse_order_param(cfg.get_choice("order"))),
        full_percent_(cfg.get_int("full_top")),
        leaves_(cfg.get_choice("leaves") == "indexed" ? CWLeaves::indexed : CWLeaves::blocks) {
    check_cwbvh_params(params_);
    check_prefetch_params(cfg, order_ == OrderParam::branching ? "order=branching"
                               : order_ == OrderParam::octant  ? "order=octant"
                                                               : nullptr);
  }
  std::string_view name() const override { return "cwbvh_single"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    // Octant slots only for the octant order (structures/cwbvh.h: the others test fewer leaves on
    // the MBVH8's slot order).
    const CWSlots slots = order_ == OrderParam::octant ? CWSlots::octant : CWSlots::mbvh;
    cw_ = fetch_cwbvh(scene, cache, params_, full_percent_, slots, leaves_);
    prefetch_ = prefetch_second_child(cfg_, memory().total());
  }
  std::string structure_info() const override { return cw_->stats.describe() + prefetch_info(prefetch_); }
  StructureBytes memory() const override { return {cw_->stats.node_bytes, cw_->stats.tri_bytes}; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const CWBVH& t = *cw_;
    std::vector<MBVHStackEntry> stack(mbvh_stack_entries(8, t.stats.max_depth));
    const CWOrder order = order_ == OrderParam::octant ? CWOrder::octant
                          : !sorts_batch(order_, batch)   ? CWOrder::branching
                          : prefetch_                     ? CWOrder::sort_prefetch
                                                          : CWOrder::sort;
    const RayCtx::ShearAxes axes = RayCtx::axes_for(batch.common_origin);
    for_each_ray(batch, range, hits, probe, [&](const Ray& ray, Hit& hit) {
      if (t.stats.blocks == 0) return;  // an empty scene: nothing to hit
      const RayCtx rc(ray, axes);
      const CWRay cr(rc, ray.tmin, t.coord_bound, t.e_min, t.e_max);
      const TriRay<8> tr(rc, ray.tmin);
      const auto go = [&]<CWOrder O>() {
        const auto leaves = [&]<bool ExpAdd>() {
          if (t.leaves == CWLeaves::indexed) {
            cw_traverse<O, ExpAdd, true>(t, cr, tr, hit, stack.data(), probe);
          } else {
            cw_traverse<O, ExpAdd, false>(t, cr, tr, hit, stack.data(), probe);
          }
        };
        if (cr.exp_add) {
          leaves.template operator()<true>();
        } else {
          leaves.template operator()<false>();
        }
      };
      if (order == CWOrder::branching) {
        go.template operator()<CWOrder::branching>();
      } else if (order == CWOrder::sort) {
        go.template operator()<CWOrder::sort>();
      } else if (order == CWOrder::sort_prefetch) {
        go.template operator()<CWOrder::sort_prefetch>();
      } else {
        go.template operator()<CWOrder::octant>();
      }
    });
  }

 private:
  SchemeConfig cfg_;
  MBVHBuildParams params_;
  std::shared_ptr<const CWBVH> cw_;
  OrderParam order_;
  int full_percent_;       // full_top: percent of the nodes kept uncompressed
  CWLeaves leaves_;
  bool prefetch_ = false;  // sorted batches take CWOrder::sort_prefetch (decided in prepare)
};

}  // namespace

std::unique_ptr<Traverser> make_cwbvh_single(const SchemeConfig& cfg) { return std::make_unique<CWBVHSingle>(cfg); }
ParamSpecs params_cwbvh_single() {
  ParamSpecs specs = mbvh_param_specs(kDefaults);
  param_named(specs, "small") = int_choice_param("small", 0, {0}, "always 0: the compressed layout holds 8-wide blocks only");
  return specs +
         ParamSpecs{choice_param("order", "auto", {"branching", "sort", "auto", "octant"},
                                 "child order: branching, sort = sort_always (as mbvh8_single's ChildOrder), "
                                 "auto = branching for common-origin batches, sort otherwise; octant = the "
                                 "layout's octant-ordered slots (slot ^ ray octant, a table lookup, no sort)"),
                    int_param("full_top", kCWFullTop, 0, 100,
                              "percent of the nodes kept uncompressed (MBVH8 nodes, float boxes), the largest "
                              "boxes first (Benthin et al. 2018's compressed-leaf BVH): 0 = every node compressed"),
                    choice_param("leaves", "indexed", {"blocks", "indexed"},
                                 "leaf triangles: blocks = the MBVH8's 8-wide blocks (320 bytes), indexed = "
                                 "blocks of up to 8 triangles over a table of up to 8 distinct vertices (160 bytes)")} +
         prefetch_param_specs();
}

}  // namespace tb
