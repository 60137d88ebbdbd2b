// The thesis' tables (../shared/reference/*.csv, transcribed from Bikker 2012) for the
// "thesis" columns printed beside our measurements. Found through $TRAVBENCH_REFERENCE_DIR or
// the path the build recorded; when absent the thesis columns stay empty (with one warning).
#pragma once
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace tb {

struct ThesisTable {
  std::vector<std::string> columns;
  std::vector<std::vector<std::string>> rows;
  // The value in column `col` of the first row whose `key_cols` equal `key_vals`.
  std::optional<double> lookup(const std::vector<std::string>& key_cols, const std::vector<std::string>& key_vals,
                               const std::string& col) const;
};

// Loads e.g. "table07_schemes_by_bounce.csv"; an empty table when the file is not available.
ThesisTable load_thesis_table(const std::string& file);

}  // namespace tb
