// Cache-line aligned std::vector storage for node arrays (a 64-byte line holds two BVH nodes), and
// huge pages for the finished arrays of large structures.
#pragma once
#include <cstddef>
#include <new>
#include <vector>
#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace tb {

// The huge-page size: blocks of at least this many bytes are aligned to it, so that the whole
// huge pages inside an array are the array's own.
inline constexpr size_t kHugePageBytes = size_t(2) << 20;

// Alignment of an allocation of `bytes` bytes whose elements need `align`.
constexpr size_t allocation_alignment(size_t bytes, size_t align) {
  return bytes >= kHugePageBytes && align < kHugePageBytes ? kHugePageBytes : align;
}

template <class T, size_t Align = 64>
struct AlignedAllocator {
  using value_type = T;
  template <class U> struct rebind { using other = AlignedAllocator<U, Align>; };
  AlignedAllocator() = default;
  template <class U> AlignedAllocator(const AlignedAllocator<U, Align>&) {}
  T* allocate(size_t n) {
    return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(allocation_alignment(n * sizeof(T), Align))));
  }
  void deallocate(T* p, size_t n) { ::operator delete(p, std::align_val_t(allocation_alignment(n * sizeof(T), Align))); }
  bool operator==(const AlignedAllocator&) const { return true; }
};

template <class T, size_t Align = 64>
using aligned_vector = std::vector<T, AlignedAllocator<T, Align>>;

// Moves a finished array of 2 MiB or more into a block advised to use transparent huge pages
// (MADV_HUGEPAGE: Linux's "madvise" mode, the common default, backs it with 2 MiB pages where it
// can; elsewhere the advice is ignored and ordinary pages remain). A traversal of a scene of
// millions of triangles fetches nodes scattered over hundreds of MiB: with 4 KiB pages nearly every
// such fetch is also a TLB miss and a page walk. Embree's allocator makes the same request for its
// BVH, so without it the large-scene comparisons would measure page sizes rather than traversal
// (docs/PERFORMANCE.md, "Session 15: huge pages"). Done once at the end of a build, not in the
// allocator: the builders' growing temporaries on huge pages made the spatial-split build ~15%
// slower (measured, same section). Costs one copy of the array.
template <class T, size_t Align>
void move_to_huge_pages(aligned_vector<T, Align>& v) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  const size_t bytes = v.size() * sizeof(T);
  if (bytes < kHugePageBytes) return;
  aligned_vector<T, Align> fresh;
  fresh.reserve(v.size());  // allocated, not yet touched: the advice applies from the first write
  (void)madvise(fresh.data(), bytes & ~(kHugePageBytes - 1), MADV_HUGEPAGE);  // a hint; failure keeps 4 KiB pages
  fresh.assign(v.begin(), v.end());
  v.swap(fresh);
#else
  (void)v;
#endif
}

}  // namespace tb
