// `travbench compare BASE.csv NEW.csv`: is a change faster, or is that noise? (issue "For the
// researcher at the desk"). Cells of two run CSVs are matched by their identifying columns (scene,
// workload, scheme, kernel, view, threads, parameters, ... whichever both files carry); each
// matched cell gets the speed ratio NEW/BASE of the medians, a two-sided Mann-Whitney U test over
// the per-repetition samples (column `mrays_samples`, as Google Benchmark's compare.py tests its
// repetitions) and the change of every accuracy column (leaks, false hits, wrong_t, ...). Cells in
// only one file are listed, never dropped. Summary: geometric mean of the ratios.
//
// Not crying wolf: with dozens of cells a per-cell p < alpha flags about alpha of them on identical
// binaries by chance, and run-to-run drift of a shared machine (a few percent, the same for every
// sample of one run, so not i.i.d.) makes every sample of one run faster than every sample of the
// other, which the U test calls significant. So a cell is "faster" or "slower" only when both hold:
// its p-value survives the Benjamini-Hochberg correction over all tested cells (q < alpha), and
// its ratio differs from 1 by at least --min-effect percent (README, "compare").
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
  std::string path;  // the file it was read from (messages name it); empty when built in memory
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  int column(const std::string& name) const;  // -1 when absent
  const std::string& at(size_t row, int col) const;
};
CsvTable read_csv(const std::string& path);  // throws InputError naming the file and line

// The whole text as a double (std::stod alone takes "2.9x" as 2.9); nullopt otherwise. Takes nan and
// inf: the caller says which values its column allows.
std::optional<double> parse_number(const std::string& text);
// Whether `text` is a speed as a run row writes it (Mrays/s): a finite number > 0, or 0 in a row
// without rays (nothing was timed). `compare` and `run --resume` check speeds by it.
bool is_speed(const std::string& text, bool no_rays);
// The accuracy columns of a run row, and whether `text` is a value of `column` as a run writes it:
// a count (finite, >= 0), or for mismatch_rate a rate in [0, 1]. `compare` and every --resume
// check them by it; accuracy_value_kind says what the column holds, for a message.
inline constexpr const char* kAccuracyColumns[] = {"mismatch_rate", "false_miss", "false_hit", "wrong_t", "ambiguous"};
bool is_accuracy_value(const std::string& text, const std::string& column);
std::string accuracy_value_kind(const std::string& column);

// Two-sided Mann-Whitney U test (Mann & Whitney 1947): the probability, under the hypothesis that
// both samples come from one distribution, of a U statistic at least as far from n1*n2/2 as the
// observed one. Exact (enumerating the null distribution by counting) when there are no ties and
// n1*n2 <= 400; otherwise the normal approximation with tie and continuity corrections, as SciPy's
// mannwhitneyu. Returns nullopt when a sample is empty or holds a value that is not finite (NaN has
// no rank; compare_runs refuses such samples where it parses them).
std::optional<double> mann_whitney_p(const std::vector<double>& a, const std::vector<double>& b);

// Benjamini-Hochberg adjusted p-values (q-values, Benjamini & Hochberg 1995): q_(i) =
// min over j >= i of p_(j) * m / j for the ascending p_(1..m), capped at 1; q < alpha keeps the
// expected share of false discoveries below alpha (and, when no cell changed, the chance of any).
std::vector<double> benjamini_hochberg(const std::vector<double>& p);

// The default --min-effect in percent: above the largest drift measured between two runs of the
// same binary on this machine (README, "compare").
inline constexpr double kDefaultMinEffectPct = 10.0;

// Below this many matched cells the scatter is not taken as the runs' noise (CompareResult).
inline constexpr size_t kMinCellsForNoise = 10;

struct CompareOptions {
  double alpha = 0.05;  // false discovery rate of the corrected U tests
  double min_effect_pct = kDefaultMinEffectPct;  // |ratio - 1| a verdict needs, percent
  // >= 0: the comparison fails when a matched cell is slower by more than this many percent and
  // the slowdown is significant (or, without samples, by the ratio alone, or the runs too noisy to
  // judge it: verdict "noise").
  double fail_on_regression_pct = -1;
};

struct CellComparison {
  std::string key;      // "scene / workload / scheme [kernel ...]" for display
  std::vector<std::pair<std::string, std::string>> id;  // the identifying columns
  double base = 0, next = 0, ratio = 0;  // Mrays/s medians and next / base
  std::optional<double> p;               // U-test p-value; nullopt without samples
  std::optional<double> q;               // p adjusted by Benjamini-Hochberg over the tested cells
  size_t base_samples = 0, next_samples = 0;
  std::string verdict;                   // faster | slower | same | noise | n/a (not tested) | no rays
  std::vector<std::pair<std::string, double>> accuracy_delta;  // column -> next - base
  bool regression = false;
};

struct CompareResult {
  std::vector<CellComparison> cells;
  std::vector<std::string> only_base, only_next;  // unmatched cells
  double geomean_ratio = 0;
  size_t faster = 0, slower = 0, same = 0, untested = 0;
  // The smallest p-value the tested cells' sample sizes allow (exact U null: 2 / C(n1+n2, n1)):
  // above alpha / tested, not even one changed cell alone could pass the correction.
  double min_attainable_p = 0;
  // How far the cells scatter around the common change: the median over the matched cells of
  // |ratio / geomean_ratio - 1|, percent. A change of the code moves the cells it touches and
  // leaves the rest; a busy machine scatters every cell (two runs of one binary on the shared
  // 2-core VM under load: ~20%, README). At half of --min-effect or more (`noisy`) unchanged
  // cells cross the threshold, so no cell gets a verdict: those that would are "noise".
  double scatter_pct = 0;
  bool noisy = false;
  size_t withheld = 0;  // cells with q < alpha and the effect, but within the runs' scatter
  bool failed = false;  // a regression beyond --fail-on-regression
};

// Throws InputError for options out of range (NaN included), a value that is not a speed or an
// accuracy (naming the file, the row's cell and the column) and for two CSVs that share no cell.
CompareResult compare_runs(const CsvTable& base, const CsvTable& next, const CompareOptions& opt = {});
// Terminal view: one aligned line per cell, the unmatched cells, the summary line.
void print_comparison(const CompareResult& r, const CompareOptions& opt, FILE* out);
// One record per matched cell (and per unmatched cell, with `status`), for --csv.
std::vector<Record> comparison_records(const CompareResult& r);

}  // namespace tb
