#include "harness/compare.h"

#include <csv.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>

#include "harness/trace_runner.h"  // median_of
#include "structures/scene.h"  // InputError

namespace tb {

// ---------------------------------------------------------------------------------------------
// CSV input through libcsv (RFC 4180: quoted fields, doubled quotes, embedded commas).

int CsvTable::column(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return int(i);
  return -1;
}

const std::string& CsvTable::at(size_t row, int col) const {
  static const std::string empty;
  if (col < 0 || size_t(col) >= rows[row].size()) return empty;
  return rows[row][size_t(col)];
}

namespace {

struct CsvSink {
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> cur;
};

void on_field(void* s, size_t len, void* data) {
  static_cast<CsvSink*>(data)->cur.emplace_back(static_cast<const char*>(s), len);
}
void on_row(int, void* data) {
  auto* sink = static_cast<CsvSink*>(data);
  sink->rows.push_back(std::move(sink->cur));
  sink->cur.clear();
}

}  // namespace

CsvTable read_csv(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open");
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string text = ss.str();
  csv_parser p;
  if (csv_init(&p, CSV_STRICT | CSV_APPEND_NULL | CSV_STRICT_FINI) != 0) throw InputError(path + ": csv_init failed");
  CsvSink sink;
  const size_t used = csv_parse(&p, text.data(), text.size(), on_field, on_row, &sink);
  const bool ok = used == text.size() && csv_fini(&p, on_field, on_row, &sink) == 0;
  const std::string err = ok ? "" : csv_strerror(csv_error(&p));
  csv_free(&p);
  if (!ok) throw InputError(path + ": not a valid CSV (" + err + " after " + std::to_string(sink.rows.size()) + " rows)");
  if (sink.rows.empty()) throw InputError(path + ": empty CSV (no header)");
  CsvTable t;
  t.path = path;
  t.header = std::move(sink.rows.front());
  for (size_t i = 1; i < sink.rows.size(); ++i) {
    if (sink.rows[i].size() != t.header.size())
      throw InputError(path + ": row " + std::to_string(i + 1) + " has " + std::to_string(sink.rows[i].size()) +
                       " fields, the header " + std::to_string(t.header.size()));
    t.rows.push_back(std::move(sink.rows[i]));
  }
  return t;
}

std::optional<double> parse_number(const std::string& text) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size() && !std::isspace(static_cast<unsigned char>(text.front()))) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

// A cell without rays (bounce:k after every ray escaped) timed nothing: `run` writes 0 for it.
bool is_speed(const std::string& text, bool no_rays) {
  const std::optional<double> v = parse_number(text);
  return v && std::isfinite(*v) && (*v > 0 || (*v == 0 && no_rays));
}

bool is_accuracy_value(const std::string& text, const std::string& column) {
  const std::optional<double> v = parse_number(text);
  return v && std::isfinite(*v) && *v >= 0 && (column != "mismatch_rate" || *v <= 1);
}
std::string accuracy_value_kind(const std::string& column) {
  return column == "mismatch_rate" ? "a rate (a finite number in [0, 1])" : "a count (a finite number >= 0)";
}

// ---------------------------------------------------------------------------------------------
// Mann-Whitney U

std::optional<double> mann_whitney_p(const std::vector<double>& a, const std::vector<double>& b) {
  const size_t n1 = a.size(), n2 = b.size();
  if (n1 == 0 || n2 == 0) return std::nullopt;
  for (const auto* s : {&a, &b})
    for (double x : *s)
      if (!std::isfinite(x)) return std::nullopt;  // no rank: the sort below needs a strict weak order
  // U of sample a: pairs where a wins, ties count one half.
  double u = 0;
  bool ties = false;
  for (double x : a)
    for (double y : b) {
      if (x > y) u += 1;
      else if (x == y) u += 0.5, ties = true;
    }
  // Ties inside a sample matter for the variance too.
  std::vector<double> all(a);
  all.insert(all.end(), b.begin(), b.end());
  std::sort(all.begin(), all.end());
  double tie_term = 0;
  for (size_t i = 0; i < all.size();) {
    size_t j = i + 1;  // always past i: a value unequal to itself (NaN) must not stop the walk
    while (j < all.size() && all[j] == all[i]) ++j;
    const double t = double(j - i);
    if (t > 1) ties = true, tie_term += t * t * t - t;
    i = j;
  }
  const size_t cells = n1 * n2;
  if (!ties && cells <= 400) {
    // Null distribution of U by counting: f(n1, n2, u) = f(n1 - 1, n2, u - n2) + f(n1, n2 - 1, u)
    // (the largest observation belongs to one sample or the other), over all n1 + n2 choose n1
    // equally likely rank assignments.
    std::vector<std::vector<double>> f(n2 + 1);  // f[j][u] for the current i
    for (size_t j = 0; j <= n2; ++j) f[j].assign(1, 1.0);  // i = 0: U = 0 in one way
    for (size_t i = 1; i <= n1; ++i) {
      std::vector<std::vector<double>> g(n2 + 1);
      g[0].assign(1, 1.0);  // j = 0: U = 0 in one way
      for (size_t j = 1; j <= n2; ++j) {
        g[j].assign(i * j + 1, 0.0);
        for (size_t k = 0; k < f[j].size(); ++k) g[j][k + j] += f[j][k];  // largest is in a: +j
        for (size_t k = 0; k < g[j - 1].size(); ++k) g[j][k] += g[j - 1][k];
      }
      f = std::move(g);
    }
    const std::vector<double>& dist = f[n2];
    double total = 0;
    for (double c : dist) total += c;
    const size_t uu = size_t(u);
    double lo = 0, hi = 0;
    for (size_t k = 0; k < dist.size(); ++k) {
      if (k <= uu) lo += dist[k];
      if (k >= uu) hi += dist[k];
    }
    return std::min(1.0, 2.0 * std::min(lo, hi) / total);
  }
  const double n = double(n1 + n2);
  const double mu = double(cells) / 2.0;
  const double var = double(cells) / 12.0 * ((n + 1.0) - tie_term / (n * (n - 1.0)));
  if (!(var > 0)) return 1.0;  // every observation equal
  const double z = std::max(0.0, std::fabs(u - mu) - 0.5) / std::sqrt(var);
  return std::min(1.0, std::erfc(z / std::sqrt(2.0)));
}

std::vector<double> benjamini_hochberg(const std::vector<double>& p) {
  const size_t m = p.size();
  std::vector<size_t> order(m);
  for (size_t i = 0; i < m; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return p[a] < p[b]; });
  std::vector<double> q(m);
  double running = 1.0;  // the minimum over j >= i, walking down from the largest p
  for (size_t r = m; r-- > 0;) {
    running = std::min(running, p[order[r]] * double(m) / double(r + 1));
    q[order[r]] = std::min(1.0, running);
  }
  return q;
}

// ---------------------------------------------------------------------------------------------
// Matching and comparing cells

namespace {

// Columns that identify a cell when both files carry them (the run, table and trace CSVs).
const char* const kIdColumns[] = {"scene", "workload", "scheme", "kernel", "params", "layout", "view",
                                  "threads", "width", "height", "row", "table", "rays_file"};

// Where a value sits, for its message: "<file>: row N (scene / workload / scheme)", N the line in
// the file (the header is line 1).
std::string where(const CsvTable& t, size_t row) {
  std::string cell;
  for (const char* c : {"scene", "workload", "scheme"})
    if (const std::string& v = t.at(row, t.column(c)); !v.empty()) cell += (cell.empty() ? "" : " / ") + v;
  return (t.path.empty() ? std::string("(csv)") : t.path) + ": row " + std::to_string(row + 2) +
         (cell.empty() ? "" : " (" + cell + ")");
}

double speed(const CsvTable& t, size_t row, const std::string& text, const std::string& col) {
  const bool no_rays = t.column("rays") >= 0 && t.at(row, t.column("rays")) == "0";
  if (is_speed(text, no_rays)) return *parse_number(text);
  throw InputError(where(t, row) + ": " + col + ": '" + text + "' is not a speed (Mrays/s: a finite number > 0" +
                   (no_rays ? ", or 0 for a cell without rays)" : ")"));
}

std::string shown(double v);

// A row's rays count, where it has the column: a whole number >= 0 (a negative or fractional
// count is a damaged row, and "0" is what marks a cell without rays for `speed`).
void check_rays(const CsvTable& t, size_t row) {
  const int col = t.column("rays");
  if (col < 0) return;
  const std::string& s = t.at(row, col);
  const std::optional<double> v = parse_number(s);
  if (!v || !std::isfinite(*v) || !(*v >= 0) || std::floor(*v) != *v)
    throw InputError(where(t, row) + ": rays: '" + s + "' is not a ray count (a whole number >= 0)");
}

// The samples are the repetitions the row's median was taken of: a median that is not theirs (to
// the 6 digits a CSV carries) is a damaged or edited row, and the U test would run on numbers the
// row does not report.
void check_samples_median(const CsvTable& t, size_t row, const std::vector<double>& samples, double median) {
  if (samples.empty()) return;
  const double m = median_of(samples);  // as `run` takes it (harness/trace_runner.h)
  if (!(std::fabs(m - median) <= 1e-4 * std::max(std::fabs(m), std::fabs(median))))
    throw InputError(where(t, row) + ": mrays_median " + shown(median) + " is not the median of its mrays_samples (" +
                     shown(m) + ")");
}

// The ';'-separated repetitions of mrays_samples; an empty field means the row has none.
std::vector<double> parse_samples(const CsvTable& t, size_t row, int col) {
  const std::string& s = t.at(row, col);
  std::vector<double> out;
  if (s.empty()) return out;
  // An empty sample ("2.9;;2.6", a trailing ';') is a damaged row, not a repetition to skip.
  if (s.back() == ';') throw InputError(where(t, row) + ": mrays_samples: '" + s + "' ends with an empty sample");
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ';');) {
    if (item.empty()) throw InputError(where(t, row) + ": mrays_samples: '" + s + "' has an empty sample");
    out.push_back(speed(t, row, item, "mrays_samples"));
  }
  return out;
}

double accuracy(const CsvTable& t, size_t row, int col, const std::string& name) {
  const std::string& s = t.at(row, col);
  if (is_accuracy_value(s, name)) return *parse_number(s);
  throw InputError(where(t, row) + ": " + name + ": '" + s + "' is not " + accuracy_value_kind(name));
}

std::string shown(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// CLI11's range checks let NaN through (every comparison with it is false), and a NaN here would
// pass any gate: a NaN --alpha or --min-effect makes every cell "same", a NaN
// --fail-on-regression turns the gate off. So compare checks its options where it uses them.
void check_options(const CompareOptions& o) {
  if (!(std::isfinite(o.alpha) && o.alpha > 0 && o.alpha < 1))
    throw InputError("compare: --alpha " + shown(o.alpha) + " is not a false discovery rate in (0, 1)");
  if (!(std::isfinite(o.min_effect_pct) && o.min_effect_pct >= 0 && o.min_effect_pct <= 100))
    throw InputError("compare: --min-effect " + shown(o.min_effect_pct) + " is not a percentage in [0, 100]");
  // Negative: no gate (the default). Above 100 no ratio could fall short of it.
  if (!(std::isfinite(o.fail_on_regression_pct) && o.fail_on_regression_pct <= 100))
    throw InputError("compare: --fail-on-regression " + shown(o.fail_on_regression_pct) +
                     " is not a percentage in [0, 100]");
}

struct Indexed {
  std::vector<std::string> order;
  std::map<std::string, size_t> row;
  std::map<std::string, std::vector<std::pair<std::string, std::string>>> id;
};

Indexed index(const CsvTable& t, const std::vector<std::string>& ids) {
  Indexed ix;
  for (size_t r = 0; r < t.rows.size(); ++r) {
    std::string key;
    std::vector<std::pair<std::string, std::string>> id;
    for (const auto& c : ids) {
      const std::string& v = t.at(r, t.column(c));
      id.emplace_back(c, v);
      if (!v.empty()) key += (key.empty() ? "" : " / ") + (c == "scene" || c == "workload" || c == "scheme" ? v : c + "=" + v);
    }
    // The same cell twice in one file (e.g. concatenated runs): keep both, numbered.
    for (int k = 2; ix.row.count(key); ++k) key = key.substr(0, key.rfind(" #")) + " #" + std::to_string(k);
    ix.order.push_back(key);
    ix.row[key] = r;
    ix.id[key] = std::move(id);
  }
  return ix;
}

}  // namespace

CompareResult compare_runs(const CsvTable& base, const CsvTable& next, const CompareOptions& opt) {
  check_options(opt);
  for (const CsvTable* t : {&base, &next})
    if (t->column("mrays_median") < 0) throw InputError("compare: a CSV has no mrays_median column (not a run CSV)");
  std::vector<std::string> ids;
  for (const char* c : kIdColumns)
    if (base.column(c) >= 0 && next.column(c) >= 0) ids.push_back(c);
  if (ids.empty()) throw InputError("compare: the CSVs share no identifying column (scene, workload, scheme, ...)");
  const Indexed bi = index(base, ids), ni = index(next, ids);
  CompareResult res;
  double log_sum = 0;
  size_t timed = 0;  // cells with rays on both sides: the ones a speed ratio describes
  for (const auto& key : bi.order) {
    auto it = ni.row.find(key);
    if (it == ni.row.end()) {
      res.only_base.push_back(key);
      continue;
    }
    const size_t br = bi.row.at(key), nr = it->second;
    CellComparison c;
    c.key = key;
    c.id = bi.id.at(key);
    check_rays(base, br);
    check_rays(next, nr);
    c.base = speed(base, br, base.at(br, base.column("mrays_median")), "mrays_median");
    c.next = speed(next, nr, next.at(nr, next.column("mrays_median")), "mrays_median");
    c.ratio = c.base > 0 ? c.next / c.base : 0;
    const int bs = base.column("mrays_samples"), ns = next.column("mrays_samples");
    if (bs >= 0 && ns >= 0) {
      const auto a = parse_samples(base, br, bs), b = parse_samples(next, nr, ns);
      check_samples_median(base, br, a, c.base);
      check_samples_median(next, nr, b, c.next);
      c.base_samples = a.size();
      c.next_samples = b.size();
      c.p = mann_whitney_p(b, a);
    }
    if (!c.p || c.base_samples < 2 || c.next_samples < 2) c.p.reset();  // too few to test
    // A cell without rays on either side (`run` writes speed 0 for it) timed nothing: no ratio,
    // no test, not in the geometric mean (its 0 counted in the mean's denominator only) nor the gate.
    if (c.base == 0 || c.next == 0) c.p.reset(), c.ratio = 0;
    for (const char* col : kAccuracyColumns) {
      const int bc = base.column(col), nc = next.column(col);
      if (bc < 0 && nc < 0) continue;
      const double bv = bc >= 0 && !base.at(br, bc).empty() ? accuracy(base, br, bc, col) : 0;
      const double nv = nc >= 0 && !next.at(nr, nc).empty() ? accuracy(next, nr, nc, col) : 0;
      c.accuracy_delta.emplace_back(col, nv - bv);
    }
    if (c.ratio > 0) log_sum += std::log(c.ratio), ++timed;
    res.cells.push_back(std::move(c));
  }
  for (const auto& key : ni.order)
    if (!bi.row.count(key)) res.only_next.push_back(key);
  if (res.cells.empty()) {
    // Nothing was compared: a summary of 0 cells (geometric mean 0.000x) and "ok" would pass a gate.
    auto first = [](const std::vector<std::string>& keys) {
      return keys.empty() ? std::string() : " (first: " + keys.front() + ")";
    };
    std::string on;
    for (const auto& c : ids) on += (on.empty() ? "" : ", ") + c;
    throw InputError("compare: " + (base.path.empty() ? std::string("base") : base.path) + " and " +
                     (next.path.empty() ? std::string("new") : next.path) + " share no cell, so nothing was compared: " +
                     std::to_string(res.only_base.size()) + " cells only in base" + first(res.only_base) + ", " +
                     std::to_string(res.only_next.size()) + " only in new" + first(res.only_next) +
                     "; cells match on " + on);
  }
  res.geomean_ratio = timed == 0 ? 0 : std::exp(log_sum / double(timed));
  std::vector<double> scatter;
  for (const auto& c : res.cells)
    if (res.geomean_ratio > 0 && c.ratio > 0) scatter.push_back(std::fabs(c.ratio / res.geomean_ratio - 1.0) * 100.0);
  if (!scatter.empty()) {
    std::nth_element(scatter.begin(), scatter.begin() + std::ptrdiff_t(scatter.size() / 2), scatter.end());
    res.scatter_pct = scatter[scatter.size() / 2];
  }
  // Only a median over many cells estimates the noise (most cells unchanged); a handful of cells,
  // one of them changed, would look "noisy" themselves.
  res.noisy = opt.min_effect_pct > 0 && scatter.size() >= kMinCellsForNoise &&
              res.scatter_pct >= opt.min_effect_pct / 2;
  // The correction runs over every tested cell of the comparison: the family is what one look at
  // the output can flag.
  std::vector<double> ps;
  for (const auto& c : res.cells)
    if (c.p) ps.push_back(*c.p);
  const std::vector<double> qs = benjamini_hochberg(ps);
  res.min_attainable_p = 1;
  size_t k = 0;
  for (auto& c : res.cells) {
    if (c.ratio == 0) {
      c.verdict = "no rays";
      res.untested++;
      continue;
    }
    if (!c.p) {
      c.verdict = "n/a";
      res.untested++;
    } else {
      c.q = qs[k++];
      // Fully separated samples of these sizes: the smallest p the test can give them.
      std::vector<double> lo(c.base_samples), hi(c.next_samples);
      for (size_t i = 0; i < lo.size(); ++i) lo[i] = double(i);
      for (size_t i = 0; i < hi.size(); ++i) hi[i] = double(lo.size() + i);
      res.min_attainable_p = std::min(res.min_attainable_p, *mann_whitney_p(hi, lo));
      const bool big = std::fabs(c.ratio - 1.0) * 100.0 >= opt.min_effect_pct;
      if (*c.q < opt.alpha && big && res.noisy) {
        c.verdict = "noise";
        res.withheld++;
      } else if (*c.q < opt.alpha && big) {
        c.verdict = c.ratio >= 1 ? "faster" : "slower";
        (c.ratio >= 1 ? res.faster : res.slower)++;
      } else {
        c.verdict = "same";
        res.same++;
      }
    }
    if (opt.fail_on_regression_pct >= 0 && c.ratio < 1.0 - opt.fail_on_regression_pct / 100.0)
      // A gate passes only what it could judge: no samples or too noisy a pair count too.
      c.regression = c.verdict == "n/a" || c.verdict == "slower" || c.verdict == "noise";
    res.failed = res.failed || c.regression;
  }
  return res;
}

void print_comparison(const CompareResult& r, const CompareOptions& opt, FILE* out) {
  size_t w = 4;
  for (const auto& c : r.cells) w = std::max(w, c.key.size());
  std::fprintf(out, "%-*s %10s %10s %7s %8s %8s  %-7s %s\n", int(w), "cell", "base", "new", "ratio", "p", "q",
               "verdict", "accuracy change (new - base)");
  for (const auto& c : r.cells) {
    char p[16] = "-", q[16] = "-";
    if (c.p) std::snprintf(p, sizeof p, "%.3g", *c.p);
    if (c.q) std::snprintf(q, sizeof q, "%.3g", *c.q);
    std::string acc;
    for (const auto& [col, d] : c.accuracy_delta)
      if (d != 0) {
        char buf[64];
        std::snprintf(buf, sizeof buf, "%s%s %+g", acc.empty() ? "" : ", ", col.c_str(), d);
        acc += buf;
      }
    std::fprintf(out, "%-*s %10.4g %10.4g %6.3fx %8s %8s  %-7s %s%s\n", int(w), c.key.c_str(), c.base, c.next, c.ratio,
                 p, q, c.verdict.c_str(), acc.empty() ? "-" : acc.c_str(), c.regression ? "  REGRESSION" : "");
  }
  for (const auto& k : r.only_base) std::fprintf(out, "only in base: %s\n", k.c_str());
  for (const auto& k : r.only_next) std::fprintf(out, "only in new:  %s\n", k.c_str());
  const size_t tested = r.cells.size() - r.untested;
  std::fprintf(out,
               "summary: %zu matched cells, geometric mean ratio %.3fx; %zu faster, %zu slower, %zu same, %zu noise, %zu "
               "without samples; %zu only in base, %zu only in new. A verdict needs q < %.3g (Mann-Whitney U, two-sided, "
               "Benjamini-Hochberg over %zu tested cells) and a change of at least %.3g%% (--min-effect)\n",
               r.cells.size(), r.geomean_ratio, r.faster, r.slower, r.same, r.withheld, r.untested, r.only_base.size(),
               r.only_next.size(), opt.alpha, tested, opt.min_effect_pct);
  if (r.noisy)
    std::fprintf(out,
                 "warning: the cells scatter by %.3g%% around the common change (median |ratio / geomean - 1|), at "
                 "least half of --min-effect %.3g%%: that is the noise of these two runs (a busy machine), so no "
                 "cell gets a verdict (%zu would have: 'noise'); re-run both on a quiet machine "
                 "(scripts/ab_compare.py interleaves runs)\n",
                 r.scatter_pct, opt.min_effect_pct, r.withheld);
  // A single changed cell passes the correction only with p <= alpha / tested; say so when the
  // repetitions cannot give that (5 a side: p >= 0.0079), and how many would.
  if (tested > 0 && r.min_attainable_p > opt.alpha / double(tested)) {
    size_t n = 2;
    double ways = 6;  // C(2n, n): the exact two-sided minimum with n a side is 2 / C(2n, n)
    while (n < 64 && 2.0 / ways > opt.alpha / double(tested)) {
      ways *= double(2 * n + 1) * double(2 * n + 2) / double((n + 1) * (n + 1));
      ++n;
    }
    std::fprintf(out,
                 "note: these samples give p >= %.2g, so one changed cell alone cannot pass the correction over %zu "
                 "cells (it needs p <= %.2g; a change shared by many cells can): use --reps %zu or more\n",
                 r.min_attainable_p, tested, opt.alpha / double(tested), n);
  }
  if (opt.fail_on_regression_pct >= 0)
    std::fprintf(out, "%s: %s regression beyond %.3g%%\n", r.failed ? "FAIL" : "ok", r.failed ? "a" : "no",
                 opt.fail_on_regression_pct);
}

std::vector<Record> comparison_records(const CompareResult& r) {
  std::vector<Record> out;
  for (const auto& c : r.cells) {
    Record rec;
    for (const auto& [k, v] : c.id) rec.set(k, v);
    rec.set("status", "matched").set("base_mrays", c.base).set("new_mrays", c.next).set("ratio", c.ratio);
    rec.set("p_value", c.p ? std::to_string(*c.p) : std::string());
    rec.set("q_value", c.q ? std::to_string(*c.q) : std::string());
    rec.set("base_samples", uint64_t(c.base_samples)).set("new_samples", uint64_t(c.next_samples));
    rec.set("verdict", c.verdict).set("regression", c.regression ? 1 : 0);
    for (const auto& [col, d] : c.accuracy_delta) rec.set("delta_" + col, d);
    out.push_back(std::move(rec));
  }
  for (const auto* list : {&r.only_base, &r.only_next})
    for (const auto& k : *list) {
      Record rec;
      rec.set("cell", k).set("status", list == &r.only_base ? "only_base" : "only_new");
      out.push_back(std::move(rec));
    }
  return out;
}

}  // namespace tb
