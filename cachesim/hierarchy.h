// The simulated cache hierarchy of thesis §5.4 / Table 11: by default a 32 KB 8-way L1, 256 KB
// 8-way L2 and 2 MB 16-way L3 with 64-byte lines and pseudo-LRU replacement, and the cost estimate
// "accesses served by each level times that level's latency" at 4:11:39:107 cycles.
//
// Model (documented here because the counters mean nothing without it):
//   - Every level is write-back and write-allocate. Levels are non-inclusive: a demand access walks
//     L1, L2, ... until a level hits (or memory serves it), and every level that missed on the way
//     is filled with the line. Nothing is ever invalidated from a level because of another level.
//   - A demand access keeps its type all the way down: a store that misses L1 and hits L2 counts
//     as an L2 write hit ("L2 write hit" in Table 11 means exactly that), and a store that misses
//     every level counts as a memory write. Only L1 performs the store, so only the L1 copy turns
//     dirty; the lower levels receive clean fills.
//   - A dirty line replaced in level i is written back to level i+1 as a write (counted in that
//     level's write_hits/write_misses); a miss there allocates the line dirty without fetching it
//     (the whole line is being written) and may push out a dirty line in turn. Write-backs from the
//     last level are memory writes. Victims are written back after the demand access has been
//     served, deepest level first.
//   - An access of `size` bytes touches every line it overlaps, each counted as one access;
//     size 0 touches nothing.
//   - Cold reads (the compulsory misses of Hill and Smith's three-C model, 1989): lines whose
//     first access since construction or reset() is a load. Every such load misses every level, so
//     memory reads >= cold reads, with equality for a cache large enough to keep every line. They
//     depend only on which lines are touched and whether each is first read or written, not on the
//     order of the other accesses: a scheme that touches the same scene lines as another, in any
//     order (treelet_queue against mbvh8_single: the same node and leaf visits, re-ordered), reads
//     at least those lines' cold reads from memory, under any cache geometry or policy.
#pragma once
#include <array>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "cachesim/cache_level.h"

namespace tb::cachesim {

struct LevelConfig {
  std::string name;          // shown in reports, e.g. "L1"
  uint64_t size_bytes = 0;
  uint32_t assoc = 0;
  uint32_t line_bytes = 64;  // every level must use the same line size
  uint32_t latency_cycles = 0;
};

struct HierarchyConfig {
  std::vector<LevelConfig> levels;
  Policy policy = Policy::TreePLRU;  // the thesis' "pseudo-LRU eviction scheme"
  uint32_t memory_latency_cycles = 107;
};

// L1 32K:8 @4, L2 256K:8 @11, L3 2M:16 @39, memory @107, 64-byte lines, tree-PLRU (§5.4).
HierarchyConfig default_config();

// Parses "l1=32K:8,l2=256K:8,l3=2M:16". Each level is lN=SIZE:ASSOC[:LINE[:LATENCY]] with N
// increasing left to right (gaps allowed, e.g. "l1=32K:8,l3=2M:16"); SIZE is bytes with an optional
// K/M/G suffix (binary, optional trailing B); LINE defaults to 64 bytes; LATENCY defaults to the
// thesis' 4/11/39 cycles for l1/l2/l3 and must be given for deeper levels. An extra "mem=CYCLES"
// item sets the memory latency (default 107). The policy is left at its default (see
// parse_policy). Bad input raises tb::InputError naming the item and field at fault.
HierarchyConfig parse_config(std::string_view spec);

// Throws tb::InputError unless every level has a valid geometry (validate_geometry), a name, and
// the line size of L1, and there is at least one level.
void validate_config(const HierarchyConfig& cfg);

// The set of line addresses seen so far (for cold reads): one bitmap of 4096 lines (256 KiB of
// address space at 64-byte lines) per region touched, found through a hash map, with the last
// region remembered, so that the common access (the same region as the previous one) costs a
// compare and a bit test and nothing is allocated but once per new region.
class LineSet {
 public:
  bool insert(uint64_t line);  // true: the line was not in the set
  void clear();

 private:
  static constexpr uint32_t kRegionShift = 12;
  using Region = std::array<uint64_t, (1u << kRegionShift) / 64>;
  std::unordered_map<uint64_t, std::unique_ptr<Region>> regions_;
  uint64_t last_key_ = ~uint64_t(0);
  Region* last_ = nullptr;
};

class Hierarchy {
 public:
  Hierarchy();  // default_config()
  explicit Hierarchy(HierarchyConfig cfg);  // throws tb::InputError if !validate_config

  // One load (write = false) or store of `size` bytes at byte address `addr`. The single entry
  // point of the instrumentation (traversal/probe.cpp) and of trace replay.
  void access(uint64_t addr, uint32_t size, bool write);

  void reset();  // empty all levels, zero all counters

  size_t num_levels() const { return levels_.size(); }
  const LevelConfig& level_config(size_t i) const { return cfg_.levels[i]; }
  const LevelCounters& counters(size_t i) const { return levels_[i].counters(); }
  const CacheLevel& level(size_t i) const { return levels_[i]; }
  const HierarchyConfig& config() const { return cfg_; }

  uint64_t memory_reads() const { return mem_reads_; }
  uint64_t memory_writes() const { return mem_writes_; }
  // Lines first touched by a load (see the model above): a lower bound of memory_reads() for any
  // hierarchy fed the same lines, each first read or written as here.
  uint64_t cold_reads() const { return cold_reads_; }

  // Table 11's estimate as the brief defines it: sum over levels of hits (reads and writes,
  // write-backs included) x latency, plus memory reads and writes x memory latency.
  uint64_t cost_cycles() const;
  // The same sum over demand reads only: read hits per level and memory reads. Thesis Table 11's
  // printed costs and percentages add up this way (e.g. batch 64: 4*907.1 + 11*10.9 + 39*9.7 +
  // 107*11.2 = 5325 ~ 5328.8, L1 share 68.1%), so use this one for a like-for-like comparison.
  uint64_t read_cost_cycles() const;

 private:
  struct PendingWriteback {
    size_t level;  // level the line is written back to (== num_levels(): memory)
    uint64_t line;
  };
  void access_line(uint64_t line, bool write);
  void write_back(size_t level, uint64_t line);

  HierarchyConfig cfg_;
  std::vector<CacheLevel> levels_;
  uint32_t line_shift_ = 6;
  uint64_t mem_reads_ = 0, mem_writes_ = 0, cold_reads_ = 0;
  LineSet seen_;
  std::vector<PendingWriteback> pending_;  // scratch for access_line, one slot per level
};

// The report of `travbench cachesim` (DESIGN.md), one level per line, e.g.
//   L1 reads=13 writes=0 hits=2 misses=11 read_misses=11 write_misses=0 evictions=3 writebacks=0
//   MEM reads=11 writes=0
//   cost_cycles=1185
void write_report(const Hierarchy& h, std::ostream& out);
std::string format_report(const Hierarchy& h);

}  // namespace tb::cachesim
