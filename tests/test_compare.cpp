// travbench compare: the Mann-Whitney U test against SciPy's values, CSV reading through libcsv,
// and cell matching (ratios, unmatched cells, accuracy deltas, the regression gate).
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <sstream>

#include "harness/compare.h"
#include "harness/records.h"
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
      "room,primary,mbvh8_single,watertight,20.05,20.05;19.95;20.15;19.85;20.1,0\n"  // noise
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
  // A cell without rays (bounce:2 of a convex scene: `run` writes 0) is no speed: not in the
  // geometric mean (it pulled the mean toward 1 through the denominator) and never a regression
  // (without samples it failed the gate).
  const std::string rh = "scene,workload,scheme,rays,mrays_median\n";
  const auto eb = write_file("empty_base.csv", rh + "s,primary,bvh_single,100,10\ns,bounce:2,bvh_single,0,0\n");
  const auto en = write_file("empty_next.csv", rh + "s,primary,bvh_single,100,8\ns,bounce:2,bvh_single,0,0\n");
  const CompareResult r3 = compare_runs(read_csv(eb), read_csv(en), opt);
  ASSERT_EQ(r3.cells.size(), 2u);
  EXPECT_NEAR(r3.geomean_ratio, 0.8, 1e-12);
  EXPECT_EQ(r3.cells[1].verdict, "no rays");
  EXPECT_FALSE(r3.cells[1].regression);
  EXPECT_TRUE(r3.cells[0].regression);  // 20% slower, no samples: the gate cannot pass it
}

TEST(Compare, BenjaminiHochbergMatchesRsPAdjust) {
  // R: p.adjust(p, "BH"), i.e. cummin(m / i * p[descending])[back to input order], capped at 1.
  auto near = [](const std::vector<double>& got, const std::vector<double>& want) {
    ASSERT_EQ(got.size(), want.size());
    for (size_t i = 0; i < got.size(); ++i) EXPECT_NEAR(got[i], want[i], 1e-12) << i;
  };
  near(benjamini_hochberg({0.01, 0.04, 0.03, 0.005}), {0.02, 0.04, 0.04, 0.02});
  near(benjamini_hochberg({0.02, 0.021}), {0.021, 0.021});
  near(benjamini_hochberg({0.001, 0.2, 0.5, 0.04, 0.04, 0.9}), {0.006, 0.3, 0.6, 0.08, 0.08, 0.9});
  near(benjamini_hochberg({0.3, 0.9}), {0.6, 0.9});
  EXPECT_TRUE(benjamini_hochberg({}).empty());
}

// A suite of `schemes` x 8 workloads with `reps` samples a cell, as two runs of one binary on a
// shared machine give them: every sample of a run scaled by that run's drift (the same for all of
// its cells: not i.i.d.), each sample with 1% noise of its own. `slow` scales one scheme's samples
// (a change that makes that scheme slower).
std::string suite_csv(const std::string& name, int schemes, int reps, double drift, uint32_t seed,
                      const std::string& slow_scheme = "", double slow = 1.0) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(1.0, 0.01);
  std::ostringstream csv;
  csv << "scene,workload,scheme,kernel,mrays_median,mrays_samples\n";
  for (int w = 0; w < 8; ++w)
    for (int s = 0; s < schemes; ++s) {
      const std::string scheme = "scheme" + std::to_string(s);
      const double speed = (1.0 + s) * (1.0 + 0.5 * w) * drift * (scheme == slow_scheme ? slow : 1.0);
      std::vector<double> v;
      std::string samples;
      for (int r = 0; r < reps; ++r) {
        v.push_back(speed * noise(rng));
        if (r) samples += ';';  // two appends: "" + std::string&& trips GCC 12's -Wrestrict
        samples += std::to_string(v.back());
      }
      std::sort(v.begin(), v.end());
      csv << "sponza,w" << w << "," << scheme << ",watertight," << v[v.size() / 2] << "," << samples << "\n";
    }
  return write_file(name, csv.str());
}

// Issue 20, "Done when": the same binary twice -> no cell marked, although the drift between the
// runs (4%, as measured on this VM) makes every sample of one run slower than every sample of the
// other; one scheme made 20% slower -> exactly its cells marked slower.
TEST(Compare, SameBinaryMarksNothingAndATwentyPercentSlowerSchemeIsMarked) {
  const int schemes = 17, reps = 9;
  const CsvTable base = read_csv(suite_csv("s_base.csv", schemes, reps, 1.0, 1));
  const CompareResult same = compare_runs(base, read_csv(suite_csv("s_same.csv", schemes, reps, 0.96, 2)));
  ASSERT_EQ(same.cells.size(), size_t(schemes * 8));
  EXPECT_EQ(same.faster + same.slower, 0u);
  EXPECT_LT(same.scatter_pct, 2);  // a common drift, not scatter
  EXPECT_FALSE(same.noisy);
  // Without the effect threshold the drift is "significant" nearly everywhere: the U test alone
  // (even corrected) cries wolf.
  CompareOptions raw;
  raw.min_effect_pct = 0;
  EXPECT_GT(compare_runs(base, read_csv(suite_csv("s_same.csv", schemes, reps, 0.96, 2)), raw).slower,
            size_t(schemes * 4));
  // Chance alone (no drift): the correction keeps it quiet too, without any effect threshold.
  const CompareResult chance = compare_runs(base, read_csv(suite_csv("s_noise.csv", schemes, reps, 1.0, 3)), raw);
  EXPECT_EQ(chance.slower + chance.faster, 0u);

  CompareOptions gate;
  gate.fail_on_regression_pct = 15;
  const CompareResult slow =
      compare_runs(base, read_csv(suite_csv("s_slow.csv", schemes, reps, 0.96, 4, "scheme5", 0.8)), gate);
  for (const auto& c : slow.cells) {
    const bool changed = c.key.find("/ scheme5 /") != std::string::npos;
    EXPECT_EQ(c.verdict, changed ? "slower" : "same") << c.key << " q " << *c.q << " ratio " << c.ratio;
    EXPECT_EQ(c.regression, changed) << c.key;
  }
  EXPECT_EQ(slow.slower, 8u);
  EXPECT_TRUE(slow.failed);
  EXPECT_FALSE(compare_runs(base, read_csv(suite_csv("s_same.csv", schemes, reps, 0.96, 2)), gate).failed);
}

std::vector<double> parse_test_samples(const std::string& s) {
  std::vector<double> v;
  std::stringstream ss(s);
  for (std::string x; std::getline(ss, x, ';');) v.push_back(std::stod(x));
  return v;
}

std::string printed(const CompareResult& r, const CompareOptions& opt) {
  const std::string path = ::testing::TempDir() + "summary.txt";
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return "";
  print_comparison(r, opt, f);
  std::fclose(f);
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// With 5 repetitions a side no p is below 2/252: one scheme's 8 cells cannot pass the correction
// over 136 cells, and the summary says so and how many repetitions would.
TEST(Compare, SummaryNamesTheCorrectionAndWarnsWhenTheRepetitionsCannotReachIt) {
  const CsvTable base = read_csv(suite_csv("r_base.csv", 17, 5, 1.0, 5));
  const CompareOptions opt;
  const CompareResult r = compare_runs(base, read_csv(suite_csv("r_slow.csv", 17, 5, 1.0, 6, "scheme5", 0.8)), opt);
  EXPECT_NEAR(r.min_attainable_p, 2.0 / 252.0, 1e-12);
  EXPECT_EQ(r.slower, 0u);
  const std::string text = printed(r, opt);
  EXPECT_NE(text.find("Benjamini-Hochberg over 136 tested cells"), std::string::npos) << text;
  EXPECT_NE(text.find("at least 10% (--min-effect)"), std::string::npos) << text;
  EXPECT_NE(text.find("use --reps 8 or more"), std::string::npos) << text;
  EXPECT_EQ(text.find("warning:"), std::string::npos) << text;
  // A busy machine: every cell of the new run 20% faster or slower at random (two runs of one
  // binary on this shared VM under load scattered by ~20%, README): verdicts withheld, and the
  // regression gate fails (it cannot show that nothing regressed).
  std::mt19937 rng(8);
  CsvTable busy_csv = base;
  for (auto& row : busy_csv.rows) {
    const double f = rng() % 2 ? 1.2 : 0.8;
    std::string samples;
    for (double v : parse_test_samples(row[5])) {
      if (!samples.empty()) samples += ';';
      samples += std::to_string(v * f);
    }
    row[4] = std::to_string(std::stod(row[4]) * f), row[5] = samples;
  }
  CompareOptions gate;
  gate.fail_on_regression_pct = 15;
  const CompareResult busy = compare_runs(base, busy_csv, gate);
  EXPECT_TRUE(busy.noisy);
  EXPECT_NEAR(busy.scatter_pct, 20, 3);
  EXPECT_EQ(busy.faster + busy.slower, 0u);
  EXPECT_EQ(busy.withheld, busy.cells.size());
  EXPECT_TRUE(busy.failed);
  EXPECT_NE(printed(busy, gate).find("so no cell gets a verdict (136 would have: 'noise')"), std::string::npos)
      << printed(busy, gate);
  // 9 repetitions can: the changed scheme's 8 cells are marked.
  const CsvTable b9 = read_csv(suite_csv("r9_base.csv", 17, 9, 1.0, 5));
  EXPECT_EQ(compare_runs(b9, read_csv(suite_csv("r9_slow.csv", 17, 9, 1.0, 6, "scheme5", 0.8)), opt).slower, 8u);
}

// ---------------------------------------------------------------------------------------------
// Bad input: values that are not speeds or accuracies, options out of range, nothing to compare,
// an output that cannot be written.

// Runs `fn` in a child process under a 20-second alarm and returns what it wrote to `out`, or
// "<killed by signal N>": a hang (a NaN sample stopped the old tie loop for ever) fails the test
// instead of stalling the suite.
std::string in_child(const std::function<void(std::string& out)>& fn) {
  int fds[2];
  if (pipe(fds) != 0) return "<pipe failed>";
  const pid_t pid = fork();
  if (pid == 0) {
    close(fds[0]);
    alarm(20);
    std::string out;
    fn(out);
    for (size_t off = 0; off < out.size();) {
      const ssize_t n = write(fds[1], out.data() + off, out.size() - off);
      if (n <= 0) break;
      off += size_t(n);
    }
    _exit(0);
  }
  close(fds[1]);
  std::string got;
  char buf[4096];
  for (ssize_t n; (n = read(fds[0], buf, sizeof buf)) > 0;) got.append(buf, size_t(n));
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (WIFSIGNALED(status)) return "<killed by signal " + std::to_string(WTERMSIG(status)) + ">";
  return got;
}

// The InputError compare_runs throws for these two files, "" when none.
std::string compare_error(const std::string& base, const std::string& next, const CompareOptions& opt = {}) {
  return in_child([&](std::string& out) {
    try {
      compare_runs(read_csv(base), read_csv(next), opt);
    } catch (const InputError& e) {
      out = e.what();
    }
  });
}

TEST(MannWhitney, NonFiniteSamplesHaveNoRankAndNeverHang) {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const std::string r = in_child([&](std::string& out) {
    for (const auto& a : std::vector<std::vector<double>>{{nan, 1}, {1, nan, 2, 3}, {inf, 1}, {nan, nan}})
      out += mann_whitney_p(a, {2, 3}).has_value() ? "p " : "none ";
  });
  EXPECT_EQ(r, "none none none none ");
}

TEST(Compare, ValuesThatAreNotSpeedsOrAccuraciesNameFileRowAndColumn) {
  const std::string head = "scene,workload,scheme,rays,mrays_median,mrays_samples,mismatch_rate,false_miss\n";
  const std::string good_row = "room,primary,bvh_single,4096,10,10;10.1;9.9,0,0\n";
  const auto good = write_file("good.csv", head + good_row);
  struct Case {
    std::string row;
    std::vector<std::string> needles;
  };
  const std::vector<Case> cases = {
      {"room,primary,bvh_single,4096,10,10;nan;9.9,0,0", {"mrays_samples", "'nan'"}},
      {"room,primary,bvh_single,4096,10,10;;9.9,0,0", {"mrays_samples", "empty sample"}},
      {"room,primary,bvh_single,4096,10,10;9.9;,0,0", {"mrays_samples", "empty sample"}},
      {"room,primary,bvh_single,4096,10,;10,0,0", {"mrays_samples", "empty sample"}},
      {"room,primary,bvh_single,4096,10,10;inf;9.9,0,0", {"mrays_samples", "'inf'"}},
      {"room,primary,bvh_single,4096,10,10;-1;9.9,0,0", {"mrays_samples", "'-1'"}},
      {"room,primary,bvh_single,4096,10,10;0;9.9,0,0", {"mrays_samples", "'0'"}},
      {"room,primary,bvh_single,4096,10,10;9.9x,0,0", {"mrays_samples", "'9.9x'"}},
      {"room,primary,bvh_single,4096,nan,10;10.1;9.9,0,0", {"mrays_median", "'nan'"}},
      {"room,primary,bvh_single,4096,-10,10;10.1;9.9,0,0", {"mrays_median", "'-10'"}},
      {"room,primary,bvh_single,4096,0,10;10.1;9.9,0,0", {"mrays_median", "'0'"}},
      {"room,primary,bvh_single,4096,1e999,10;10.1;9.9,0,0", {"mrays_median", "'1e999'"}},
      {"room,primary,bvh_single,4096,10,10;10.1;9.9,nan,0", {"mismatch_rate", "'nan'"}},
      {"room,primary,bvh_single,4096,10,10;10.1;9.9,-0.5,0", {"mismatch_rate", "'-0.5'"}},
      {"room,primary,bvh_single,4096,10,10;10.1;9.9,1.5,0", {"mismatch_rate", "'1.5'"}},
      {"room,primary,bvh_single,4096,10,10;10.1;9.9,0,-1", {"false_miss", "'-1'"}},
      // A ray count that is no count, and a median that is not its samples' (the U test ran on them).
      {"room,primary,bvh_single,-1,10,10;10.1;9.9,0,0", {"rays", "'-1'", "whole number"}},
      {"room,primary,bvh_single,40.5,10,10;10.1;9.9,0,0", {"rays", "'40.5'"}},
      {"room,primary,bvh_single,inf,10,10;10.1;9.9,0,0", {"rays", "'inf'"}},
      {"room,primary,bvh_single,4096,4.44,1e308;1e308;1e308,0,0", {"mrays_median 4.44", "not the median", "1e+308"}},
      {"room,primary,bvh_single,4096,10,10;12;12,0,0", {"mrays_median 10", "not the median"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.row);
    const auto bad = write_file("bad.csv", head + c.row + "\n");
    for (const bool bad_is_base : {true, false}) {
      const std::string e = bad_is_base ? compare_error(bad, good) : compare_error(good, bad);
      for (const std::string& n : c.needles) EXPECT_NE(e.find(n), std::string::npos) << "'" << n << "' in: " << e;
      EXPECT_NE(e.find(bad + ": row 2 (room / primary / bvh_single): "), std::string::npos) << e;
    }
  }
  // A cell without rays timed nothing: run writes 0 for it, which is no error.
  const std::string none_head = "scene,workload,scheme,rays,mrays_median,mrays_samples\n";
  const auto none = write_file("norays.csv", none_head + "sphere,bounce:2,bvh_single,0,0,0;0;0\n");
  EXPECT_EQ(compare_error(none, none), "");
}

TEST(Compare, OptionsOutOfRangeAndNaNAreRefused) {
  const auto csv = write_file("opt.csv", "scene,workload,scheme,mrays_median,mrays_samples\nroom,primary,bvh_single,10,"
                                         "10;10.1;9.9\n");
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(compare_error(csv, csv), "");
  for (double v : {nan, 0.0, 1.0, -0.1, inf}) {
    CompareOptions o;
    o.alpha = v;
    EXPECT_NE(compare_error(csv, csv, o).find("--alpha"), std::string::npos) << v;
  }
  for (double v : {nan, -1.0, 100.5, inf}) {
    CompareOptions o;
    o.min_effect_pct = v;
    EXPECT_NE(compare_error(csv, csv, o).find("--min-effect"), std::string::npos) << v;
  }
  for (double v : {nan, 100.5, inf, -inf}) {
    CompareOptions o;
    o.fail_on_regression_pct = v;
    EXPECT_NE(compare_error(csv, csv, o).find("--fail-on-regression"), std::string::npos) << v;
  }
  CompareOptions off;  // the default -1: no gate
  off.fail_on_regression_pct = -1;
  EXPECT_EQ(compare_error(csv, csv, off), "");
}

TEST(Compare, CsvsWithoutACommonCellAreAnError) {
  const std::string head = "scene,workload,scheme,mrays_median\n";
  const auto a = write_file("cell_a.csv", head + "room,primary,bvh_single,10\n");
  const auto b = write_file("cell_b.csv", head + "room,primary,kd_single,10\n");
  const std::string e = compare_error(a, b);
  for (const std::string& n : std::vector<std::string>{a, b, "share no cell",
                                                        "1 cells only in base (first: room / primary / bvh_single)",
                                                        "1 only in new (first: room / primary / kd_single)"})
    EXPECT_NE(e.find(n), std::string::npos) << "'" << n << "' in: " << e;
  EXPECT_NE(compare_error(write_file("empty.csv", head), a).find("share no cell"), std::string::npos);
}

// The output goes to a temporary file renamed over the path: a FIFO (or, as root, a device such as
// /dev/full) there was replaced by a regular file and the write reported done.
TEST(Compare, CsvOutputThatIsNotARegularFileIsAnError) {
  const auto dir = test::temp_dir("compare_fifo");
  const std::string fifo = (dir / "cmp.csv").string();
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  Record r;
  r.set("a", 1);
  try {
    write_csv(fifo, {r});
    ADD_FAILURE() << "no error for a FIFO";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("'" + fifo + "' is a FIFO"), std::string::npos) << e.what();
  }
  struct stat st;
  ASSERT_EQ(stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced";
  EXPECT_FALSE(std::filesystem::exists(dir / "cmp.csv.tmp"));
  std::filesystem::remove_all(dir);
}

// The same through the binary, which must never hang on them: one error line, exit 2 (the
// comparison itself is printed before --csv is written).
TEST(Compare, CommandRefusesBadValuesOptionsAndOutputs) {
  const auto dir = test::temp_dir("compare_cli");
  auto file = [&](const std::string& name, const std::string& text) {
    const std::string p = (dir / name).string();
    std::ofstream(p) << text;
    return p;
  };
  const std::string head = "scene,workload,scheme,mrays_median,mrays_samples\n";
  const auto base = file("base.csv", head + "room,primary,bvh_single,10,10;10.1;9.9;10.2;9.8\n");
  const auto slow = file("slow.csv", head + "room,primary,bvh_single,5,5;5.1;4.9;5.2;4.8\n");
  const auto nan = file("nan.csv", head + "room,primary,bvh_single,10,2.9;nan;2.6\n");
  const auto other = file("other.csv", head + "room,primary,kd_single,10,10;10.1;9.9;10.2;9.8\n");
  const std::string err_file = (dir / "stderr.txt").string();
  auto travbench = [&](const std::string& args) {  // exit status and stderr
    const std::string cmd =
        "timeout 60 " + std::string(TRAVBENCH_BINARY) + " compare " + args + " </dev/null >/dev/null 2>" + err_file;
    const int status = std::system(cmd.c_str());
    std::ifstream ef(err_file);
    const std::string err((std::istreambuf_iterator<char>(ef)), std::istreambuf_iterator<char>());
    return std::make_pair(WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), err);
  };
  const std::string fifo = (dir / "out.csv").string();
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {base + " " + nan, {nan + ": row 2 (room / primary / bvh_single): mrays_samples: 'nan'"}},
      {base + " " + slow + " --alpha nan", {"--alpha nan"}},
      {base + " " + slow + " --min-effect nan", {"--min-effect nan"}},
      {base + " " + slow + " --fail-on-regression nan", {"--fail-on-regression nan"}},
      {base + " " + other + " --fail-on-regression 5", {"share no cell"}},
      {base + " " + base + " --csv " + fifo, {"'" + fifo + "' is a FIFO"}},
  };
  for (const auto& [args, needles] : cases) {
    SCOPED_TRACE(args);
    const auto [code, out] = travbench(args);
    EXPECT_EQ(code, 2) << out;
    EXPECT_EQ(out.rfind("travbench: error: ", 0), 0u) << out;
    EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
    for (const auto& n : needles) EXPECT_NE(out.find(n), std::string::npos) << "'" << n << "' in: " << out;
  }
  struct stat st;
  ASSERT_EQ(stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced";
  EXPECT_EQ(travbench(base + " " + slow + " --fail-on-regression 10").first, 3) << "a real regression still fails";
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tb
