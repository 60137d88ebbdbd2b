// cwbvh_single: single-ray traversal of the compressed 8-wide BVH (structures/cwbvh.h; Ylitie,
// Karras and Laine 2017; CS348K lecture 18, "compression" as the first answer to incoherent rays
// being bandwidth bound). Each node is 80 bytes instead of the MBVH8's 256: the child boxes are
// decoded in SIMD (8-bit offsets widened to float, times the node's power-of-two cell, plus its
// origin: exact in the cell multiply, one rounding in the add, the operations the builder checked
// when it quantized conservatively) and fed to the kernel library's slab test with Ize's far
// padding, so a decoded box is never smaller than the true one and robustness is the MBVH8's.
// Children are ordered as mbvh8_single's "sort always" path orders them (bitonic network on
// distance keys), leaves are the MBVH8's 8-wide triangle blocks under the watertight SIMD test.
// The tree is the SAH-collapsed MBVH8 (same parameters as mbvh8_single, leaves of at most 16
// triangles), re-laid out and quantized.
#include <cstddef>
#include <cstring>

#include "structures/cwbvh.h"
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"

namespace tb {
namespace {

constexpr MBVHDefaults kDefaults = kMBVH8Defaults;  // compresses mbvh8_single's cached tree

// Per-ray constants of the decoded box test: as NodeRay<8>, with the near/far choice per axis
// expressed as the byte offsets in a node of the quantized arrays holding the near and far planes
// (a direction with the sign bit set has its near plane at the box's hi), so the decode selects
// them without a branch.
struct CWRay {
  __m256 o[3], rn[3], rf[3], tmin;
  uint32_t near_at[3], far_at[3];
  CWRay(const RayCtx& rc, float t0) {
    for (int a = 0; a < 3; ++a) {
      o[a] = _mm256_set1_ps(rc.org[a]);
      rn[a] = _mm256_set1_ps(rc.inv[a]);
      rf[a] = _mm256_set1_ps(rc.inv[a] * kFarPad);
      const uint32_t lo = uint32_t(offsetof(CWNode, qlo)) + 8u * uint32_t(a);
      const uint32_t hi = uint32_t(offsetof(CWNode, qhi)) + 8u * uint32_t(a);
      near_at[a] = std::signbit(rc.inv[a]) ? hi : lo;
      far_at[a] = std::signbit(rc.inv[a]) ? lo : hi;
    }
    tmin = _mm256_set1_ps(t0);
  }
};

// p + float(q) * s on 8 slots in one fused multiply-add: the builder's cw_decode, lane by lane.
// For 8-bit q and s = 2^e (e >= -126) q * s is exact unless it overflows, so these are the floats
// of a multiply then add (tested) at one instruction fewer per array.
[[gnu::always_inline]] inline __m256 decode8(const CWNode& n, uint32_t at, __m256 p, __m256 s) {
  const auto* q = reinterpret_cast<const __m128i*>(reinterpret_cast<const uint8_t*>(&n) + at);
  const __m256i qi = _mm256_cvtepu8_epi32(_mm_loadl_epi64(q));
  return _mm256_fmadd_ps(_mm256_cvtepi32_ps(qi), s, p);
}

// The 8 child references of a node in the MBVH format (leaf bit, first block, triangles - 1).
[[gnu::always_inline]] inline __m256i child_refs(const CWNode& n) {
  const __m256i meta = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(n.meta)));
  const __m256i bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  const __m256i interior = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(n.imask), bit), bit);
  const __m256i inner = _mm256_add_epi32(_mm256_set1_epi32(int(n.child_base)), meta);
  const __m256i block = _mm256_add_epi32(_mm256_set1_epi32(int(n.block_base)), _mm256_and_si256(meta, _mm256_set1_epi32(15)));
  const __m256i leaf = _mm256_or_si256(_mm256_or_si256(_mm256_set1_epi32(int(mbvh_ref::kLeaf)), _mm256_slli_epi32(block, 6)),
                                       _mm256_srli_epi32(meta, 4));
  return _mm256_blendv_epi8(leaf, inner, interior);
}

template <class P>
void cw_traverse(const CWBVH& t, const CWRay& r, const TriRay<8>& tr, Hit& hit, MBVHStackEntry* stack, P& probe) {
  using S = simd::V<8>;
  const CWNode* nodes = t.nodes.data();
  uint32_t sp = 0, cur = 0;
  float tfar = hit.t;
  for (;;) {
    if (!mbvh_ref::is_leaf(cur)) {
      const CWNode& nd = nodes[cur];
      probe.node(&nd, sizeof(nd));
      __m256 xn[3], xf[3];
      // The three cells 2^e at once (cw_scale on 4 lanes: e[0..2] and imask, whose lane is unused),
      // then broadcast: 8 instructions per node instead of 15.
      static_assert(offsetof(CWNode, imask) == offsetof(CWNode, e) + 3);
      int32_t e4;
      std::memcpy(&e4, reinterpret_cast<const char*>(&nd) + offsetof(CWNode, e), sizeof e4);
      const __m128 cells = _mm_castsi128_ps(
          _mm_slli_epi32(_mm_add_epi32(_mm_cvtepi8_epi32(_mm_cvtsi32_si128(e4)), _mm_set1_epi32(127)), 23));
      const __m256 scale[3] = {_mm256_broadcastss_ps(cells), _mm256_broadcastss_ps(_mm_movehdup_ps(cells)),
                               _mm256_broadcastss_ps(_mm_movehl_ps(cells, cells))};
      for (int a = 0; a < 3; ++a) {
        const __m256 p = _mm256_set1_ps(nd.p[a]), s = scale[a];
        xn[a] = _mm256_sub_ps(decode8(nd, r.near_at[a], p, s), r.o[a]);
        xf[a] = _mm256_sub_ps(decode8(nd, r.far_at[a], p, s), r.o[a]);
      }
      __m256 tn;
      const __m256 entered = slab<8, true>(xn, xf, r.rn, r.rf, r.tmin, _mm256_set1_ps(tfar), tn);
      const int mask = S::mask(entered);
      if (mask) {
        const int count = std::popcount(unsigned(mask));
        const __m256i refs = child_refs(nd);
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
      probe_leaf<8>(t.blocks.data(), cur, probe, 1);
      leaf_test<8, TriKernel::watertight>(t.blocks.data(), nullptr, tr, nullptr, cur, hit);
      tfar = hit.t;
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
      const RayCtx rc(ray);
      cw_traverse(t, CWRay(rc, ray.tmin), TriRay<8>(rc, ray.tmin), hit, stack.data(), probe);
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
