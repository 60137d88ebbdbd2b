// A table's row names the scheme entry it ran, with the parameters it ran with: `raygrid` and
// `raygrid:queue=64` are two rows of their own, and the entry's scheme still picks the thesis'
// layout and rows (harness/table_raygrid.cpp, table_bounce.cpp, table_cache.cpp, tables.cpp's
// accuracy table; the bandwidth table in test_table_bandwidth.cpp). Before, the raygrid, cache and
// accuracy tables labelled such rows by the scheme's name, with the entry's parameters missing from
// `params`, an entry lost the thesis' layout, and the cache table ran RayGrid's rows whatever
// --schemes said.
#include <gtest/gtest.h>

#include <set>

#include "harness/compare.h"
#include "harness/tables.h"
#include "test_util.h"

namespace tb {
namespace {

CsvTable run_small_table(const std::string& table, const std::string& scene, std::vector<std::string> schemes,
                         uint32_t side, const std::filesystem::path& dir) {
  TableOptions opt;
  opt.scene = scene;
  opt.csv = (dir / (table + ".csv")).string();
  opt.run.schemes = std::move(schemes);
  opt.run.width = opt.run.height = side;
  opt.width_given = opt.height_given = true;
  opt.run.reps = 1;
  opt.run.progress = false;
  EXPECT_EQ(run_table(table, opt), 0);
  return read_csv(opt.csv);
}

// The rows of `t` whose `scheme` column is `entry`, as (params, layout) pairs.
std::set<std::pair<std::string, std::string>> rows_of(const CsvTable& t, const std::string& entry) {
  const int scheme = t.column("scheme"), params = t.column("params"), layout = t.column("layout");
  std::set<std::pair<std::string, std::string>> s;
  for (size_t i = 0; i < t.rows.size(); ++i)
    if (t.at(i, scheme) == entry) s.insert({t.at(i, params), layout >= 0 ? t.at(i, layout) : ""});
  return s;
}

TEST(TableLabels, EntriesWithParametersAreRowsOfTheirOwn) {
  const auto dir = test::temp_dir("table_labels");
  // Table 9 (raygrid: four bounces per entry) and Table 7 (bounce): both entries in the thesis'
  // 4-wide layout, each with its own M or stream length, and the thesis' row of their scheme.
  struct Case {
    const char* table;
    std::string plain, entry, plain_params, entry_params;
  };
  for (const Case& c : {Case{"raygrid", "raygrid", "raygrid:queue=64", "queue=384;task_order=sum;width=4",
                             "queue=64;task_order=sum;width=4"},
                        Case{"bounce", "mbvh_rs", "mbvh_rs:stream=512", "sort=none;stream=256;task_order=sum;width=4",
                             "sort=none;stream=512;task_order=sum;width=4"}}) {
    SCOPED_TRACE(c.table);
    const CsvTable t = run_small_table(c.table, "room", {c.plain, c.entry}, 16, dir);
    const std::string kind = c.plain == "raygrid" ? "queue=" : "stream=";
    // The layout column spells the same settings: width, then M or the stream length (and the
    // streams' ray order, the batch's own), then the order of the children.
    auto layout = [&](const std::string& params) {
      const size_t at = params.find(kind);
      return "width=4 " + params.substr(at, params.find(';', at) - at) + (kind == "stream=" ? " sort=none" : "") +
             " task_order=sum";
    };
    using P = std::set<std::pair<std::string, std::string>>;
    EXPECT_EQ(rows_of(t, c.plain), (P{{c.plain_params, layout(c.plain_params)}}));
    EXPECT_EQ(rows_of(t, c.entry), (P{{c.entry_params, layout(c.entry_params)}}));
    const int ts = t.column("thesis_scheme");
    ASSERT_GE(ts, 0);
    for (size_t i = 0; i < t.rows.size(); ++i) EXPECT_EQ(t.at(i, ts), c.plain);
  }
  {
    // Table 11: the entry as given, and no RayGrid M rows when --schemes leaves raygrid out.
    const CsvTable t = run_small_table("cache", "room", {"mbvh8_single:order=sort"}, 16, dir);
    ASSERT_EQ(t.rows.size(), 1u);
    EXPECT_EQ(t.at(0, t.column("scheme")), "mbvh8_single:order=sort");
    EXPECT_EQ(t.at(0, t.column("params")), "order=sort");
  }
  {
    // The accuracy table: the entry as given; Embree's two variants carry their robust setting.
    const CsvTable t = run_small_table("accuracy", "sphere", {"mbvh8_single:order=sort", "embree_single"}, 16, dir);
    const int scheme = t.column("scheme"), kernel = t.column("kernel"), params = t.column("params");
    ASSERT_GE(params, 0);
    std::set<std::string> seen;
    for (size_t i = 0; i < t.rows.size(); ++i) {
      if (t.at(i, scheme) == "mbvh8_single:order=sort") {
        EXPECT_EQ(t.at(i, params), "order=sort");
      } else {
        ASSERT_EQ(t.at(i, scheme), "embree_single");
        EXPECT_EQ(t.at(i, params), t.at(i, kernel) == "embree_robust" ? "robust=1" : "robust=0") << t.at(i, kernel);
      }
      seen.insert(t.at(i, scheme));
    }
    EXPECT_EQ(seen, (std::set<std::string>{"mbvh8_single:order=sort", "embree_single"}));
  }
  {
    // Schemes with one triangle test of their own have rows too (they had none: no kernel
    // variants and not Embree's two), labelled with it.
    const CsvTable t = run_small_table("accuracy", "sphere", {"cwbvh_single", "treelet_queue"}, 16, dir);
    const int scheme = t.column("scheme"), kernel = t.column("kernel");
    std::set<std::string> seen;
    for (size_t i = 0; i < t.rows.size(); ++i) {
      EXPECT_EQ(t.at(i, kernel), "watertight");
      seen.insert(t.at(i, scheme));
    }
    EXPECT_EQ(seen, (std::set<std::string>{"cwbvh_single", "treelet_queue"}));
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tb
