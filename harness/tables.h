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
};

std::vector<std::string> table_names();

// What the table functions (harness/table_*.cpp) share.
// The schemes a table measures: --schemes when given, else `fallback` (those registered), else all.
std::vector<std::string> default_schemes(const TableOptions& opt, std::vector<std::string> fallback = {});
// A workload spec with the table's image size and seed.
WorkloadSpec table_spec(const TableOptions& opt, const std::string& workload, uint32_t view = 0);
// A scheme variant of the accuracy table: a kernel for our schemes, robust or fast mode for Embree.
struct Variant {
  std::string label;
  SchemeConfig config;
};
int run_table(const std::string& name, const TableOptions& opt);

}  // namespace tb
