// Bad input the harness reads back from its own earlier output: the CSV a `run --resume` keeps. It
// may not be trusted blindly: a kept row of another sweep, a cell twice, a nan speed or a CSV read
// under another header would end up in the finished CSV. (compare's CSVs and options:
// test_compare.cpp.)
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "harness/compare.h"  // read_csv
#include "harness/sweep.h"
#include "structures/scene.h"  // InputError
#include "test_util.h"

namespace fs = std::filesystem;

namespace tb {
namespace {

std::vector<std::string> lines_of(const std::string& path) {
  std::ifstream f(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(f, line);) lines.push_back(line);
  return lines;
}

void write_lines(const std::string& path, const std::vector<std::string>& lines) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  for (const auto& l : lines) f << l << "\n";
}

// The message of the InputError `fn` throws, "" when it throws none.
std::string error_of(const std::function<void()>& fn) {
  try {
    fn();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

// ---------------------------------------------------------------------------------------------
// run --resume

// A 4-cell sweep (2 workloads x 2 schemes) on the sphere, small enough to run in a moment.
class Resume : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::temp_dir(std::string("resume_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    csv_ = (dir_ / "r.csv").string();
    opt_.schemes = {"bvh_single", "mbvh8_single"};
    opt_.workloads = {"primary", "bounce:1"};
    opt_.width = opt_.height = 16;
    opt_.reps = 1;
    opt_.progress = false;
    run(false);
    full_ = lines_of(csv_);
    ASSERT_EQ(full_.size(), 5u) << "header + 4 cells";
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::vector<Record> run(bool resume) {
    return run_sweep(test::bench_for("sphere"), opt_, "sphere", csv_, resume);
  }
  // Refused with a message containing every needle, the CSV left as it was.
  void expect_refused(const std::vector<std::string>& lines, const std::vector<std::string>& needles) {
    write_lines(csv_, lines);
    const std::string e = error_of([&] { run(true); });
    EXPECT_NE(e, "") << "kept";
    for (const auto& n : needles) EXPECT_NE(e.find(n), std::string::npos) << "'" << n << "' in: " << e;
    EXPECT_EQ(lines_of(csv_), lines) << "the CSV changed";
  }
  // The cells (workload/scheme) of the CSV, in order.
  std::vector<std::string> cells() const {
    const CsvTable t = read_csv(csv_);
    std::vector<std::string> out;
    for (size_t r = 0; r < t.rows.size(); ++r)
      out.push_back(t.at(r, t.column("workload")) + "/" + t.at(r, t.column("scheme")));
    return out;
  }

  fs::path dir_;
  std::string csv_;
  RunOptions opt_;
  std::vector<std::string> full_;
};

std::string replaced(std::string line, const std::string& from, const std::string& to) {
  const size_t at = line.find(from);
  EXPECT_NE(at, std::string::npos) << from << " in " << line;
  return at == std::string::npos ? line : line.replace(at, from.size(), to);
}

// The value of column `col` of a CSV line (no quoted fields in a run CSV's first columns).
std::string with_field(const std::string& header, const std::string& line, const std::string& col,
                       const std::string& value) {
  std::vector<std::string> head, fields;
  std::stringstream hs(header), ls(line);
  for (std::string h; std::getline(hs, h, ',');) head.push_back(h);
  for (std::string v; std::getline(ls, v, ',');) fields.push_back(v);
  std::string out;
  for (size_t i = 0; i < fields.size(); ++i)
    out += (i ? "," : "") + (i < head.size() && head[i] == col ? value : fields[i]);
  return out + (line.back() == ',' ? "," : "");
}

TEST_F(Resume, RowsOfOtherCellsAreDroppedAndTheRestIsKept) {
  // The last cell lost (killed before it), a row of a scheme this sweep does not have, and one of
  // another view: only the sweep's own cells stay, the lost one is measured.
  std::vector<std::string> lines(full_.begin(), full_.end() - 1);
  lines.push_back(replaced(full_[1], ",bvh_single,", ",kd_single,"));
  lines.push_back(with_field(full_[0], full_[2], "view", "3"));
  write_lines(csv_, lines);
  ::testing::internal::CaptureStderr();
  const std::vector<Record> rows = run(true);
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("drops 2 row(s) that are no cell of this sweep (first: row 5 (primary / kd_single))"),
            std::string::npos)
      << err;
  EXPECT_EQ(rows.size(), 4u);
  const std::vector<std::string> got = cells();
  EXPECT_EQ(got.size(), 4u);
  for (const char* c : {"primary/bvh_single", "primary/mbvh8_single", "bounce:1/bvh_single", "bounce:1/mbvh8_single"})
    EXPECT_EQ(std::count(got.begin(), got.end(), c), 1) << c;
  const std::vector<std::string> now = lines_of(csv_);
  for (size_t i = 1; i < 4; ++i) EXPECT_EQ(now[i], full_[i]) << "kept row " << i << " as it was";
  // Nothing to measure, only rows to drop: the file loses them too.
  std::vector<std::string> extra = lines_of(csv_);
  extra.push_back(replaced(full_[1], ",bvh_single,", ",kd_single,"));
  write_lines(csv_, extra);
  run(true);
  EXPECT_EQ(lines_of(csv_).size(), 5u);
}

TEST_F(Resume, DuplicateCellsAreRefused) {
  std::vector<std::string> lines = full_;
  lines.push_back(full_[2]);
  expect_refused(lines, {csv_, "row 6 (", "is the cell of row 3 again"});
}

TEST_F(Resume, SpeedsThatAreNotSpeedsAreRefused) {
  for (const char* bad : {"nan", "-1", "inf", "x"}) {
    SCOPED_TRACE(bad);
    std::vector<std::string> lines = full_;
    lines[3] = with_field(full_[0], full_[3], "mrays_median", bad);
    expect_refused(lines, {csv_, "row 4 (", "mrays_median '" + std::string(bad) + "' is not a speed"});
  }
}

TEST_F(Resume, AnotherHeaderIsRefused) {
  std::vector<std::string> lines = full_;
  lines[0] = replaced(full_[0], "workload,scheme", "scheme,workload");
  expect_refused(lines, {csv_, "header", "column 3 is 'scheme', a run writes 'workload' there"});
  lines = full_;
  lines[0] = replaced(full_[0], ",params,", ",kernel,");
  expect_refused(lines, {csv_, "'kernel' appears twice"});
  // A header alone (killed before its first row, had that been possible) is checked too.
  expect_refused({"scene,workload"}, {"column 2 is 'workload', a run writes 'triangles' there"});
}

}  // namespace
}  // namespace tb
