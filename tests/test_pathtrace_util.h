// Shared by the `table pathtrace` tests (test_pathtrace.cpp, test_bad_input_harness.cpp).
#pragma once
#include <map>
#include <string>

#include "harness/tables.h"

namespace tb::test {

// A small `table pathtrace` (room, bvh_single, 16x16, quiet) with the table parameters `params`,
// writing `csv` and its converged-image cache beside it.
inline TableOptions small_pathtrace_table(const std::string& csv, std::map<std::string, std::string> params) {
  TableOptions opt;
  opt.scene = "room";
  opt.run.schemes = {"bvh_single"};
  opt.run.width = opt.run.height = 16;
  opt.run.progress = false;
  opt.run.scheme_config.params = std::move(params);
  opt.csv = csv;
  return opt;
}

}  // namespace tb::test
