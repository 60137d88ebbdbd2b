// `table bandwidth`'s interleaved timing (harness/table_bandwidth.cpp, issue 19): the columns its
// speed comparison rests on. No timing is asserted: only that every cell has one Mrays/s sample
// per round, that each round's ratio is taken against the same round of the first scheme, and that
// the simulated memory reads are those of a plain --cache run.
#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>

#include "harness/compare.h"
#include "harness/tables.h"
#include "test_util.h"

namespace tb {
namespace {

std::vector<double> samples_of(const std::string& s) {
  std::vector<double> v;
  std::stringstream in(s);
  for (std::string x; std::getline(in, x, ';');) v.push_back(std::stod(x));
  return v;
}

TEST(TableBandwidth, RoundsInterleaveAndRatiosPairTheSameRound) {
  const auto dir = test::temp_dir("table_bandwidth");
  TableOptions opt;
  opt.scene = "room";  // bounce:2 rays exist (the sphere scene has none)
  opt.csv = (dir / "b.csv").string();
  // An entry with a parameter of its own is a row of its own, labelled as given.
  opt.run.schemes = {"mbvh8_single", "cwbvh_single", "treelet_queue", "cwbvh_single:full_top=0"};
  opt.run.width = opt.run.height = 32;
  opt.run.reps = 3;
  opt.run.progress = false;
  ASSERT_EQ(run_table("bandwidth", opt), 0);
  const CsvTable t = read_csv(opt.csv);
  ASSERT_EQ(t.rows.size(), 8u);  // 4 schemes x primary, bounce:2
  const int scheme = t.column("scheme"), workload = t.column("workload"), samples = t.column("mrays_samples");
  const int base = t.column("speed_base"), median = t.column("speed_ratio_median"), reps = t.column("reps");
  const int lo = t.column("speed_ratio_min"), hi = t.column("speed_ratio_max"), reads = t.column("mem_reads_per_ray");
  const int cold = t.column("cold_reads_per_ray");
  for (int c : {scheme, workload, samples, base, median, reps, lo, hi, reads, cold}) ASSERT_GE(c, 0);
  for (size_t i = 0; i < t.rows.size(); ++i) {
    EXPECT_EQ(t.at(i, base), "mbvh8_single");
    EXPECT_EQ(t.at(i, reps), "3");
    const std::vector<double> s = samples_of(t.at(i, samples));
    ASSERT_EQ(s.size(), 3u) << "one sample per round";
    // The first scheme's row of the same workload: its rounds are the ratios' denominators.
    size_t b = 0;
    while (t.at(b, scheme) != "mbvh8_single" || t.at(b, workload) != t.at(i, workload)) ++b;
    const std::vector<double> sb = samples_of(t.at(b, samples));
    std::vector<double> ratio;
    for (size_t k = 0; k < 3; ++k) ratio.push_back(s[k] / sb[k]);
    std::sort(ratio.begin(), ratio.end());
    EXPECT_NEAR(std::stod(t.at(i, median)), ratio[1], 1e-3 * ratio[1]);
    EXPECT_NEAR(std::stod(t.at(i, lo)), ratio[0], 1e-3 * ratio[0]);
    EXPECT_NEAR(std::stod(t.at(i, hi)), ratio[2], 1e-3 * ratio[2]);
    if (i == b) {
      EXPECT_EQ(t.at(i, median), "1");
    }
    EXPECT_GT(std::stod(t.at(i, reads)), 0.0);
    // Cold reads (lines first touched by a load, cachesim/hierarchy.h) bound the memory reads.
    EXPECT_GT(std::stod(t.at(i, cold)), 0.0);
    EXPECT_LE(std::stod(t.at(i, cold)), std::stod(t.at(i, reads)) * (1 + 1e-5));
  }
  // The entry's rows: its own parameter in the params column, the plain compressed layout's 80
  // bytes per node fetch (the default's uncompressed top reads more per fetch).
  const int params = t.column("params"), bytes = t.column("bytes_per_node");
  ASSERT_GE(params, 0);
  ASSERT_GE(bytes, 0);
  int plain = 0;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    if (t.at(i, scheme) == "cwbvh_single:full_top=0") {
      ++plain;
      EXPECT_NE(t.at(i, params).find("full_top=0"), std::string::npos) << t.at(i, params);
      EXPECT_EQ(t.at(i, bytes), "80");
    } else if (t.at(i, scheme) == "cwbvh_single") {
      EXPECT_EQ(t.at(i, params).find("full_top"), std::string::npos) << t.at(i, params);
    }
  }
  EXPECT_EQ(plain, 2);
  std::filesystem::remove_all(dir);
}

// Without --schemes the table runs its default set, entries with parameters of their own
// included (the reordering alone, `treelet_queue:tree=mbvh8`, beside the default treelet_queue).
TEST(TableBandwidth, DefaultSchemesKeepEntriesWithParameters) {
  const auto dir = test::temp_dir("table_bandwidth_default");
  TableOptions opt;
  opt.scene = "room";
  opt.csv = (dir / "b.csv").string();
  opt.run.width = opt.run.height = 16;
  opt.run.reps = 1;
  opt.run.progress = false;
  ASSERT_EQ(run_table("bandwidth", opt), 0);
  const CsvTable t = read_csv(opt.csv);
  const int scheme = t.column("scheme");
  ASSERT_GE(scheme, 0);
  std::vector<std::string> seen;
  for (size_t i = 0; i < t.rows.size(); ++i)
    if (std::find(seen.begin(), seen.end(), t.at(i, scheme)) == seen.end()) seen.push_back(t.at(i, scheme));
  EXPECT_EQ(seen, (std::vector<std::string>{"mbvh8_single", "cwbvh_single", "treelet_queue", "treelet_queue:tree=mbvh8",
                                            "mbvh_rs", "raygrid"}));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tb
