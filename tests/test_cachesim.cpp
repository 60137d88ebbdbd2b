// Known-answer tests of the cache simulator (thesis §5.4, Table 11): replacement policies, the
// write-back/write-allocate hierarchy, the config/policy parsers and din trace replay.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "cachesim/cache_level.h"
#include "cachesim/din_trace.h"
#include "cachesim/hierarchy.h"
#include "structures/scene.h"

namespace cs = tb::cachesim;

namespace {

cs::Hierarchy single_level(uint64_t size, uint32_t assoc, cs::Policy policy) {
  cs::HierarchyConfig cfg;
  cfg.levels = {{"L1", size, assoc, 64, 4}};
  cfg.policy = policy;
  return cs::Hierarchy(cfg);
}

cs::Hierarchy from_spec(const std::string& spec, cs::Policy policy) {
  cs::HierarchyConfig cfg = cs::parse_config(spec);
  cfg.policy = policy;
  return cs::Hierarchy(cfg);
}

// The message of the tb::InputError `f` throws ("" and a test failure if it throws nothing).
std::string input_error(const std::function<void()>& f) {
  try {
    f();
  } catch (const tb::InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << "expected tb::InputError";
  return "";
}

// Dinero IV's classic test trace: 13 reads, all in set 0 of a 32 KB / 64 B / 8-way cache (64 sets,
// set = address bits 6..11, which are zero for every multiple of 0x1000).
const std::vector<uint64_t> kDineroTrace = {0x1000, 0x2000, 0x3000, 0x4000, 0x5000, 0x6000, 0x7000,
                                            0x8000, 0x9000, 0x8000, 0x1000, 0x2000, 0x4000};

// Replays the trace through that cache under `policy` and checks the read counters that each
// test below derives by hand; returns the hierarchy for the policy's own checks.
cs::Hierarchy replay_dinero(cs::Policy policy, uint64_t read_misses, uint64_t read_hits, uint64_t evictions) {
  cs::Hierarchy h = single_level(32 << 10, 8, policy);
  for (uint64_t a : kDineroTrace) h.access(a, 4, false);
  const cs::LevelCounters& c = h.counters(0);
  EXPECT_EQ(c.read_misses, read_misses);
  EXPECT_EQ(c.read_hits, read_hits);
  EXPECT_EQ(c.evictions, evictions);
  return h;
}

}  // namespace

// LRU: 8 cold misses fill the set; 0x9000 evicts 0x1000; 0x8000 hits; 0x1000 misses and evicts the
// then-oldest 0x2000; 0x2000 misses and evicts 0x3000; 0x4000 hits. 11 misses, 3 evictions.
TEST(CacheSim, DineroTraceLru) {
  const cs::Hierarchy h = replay_dinero(cs::Policy::LRU, /*read_misses=*/11, /*read_hits=*/2, /*evictions=*/3);
  EXPECT_EQ(h.counters(0).writebacks, 0u);
  EXPECT_EQ(h.memory_reads(), 11u);
  EXPECT_EQ(cs::format_report(h),
            "L1 reads=13 writes=0 hits=2 misses=11 read_misses=11 write_misses=0 evictions=3 writebacks=0\n"
            "MEM reads=11 writes=0 cold_reads=9\n"
            "cost_cycles=1185\n");  // 2 hits x 4 + 11 memory reads x 107
}

// Tree-PLRU (gem5): the cold fills go to ways 0,4,2,6,1,5,3,7 (0x1000..0x8000), leaving every node
// bit 0, so 0x9000 replaces way 0 (0x1000). The hit on 0x8000 (way 7) turns the root left again,
// so 0x1000 replaces way 2 (0x3000, not the LRU line 0x2000); 0x2000 (way 4) and 0x4000 (way 6)
// then hit. 10 misses, 2 evictions.
TEST(CacheSim, DineroTraceTreePlru) {
  const cs::Hierarchy h = replay_dinero(cs::Policy::TreePLRU, /*read_misses=*/10, /*read_hits=*/3, /*evictions=*/2);
  EXPECT_TRUE(h.level(0).contains(0x2000 >> 6));
  EXPECT_FALSE(h.level(0).contains(0x3000 >> 6));
}

// Bit-PLRU: filling way 7 sets all MRU bits, so only way 7's survives; 0x9000 replaces way 0,
// 0x1000 way 1 (0x2000), 0x2000 way 2 (0x3000); 0x8000 and 0x4000 hit. 11 misses, 3 evictions.
TEST(CacheSim, DineroTraceBitPlru) {
  replay_dinero(cs::Policy::BitPLRU, /*read_misses=*/11, /*read_hits=*/2, /*evictions=*/3);
}

// The textbook LRU pathology: cycling through assoc+1 lines of one set evicts each line just before
// it is needed again.
TEST(CacheSim, CyclicNineLinesInEightWaySetAlwaysMissUnderLru) {
  cs::Hierarchy h = single_level(32 << 10, 8, cs::Policy::LRU);
  for (int round = 0; round < 20; ++round)
    for (uint64_t k = 0; k < 9; ++k) h.access(k * 4096, 8, false);  // 4096 B apart: all set 0
  EXPECT_EQ(h.counters(0).read_hits, 0u);
  EXPECT_EQ(h.counters(0).read_misses, 180u);
  EXPECT_EQ(h.counters(0).evictions, 180u - 8u);
}

// gem5 TreePLRURP with 8 leaves: all node bits start at 0 (victim = leftmost), and every fill
// touches the new way, so successive victims of a set that only misses are 0,4,2,6,1,5,3,7 and
// then the same again.
TEST(CacheSim, TreePlruVictimSequenceMatchesGem5) {
  cs::CacheLevel l(32 << 10, 8, 64, cs::Policy::TreePLRU);
  const std::vector<uint32_t> order = {0, 4, 2, 6, 1, 5, 3, 7};
  std::vector<uint32_t> victims;
  for (uint64_t i = 0; i < 24; ++i) {
    victims.push_back(l.victim_way(0));
    l.access((i + 1) * 64, false, false);  // line addresses 64, 128, ...: all in set 0
  }
  for (size_t i = 0; i < victims.size(); ++i) EXPECT_EQ(victims[i], order[i % 8]) << "miss " << i;

  // A hit re-points the path: touching way 0 (leaf 7; nodes 3, 1, 0 all set to "right") makes the
  // next victim the leftmost way of the right half, way 4.
  const uint64_t in_way0 = 17 * 64;  // the 17th fill (i = 16) went to way 0
  ASSERT_EQ(l.way_of(in_way0), 0);
  l.access(in_way0, false, false);
  EXPECT_EQ(l.victim_way(0), 4u);

  cs::CacheLevel four(4 * 64, 4, 64, cs::Policy::TreePLRU);  // 1 set, 4 ways: 0,2,1,3
  std::vector<uint32_t> v4;
  for (uint64_t i = 0; i < 4; ++i) {
    v4.push_back(four.victim_way(0));
    four.access(i, false, false);
  }
  EXPECT_EQ(v4, (std::vector<uint32_t>{0, 2, 1, 3}));
}

// Eight distinct lines in one 8-way set, in the order 4 1 0 3 8 1 2 1 6 5: LRU keeps all of them.
// Tree-PLRU already evicts line 4 during the first round: the two hits on line 1 (way 4) re-point
// the root, so 2 goes to way 3, and 6 is sent to way 0 (line 4) while ways 5 and 7 are still empty.
// From the second round on it misses 5 of every 10 accesses (4, 0, 8, 2 and 6).
TEST(CacheSim, EightLinesFitLruButNotTreePlru) {
  const uint64_t seq[] = {4, 1, 0, 3, 8, 1, 2, 1, 6, 5};
  for (cs::Policy p : {cs::Policy::LRU, cs::Policy::TreePLRU}) {
    cs::CacheLevel l(8 * 64, 8, 64, p);  // one set
    for (uint64_t line : seq) l.access(line, false, false);
    EXPECT_EQ(l.counters().misses(), 8u);
    EXPECT_EQ(l.counters().evictions, p == cs::Policy::LRU ? 0u : 1u);
    if (p == cs::Policy::TreePLRU) {
      EXPECT_EQ(l.way_of(6), 0);
      EXPECT_EQ(l.way_of(2), 3);
      EXPECT_FALSE(l.contains(4));
    }
    for (int round = 0; round < 10; ++round)
      for (uint64_t line : seq) l.access(line, false, false);
    EXPECT_EQ(l.counters().misses(), p == cs::Policy::LRU ? 8u : 8u + 10 * 5u) << cs::policy_name(p);
  }
}

TEST(CacheSim, LruEvictsLeastRecentlyTouched) {
  cs::CacheLevel l(4 * 64, 4, 64, cs::Policy::LRU);  // one set, 4 ways
  for (uint64_t line : {10, 11, 12, 13}) l.access(line, false, false);
  l.access(10, false, false);  // 11 is now the oldest
  l.access(14, false, false);
  EXPECT_FALSE(l.contains(11));
  EXPECT_TRUE(l.contains(10));
}

// Storing 64 KB line by line through a 32 KB L1: the first 512 stores fill L1 with dirty lines, the
// next 512 each evict one. A second sweep misses again everywhere in L1 (LRU streaming) and evicts
// 1024 more dirty lines. The 256 KB L2 keeps all 1024 lines: the second sweep's demand writes and
// every write-back hit there.
TEST(CacheSim, StoreSweepLargerThanL1WritesBack) {
  cs::Hierarchy h = from_spec("l1=32K:8,l2=256K:8", cs::Policy::LRU);
  const uint64_t base = 0x100000, bytes = 64 << 10;
  for (uint64_t a = base; a < base + bytes; a += 64) h.access(a, 8, true);
  const cs::LevelCounters& l1 = h.counters(0);
  const cs::LevelCounters& l2 = h.counters(1);
  EXPECT_EQ(l1.write_misses, 1024u);
  EXPECT_EQ(l1.evictions, 512u);
  EXPECT_EQ(l1.writebacks, 512u);
  EXPECT_EQ(l2.write_misses, 1024u);  // the demand stores, passed down as writes
  EXPECT_EQ(l2.write_hits, 512u);     // the write-backs, all to lines L2 already holds
  EXPECT_EQ(l2.evictions, 0u);
  EXPECT_EQ(h.memory_writes(), 1024u);  // stores that missed every level
  EXPECT_EQ(h.memory_reads(), 0u);
  EXPECT_TRUE(h.level(1).is_dirty(base >> 6));          // written back
  EXPECT_FALSE(h.level(1).is_dirty((base + bytes - 64) >> 6));  // still only dirty in L1
  EXPECT_TRUE(h.level(0).is_dirty((base + bytes - 64) >> 6));

  for (uint64_t a = base; a < base + bytes; a += 64) h.access(a, 8, true);
  EXPECT_EQ(l1.write_misses, 2048u);
  EXPECT_EQ(l1.writebacks, 512u + 1024u);
  EXPECT_EQ(l2.write_misses, 1024u);
  EXPECT_EQ(l2.write_hits, 512u + 1024u + 1024u);
  EXPECT_EQ(h.memory_writes(), 1024u);
}

// With a single level, a dirty victim has nowhere to go but memory.
TEST(CacheSim, DirtyVictimOfLastLevelIsMemoryWrite) {
  cs::Hierarchy h = from_spec("l1=128:2", cs::Policy::LRU);  // one set, two ways
  h.access(0 * 64, 4, true);
  h.access(1 * 64, 4, false);
  h.access(2 * 64, 4, false);  // evicts the dirty line 0
  h.access(3 * 64, 4, false);  // evicts the clean line 1
  EXPECT_EQ(h.counters(0).evictions, 2u);
  EXPECT_EQ(h.counters(0).writebacks, 1u);
  EXPECT_EQ(h.memory_reads(), 3u);
  EXPECT_EQ(h.memory_writes(), 1u + 1u);  // the missing store + its write-back
}

TEST(CacheSim, StraddlingAccessTouchesEveryLine) {
  cs::Hierarchy h = single_level(32 << 10, 8, cs::Policy::LRU);
  h.access(60, 8, false);  // bytes 60..67: lines 0 and 1
  EXPECT_EQ(h.counters(0).reads(), 2u);
  EXPECT_EQ(h.counters(0).read_misses, 2u);
  h.access(64, 64, false);  // exactly line 1
  EXPECT_EQ(h.counters(0).reads(), 3u);
  EXPECT_EQ(h.counters(0).read_hits, 1u);
  h.access(0, 200, true);  // bytes 0..199: lines 0..3
  EXPECT_EQ(h.counters(0).writes(), 4u);
  h.access(1000, 0, false);  // empty access: nothing
  EXPECT_EQ(h.counters(0).accesses(), 7u);
  h.access(~uint64_t{0} - 1, 16, false);  // clamped at the top of the address space: one line
  EXPECT_EQ(h.counters(0).accesses(), 8u);
}

// A miss fills every level on the way; an L1 eviction leaves L2 and L3 copies that then serve the
// line at their latency.
TEST(CacheSim, HierarchyFillsEveryLevelOnAMiss) {
  cs::Hierarchy h(cs::default_config());
  h.access(0, 4, false);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(h.counters(i).read_misses, 1u) << "level " << i;
    EXPECT_TRUE(h.level(i).contains(0)) << "level " << i;
  }
  EXPECT_EQ(h.memory_reads(), 1u);

  // Eight more lines in L1 set 0 (4 KB apart) spread over eight L2 sets: line 0 leaves L1 only.
  for (uint64_t k = 1; k <= 8; ++k) h.access(k * 4096, 4, false);
  EXPECT_FALSE(h.level(0).contains(0));
  EXPECT_TRUE(h.level(1).contains(0));
  h.access(0, 4, false);
  EXPECT_EQ(h.counters(0).read_misses, 10u);
  EXPECT_EQ(h.counters(1).read_hits, 1u);
  EXPECT_EQ(h.counters(2).reads(), 9u);  // L3 saw only the nine cold misses
  EXPECT_EQ(h.memory_reads(), 9u);
  EXPECT_EQ(h.cost_cycles(), 1u * 11 + 9u * 107);
  EXPECT_EQ(h.read_cost_cycles(), h.cost_cycles());

  h.access(0, 4, false);  // now an L1 hit
  EXPECT_EQ(h.cost_cycles(), 4u + 11u + 9u * 107);

  h.reset();
  EXPECT_EQ(h.counters(0).accesses(), 0u);
  EXPECT_EQ(h.memory_reads(), 0u);
  EXPECT_FALSE(h.level(2).contains(0));
}

// Levels are not inclusive: L2 may drop a line L1 still holds, and L1 keeps serving it.
TEST(CacheSim, HierarchyIsNotInclusive) {
  cs::Hierarchy h = from_spec("l1=128:2,l2=128:2", cs::Policy::LRU);  // one 2-way set each
  const uint64_t A = 0, B = 64, C = 128;
  h.access(A, 4, false);
  h.access(B, 4, false);
  h.access(A, 4, false);  // L1 hit: L2 does not see it, so A stays L2's oldest line
  h.access(C, 4, false);  // L1 evicts B; L2 evicts A
  EXPECT_TRUE(h.level(0).contains(A >> 6));
  EXPECT_FALSE(h.level(1).contains(A >> 6));
  h.access(A, 4, false);
  EXPECT_EQ(h.counters(0).read_hits, 2u);
  EXPECT_EQ(h.counters(1).reads(), 3u);
}

TEST(CacheSim, StoreMissServedByL2CountsAsL2WriteHit) {
  cs::Hierarchy h = from_spec("l1=128:2,l2=1K:4", cs::Policy::LRU);
  h.access(0, 4, false);
  h.access(64, 4, false);
  h.access(128, 4, false);  // L1 drops line 0
  h.access(0, 4, true);
  EXPECT_EQ(h.counters(0).write_misses, 1u);
  EXPECT_EQ(h.counters(1).write_hits, 1u);
  EXPECT_TRUE(h.level(0).is_dirty(0));
  EXPECT_FALSE(h.level(1).is_dirty(0));  // only the level performing the store holds new data
}

TEST(CacheSim, ParseConfig) {
  cs::HierarchyConfig cfg = cs::parse_config("l1=32K:8,l2=256K:8,l3=2M:16");
  ASSERT_EQ(cfg.levels.size(), 3u);
  EXPECT_EQ(cfg.levels[0].name, "L1");
  EXPECT_EQ(cfg.levels[0].size_bytes, 32768u);
  EXPECT_EQ(cfg.levels[1].size_bytes, 262144u);
  EXPECT_EQ(cfg.levels[2].size_bytes, 2097152u);
  EXPECT_EQ(cfg.levels[2].assoc, 16u);
  EXPECT_EQ(cfg.levels[1].line_bytes, 64u);
  EXPECT_EQ(cfg.levels[0].latency_cycles, 4u);
  EXPECT_EQ(cfg.levels[1].latency_cycles, 11u);
  EXPECT_EQ(cfg.levels[2].latency_cycles, 39u);
  EXPECT_EQ(cfg.memory_latency_cycles, 107u);
  EXPECT_EQ(cfg.policy, cs::Policy::TreePLRU);

  cfg = cs::parse_config(" l1=32KB:8:128 , L3=2m:16:128:40, mem=200 ");
  ASSERT_EQ(cfg.levels.size(), 2u);
  EXPECT_EQ(cfg.levels[0].line_bytes, 128u);
  EXPECT_EQ(cfg.levels[1].name, "L3");
  EXPECT_EQ(cfg.levels[1].latency_cycles, 40u);
  EXPECT_EQ(cfg.memory_latency_cycles, 200u);
  EXPECT_EQ(cs::parse_config("l1=4096:64").levels[0].assoc, 64u);  // fully associative

  EXPECT_EQ(cs::parse_policy("lru"), cs::Policy::LRU);
  EXPECT_EQ(cs::parse_policy("plru"), cs::Policy::TreePLRU);
  EXPECT_EQ(cs::parse_policy("bitplru"), cs::Policy::BitPLRU);
}

TEST(CacheSim, ParseConfigErrorsNameTheBadField) {
  auto err = [](const std::string& spec) { return input_error([&] { cs::parse_config(spec); }); };
  EXPECT_NE(err("l1=30K:8").find("'l1=30K:8': size '30K' is not a power of two"), std::string::npos);
  EXPECT_NE(err("l1=32X:8").find("size '32X'"), std::string::npos);
  EXPECT_NE(err("l1=32K:0").find("associativity '0'"), std::string::npos);
  EXPECT_NE(err("l1=32K:3").find("associativity 3 does not divide"), std::string::npos);
  EXPECT_NE(err("l1=32K:128").find("associativity 128 exceeds 64"), std::string::npos);
  EXPECT_NE(err("l1=256:8").find("does not divide the 4 lines"), std::string::npos);
  EXPECT_NE(err("l1=32K").find("expected SIZE:ASSOC"), std::string::npos);
  EXPECT_NE(err("l1=32K:8:48").find("line size 48 is not a power of two"), std::string::npos);
  EXPECT_NE(err("l1=32K:8:").find("line size ''"), std::string::npos);
  EXPECT_NE(err("l1=32K:8:64:x").find("latency 'x'"), std::string::npos);
  EXPECT_NE(err("x1=32K:8").find("level name 'x1'"), std::string::npos);
  EXPECT_NE(err("l0=32K:8").find("level name 'l0'"), std::string::npos);
  EXPECT_NE(err("l2=256K:8,l1=32K:8").find("l1 must come after l2"), std::string::npos);
  EXPECT_NE(err("l1=32K:8,l1=32K:8").find("l1 must come after l1"), std::string::npos);
  // Non-canonical level names (`l01` was accepted and shown as L01) and caches beyond what the
  // simulator models (l1=64G:8 asked for 16 GiB of tags).
  EXPECT_NE(err("l01=32K:8").find("level name 'l01' is not l1, l2"), std::string::npos);
  EXPECT_NE(err("l1=64G:8").find("more than the 2^26"), std::string::npos);
  EXPECT_NE(err("l1=1G:8:4").find("more than the 2^26"), std::string::npos);
  EXPECT_NO_THROW(cs::parse_config("l1=32K:8,l2=256K:8,l3=4G:16"));
  EXPECT_NE(err("l4=8M:16").find("no default latency"), std::string::npos);
  EXPECT_NE(err("l1=32K:8:32,l2=256K:8").find("line size 64 differs"), std::string::npos);
  EXPECT_NE(err("l132K:8").find("expected NAME=VALUE"), std::string::npos);
  EXPECT_NE(err("l1=32K:8,,l2=256K:8").find("empty item"), std::string::npos);
  EXPECT_NE(err("mem=107").find("no cache level"), std::string::npos);
  EXPECT_NE(err("l1=32K:8,mem=fast").find("memory latency 'fast'"), std::string::npos);
  EXPECT_NE(err("").find("empty"), std::string::npos);
  EXPECT_NE(err("l1=99999999999999999999K:8").find("size"), std::string::npos);

  const std::string p = input_error([] { cs::parse_policy("fifo"); });
  EXPECT_NE(p.find("'fifo'"), std::string::npos);
  EXPECT_NE(p.find("lru, plru or bitplru"), std::string::npos);

  cs::HierarchyConfig bad = cs::default_config();
  bad.levels[1].size_bytes = 3000;
  EXPECT_NE(input_error([&] { cs::Hierarchy h(bad); }).find("cache level L2: size 3000"),
            std::string::npos);
}

TEST(CacheSim, DinReplay) {
  std::istringstream in(
      "# a comment\n"
      "\n"
      "0 1000\n"
      "1 0x1004 trailing text is ignored, as in Dinero\r\n"
      "   2 0X00000000002000\n"
      "0 103e\n");  // 4 bytes at 0x103e straddle lines 0x40 and 0x41
  cs::Hierarchy h = single_level(32 << 10, 8, cs::Policy::LRU);
  EXPECT_EQ(cs::replay_din(in, h, "t.din"), 4u);
  const cs::LevelCounters& c = h.counters(0);
  EXPECT_EQ(c.reads(), 3u + 1u);
  EXPECT_EQ(c.writes(), 1u);
  EXPECT_EQ(c.write_hits, 1u);
  EXPECT_EQ(c.read_misses, 3u);  // 0x1000, 0x2000, 0x1040
}

TEST(CacheSim, DinErrorsNameFileAndLine) {
  auto err = [](const std::string& text) {
    return input_error([&] {
      std::istringstream in("0 1000\n\n" + text + "\n");
      cs::Hierarchy h = single_level(32 << 10, 8, cs::Policy::LRU);
      cs::replay_din(in, h, "t.din");
    });
  };
  EXPECT_NE(err("7 1000").find("t.din:3: label '7' is not a din access type"), std::string::npos);
  EXPECT_NE(err("r 1000").find("t.din:3: label 'r'"), std::string::npos);
  EXPECT_NE(err("3 1000").find("t.din:3: din escape label 3"), std::string::npos);
  EXPECT_NE(err("4 0").find("cache flush"), std::string::npos);
  EXPECT_NE(err("0").find("t.din:3: missing hex address"), std::string::npos);
  EXPECT_NE(err("1 12g4").find("t.din:3: address '12g4' is not hexadecimal"), std::string::npos);
  EXPECT_NE(err("0 0x").find("is not hexadecimal"), std::string::npos);
  EXPECT_NE(err("0 -10").find("is not hexadecimal"), std::string::npos);
  EXPECT_NE(err("0 10000000000000000").find("does not fit in 64 bits"), std::string::npos);
  // Control bytes in a token are shown escaped: a raw NUL cut the message off before its reason.
  EXPECT_NE(err(std::string("0 10\0zz", 7)).find("address '10\\x00zz' is not hexadecimal"), std::string::npos);
  EXPECT_NE(err("\x1b[31m 10").find("label '\\x1B[31m' is not a din access type"), std::string::npos);
}

TEST(CacheSim, RunCachesimCommand) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "tb_cachesim_test";
  std::filesystem::create_directories(dir);
  const std::filesystem::path trace = dir / "dinero.din";
  {
    std::ofstream f(trace);
    for (uint64_t a : kDineroTrace) f << "0 " << std::hex << a << "\n";
  }
  std::ostringstream out;
  EXPECT_EQ(cs::run_cachesim_command("l1=32K:8", "lru", trace.string(), out), 0);
  EXPECT_EQ(out.str().substr(0, out.str().find('\n')),
            "L1 reads=13 writes=0 hits=2 misses=11 read_misses=11 write_misses=0 evictions=3 writebacks=0");

  // Empty config and policy: the §5.4 hierarchy with tree-PLRU. L2 spreads the nine lines over
  // eight of its 512 sets, so the re-read of 0x1000 (evicted from L1) hits there.
  std::ostringstream dflt;
  cs::run_cachesim_command("", "", trace.string(), dflt);
  EXPECT_EQ(dflt.str(),
            "L1 reads=13 writes=0 hits=3 misses=10 read_misses=10 write_misses=0 evictions=2 writebacks=0\n"
            "L2 reads=10 writes=0 hits=1 misses=9 read_misses=9 write_misses=0 evictions=0 writebacks=0\n"
            "L3 reads=9 writes=0 hits=0 misses=9 read_misses=9 write_misses=0 evictions=0 writebacks=0\n"
            "MEM reads=9 writes=0 cold_reads=9\n"
            "cost_cycles=986\n");  // 3 x 4 + 1 x 11 + 9 x 107

  std::ostringstream sink;
  const std::string missing = (dir / "nope.din").string();
  EXPECT_NE(input_error([&] { cs::run_cachesim_command("", "", missing, sink); })
                .find("cannot open trace '" + missing + "'"),
            std::string::npos);
  EXPECT_NE(input_error([&] { cs::run_cachesim_command("", "", dir.string(), sink); })
                .find("is a directory"),
            std::string::npos);
  EXPECT_NE(input_error([&] { cs::run_cachesim_command("l1=32K:8", "mru", trace.string(), sink); })
                .find("'mru'"),
            std::string::npos);
  std::filesystem::remove_all(dir);
}

// Cold reads (hierarchy.h: lines first touched by a load): a line first written is not one, a
// re-read after eviction is a memory read but not a cold read, lines in different 256 KiB regions
// of the line set (and far apart) are told apart, reset() forgets them.
TEST(CacheSim, ColdReadsCountFirstTouchLoads) {
  cs::Hierarchy h = single_level(1 << 10, 2, cs::Policy::LRU);  // 8 sets of 2 ways
  h.access(0x0, 8, false);        // cold
  h.access(0x8, 8, false);        // same line: hit
  h.access(0x40, 4, true);        // first touch is a store: a memory write, not a cold read
  h.access(0x40, 4, false);       // hit
  h.access(0x3FFC0, 128, false);  // lines 4095 and 4096: the last of one region, the first of the next
  h.access(uint64_t(1) << 40, 4, false);
  EXPECT_EQ(h.cold_reads(), 4u);
  EXPECT_EQ(h.memory_reads(), 4u);
  // Set 0 holds two lines: three more in it evict line 0, whose re-read is a miss but not cold.
  for (uint64_t a : {0x200, 0x400, 0x600}) h.access(a, 4, false);
  h.access(0x0, 4, false);
  EXPECT_EQ(h.cold_reads(), 7u);
  EXPECT_EQ(h.memory_reads(), 8u);
  h.reset();
  EXPECT_EQ(h.cold_reads(), 0u);
  h.access(0x0, 4, false);
  EXPECT_EQ(h.cold_reads(), 1u);
}

// The bound: memory reads >= cold reads for any geometry and policy, and equal where no line is
// ever evicted: under LRU a working set that fits each set's ways (tree-PLRU may evict a line of
// such a set, EightLinesFitLruButNotTreePlru). Random loads and stores.
TEST(CacheSim, ColdReadsBoundMemoryReads) {
  for (cs::Policy policy : {cs::Policy::LRU, cs::Policy::TreePLRU, cs::Policy::BitPLRU}) {
    SCOPED_TRACE(std::string(cs::policy_name(policy)));
    cs::Hierarchy small = from_spec("l1=4K:4,l2=16K:8", policy);
    cs::Hierarchy big = single_level(64 << 10, 8, policy);
    uint64_t x = 2463534242ull;
    for (int i = 0; i < 200000; ++i) {
      x ^= x << 13, x ^= x >> 7, x ^= x << 17;
      const uint64_t addr = x & ((64u << 10) - 16);  // 16-aligned, fits `big` exactly: 128 sets x 8 ways
      const bool write = (x >> 20) % 5 == 0;
      small.access(addr, 16, write);
      big.access(addr, 16, write);
    }
    EXPECT_GT(small.memory_reads(), small.cold_reads());
    EXPECT_EQ(small.cold_reads(), big.cold_reads());  // the same lines, first touched alike
    EXPECT_GE(big.memory_reads(), big.cold_reads());
    if (policy == cs::Policy::LRU) {
      EXPECT_EQ(big.counters(0).evictions, 0u);
      EXPECT_EQ(big.memory_reads(), big.cold_reads());
    }
    EXPECT_GT(big.cold_reads(), 0u);
  }
}

// Not a timing assertion (machines differ): checks that long runs stay consistent and reports the
// rate for two mixes of 32-byte accesses, one in sixteen a store: a hit-dominated one (16 KB
// working set, as in coherent traversal) and a miss-heavy one (random over 256 KB, every eighth
// access anywhere in 64 MB: ~90 % L1 misses). An optimized build should do tens of millions of
// accesses per second on both.
TEST(CacheSim, ThroughputSanity) {
  struct Mix {
    const char* name;
    uint64_t working_set;
    bool scatter;
  };
  for (const Mix& mix : {Mix{"L1-resident", 16u << 10, false}, Mix{"miss-heavy", 256u << 10, true}}) {
    cs::Hierarchy h(cs::default_config());
    const uint64_t n = 10'000'000;
    uint64_t x = 88172645463325252ull;
    const auto t0 = std::chrono::steady_clock::now();
    for (uint64_t i = 0; i < n; ++i) {
      x ^= x << 13, x ^= x >> 7, x ^= x << 17;
      const uint64_t addr = mix.scatter && (i & 7) == 0 ? (x & ((64u << 20) - 1)) : (x & (mix.working_set - 1));
      h.access(addr & ~uint64_t{31}, 32, (i & 15) == 3);
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const cs::LevelCounters& l1 = h.counters(0);
    EXPECT_EQ(l1.accesses(), n);  // 32-byte aligned 32-byte accesses: one line each
    EXPECT_EQ(l1.writes(), n / 16);
    // Every L1 miss and every L1 write-back reaches L2, and nothing else does.
    EXPECT_EQ(h.counters(1).accesses(), l1.misses() + l1.writebacks);
    if (!mix.scatter) {
      EXPECT_EQ(l1.misses(), (16u << 10) / 64);  // cold misses only
    }
    const double rate = static_cast<double>(n) / s;
    std::printf("[ throughput ] %-12s %6.1f M accesses/s, L1 miss rate %.3f\n", mix.name, rate / 1e6,
                static_cast<double>(l1.misses()) / static_cast<double>(n));
    RecordProperty(std::string("accesses_per_second_") + mix.name, static_cast<int>(rate));
  }
}
