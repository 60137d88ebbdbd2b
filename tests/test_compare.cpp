// travbench compare: the Mann-Whitney U test against SciPy's values, CSV reading through libcsv,
// and cell matching (ratios, unmatched cells, accuracy deltas, the regression gate).
#include <cstdio>
#include <fstream>

#include "harness/compare.h"
#include "test_util.h"

namespace tb {
namespace {

std::string write_file(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << text;
  return path;
}

TEST(MannWhitney, MatchesScipy) {
  // scipy.stats.mannwhitneyu(a, b, alternative='two-sided') (SciPy 1.10, Debian 12).
  EXPECT_NEAR(*mann_whitney_p({1, 2, 3}, {4, 5, 6}), 0.1, 1e-12);
  EXPECT_NEAR(*mann_whitney_p({1, 2, 3, 4, 5}, {6, 7, 8, 9, 10}), 0.007936507936507936, 1e-12);
  EXPECT_NEAR(*mann_whitney_p({10.1, 10.3, 9.9, 10.2, 10.0}, {10.05, 10.25, 9.95, 10.15, 10.35}), 0.6904761904761905, 1e-12);
  // Ties: normal approximation with tie and continuity corrections.
  EXPECT_NEAR(*mann_whitney_p({1, 2, 2, 3, 5}, {2, 3, 4, 4, 6}), 0.2418443040494631, 1e-9);
  std::vector<double> a, b;
  for (int i = 0; i < 30; ++i) a.push_back(i), b.push_back(i + 5.5);
  EXPECT_NEAR(*mann_whitney_p(a, b), 0.027086318388295935, 1e-9);
  // Symmetric, bounded, and defined for degenerate samples.
  EXPECT_DOUBLE_EQ(*mann_whitney_p({4, 5, 6}, {1, 2, 3}), *mann_whitney_p({1, 2, 3}, {4, 5, 6}));
  EXPECT_DOUBLE_EQ(*mann_whitney_p({3, 3, 3}, {3, 3, 3}), 1.0);
  EXPECT_FALSE(mann_whitney_p({}, {1}).has_value());
}

TEST(Compare, ReadsQuotedCsvAndRejectsMalformed) {
  const auto p = write_file("q.csv", "scene,params,mrays_median\nroom,\"a=1,b=2\",3.5\n");
  const CsvTable t = read_csv(p);
  ASSERT_EQ(t.rows.size(), 1u);
  EXPECT_EQ(t.at(0, t.column("params")), "a=1,b=2");
  EXPECT_THROW(read_csv(write_file("bad.csv", "a,b\n1,2,3\n")), InputError);
  EXPECT_THROW(read_csv(write_file("quote.csv", "a,b\n\"1,2\n")), InputError);
  EXPECT_THROW(read_csv(::testing::TempDir() + "does_not_exist.csv"), InputError);
}

TEST(Compare, MatchesCellsAndGatesRegressions) {
  const std::string head = "scene,workload,scheme,kernel,mrays_median,mrays_samples,false_miss\n";
  const auto base = write_file("base.csv", head +
      "room,primary,bvh_single,watertight,10,10;10.1;9.9;10.2;9.8,0\n"
      "room,primary,mbvh8_single,watertight,20,20;20.1;19.9;20.2;19.8,0\n"
      "room,bounce:2,bvh_single,watertight,5,5;5.1;4.9;5.2;4.8,0\n");
  const auto next = write_file("next.csv", head +
      "room,primary,bvh_single,watertight,8,8;8.1;7.9;8.2;7.8,2\n"          // 20% slower, significant
      "room,primary,mbvh8_single,watertight,20.05,20.05;19.95;20.15;19.85;20.0,0\n"  // noise
      "room,shadow,bvh_single,watertight,7,7;7;7;7;7,0\n");                 // unmatched
  CompareOptions opt;
  opt.fail_on_regression_pct = 5;
  const CompareResult r = compare_runs(read_csv(base), read_csv(next), opt);
  ASSERT_EQ(r.cells.size(), 2u);
  EXPECT_NEAR(r.cells[0].ratio, 0.8, 1e-12);
  EXPECT_EQ(r.cells[0].verdict, "slower");
  EXPECT_TRUE(r.cells[0].regression);
  ASSERT_FALSE(r.cells[0].accuracy_delta.empty());
  EXPECT_EQ(r.cells[0].accuracy_delta[0].first, "false_miss");
  EXPECT_EQ(r.cells[0].accuracy_delta[0].second, 2);
  EXPECT_EQ(r.cells[1].verdict, "same");
  EXPECT_FALSE(r.cells[1].regression);
  EXPECT_TRUE(r.failed);
  EXPECT_EQ(r.only_base.size(), 1u);
  EXPECT_EQ(r.only_next.size(), 1u);
  EXPECT_NEAR(r.geomean_ratio, std::sqrt(0.8 * 20.05 / 20), 1e-9);
  // A looser gate passes; without samples the ratio alone decides.
  opt.fail_on_regression_pct = 25;
  EXPECT_FALSE(compare_runs(read_csv(base), read_csv(next), opt).failed);
  const auto nos = write_file("nosamples.csv", "scene,workload,scheme,mrays_median\nroom,primary,bvh_single,9\n");
  opt.fail_on_regression_pct = 5;
  const CompareResult r2 = compare_runs(read_csv(nos), read_csv(nos), opt);
  EXPECT_EQ(r2.cells[0].verdict, "n/a");
  EXPECT_FALSE(r2.failed);
  EXPECT_EQ(comparison_records(r).size(), 4u);
  EXPECT_THROW(compare_runs(read_csv(write_file("x.csv", "a,b\n1,2\n")), read_csv(base)), InputError);
}

}  // namespace
}  // namespace tb
