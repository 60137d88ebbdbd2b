// Bad input the harness reads back from its own earlier output: the CSV a `run --resume` keeps and
// the converged-image cache of `table pathtrace`. Neither may be trusted blindly: a kept row of
// another sweep, a cell twice, a nan speed or a CSV read under another header would end up in the
// finished CSV; a damaged cache would size an allocation from its header or put a NaN into every
// rmse. (compare's CSVs and options: test_compare.cpp.)
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "harness/compare.h"  // read_csv
#include "harness/pathtrace.h"
#include "harness/sweep.h"
#include "harness/tables.h"
#include "structures/scene.h"  // InputError
#include "test_pathtrace_util.h"
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

// ---------------------------------------------------------------------------------------------
// The converged-image cache of `table pathtrace`

std::string bytes_of(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

std::string with_u32(std::string bytes, size_t at, uint32_t v) {
  std::memcpy(bytes.data() + at, &v, 4);
  return bytes;
}

std::string with_float(std::string bytes, size_t pixel_value, float v) {
  std::memcpy(bytes.data() + 16 + 4 * pixel_value, &v, 4);
  return bytes;
}

TEST(PtImageCache, LoadRefusesWhatTheFileDoesNotHold) {
  const auto dir = test::temp_dir("pt_cache_load");
  const std::string bin = (dir / "c.bin").string();
  save_pt_image(bin, PtImage{4, 2, std::vector<float>(24, 0.25f)});
  const std::string good = bytes_of(bin);
  PtImage img;
  std::string why = "x";
  ASSERT_TRUE(load_pt_image(bin, img, &why));
  EXPECT_EQ(why, "");
  EXPECT_EQ(img.width, 4u);
  EXPECT_EQ(img.rgb.size(), 24u);
  struct Case {
    std::string bytes, needle;
  };
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  const std::vector<Case> cases = {
      {with_u32(with_u32(good, 8, 0xFFFFFFFFu), 12, 0xFFFFFFFFu), "declares 4294967295x4294967295 pixels but holds 96"},
      {with_u32(with_u32(good, 8, 65536), 12, 65536), "declares 65536x65536 pixels"},
      {with_u32(good, 8, 0), "empty image"},
      {good.substr(0, good.size() - 4), "holds 92 bytes"},
      {good + "x", "holds 97 bytes"},
      {good.substr(0, 10), "no TBPTIMG1 header"},
      {"TBPTIMGX" + good.substr(8), "no TBPTIMG1 header"},
      {with_float(good, 5, nan), "pixel 1 holds nan"},
      {with_float(good, 23, inf), "pixel 7 holds inf"},
      {with_float(good, 0, -1e30f), "pixel 0 holds -"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_bytes(bin, c.bytes);
    PtImage out{1, 1, {1, 2, 3}};
    EXPECT_FALSE(load_pt_image(bin, out, &why));
    EXPECT_NE(why.find(c.needle), std::string::npos) << why;
    EXPECT_EQ(out.width, 1u) << "left as it was";
  }
  EXPECT_FALSE(load_pt_image((dir / "missing.bin").string(), img, &why));
  EXPECT_EQ(why, "") << "missing: a cache miss, not damage";
  fs::remove_all(dir);
}

// A damaged cache is a cache miss with a warning naming the file and what is wrong: the table
// renders the converged image again, replaces the cache and writes finite rmse columns.
TEST(PtImageCache, TableRendersADamagedCacheAgain) {
  const auto dir = test::temp_dir("pt_cache_table");
  TableOptions opt = test::small_pathtrace_table(
      (dir / "pt.csv").string(), {{"min_spp", "1"}, {"max_spp", "1"}, {"ref_spp", "2"}, {"seeds", "1"}});
  ASSERT_EQ(run_table("pathtrace", opt), 0);
  const std::string bin = (dir / "pt_converged.bin").string(), side = (dir / "pt_converged.json").string();
  const std::string good_bin = bytes_of(bin), good_side = bytes_of(side);
  const nlohmann::json meta = nlohmann::json::parse(good_side);
  auto side_with = [&](const nlohmann::json& residual) {
    nlohmann::json m = meta;
    m["residual_rmse"] = residual;
    return m.dump(2);
  };
  struct Case {
    std::string bin, side, needle;
  };
  const std::vector<Case> cases = {
      {with_u32(with_u32(good_bin, 8, 0xFFFFFFFFu), 12, 0xFFFFFFFFu), good_side, bin + ": declares 4294967295x4294967295"},
      {with_u32(with_u32(good_bin, 8, 65536), 12, 65536), good_side, bin + ": declares 65536x65536"},
      {with_u32(with_u32(good_bin, 8, 8), 12, 32), good_side, bin + ": 8x32, the table renders 16x16"},
      {with_float(good_bin, 7, std::numeric_limits<float>::quiet_NaN()), good_side, bin + ": pixel 2 holds nan"},
      {good_bin, side_with("x"), side + ": residual_rmse \"x\" is not an rmse"},
      {good_bin, side_with(-1e300), side + ": residual_rmse -1e+300 is not an rmse"},
      {good_bin, side_with(nullptr), side + ": residual_rmse is missing"},
      {good_bin, "[1, 2]", side + ": not a JSON object"},
      {good_bin, "{", side + ": not a JSON object"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.needle);
    write_bytes(bin, c.bin);
    write_bytes(side, c.side);
    ::testing::internal::CaptureStderr();
    std::string e;
    try {
      EXPECT_EQ(run_table("pathtrace", opt), 0);
    } catch (const std::exception& ex) {
      e = ex.what();
    }
    const std::string err = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(e, "") << "the table failed";
    EXPECT_NE(err.find("warning: converged-image cache " + c.needle), std::string::npos) << err;
    const CsvTable t = read_csv(opt.csv);
    for (const char* col : {"rmse", "rmse_corr", "converged_residual_rmse", "converged_mean"})
      for (size_t r = 0; r < t.rows.size(); ++r) {
        const double v = std::stod(t.at(r, t.column(col)));
        EXPECT_TRUE(std::isfinite(v) && v >= 0) << col << " " << t.at(r, t.column(col));
      }
    PtImage img;
    EXPECT_TRUE(load_pt_image(bin, img)) << "the cache was replaced";
    const nlohmann::json now = nlohmann::json::parse(bytes_of(side));
    EXPECT_TRUE(now["residual_rmse"].is_number() && now["residual_rmse"].get<double>() >= 0) << now.dump();
  }
  // A cache of other settings is a plain miss: rendered again without a warning.
  ::testing::internal::CaptureStderr();
  opt.run.scheme_config.params["ref_spp"] = "4";
  EXPECT_EQ(run_table("pathtrace", opt), 0);
  EXPECT_EQ(::testing::internal::GetCapturedStderr().find("warning"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tb
