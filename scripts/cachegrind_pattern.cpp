// Synthetic data-access pattern for scripts/cachegrind_check.sh: the same sequence of 4-byte loads
// and stores is either performed on a real buffer (mode "run", measured by valgrind's cachegrind)
// or written out as a Dinero "din" trace (mode "din", replayed by `travbench cachesim`), so the two
// cache simulators see the same address stream.
//
//   cachegrind_pattern run          performs the accesses, prints a checksum
//   cachegrind_pattern din [BASE]   prints the din trace, buffer placed at hex BASE (default 10000000)
//
// The buffer comes from mmap, so it reads as zeros without any user-space initialisation that
// cachegrind would count, and is aligned to 2 MB, so every set index of a 32 KB/8-way D1 (4 KB period) and of a
// 2 MB/16-way LL (128 KB period) depends only on the offset into the buffer: the real run and the
// trace map identically. Addresses come from the offsets alone, never from loaded values.
// Standalone on purpose (C++17, no project headers): the script compiles it with g++ -O1.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <sys/mman.h>

#define ALWAYS_INLINE inline __attribute__((always_inline))

namespace {

constexpr size_t kBufferBytes = size_t{8} << 20;
constexpr size_t kAlign = size_t{2} << 20;

// Performs the accesses. volatile keeps every load and store, once each, in program order.
struct RealSink {
  volatile uint32_t* buf;
  uint32_t sum = 0;
  ALWAYS_INLINE void read(size_t off) { sum += buf[off / 4]; }
  ALWAYS_INLINE void write(size_t off, uint32_t v) { buf[off / 4] = v; }
};

// Prints the accesses as din records: label 0 = read, 1 = write; hex byte address.
struct DinSink {
  uint64_t base;
  void read(size_t off) { std::printf("0 %llx\n", static_cast<unsigned long long>(base + off)); }
  void write(size_t off, uint32_t) { std::printf("1 %llx\n", static_cast<unsigned long long>(base + off)); }
};

struct Lcg {  // Numerical Recipes LCG; the high bits are used
  uint32_t s;
  ALWAYS_INLINE uint32_t next() { return s = s * 1664525u + 1013904223u; }
};

template <class Sink>
void pattern(Sink& sink) {
  // 1. Store sweep, one store per 64-byte line over 1 MB, four times: larger than D1 (every store
  //    misses D1), smaller than LL (only the first pass misses LL).
  for (uint32_t pass = 0; pass < 4; ++pass)
    for (size_t off = 0; off < (size_t{1} << 20); off += 64) sink.write(off, pass);

  // 2. Twelve lines 4 KB apart share one D1 set; cycling through them misses D1 every time under
  //    LRU (12 > 8 ways) but hits LL after the first round.
  for (uint32_t round = 0; round < 2000; ++round)
    for (size_t k = 0; k < 12; ++k) sink.read((size_t{2} << 20) + k * 4096);

  // 3. Sequential word reads over 16 KB, twenty times: D1 hits after the first pass.
  for (uint32_t pass = 0; pass < 20; ++pass)
    for (size_t off = 0; off < (size_t{16} << 10); off += 4) sink.read((size_t{3} << 20) + off);

  // 4. Pseudo-random word reads over the whole 8 MB: D1 misses almost always, LL about 3 in 4.
  Lcg rng{12345};
  for (uint32_t i = 0; i < 1000000; ++i) sink.read((rng.next() >> 8) % (kBufferBytes / 4) * 4);

  // 5. Pseudo-random read-then-store pairs within 512 KB (different words, so no compiler or
  //    cachegrind read-modify-write folding): fits LL, not D1.
  for (uint32_t i = 0; i < 200000; ++i) {
    const size_t a = (rng.next() >> 8) % ((size_t{512} << 10) / 4) * 4;
    const size_t b = (rng.next() >> 8) % ((size_t{512} << 10) / 4) * 4;
    sink.read((size_t{4} << 20) + a);
    sink.write((size_t{4} << 20) + b, i);
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::strcmp(argv[1], "run") == 0) {
    const size_t span = kBufferBytes + kAlign;
    void* mem = mmap(nullptr, span, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (mem == MAP_FAILED) {
      std::perror("cachegrind_pattern: mmap");
      return 1;
    }
    const uintptr_t aligned = (reinterpret_cast<uintptr_t>(mem) + kAlign - 1) & ~(kAlign - 1);
    RealSink sink{reinterpret_cast<volatile uint32_t*>(aligned)};
    pattern(sink);
    std::printf("checksum %u\n", sink.sum);
    munmap(mem, span);
    return 0;
  }
  if (argc >= 2 && std::strcmp(argv[1], "din") == 0) {
    const uint64_t base = argc >= 3 ? std::strtoull(argv[2], nullptr, 16) : 0x10000000ull;
    if (base % kAlign != 0) {
      std::fprintf(stderr, "cachegrind_pattern: base %llx is not 2 MB aligned\n",
                   static_cast<unsigned long long>(base));
      return 1;
    }
    DinSink sink{base};
    pattern(sink);
    return 0;
  }
  std::fprintf(stderr, "usage: cachegrind_pattern run | din [HEX_BASE]\n");
  return 2;
}
