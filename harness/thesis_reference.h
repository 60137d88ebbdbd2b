// The thesis' tables (../shared/reference/*.csv, transcribed from Bikker 2012) for the
// "thesis" columns printed beside our measurements. Found through $TRAVBENCH_REFERENCE_DIR or
// the path the build recorded; when absent the thesis columns stay empty (with one warning).
#pragma once
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "harness/records.h"

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

// Tables 8 and 10 (table08_10_rays_per_node.csv, loaded on construction): the average number of
// rays of the 256-ray packets per visited interior node and leaf, which the thesis measured on
// Modern Room only. The bounce and raygrid tables print them beside their own.
class ThesisRaysPerNode {
 public:
  ThesisRaysPerNode() : t_(load_thesis_table("table08_10_rays_per_node.csv")) {}
  // Sets thesis_rays_per_node / thesis_rays_per_leaf from table `table` ("8" or "10"), the thesis'
  // row `scheme` and column `depth_col` ("depth0".."depth4"), and thesis_rays_scene to
  // "modern_room" where the thesis has the value; blank where it does not (table or scheme "").
  void set_columns(Record& r, const std::string& table, const std::string& scheme, const std::string& depth_col) const;

 private:
  ThesisTable t_;
};

// Our scene -> the thesis' scene of the same geometry in Tables 7-10 (the shared scenes sponza,
// sibenik_lucy and conference); "" for the others, the built-in room included (a procedural
// stand-in for Modern Room, not the same geometry).
std::string thesis_scene(const std::string& scene);

}  // namespace tb
