// Cache-line aligned std::vector storage for node arrays (a 64-byte line holds two BVH nodes).
#pragma once
#include <cstddef>
#include <new>
#include <vector>

namespace tb {

template <class T, size_t Align = 64>
struct AlignedAllocator {
  using value_type = T;
  template <class U> struct rebind { using other = AlignedAllocator<U, Align>; };
  AlignedAllocator() = default;
  template <class U> AlignedAllocator(const AlignedAllocator<U, Align>&) {}
  T* allocate(size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(Align))); }
  void deallocate(T* p, size_t) { ::operator delete(p, std::align_val_t(Align)); }
  bool operator==(const AlignedAllocator&) const { return true; }
};

template <class T, size_t Align = 64>
using aligned_vector = std::vector<T, AlignedAllocator<T, Align>>;

}  // namespace tb
