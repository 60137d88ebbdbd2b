// Synthetic data-access pattern for scripts/cachegrind_check.sh: the same sequence of 4-byte loads
// and stores is either performed on a real buffer (mode "run", measured by valgrind's cachegrind)
// or written out as a Dinero "din" trace (mode "din", replayed by `travbench cachesim`), so the two
// cache simulators see the same address stream.
//
//   cachegrind_pattern run          performs the accesses, prints a checksum
//   cachegrind_pattern idle         the same process without the accesses (start-up baseline)
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

constexpr size_t KB = size_t{1} << 10, MB = size_t{1} << 20;

// Every phase is built so that the geometry or the replacement policy decides its miss count
// (the comments give the count for a 32 KB 8-way D1 and a 2 MB 16-way LL, both LRU): a wrong set
// index, associativity, size or policy in either simulator moves the totals by several percent.
template <class Sink>
void pattern(Sink& sink) {
  // 1. Store sweep, one store per 64-byte line over 1 MB, four times: every store misses D1; only
  //    the first pass misses LL (16384).
  for (uint32_t pass = 0; pass < 4; ++pass)
    for (size_t off = 0; off < 1 * MB; off += 64) sink.write(off, pass);

  // 2. In each of the 64 D1 sets, the sequence of lines 4 1 0 3 8 1 2 1 6 5 (4 KB apart): eight
  //    distinct lines, so LRU keeps them all after the cold misses, while tree-PLRU misses half the
  //    accesses and a 4-way cache most of them.
  //    The sequence is packed in a register-sized constant, one hex digit per access (first access
  //    in the lowest digit): a table in memory would itself occupy a D1 line in one of the sets.
  constexpr uint64_t kSeq = 0x5612183014;
  for (uint32_t round = 0; round < 300; ++round)
    for (size_t set = 0; set < 64; ++set)
      for (uint32_t j = 0; j < 10; ++j) sink.read(1 * MB + (kSeq >> (4 * j) & 15) * 4 * KB + set * 64);

  // 3. Twelve lines 4 KB apart cycled: more than 8 ways, so D1 misses every time; LL hits.
  for (uint32_t round = 0; round < 2000; ++round)
    for (size_t k = 0; k < 12; ++k) sink.read(3 * MB / 2 + k * 4 * KB);

  Lcg rng{12345};
  // 4. Random words within 24 KB: fits D1 (cold misses only), would not fit 16 KB.
  for (uint32_t i = 0; i < 200000; ++i) sink.read(2 * MB + (rng.next() >> 8) % (24 * KB / 4) * 4);

  // 5. Lines 256 KB apart share one LL set (and one D1 set) for any LL of 2 MB with up to 16 ways:
  //    16 of them cycled fit a 16-way LL (hits after the first round; 8 ways would thrash), 20 of
  //    them miss LL every time.
  for (uint32_t round = 0; round < 3000; ++round)
    for (size_t k = 0; k < 16; ++k) sink.read(192 + k * 256 * KB);
  for (uint32_t round = 0; round < 3000; ++round)
    for (size_t k = 0; k < 20; ++k) sink.read(128 + k * 256 * KB);

  // 6. Random words within 1.5 MB: fits LL, not D1.
  for (uint32_t i = 0; i < 300000; ++i) sink.read(6 * MB + (rng.next() >> 8) % (3 * MB / 2 / 4) * 4);

  // 7. Random words over the whole 8 MB: D1 misses almost always, LL about 3 in 4.
  for (uint32_t i = 0; i < 200000; ++i) sink.read((rng.next() >> 8) % (kBufferBytes / 4) * 4);

  // 8. Random read-then-store pairs within 512 KB (different words, so neither the compiler nor
  //    cachegrind sees a read-modify-write instruction): fits LL, not D1.
  for (uint32_t i = 0; i < 100000; ++i) {
    const size_t a = (rng.next() >> 8) % (512 * KB / 4) * 4;
    const size_t b = (rng.next() >> 8) % (512 * KB / 4) * 4;
    sink.read(15 * MB / 2 + a);
    sink.write(15 * MB / 2 + b, i);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const bool idle = argc >= 2 && std::strcmp(argv[1], "idle") == 0;
  if (argc >= 2 && (std::strcmp(argv[1], "run") == 0 || idle)) {
    const size_t span = kBufferBytes + kAlign;
    void* mem = mmap(nullptr, span, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (mem == MAP_FAILED) {
      std::perror("cachegrind_pattern: mmap");
      return 1;
    }
    const uintptr_t aligned = (reinterpret_cast<uintptr_t>(mem) + kAlign - 1) & ~(kAlign - 1);
    RealSink sink{reinterpret_cast<volatile uint32_t*>(aligned)};
    if (!idle) pattern(sink);
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
  std::fprintf(stderr, "usage: cachegrind_pattern run | idle | din [HEX_BASE]\n");
  return 2;
}
