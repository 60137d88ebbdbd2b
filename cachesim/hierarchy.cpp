#include "cachesim/hierarchy.h"

#include <cctype>
#include <charconv>
#include <limits>
#include <ostream>
#include <sstream>

#include "structures/scene.h"  // tb::InputError

namespace tb::cachesim {

namespace {

// Thesis §5.4: "4, 11, 39, 107 cycles on our test platform" for L1, L2, L3 and memory.
constexpr uint32_t kDefaultLatency[] = {4, 11, 39};
constexpr uint32_t kDefaultMemoryLatency = 107;

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

std::string lower(std::string_view s) {
  std::string r(s);
  for (char& c : r) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return r;
}

std::string upper(std::string_view s) {
  std::string r(s);
  for (char& c : r) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return r;
}

// Decimal digits only (no sign, no spaces); false on anything else or overflow.
bool parse_uint(std::string_view s, uint64_t& v) {
  if (s.empty()) return false;
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return ec == std::errc() && p == s.data() + s.size();
}

// "32768", "32K", "32KB", "2M", "1g": binary multiples.
bool parse_size(std::string_view s, uint64_t& bytes) {
  std::string t = lower(s);
  if (t.size() > 1 && t.back() == 'b') t.pop_back();
  uint64_t mult = 1;
  if (!t.empty()) {
    switch (t.back()) {
      case 'k': mult = uint64_t{1} << 10; break;
      case 'm': mult = uint64_t{1} << 20; break;
      case 'g': mult = uint64_t{1} << 30; break;
      default: break;
    }
    if (mult != 1) t.pop_back();
  }
  uint64_t n = 0;
  if (!parse_uint(t, n) || n > std::numeric_limits<uint64_t>::max() / mult) return false;
  bytes = n * mult;
  return true;
}

std::vector<std::string_view> split(std::string_view s, char sep) {
  std::vector<std::string_view> parts;
  size_t start = 0;
  for (;;) {
    const size_t pos = s.find(sep, start);
    parts.push_back(s.substr(start, pos == std::string_view::npos ? std::string_view::npos : pos - start));
    if (pos == std::string_view::npos) return parts;
    start = pos + 1;
  }
}

}  // namespace

HierarchyConfig default_config() {
  HierarchyConfig cfg;
  cfg.levels = {{"L1", 32u << 10, 8, 64, kDefaultLatency[0]},
                {"L2", 256u << 10, 8, 64, kDefaultLatency[1]},
                {"L3", 2u << 20, 16, 64, kDefaultLatency[2]}};
  cfg.policy = Policy::TreePLRU;
  cfg.memory_latency_cycles = kDefaultMemoryLatency;
  return cfg;
}

HierarchyConfig parse_config(std::string_view spec) {
  HierarchyConfig cfg;
  cfg.memory_latency_cycles = kDefaultMemoryLatency;
  if (trim(spec).empty()) throw InputError("cache config is empty (expected e.g. l1=32K:8,l2=256K:8,l3=2M:16)");

  uint64_t last_level = 0;
  bool have_mem = false;
  for (std::string_view raw : split(spec, ',')) {
    const std::string_view item = trim(raw);
    const std::string where = "cache config item '" + std::string(item) + "'";
    auto fail = [&](const std::string& msg) { throw InputError(where + ": " + msg); };
    if (item.empty()) throw InputError("cache config '" + std::string(spec) + "' has an empty item");

    const size_t eq = item.find('=');
    if (eq == std::string_view::npos) fail("expected NAME=VALUE, e.g. l1=32K:8");
    const std::string name = lower(trim(item.substr(0, eq)));
    const std::string_view value = trim(item.substr(eq + 1));

    if (name == "mem") {
      uint64_t lat = 0;
      if (have_mem) fail("memory latency given twice");
      if (!parse_uint(value, lat) || lat > std::numeric_limits<uint32_t>::max())
        fail("memory latency '" + std::string(value) + "' is not a cycle count");
      cfg.memory_latency_cycles = static_cast<uint32_t>(lat);
      have_mem = true;
      continue;
    }

    uint64_t number = 0;
    // (no operator+ on a literal here: where the profile-guided build inlines that form, GCC 12
    // raises a false -Wrestrict inside std::string)
    if (name.size() < 2 || name[0] != 'l' || !parse_uint(std::string_view(name).substr(1), number) ||
        number == 0 || std::string_view(name).substr(1) != std::to_string(number))
      fail(std::string("level name '").append(name).append("' is not l1, l2, ... (or mem)"));
    if (number <= last_level)
      fail("level l" + std::to_string(number) + " must come after l" + std::to_string(last_level) +
           " (levels are listed from L1 toward memory, each once)");
    last_level = number;

    const std::vector<std::string_view> f = split(value, ':');
    if (f.size() < 2 || f.size() > 4) fail("expected SIZE:ASSOC[:LINE[:LATENCY]], e.g. 32K:8");

    LevelConfig lv;
    lv.name = upper(name);
    if (!parse_size(trim(f[0]), lv.size_bytes))
      fail("size '" + std::string(f[0]) + "' is not a byte count (e.g. 32768, 32K, 2M)");
    if (lv.size_bytes == 0 || (lv.size_bytes & (lv.size_bytes - 1)) != 0)
      fail("size '" + std::string(f[0]) + "' is not a power of two");
    uint64_t assoc = 0;
    if (!parse_uint(trim(f[1]), assoc) || assoc == 0)
      fail("associativity '" + std::string(f[1]) + "' is not a positive integer");
    if (assoc > 64) fail("associativity " + std::to_string(assoc) + " exceeds 64");
    lv.assoc = static_cast<uint32_t>(assoc);
    if (f.size() >= 3) {
      uint64_t line = 0;
      if (!parse_size(trim(f[2]), line) || line == 0 || line > (uint64_t{1} << 31))
        fail("line size '" + std::string(f[2]) + "' is not a byte count");
      lv.line_bytes = static_cast<uint32_t>(line);
    }
    if (f.size() == 4) {
      uint64_t lat = 0;
      if (!parse_uint(trim(f[3]), lat) || lat > std::numeric_limits<uint32_t>::max())
        fail("latency '" + std::string(f[3]) + "' is not a cycle count");
      lv.latency_cycles = static_cast<uint32_t>(lat);
    } else if (number <= 3) {
      lv.latency_cycles = kDefaultLatency[number - 1];
    } else {
      fail("level l" + std::to_string(number) +
           " has no default latency; give one as SIZE:ASSOC:LINE:LATENCY");
    }
    validate_geometry(where, lv.size_bytes, lv.assoc, lv.line_bytes);
    cfg.levels.push_back(std::move(lv));
  }
  if (cfg.levels.empty()) throw InputError("cache config '" + std::string(spec) + "' has no cache level");
  validate_config(cfg);
  return cfg;
}

void validate_config(const HierarchyConfig& cfg) {
  if (cfg.levels.empty()) throw InputError("cache hierarchy has no level");
  for (size_t i = 0; i < cfg.levels.size(); ++i) {
    const LevelConfig& lv = cfg.levels[i];
    const std::string what = "cache level " + (lv.name.empty() ? std::to_string(i + 1) : lv.name);
    if (lv.name.empty()) throw InputError(what + ": has no name");
    validate_geometry(what, lv.size_bytes, lv.assoc, lv.line_bytes);
    // One line size throughout keeps fills and write-backs one line each; every x86 level the
    // thesis simulates uses 64 bytes anyway.
    if (lv.line_bytes != cfg.levels[0].line_bytes)
      throw InputError(what + ": line size " + std::to_string(lv.line_bytes) + " differs from " +
                       cfg.levels[0].name + "'s " + std::to_string(cfg.levels[0].line_bytes) +
                       " (all levels must share one line size)");
  }
}

Hierarchy::Hierarchy() : Hierarchy(default_config()) {}

Hierarchy::Hierarchy(HierarchyConfig cfg) : cfg_(std::move(cfg)) {
  validate_config(cfg_);
  levels_.reserve(cfg_.levels.size());
  for (const LevelConfig& lv : cfg_.levels)
    levels_.emplace_back(lv.size_bytes, lv.assoc, lv.line_bytes, cfg_.policy);
  line_shift_ = levels_[0].line_shift();
  pending_.resize(levels_.size());
}

void Hierarchy::access(uint64_t addr, uint32_t size, bool write) {
  if (size == 0) return;
  const uint64_t first = addr >> line_shift_;
  // The last byte, clamped at the top of the address space rather than wrapping to line 0.
  const uint64_t end = addr > std::numeric_limits<uint64_t>::max() - (size - 1)
                           ? std::numeric_limits<uint64_t>::max()
                           : addr + (size - 1);
  const uint64_t last = end >> line_shift_;
  for (uint64_t line = first;; ++line) {
    access_line(line, write);
    if (line == last) break;
  }
}

bool LineSet::insert(uint64_t line) {
  const uint64_t key = line >> kRegionShift;
  if (key != last_key_) {
    std::unique_ptr<Region>& r = regions_[key];
    if (!r) r = std::make_unique<Region>(Region{});
    last_key_ = key, last_ = r.get();
  }
  const uint32_t bit = uint32_t(line) & ((1u << kRegionShift) - 1);
  uint64_t& word = (*last_)[bit >> 6];
  const uint64_t m = uint64_t(1) << (bit & 63);
  if (word & m) return false;
  word |= m;
  return true;
}

void LineSet::clear() {
  regions_.clear();
  last_key_ = ~uint64_t(0), last_ = nullptr;
}

void Hierarchy::access_line(uint64_t line, bool write) {
  const size_t n = levels_.size();
  size_t npending = 0;
  size_t i = 0;
  for (; i < n; ++i) {
    // Only L1 performs the store; lower levels supply (or receive) a clean copy.
    const CacheLevel::Outcome r = levels_[i].access(line, write, write && i == 0);
    if (r.dirty_victim) pending_[npending++] = {i + 1, r.victim_line};
    if (r.hit) break;
  }
  if (i == n) {
    ++(write ? mem_writes_ : mem_reads_);
    // A line never touched before misses every level, so only these accesses need the set.
    if (seen_.insert(line) && !write) ++cold_reads_;
  }
  while (npending > 0) {
    --npending;
    write_back(pending_[npending].level, pending_[npending].line);
  }
}

void Hierarchy::write_back(size_t level, uint64_t line) {
  for (size_t i = level; i < levels_.size(); ++i) {
    const CacheLevel::Outcome r = levels_[i].access(line, /*write=*/true, /*make_dirty=*/true);
    if (!r.dirty_victim) return;  // absorbed: hit, or allocated over a clean/empty way
    line = r.victim_line;         // allocated over a dirty line, which moves on down
  }
  ++mem_writes_;
}

void Hierarchy::reset() {
  for (CacheLevel& l : levels_) l.reset();
  mem_reads_ = mem_writes_ = cold_reads_ = 0;
  seen_.clear();
}

uint64_t Hierarchy::cost_cycles() const {
  uint64_t cost = 0;
  for (size_t i = 0; i < levels_.size(); ++i)
    cost += levels_[i].counters().hits() * cfg_.levels[i].latency_cycles;
  return cost + (mem_reads_ + mem_writes_) * cfg_.memory_latency_cycles;
}

uint64_t Hierarchy::read_cost_cycles() const {
  uint64_t cost = 0;
  for (size_t i = 0; i < levels_.size(); ++i)
    cost += levels_[i].counters().read_hits * cfg_.levels[i].latency_cycles;
  return cost + mem_reads_ * cfg_.memory_latency_cycles;
}

void write_report(const Hierarchy& h, std::ostream& out) {
  for (size_t i = 0; i < h.num_levels(); ++i) {
    const LevelCounters& c = h.counters(i);
    out << h.level_config(i).name << " reads=" << c.reads() << " writes=" << c.writes()
        << " hits=" << c.hits() << " misses=" << c.misses() << " read_misses=" << c.read_misses
        << " write_misses=" << c.write_misses << " evictions=" << c.evictions
        << " writebacks=" << c.writebacks << '\n';
  }
  out << "MEM reads=" << h.memory_reads() << " writes=" << h.memory_writes() << " cold_reads=" << h.cold_reads()
      << '\n';
  out << "cost_cycles=" << h.cost_cycles() << '\n';
}

std::string format_report(const Hierarchy& h) {
  std::ostringstream s;
  write_report(h, s);
  return s.str();
}

}  // namespace tb::cachesim
