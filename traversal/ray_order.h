// Ray reordering for the batch schemes: a batch of incoherent rays (bounce:k, path-traced
// extension rays) traced in the order of its origins' Morton codes, so that the rays of one stream
// start in the same region of the scene and share the nodes and triangles they read. This is the
// ray sorting of Pharr et al. 1997 ("Rendering complex scenes with memory-coherent ray tracing"),
// of Moon et al. 2010 ("Cache-oblivious ray reordering", which orders secondary rays by their hit
// points: the origins here) and of Garanzha & Loop 2010 ("Fast ray sorting and breadth-first
// packet traversal for GPU ray tracing"). A scheme that sorts pays for the sort inside its timed
// trace: one pass over the origins for their bounds, one for the keys (SIMD) and their histogram,
// one counting-sort scatter of ray indices; the scheme then reads each ray through its index.
// On sponza bounce:3 (238k rays) the order takes ~3 ns a ray, and with mbvh_rs's gather of the
// rays and scatter of the hits ~7 ns, against ~200 ns a ray of tracing.
//
// The grid is coarse, 4^3 cells over the rays' origins: a stream of mbvh_rs holds thousands of
// rays, and what the order decides is which rays share a stream. mbvh_rs on ray files sorted
// beforehand (sponza, sibenik_lucy, conference bounce:3 at 512x512, 3 rounds): 4^3 and 8^3 cells
// traced as fast as a 1024^3 grid's order (conference faster), 1.1-1.4x the unsorted batch; the
// sort alone took 12 ns a ray with a 30-bit key's radix sort, 14 with whole rays scattered
// (docs/PERFORMANCE.md, "Session 36").
//
// Rays with one common origin (camera rays) all fall into one cell, and a batch whose
// neighbouring rays mostly share a cell (first bounces: 1-5% change cell, against 84-94% from
// bounce:2 on) is coherent already when the caller says so (`min_change`): either way nothing is
// moved and the batch is read in place.
#pragma once
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <immintrin.h>

#include "workloads/ray_batch.h"

namespace tb {

class RayOrder {
 public:
  // Orders rays[first, last) by the Morton code of their origins' cells (stable: the rays of one
  // cell keep their order), unless the batch is coherent already: fewer than `min_change` of the
  // first kProbe rays lie in another cell than the ray before them (0: always sort). The probe
  // sees the passes' reads and writes.
  template <class P>
  void sort(std::span<const Ray> rays, uint32_t first, uint32_t last, double min_change, P& probe);
  // The index into `rays` of the j-th ray in that order, j in [0, last - first).
  uint32_t index(uint32_t j) const { return moved_ ? index_[j] : first_ + j; }
  // False when the order is the rays' own: every ray fell into one cell, or the batch was found
  // coherent under min_change (index(j) is then first + j).
  bool moved() const { return moved_; }
  // The rays of the last sort: last - first.
  uint32_t size() const { return size_; }

 private:
  static constexpr int kBitsPerAxis = 2;
  static constexpr uint32_t kCells = 1u << (3 * kBitsPerAxis);
  static constexpr uint32_t kProbe = 4096;  // rays whose cells decide whether the batch is coherent

  uint32_t first_ = 0, size_ = 0;
  bool moved_ = false;
  std::vector<uint32_t> index_;
  std::vector<uint8_t> key_;
};

template <class P>
void RayOrder::sort(std::span<const Ray> rays, uint32_t first, uint32_t last, double min_change, P& probe) {
  const uint32_t n = last - first;
  first_ = first;
  size_ = n;
  moved_ = false;
  if (n == 0) return;
  const Ray* in = rays.data() + first;
  // A Ray's first 16 bytes are org and tmin: one load a ray, the fourth lane ignored.
  static_assert(offsetof(Ray, org) == 0 && offsetof(Ray, tmin) == 12);
  __m128 lo = _mm_loadu_ps(&in[0].org.x), hi = lo;
  for (uint32_t i = 0; i < n; ++i) {
    probe.read(&in[i].org, sizeof(Vec3));
    const __m128 o = _mm_loadu_ps(&in[i].org.x);
    lo = _mm_min_ps(lo, o);
    hi = _mm_max_ps(hi, o);
  }
  // Cells per side / extent per axis; an axis on which every origin agrees gets scale 0 (cell 0).
  // Origins are finite (RayBatch::validate), so every product is; the top edge is clamped into
  // the last cell.
  constexpr float kSide = float(1u << kBitsPerAxis);
  const __m128 ext = _mm_sub_ps(hi, lo);
  const __m128 scale = _mm_and_ps(_mm_cmpgt_ps(ext, _mm_setzero_ps()), _mm_div_ps(_mm_set1_ps(kSide), ext));
  const __m128 top = _mm_set1_ps(kSide - 1);
  // The Morton code of cell (x, y, z), 2 bits each: bit b of axis a goes to bit 3b + a.
  static_assert(kBitsPerAxis == 2);
  const __m128i low_to = _mm_setr_epi32(0, 1, 2, 31), high_to = _mm_setr_epi32(2, 3, 4, 31);
  key_.resize(n);
  // Four histograms, so that neighbouring rays of one cell do not chain their increments.
  std::array<std::array<uint32_t, kCells>, 4> count4{};
  uint32_t changes = 0;
  for (uint32_t i = 0; i < n; ++i) {
    const __m128 c = _mm_min_ps(
        _mm_max_ps(_mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(&in[i].org.x), lo), scale), _mm_setzero_ps()), top);
    const __m128i ci = _mm_cvttps_epi32(c);
    __m128i m = _mm_or_si128(_mm_sllv_epi32(_mm_and_si128(ci, _mm_set1_epi32(1)), low_to),
                             _mm_sllv_epi32(_mm_and_si128(ci, _mm_set1_epi32(2)), high_to));
    m = _mm_or_si128(m, _mm_shuffle_epi32(m, 0x4e));  // lanes 0|2, 1|3
    m = _mm_or_si128(m, _mm_shuffle_epi32(m, 0xb1));  // all four
    const uint32_t key = uint32_t(_mm_cvtsi128_si32(m)) & (kCells - 1);
    key_[i] = uint8_t(key);
    count4[i & 3][key]++;
    probe.read(&in[i].org, sizeof(Vec3));
    probe.write(&key_[i], sizeof(uint8_t));
    if (i < kProbe) {
      changes += i > 0 && key_[i] != key_[i - 1];
      if (i + 1 == std::min(n, kProbe) && changes < min_change * i) return;  // coherent: keep the order
    }
  }
  std::array<uint32_t, kCells> start;
  uint32_t sum = 0;
  for (uint32_t k = 0; k < kCells; ++k) {
    const uint32_t c = count4[0][k] + count4[1][k] + count4[2][k] + count4[3][k];
    if (c == n) return;  // one cell for every ray: keep the order
    start[k] = sum;
    sum += c;
  }
  index_.resize(n);
  for (uint32_t i = 0; i < n; ++i) {
    uint32_t& to = index_[start[key_[i]]++];
    to = first + i;
    probe.read(&key_[i], sizeof(uint8_t));
    probe.write(&to, sizeof(uint32_t));
  }
  moved_ = true;
}

// Rays fetched ahead by gather_rays and scatter_hits.
inline constexpr uint32_t kOrderAhead = 48;

// out[j - from] = rays[order.index(j)] for the positions j in [from, to) of the order: the rays
// gathered into it in a loop of their own, fetching kOrderAhead rays ahead. The batch is mostly
// out of the caches by the time it is read through the order, and reading it ray by ray inside a
// stream's copy loop instead cost 5-17% (mbvh_rs on sponza, crytek, conference bounce:3;
// docs/PERFORMANCE.md, "Session 36"). (The prefetch sits in the loop itself: GCC deletes a
// prefetch-only helper that it does not inline, traversal/mbvh_traverse.h's enter_branching.)
template <class P>
void gather_rays(const RayOrder& order, std::span<const Ray> rays, uint32_t from, uint32_t to, Ray* out, P& probe) {
  for (uint32_t j = from; j < to; ++j) {
    if (j + kOrderAhead < to) __builtin_prefetch(&rays[order.index(j + kOrderAhead)], 0);
    const Ray& r = rays[order.index(j)];
    out[j - from] = r;
    probe.read(&r, sizeof(Ray));
    probe.write(&out[j - from], sizeof(Ray));
  }
}

// hits[order.index(j)] = in[j - from] for the positions j in [from, to): the hits of gathered rays
// written back to the rays' own places, fetching ahead as gather_rays does.
template <class P>
void scatter_hits(const RayOrder& order, const Hit* in, uint32_t from, uint32_t to, std::span<Hit> hits, P& probe) {
  for (uint32_t j = from; j < to; ++j) {
    if (j + kOrderAhead < to) __builtin_prefetch(&hits[order.index(j + kOrderAhead)], 1);
    Hit& h = hits[order.index(j)];
    h = in[j - from];
    probe.read(&in[j - from], sizeof(Hit));
    probe.write(&h, sizeof(Hit));
  }
}

}  // namespace tb
