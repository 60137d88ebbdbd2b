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

// sort_prefetch: sort, and the second-nearest entered child's node or first block lines fetched
// after the push (as mbvh8_single's ChildOrder::sort_prefetch; `prefetch`).
enum class CWOrder { branching, sort, sort_prefetch, octant };

// The address of the node an interior reference names (either kind, structures/cwbvh.h), as an
// integer: the prefetches below may form it for a leaf's reference, which is never dereferenced.
inline uintptr_t cw_node_address(const CWBVH& t, uint32_t ref) {
  return (ref & kCWFull) ? reinterpret_cast<uintptr_t>(t.full.data()) + uintptr_t(ref & ~(kCWFull | mbvh_ref::kLeaf)) * sizeof(MBVHNode<8>)
                         : reinterpret_cast<uintptr_t>(t.nodes.data()) + uintptr_t(ref & ~mbvh_ref::kLeaf) * sizeof(CWNode);
}

// One traversal for both node kinds: a full node (kCWFull) takes the MBVH8's fused node test
// (box_test on cw_full_ray's constants, the same as `r`'s), a compressed node
// the fused test on 8-bit planes; what follows the test (ordering, push, prefetch) is the same
// code, instantiated per kind with the node's reference getters.
template <CWOrder O, bool ExpAdd, bool Indexed, class P>
void cw_traverse(const CWBVH& t, const CWRay& r, const TriRay<8>& tr, Hit& hit, MBVHStackEntry* stack, P& probe) {
  using S = simd::V<8>;
  const CWNode* nodes = t.nodes.data();
  const MBVHNode<8>* full = t.full.data();
  uint32_t sp = 0, cur = t.root;
  float tfar = hit.t;
  __m256 tfar8 = _mm256_set1_ps(tfar);  // changes only at a leaf
  // The entered children (mask non-zero) of the node just tested: `refs` gives the 8 references as
  // a vector, ref(i) slot i's. Sets cur (and sp); false: none entered.
  const auto descend = [&](const __m256 entered, const __m256 tn, auto&& refs, auto&& ref) {
    const int mask = S::mask(entered);
    if (!mask) return false;
    if constexpr (O == CWOrder::branching) {
      const auto prefetch = [&](uint32_t c) {
        if (mbvh_ref::is_leaf(c)) return;
        const char* a = reinterpret_cast<const char*>(cw_node_address(t, c));
        if (c & kCWFull) {
          for (size_t l = 0; l < sizeof(MBVHNode<8>); l += 64) _mm_prefetch(a + l, _MM_HINT_T0);
        } else {  // 80 bytes, 16-aligned: two lines
          _mm_prefetch(a, _MM_HINT_T0), _mm_prefetch(a + sizeof(CWNode) - 1, _MM_HINT_T0);
        }
      };
      cur = enter_branching<8>(
          mask, tn, ref, prefetch,
          [&](int count, MBVHStackEntry* out) {
            const __m256i rv = refs();
            push_sorted8(rv, tn, entered, count, out);
            return nearest_ref8(rv, mbvh_simd::sort_keys8(tn, entered));  // beside the network, not after it
          },
          stack, sp, probe);
      return true;
    } else {
      const int count = std::popcount(unsigned(mask));
      const __m256i rv = refs();
      if constexpr (O == CWOrder::octant) {
        const uint64_t order = r.order[mask];
        push_in_order8(rv, tn, _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(int64_t(order))), stack + sp);
        cur = ref(uint32_t(order >> (8 * (count - 1))) & 7);
      } else {
        if constexpr (O == CWOrder::sort_prefetch) {
          uint32_t second;
          push_sorted8(rv, tn, entered, count, stack + sp, &second);
          const uintptr_t block =
              Indexed ? reinterpret_cast<uintptr_t>(t.iblocks.data()) + uintptr_t(cw_ileaf_block(second)) * sizeof(CWTriBlock)
                      : reinterpret_cast<uintptr_t>(t.blocks.data()) +
                            uintptr_t(mbvh_ref::first_block(cw_leaf_to_mbvh(second))) * sizeof(TriBlock<8>);
          prefetch_node_or_block(cw_node_address(t, second), block, mbvh_ref::is_leaf(second));
        } else {
          push_sorted8(rv, tn, entered, count, stack + sp);
        }
        cur = nearest_ref8(rv, mbvh_simd::sort_keys8(tn, entered));
      }
      if constexpr (P::enabled) {
        for (int j = 0; j < count - 1; ++j) probe.write(&stack[sp + j], sizeof(MBVHStackEntry));
      }
      sp += uint32_t(count - 1);
      return true;
    }
  };
  for (;;) {
    if (!mbvh_ref::is_leaf(cur)) {
      __m256 tn;
      if (cur & kCWFull) {
        const MBVHNode<8>& nd = full[cur & ~kCWFull];
        probe.node(&nd, sizeof(nd));
        const __m256 entered = box_test<8>(nd, cw_full_ray(r), tfar, tn);
        if (descend(
                entered, tn, [&] { return _mm256_load_si256(reinterpret_cast<const __m256i*>(nd.ref)); },
                [&](uint32_t i) { return nd.ref[i]; }))
          continue;
      } else {
        const CWNode& nd = nodes[cur];
        probe.node(&nd, sizeof(nd));
        const __m256 entered = cw_box_test<ExpAdd>(nd, r, tfar8, tn);
        if (descend(
                entered, tn, [&] { return cw_child_refs(nd); }, [&](uint32_t i) { return cw_child_ref(nd, i); }))
          continue;
      }
    } else {
      if constexpr (Indexed) {
        uint32_t k = cw_ileaf_block(cur);
        probe.leaf(&t.iblocks[k], 0, 1);
        for (;; ++k) {
          const CWTriBlock& b = t.iblocks[k];
          probe.tris(&b, sizeof(CWTriBlock), b.lanes);
          indexed_block_intersect(tr, b, hit);
          if (b.last) break;
        }
      } else {
        const uint32_t leaf = cw_leaf_to_mbvh(cur);
        probe_leaf<8>(t.blocks.data(), leaf, probe, 1);
        leaf_test<8, TriKernel::watertight>(t.blocks.data(), nullptr, tr, nullptr, leaf, hit);
      }
      tfar = hit.t;
      tfar8 = _mm256_set1_ps(tfar);
    }
    if (!pop_pending(stack, sp, tfar, cur, probe)) return;
  }
}

class CWBVHSingle final : public TraverserBase<CWBVHSingle> {
 public:
  explicit CWBVHSingle(const SchemeConfig& cfg)
      : cfg_(cfg),
        params_(mbvh_params(cfg, kDefaults)),
        order_(parse_order_param(cfg.get_choice("order"))),
        full_percent_(cfg.get_int("full_top")),
        leaves_(cfg.get_choice("leaves") == "indexed" ? CWLeaves::indexed : CWLeaves::blocks) {
    if (params_.merge > 16) throw InputError("merge must be <= 16 (a compressed leaf holds at most 16 triangles)");
    if (params_.bvh.max_leaf > 16) throw InputError("leaf_size must be <= 16 (a compressed leaf holds at most 16 triangles)");
  }
  std::string_view name() const override { return "cwbvh_single"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    const MBVHData<8, 8> m = fetch_mbvh<8, 8>(scene, cache, params_, TriKernel::watertight);
    // Octant slots only for the octant order (structures/cwbvh.h: the others test fewer leaves on
    // the MBVH8's slot order).
    const CWSlots slots = order_ == OrderParam::octant ? CWSlots::octant : CWSlots::mbvh;
    cw_ = cache.get<CWBVH>(params_.key(8, 8) + ":full" + std::to_string(full_percent_) +
                               (slots == CWSlots::octant ? ":octant" : "") + (leaves_ == CWLeaves::indexed ? ":indexed" : ""),
                           [&] { return CWBVH::compress(*m.mbvh, full_percent_ / 100.0, slots, leaves_); });
    prefetch_ = prefetch_second_child(cfg_, memory().total());
  }
  std::string structure_info() const override { return cw_->stats.describe() + prefetch_info(prefetch_); }
  StructureBytes memory() const override { return {cw_->stats.node_bytes, cw_->stats.tri_bytes}; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const CWBVH& t = *cw_;
    std::vector<MBVHStackEntry> stack(size_t(7) * t.stats.max_depth + 10);
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
                    int_param("full_top", 4, 0, 100,
                              "percent of the nodes kept uncompressed (MBVH8 nodes, float boxes), the largest "
                              "boxes first (Benthin et al. 2018's compressed-leaf BVH): 0 = every node compressed"),
                    choice_param("leaves", "indexed", {"blocks", "indexed"},
                                 "leaf triangles: blocks = the MBVH8's 8-wide blocks (320 bytes), indexed = "
                                 "blocks of up to 8 triangles over a table of up to 8 distinct vertices (160 bytes)")} +
         prefetch_param_specs();
}

}  // namespace tb
