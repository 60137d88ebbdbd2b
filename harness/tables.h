// `travbench table NAME`: the thesis' experiments, each a tidy CSV (+ sidecar JSON) with the
// thesis' value in its own column where one exists, and a terminal table.
#pragma once
#include <string>
#include <vector>

#include "harness/experiment.h"

namespace tb {

struct TableOptions {
  std::string scene;  // empty: the table's default scene
  RunOptions run;     // run.schemes empty: the table's default scheme set
  std::string csv;
  // Whether --width / --height were given; when not, a table measured at a stated resolution
  // runs at the thesis' (divergence: 1280x800, §3.4).
  bool width_given = false, height_given = false;
  // Keep the cells an interrupted table of the same settings streamed into `csv` and measure only
  // the rest (harness/sweep.h); refused for the tables that do not stream cells (build, simt).
  bool resume = false;
  // The options given on the command line ("--threads", ...): run_table refuses those the table
  // has no use for (tables.def) rather than ignore them.
  std::vector<std::string> given;
};

std::vector<std::string> table_names();

// What the table functions (harness/table_*.cpp) share.
// How a table runs a scheme with its own triangle test (cwbvh_single, treelet_queue, Embree) when
// --kernel names another: `refuse` it (before the first cell), or `keep` its own test (the tables
// whose Embree rows are anchors beside the kernel under test).
enum class OwnTriangleTest { refuse, keep };
// The schemes a table measures: --schemes when given, else `fallback` (those registered), else all.
// Checks --param against them (check_run_params) and `table_params`, the table's own parameters,
// and every scheme's whole configuration (table_scheme_config, --kernel included) before the table
// measures anything; each scheme is then made with config_for(name, ...), so it sees only the keys
// it declares.
std::vector<std::string> default_schemes(const TableOptions& opt, std::vector<std::string> fallback = {},
                                         const ParamSpecs& table_params = {},
                                         OwnTriangleTest own = OwnTriangleTest::refuse);
// A table's own parameter `key` (one of the table_params given to default_schemes): its --param
// value, else its default.
std::string table_param(const TableOptions& opt, const ParamSpecs& table_params, const std::string& key);
// The configuration a table's cell makes scheme `entry` with: config_for, and the kernel rule above.
SchemeConfig table_scheme_config(const std::string& entry, const SchemeConfig& run_cfg, OwnTriangleTest own);
// The scene a table runs on: --scene, else the built-in room.
std::string table_scene(const TableOptions& opt);
// The sidecar fields of a table compared with the thesis: the command, the scene asked for, the
// thesis' scene it is compared with ("" for none) and the seed, then the table's own `extra`.
nlohmann::json thesis_table_meta(const std::string& table, const TableOptions& opt, const std::string& thesis_scene,
                                 const nlohmann::json& extra = nlohmann::json::object());
// A workload spec with the table's image size and seed.
WorkloadSpec table_spec(const TableOptions& opt, const std::string& workload, uint32_t view = 0);
// The thesis' layout for the stream schemes of Tables 7-10: mbvh_rs and raygrid default to 8-wide
// nodes (faster here, docs/PERFORMANCE.md) but the thesis measured 4-wide SSE nodes (and RayGrid
// queues of M = 384, §5.3.5, MBVH/RS streams of 256 rays, Table 8, children sorted by summed
// distance, Alg. 2.10); unless --param width is given, these tables pin that layout so their rows
// compare with the thesis' and with mbvh4_single. Returns the label for a "layout" column.
std::string thesis_layout(const std::string& scheme, SchemeConfig& cfg);
// A scheme variant of the accuracy table: a kernel for our schemes, robust or fast mode for Embree.
struct Variant {
  std::string label;
  SchemeConfig config;
};
int run_table(const std::string& name, const TableOptions& opt);

}  // namespace tb
