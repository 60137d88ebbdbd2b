// cwbvh_single: single-ray traversal of the compressed 8-wide BVH (structures/cwbvh.h; Ylitie,
// Karras and Laine 2017; CS348K lecture 18, "compression" as the first answer to incoherent rays
// being bandwidth bound). Each node is 80 bytes instead of the MBVH8's 256. The node test
// computes the child planes' distances straight from the 8-bit offsets, one fused multiply-add per
// plane row (Ylitie et al. §3.1), with a proven error bound in place of Ize's padding: every
// computed near distance is a lower bound and every far one an upper bound of the exact distance,
// so a child the ray really enters is never culled (traversal/cwbvh_traverse.h has the bound; the
// builder's quantization guarantees the decoded box contains the true one).
// Children are ordered as mbvh8_single's "sort always" path orders them (bitonic network on
// distance keys), leaves are the MBVH8's 8-wide triangle blocks under the watertight SIMD test.
// The tree is the SAH-collapsed MBVH8 (same parameters as mbvh8_single, leaves of at most 16
// triangles), re-laid out and quantized.
#include <cstddef>
#include <cstring>

#include "structures/cwbvh.h"
#include "traversal/cwbvh_traverse.h"
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"

namespace tb {
namespace {

constexpr MBVHDefaults kDefaults = kMBVH8Defaults;  // compresses mbvh8_single's cached tree

template <class P>
void cw_traverse(const CWBVH& t, const CWRay& r, const TriRay<8>& tr, Hit& hit, MBVHStackEntry* stack, P& probe) {
  using S = simd::V<8>;
  const CWNode* nodes = t.nodes.data();
  uint32_t sp = 0, cur = 0;
  float tfar = hit.t;
  __m256 tfar8 = _mm256_set1_ps(tfar);  // changes only at a leaf
  for (;;) {
    if (!mbvh_ref::is_leaf(cur)) {
      const CWNode& nd = nodes[cur];
      probe.node(&nd, sizeof(nd));
      __m256 tn;
      const __m256 entered = cw_box_test(nd, r, tfar8, tn);
      const int mask = S::mask(entered);
      if (mask) {
        const int count = std::popcount(unsigned(mask));
        const __m256i refs = cw_child_refs(nd);
        push_sorted8(refs, tn, entered, count, stack + sp);
        if constexpr (P::enabled) {
          for (int j = 0; j < count - 1; ++j) probe.write(&stack[sp + j], sizeof(MBVHStackEntry));
        }
        alignas(32) uint32_t ref[8];
        _mm256_store_si256(reinterpret_cast<__m256i*>(ref), refs);
        cur = ref[min_key8(mbvh_simd::sort_keys8(tn, entered)) & 7];
        sp += uint32_t(count - 1);
        continue;
      }
    } else {
      const uint32_t leaf = cw_leaf_to_mbvh(cur);
      probe_leaf<8>(t.blocks.data(), leaf, probe, 1);
      leaf_test<8, TriKernel::watertight>(t.blocks.data(), nullptr, tr, nullptr, leaf, hit);
      tfar = hit.t;
      tfar8 = _mm256_set1_ps(tfar);
    }
    if (!pop_pending(stack, sp, tfar, cur, probe)) return;
  }
}

class CWBVHSingle final : public TraverserBase<CWBVHSingle> {
 public:
  explicit CWBVHSingle(const SchemeConfig& cfg) : cfg_(cfg), params_(mbvh_params(cfg, kDefaults)) {
    if (params_.merge > 16) throw InputError("cwbvh_single: merge must be <= 16 (a compressed leaf holds at most 16 triangles)");
    if (params_.bvh.max_leaf > 16) throw InputError("cwbvh_single: leaf_size must be <= 16 (a compressed leaf holds at most 16 triangles)");
  }
  std::string_view name() const override { return "cwbvh_single"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    const MBVHData<8, 8> m = fetch_mbvh<8, 8>(scene, cache, params_, TriKernel::watertight);
    cw_ = cache.get<CWBVH>(params_.key(8, 8), [&] { return CWBVH::compress(*m.mbvh); });
  }
  std::string structure_info() const override { return cw_->stats.describe(); }
  StructureBytes memory() const override { return {cw_->stats.node_bytes, cw_->stats.tri_bytes}; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const CWBVH& t = *cw_;
    std::vector<MBVHStackEntry> stack(size_t(7) * t.stats.max_depth + 10);
    for_each_ray(batch, range, hits, probe, [&](const Ray& ray, Hit& hit) {
      if (t.blocks.empty()) return;  // an empty scene: nothing to hit
      const RayCtx rc(ray);
      cw_traverse(t, CWRay(rc, ray.tmin, t.coord_bound), TriRay<8>(rc, ray.tmin), hit, stack.data(), probe);
    });
  }

 private:
  SchemeConfig cfg_;
  MBVHBuildParams params_;
  std::shared_ptr<const CWBVH> cw_;
};

}  // namespace

std::unique_ptr<Traverser> make_cwbvh_single(const SchemeConfig& cfg) { return std::make_unique<CWBVHSingle>(cfg); }
ParamSpecs params_cwbvh_single() {
  ParamSpecs specs = mbvh_param_specs(kDefaults);
  for (ParamSpec& p : specs)
    if (p.name == "small") p = int_choice_param("small", 0, {0}, "always 0: the compressed layout holds 8-wide blocks only");
  return specs;
}

}  // namespace tb
