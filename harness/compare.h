// `travbench compare BASE.csv NEW.csv`: is a change faster, or is that noise? (issue "For the
// researcher at the desk"). Cells of two run CSVs are matched by their identifying columns (scene,
// workload, scheme, kernel, view, threads, parameters, ... whichever both files carry); each
// matched cell gets the speed ratio NEW/BASE of the medians, a two-sided Mann-Whitney U test over
// the per-repetition samples (column `mrays_samples`, as Google Benchmark's compare.py tests its
// repetitions) and the change of every accuracy column (leaks, false hits, wrong_t, ...). Cells in
// only one file are listed, never dropped. Summary: geometric mean of the ratios.
#pragma once
#include <cstdio>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "harness/records.h"

namespace tb {

// A CSV as written by write_csv (RFC 4180), header first.
struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  int column(const std::string& name) const;  // -1 when absent
  const std::string& at(size_t row, int col) const;
};
CsvTable read_csv(const std::string& path);  // throws InputError naming the file and line

// Two-sided Mann-Whitney U test (Mann & Whitney 1947): the probability, under the hypothesis that
// both samples come from one distribution, of a U statistic at least as far from n1*n2/2 as the
// observed one. Exact (enumerating the null distribution by counting) when there are no ties and
// n1*n2 <= 400; otherwise the normal approximation with tie and continuity corrections, as SciPy's
// mannwhitneyu. Returns nullopt when a sample is empty.
std::optional<double> mann_whitney_p(const std::vector<double>& a, const std::vector<double>& b);

struct CompareOptions {
  double alpha = 0.05;  // significance level of the U test
  // >= 0: the comparison fails when a matched cell is slower by more than this many percent and
  // the slowdown is significant (or, without samples, by the ratio alone).
  double fail_on_regression_pct = -1;
};

struct CellComparison {
  std::string key;      // "scene / workload / scheme [kernel ...]" for display
  std::vector<std::pair<std::string, std::string>> id;  // the identifying columns
  double base = 0, next = 0, ratio = 0;  // Mrays/s medians and next / base
  std::optional<double> p;               // U-test p-value; nullopt without samples
  size_t base_samples = 0, next_samples = 0;
  std::string verdict;                   // faster | slower | same | n/a (not tested)
  std::vector<std::pair<std::string, double>> accuracy_delta;  // column -> next - base
  bool regression = false;
};

struct CompareResult {
  std::vector<CellComparison> cells;
  std::vector<std::string> only_base, only_next;  // unmatched cells
  double geomean_ratio = 0;
  size_t faster = 0, slower = 0, same = 0, untested = 0;
  bool failed = false;  // a regression beyond --fail-on-regression
};

CompareResult compare_runs(const CsvTable& base, const CsvTable& next, const CompareOptions& opt = {});
// Terminal view: one aligned line per cell, the unmatched cells, the summary line.
void print_comparison(const CompareResult& r, const CompareOptions& opt, FILE* out);
// One record per matched cell (and per unmatched cell, with `status`), for --csv.
std::vector<Record> comparison_records(const CompareResult& r);

}  // namespace tb
