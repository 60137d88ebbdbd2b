#include "cachesim/cache_level.h"

#include <algorithm>
#include <bit>

#include "structures/scene.h"  // tb::InputError

namespace tb::cachesim {

Policy parse_policy(std::string_view name) {
  if (name == "lru") return Policy::LRU;
  if (name == "plru") return Policy::TreePLRU;
  if (name == "bitplru") return Policy::BitPLRU;
  throw InputError("cache policy '" + std::string(name) + "' is unknown (expected lru, plru or bitplru)");
}

std::string_view policy_name(Policy p) {
  switch (p) {
    case Policy::LRU: return "lru";
    case Policy::TreePLRU: return "plru";
    case Policy::BitPLRU: return "bitplru";
  }
  return "?";
}

void validate_geometry(const std::string& what, uint64_t size_bytes, uint32_t assoc,
                       uint32_t line_bytes) {
  auto fail = [&](const std::string& msg) { throw InputError(what + ": " + msg); };
  if (size_bytes == 0 || !std::has_single_bit(size_bytes))
    fail("size " + std::to_string(size_bytes) + " bytes is not a power of two");
  if (line_bytes < 4 || !std::has_single_bit(line_bytes))
    fail("line size " + std::to_string(line_bytes) + " is not a power of two >= 4");
  if (line_bytes > size_bytes)
    fail("line size " + std::to_string(line_bytes) + " exceeds the cache size " +
         std::to_string(size_bytes));
  // Dirty bits and PLRU state are one 64-bit word per set; wider sets would also make every
  // lookup a long scan.
  if (assoc < 1 || assoc > 64)
    fail("associativity " + std::to_string(assoc) + " is outside 1..64");
  const uint64_t lines = size_bytes / line_bytes;
  // The simulator keeps 8-16 bytes of tags per line: 2^26 lines (4 GiB of 64-byte lines) is 1 GiB
  // of tags; `l1=64G:8` asked for 16 GiB and the host's memory ran out.
  if (lines > (uint64_t{1} << 26))
    fail("size " + std::to_string(size_bytes) + " bytes in " + std::to_string(line_bytes) + "-byte lines is " +
         std::to_string(lines) + " lines, more than the 2^26 (4 GiB of 64-byte lines) the simulator models");
  if (lines % assoc != 0)
    fail("associativity " + std::to_string(assoc) + " does not divide the " +
         std::to_string(lines) + " lines of the cache");
}

CacheLevel::CacheLevel(uint64_t size_bytes, uint32_t assoc, uint32_t line_bytes, Policy policy)
    : policy_(policy), assoc_(assoc), line_bytes_(line_bytes) {
  validate_geometry("cache level", size_bytes, assoc, line_bytes);
  // size, line and hence lines are powers of two; assoc divides lines, so it is one as well.
  assoc_shift_ = static_cast<uint32_t>(std::countr_zero(assoc));
  line_shift_ = static_cast<uint32_t>(std::countr_zero(line_bytes));
  num_sets_ = size_bytes / line_bytes / assoc;
  set_mask_ = num_sets_ - 1;
  full_mask_ = assoc == 64 ? ~uint64_t{0} : (uint64_t{1} << assoc) - 1;
  stride_shift_ = assoc_shift_ + (policy_ == Policy::LRU ? 1 : 0);
  tags_.resize(num_sets_ << stride_shift_);
  dirty_.resize(num_sets_);
  if (policy_ != Policy::LRU) bits_.resize(num_sets_);
  reset();
}

void CacheLevel::reset() {
  for (uint64_t set = 0; set < num_sets_; ++set) {
    uint64_t* block = &tags_[set << stride_shift_];
    std::fill(block, block + assoc_, kInvalid);
    if (policy_ == Policy::LRU) std::fill(block + assoc_, block + 2 * assoc_, 0);
  }
  std::fill(dirty_.begin(), dirty_.end(), 0);
  std::fill(bits_.begin(), bits_.end(), 0);
  clock_ = 0;
  c_ = {};
}

int CacheLevel::way_of(uint64_t line) const {
  const uint64_t* tags = &tags_[(line & set_mask_) << stride_shift_];
  for (uint32_t w = 0; w < assoc_; ++w)
    if (tags[w] == line) return static_cast<int>(w);
  return -1;
}

bool CacheLevel::is_dirty(uint64_t line) const {
  const int w = way_of(line);
  return w >= 0 && (dirty_[line & set_mask_] >> w & 1);
}

}  // namespace tb::cachesim
