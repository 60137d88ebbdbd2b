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

// The same storage, but `resize` leaves new elements of trivial types uninitialised, so a large
// scratch array whose parts are written before they are read (raygrid's ray queues) costs no
// memset and faults in only the pages actually used.
template <class T, size_t Align = 64>
struct UninitAllocator : AlignedAllocator<T, Align> {
  template <class U> struct rebind { using other = UninitAllocator<U, Align>; };
  UninitAllocator() = default;
  template <class U> UninitAllocator(const UninitAllocator<U, Align>&) {}
  template <class U> void construct(U* p) noexcept { ::new (static_cast<void*>(p)) U; }
  template <class U, class... A> void construct(U* p, A&&... a) { ::new (static_cast<void*>(p)) U(static_cast<A&&>(a)...); }
  bool operator==(const UninitAllocator&) const { return true; }
};
template <class T, size_t Align = 64>
using uninit_vector = std::vector<T, UninitAllocator<T, Align>>;

// Huge pages for the arrays a traversal reads. A traversal of a scene of millions of triangles
// fetches nodes scattered over hundreds of MiB: with 4 KiB pages nearly every such fetch is also a
// TLB miss and a page walk. MADV_HUGEPAGE asks Linux to back a block with 2 MiB pages (its
// "madvise" mode, the common default, does so only for advised blocks; elsewhere the advice is
// ignored and ordinary pages remain). Embree's allocator makes the same request for its BVH, so
// without it the large-scene comparisons would measure page sizes rather than traversal
// (docs/PERFORMANCE.md, "Session 15: huge pages"). The finished arrays get it (reserved on huge
// pages where a builder writes them in place, or copied there once) and so do the spatial-split
// builder's scratch arrays, which it rewrites over and over (session 28), but not every large
// block: advising every large block in the allocator made the spatial-split build ~15% slower
// (measured, session 15).

// Drops v's contents and gives it an untouched block of capacity n, advised to use huge pages when
// it spans one (the advice applies from the first write, which is why the block must be fresh).
template <class T, size_t Align>
void reserve_on_huge_pages(aligned_vector<T, Align>& v, size_t n) {
  aligned_vector<T, Align> fresh;
  fresh.reserve(n);
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  const size_t bytes = n * sizeof(T);
  if (bytes >= kHugePageBytes) (void)madvise(fresh.data(), bytes & ~(kHugePageBytes - 1), MADV_HUGEPAGE);  // a hint
#endif
  v.swap(fresh);
}

// Reserves capacity n for an array a builder writes in place and keeps (a tree's nodes): on huge
// pages where that spans one, so the array needs no move_to_huge_pages copy afterwards, else an
// ordinary reservation. Returns whether it is on huge pages.
template <class T, size_t Align>
bool reserve_to_keep(aligned_vector<T, Align>& v, size_t n) {
  if (n * sizeof(T) < kHugePageBytes) {
    v.reserve(n);
    return false;
  }
  reserve_on_huge_pages(v, n);
  return true;
}

// Moves a finished array of 2 MiB or more onto huge pages (one copy of it).
template <class T, size_t Align>
void move_to_huge_pages(aligned_vector<T, Align>& v) {
  if (v.size() * sizeof(T) < kHugePageBytes) return;
  aligned_vector<T, Align> fresh;
  reserve_on_huge_pages(fresh, v.size());
  fresh.assign(v.begin(), v.end());
  v.swap(fresh);
}

}  // namespace tb
