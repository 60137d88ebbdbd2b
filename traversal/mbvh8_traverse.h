// The single-ray loop of mbvh8_single (8-wide nodes, 8-wide triangle blocks, watertight kernel),
// kept apart from mbvh.h's mbvh_traverse (shared with mbvh_rs, raygrid and the octree) so that it
// can be tuned for the one-ray case alone.
//
// What differs from mbvh_traverse: the entered children are ordered without branching on how
// many there are. mbvh_traverse branches three ways (one child: enter; two: compare; three or
// more: sorting network); with 8 children the count varies from node to node and those branches,
// plus the data-dependent compare of the two-child case, mispredict often. Here every node with
// an entered child takes the same path: the bitonic network sorts the distance keys and pushes
// all but the nearest (push_sorted; with one child it pushes nothing), and the nearest comes from
// a three-step min reduction of the unsorted keys, so the next node's address does not wait for
// the whole network. Measured on bounce:2 (512x512, 7 reps, median, ratio to embree_single):
// +4 to +13% over the branching loop on the nine scenes of /work/shared/scenes
// (docs/PERFORMANCE.md). This is the "sort always" variant of the child ordering discussed by
// Wald et al. (2008) and Ernst & Greiner (2008) for 4-wide nodes, with the keys of thesis Alg. 2.10.
#pragma once
#include "traversal/mbvh_traverse.h"

namespace tb {

// The smallest of 8 sort keys (mbvh_simd::sort_keys8: distance bits with the child index in the
// low 3 bits; misses are the largest key): three shuffle + min steps.
inline uint32_t min_key8(__m256i k) {
  k = _mm256_min_epi32(k, _mm256_permute2x128_si256(k, k, 0x01));
  k = _mm256_min_epi32(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(1, 0, 3, 2)));
  k = _mm256_min_epi32(k, _mm256_shuffle_epi32(k, _MM_SHUFFLE(2, 3, 0, 1)));
  return uint32_t(_mm256_cvtsi256_si32(k));
}

// Ordered single-ray traversal of an MBVH<8, 8> with the watertight SIMD triangle test; the
// stack holds 7 * max_depth + 8 entries (push_sorted's 8-entry store, as in mbvh_traverse).
template <class P>
inline void mbvh8_traverse(const MBVH<8, 8>& m, const NodeRay<8>& nr, const TriRay<8>& tr, Hit& hit,
                           MBVHStackEntry* stack, P& probe) {
  using S = mbvh_simd::V<8>;
  const MBVHNode<8>* nodes = m.nodes.data();
  uint32_t sp = 0, cur = 0;
  float tfar = hit.t;  // a register copy: stack stores could alias hit.t and force reloads
  for (;;) {
    if (!mbvh_ref::is_leaf(cur)) {
      const MBVHNode<8>& nd = nodes[cur];
      probe.node(&nd, sizeof(nd));
      typename S::f tn;
      const auto entered = box_test<8>(nd, nr, tfar, tn);
      const int mask = S::mask(entered);
      if (mask) {
        const int count = std::popcount(unsigned(mask));
        push_sorted<8>(nd, tn, entered, count, stack + sp);
        if constexpr (P::enabled) {
          for (int j = 0; j < count - 1; ++j) probe.write(&stack[sp + j], sizeof(MBVHStackEntry));
        }
        cur = nd.ref[min_key8(mbvh_simd::sort_keys8(tn, entered)) & 7];
        sp += uint32_t(count - 1);
        continue;
      }
    } else {
      probe_leaf(m, cur, probe, 1);
      leaf_test<8, 8, TriKernel::watertight>(m, nullptr, tr, nullptr, cur, hit);
      tfar = hit.t;
    }
    if (!pop_pending(stack, sp, tfar, cur, probe)) return;
  }
}

// The timed loop of mbvh8_single (tri_width=8, watertight kernel).
template <class P>
void mbvh8_trace_rays(const MBVHData<8, 8>& d, const RayBatch& batch, PacketRange range, std::span<Hit> hits,
                      P& probe) {
  const MBVH<8, 8>& m = *d.mbvh;
  mbvh_for_each_ray(m, batch, range, hits, probe,
                    [&](const NodeRay<8>& nr, const TriRay<8>& tr, const RayCtx&, Hit& hit, MBVHStackEntry* stack) {
                      mbvh8_traverse(m, nr, tr, hit, stack, probe);
                    });
}

}  // namespace tb
