// One set-associative, write-back, write-allocate cache level (thesis §5.4: the simulated L1/L2/L3
// of Table 11 are 8-, 8- and 16-way pseudo-LRU caches with 64-byte lines).
//
// The level works on line addresses (byte address >> log2(line size)); the Hierarchy splits byte
// accesses into lines and decides what travels to the next level. Speed matters because a single
// instrumented frame feeds hundreds of millions of accesses through here, so:
//   - sets and lines are powers of two: set index = line & mask, no division;
//   - the tags of a set sit next to each other in one flat array and hold the whole line address
//     (no tag/index split to get wrong), kInvalid marks an empty way; LRU time stamps follow the
//     tags of their set;
//   - dirty bits and the PLRU state of a set are one 64-bit word each, hence assoc <= 64;
//   - nothing is allocated per access, and the hot path is inline in this header.
#pragma once
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace tb::cachesim {

enum class Policy : uint8_t {
  LRU,       // exact least-recently-used (per-way age stamps)
  TreePLRU,  // binary-tree pseudo-LRU, bit for bit gem5's TreePLRURP
  BitPLRU,   // MRU-bit pseudo-LRU ("PLRUm"): one bit per way, victim = lowest way with bit clear
};

// "lru" | "plru" | "bitplru"; anything else raises tb::InputError naming the bad value.
Policy parse_policy(std::string_view name);
std::string_view policy_name(Policy p);

// Demand and write-back traffic seen by one level. Write-backs arriving from the level above are
// counted as writes (they are writes to this level); evictions count valid lines replaced and
// writebacks the dirty ones among them (each sent one level down).
struct LevelCounters {
  uint64_t read_hits = 0, read_misses = 0;
  uint64_t write_hits = 0, write_misses = 0;
  uint64_t evictions = 0, writebacks = 0;

  uint64_t reads() const { return read_hits + read_misses; }
  uint64_t writes() const { return write_hits + write_misses; }
  uint64_t hits() const { return read_hits + write_hits; }
  uint64_t misses() const { return read_misses + write_misses; }
  uint64_t accesses() const { return reads() + writes(); }
};

// Throws tb::InputError("<what>: ...") unless the geometry is simulable: size and line size powers
// of two, 4 <= line <= size, 1 <= assoc <= 64 and assoc dividing size/line (so the set count is a
// power of two too).
void validate_geometry(const std::string& what, uint64_t size_bytes, uint32_t assoc,
                       uint32_t line_bytes);

class CacheLevel {
 public:
  static constexpr uint64_t kInvalid = ~uint64_t{0};  // never a line address: line >= 4 bytes

  struct Outcome {
    bool hit = false;
    bool dirty_victim = false;  // a dirty line was replaced: the caller must write it back
    uint64_t victim_line = 0;   // its line address (valid when dirty_victim)
  };

  // Throws tb::InputError on an invalid geometry (see validate_geometry).
  CacheLevel(uint64_t size_bytes, uint32_t assoc, uint32_t line_bytes, Policy policy);

  // Looks `line` up. A hit updates the replacement state; a miss allocates the line (write-
  // allocate), replacing the policy's victim. `write` picks the counter (read_* or write_*);
  // `make_dirty` marks the line modified (true for a store performed here or a write-back landing
  // here, false for a clean fill).
  inline Outcome access(uint64_t line, bool write, bool make_dirty);

  bool contains(uint64_t line) const { return way_of(line) >= 0; }
  bool is_dirty(uint64_t line) const;
  int way_of(uint64_t line) const;  // -1 if absent
  // The way the policy would replace next in `set` (state unchanged). Test hook.
  uint32_t victim_way(uint64_t set) const { return victim(set); }

  void reset();  // empty every set, clear replacement state and counters

  const LevelCounters& counters() const { return c_; }
  uint64_t size_bytes() const { return uint64_t{num_sets_} * assoc_ * line_bytes_; }
  uint32_t assoc() const { return assoc_; }
  uint32_t line_bytes() const { return line_bytes_; }
  uint32_t line_shift() const { return line_shift_; }
  uint64_t num_sets() const { return num_sets_; }
  uint64_t set_of(uint64_t line) const { return line & set_mask_; }
  Policy policy() const { return policy_; }

 private:
  static uint64_t bit(uint32_t w) { return uint64_t{1} << w; }
  inline uint32_t victim(uint64_t set) const;
  inline void touch(uint64_t set, uint32_t way);

  Policy policy_;
  uint32_t assoc_, assoc_shift_, stride_shift_, line_bytes_, line_shift_;
  uint64_t num_sets_, set_mask_;
  uint64_t full_mask_;             // low `assoc_` bits set
  // Per set: the line address (or kInvalid) of each way, and for LRU then the last-touch time of
  // each way (0 = never). Keeping a set's stamps next to its tags saves a host cache miss per
  // simulated miss. A set's block is 1 << stride_shift_ words.
  std::vector<uint64_t> tags_;
  std::vector<uint64_t> dirty_;    // [set] bit w = way w modified
  std::vector<uint64_t> bits_;     // TreePLRU: [set] tree node bits; BitPLRU: [set] MRU bits
  uint64_t clock_ = 0;             // LRU time
  LevelCounters c_;
};

// ---- hot path ------------------------------------------------------------------------------

inline CacheLevel::Outcome CacheLevel::access(uint64_t line, bool write, bool make_dirty) {
  const uint64_t set = line & set_mask_;
  uint64_t* tags = &tags_[set << stride_shift_];
  // Compare every way without an early exit: the loop vectorizes and there is no branch on which
  // way hit, which a random access stream would mispredict every time.
  uint64_t match = 0;
  for (uint32_t w = 0; w < assoc_; ++w) match |= uint64_t{tags[w] == line} << w;
  if (match) {
    const uint32_t w = static_cast<uint32_t>(__builtin_ctzll(match));
    ++(write ? c_.write_hits : c_.read_hits);
    if (make_dirty) dirty_[set] |= bit(w);
    touch(set, w);
    return {true, false, 0};
  }
  ++(write ? c_.write_misses : c_.read_misses);
  const uint32_t w = victim(set);
  Outcome out;
  if (tags[w] != kInvalid) {
    ++c_.evictions;
    if (dirty_[set] & bit(w)) {
      ++c_.writebacks;
      out.dirty_victim = true;
      out.victim_line = tags[w];
    }
  }
  tags[w] = line;
  dirty_[set] = make_dirty ? (dirty_[set] | bit(w)) : (dirty_[set] & ~bit(w));
  touch(set, w);  // gem5 inserts with reset(), which for every policy here equals touch()
  return out;
}

// Tree-PLRU follows gem5's TreePLRURP exactly: the assoc-1 node bits of a set form a heap-ordered
// binary tree (node n has children 2n+1, 2n+2; leaf of way w is node w + assoc - 1). A set bit
// means "the victim is in the right subtree". A touch walks from the leaf to the root and points
// every node away from the touched way; the victim walk follows the bits from the root. Like gem5,
// the walk ignores whether ways are valid: a stream of misses fills an empty 8-way set in the order
// 0,4,2,6,1,5,3,7, but hits during the first fill can steer it to a valid way while others are
// still empty (tests/test_cachesim.cpp, EightLinesFitLruButNotTreePlru). That only matters while a
// set warms up.
inline uint32_t CacheLevel::victim(uint64_t set) const {
  switch (policy_) {
    case Policy::LRU: {
      // Invalid ways have stamp 0 and are taken first (lowest way on ties), as in gem5's LRURP.
      const uint64_t* st = &tags_[(set << stride_shift_) + assoc_];
      uint32_t best = 0;
      uint64_t oldest = st[0];
      for (uint32_t w = 1; w < assoc_; ++w) {  // written to compile to conditional moves
        const bool older = st[w] < oldest;
        oldest = older ? st[w] : oldest;
        best = older ? w : best;
      }
      return best;
    }
    case Policy::TreePLRU: {
      const uint64_t tree = bits_[set];
      const uint32_t inner = assoc_ - 1;
      uint32_t n = 0;
      while (n < inner) n = 2 * n + 1 + static_cast<uint32_t>(tree >> n & 1);  // bit 1: right child
      return n - inner;
    }
    case Policy::BitPLRU: {
      // Invalid ways always have a clear bit, and the bits are only reset when every way is valid
      // and recently used, so the lowest clear bit also fills empty ways first.
      const uint64_t free = ~bits_[set] & full_mask_;
      return free ? static_cast<uint32_t>(__builtin_ctzll(free)) : 0;
    }
  }
  return 0;
}

inline void CacheLevel::touch(uint64_t set, uint32_t way) {
  switch (policy_) {
    case Policy::LRU:
      tags_[(set << stride_shift_) + assoc_ + way] = ++clock_;
      return;
    case Policy::TreePLRU: {
      uint64_t tree = bits_[set];
      uint32_t n = way + assoc_ - 1;
      while (n != 0) {
        const uint64_t came_from_left = n & 1;  // odd nodes are left children
        n = (n - 1) / 2;
        // Point away from the touched leaf: came from the left -> bit 1 (go right next time).
        tree = (tree & ~bit(n)) | came_from_left << n;
      }
      bits_[set] = tree;
      return;
    }
    case Policy::BitPLRU: {
      uint64_t mru = bits_[set] | bit(way);
      if (mru == full_mask_) mru = bit(way);  // all recently used: keep only the newest
      bits_[set] = mru;
      return;
    }
  }
}

}  // namespace tb::cachesim
