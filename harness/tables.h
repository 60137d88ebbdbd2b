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
int run_table(const std::string& name, const TableOptions& opt);

}  // namespace tb
