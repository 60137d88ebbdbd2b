#include "harness/thesis_reference.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#ifndef TRAVBENCH_REFERENCE_DIR
#define TRAVBENCH_REFERENCE_DIR "../shared/reference"
#endif

namespace tb {

void ThesisRaysPerNode::set_columns(Record& r, const std::string& table, const std::string& scheme,
                                    const std::string& depth_col) const {
  auto value = [&](const char* node_kind) {
    return table.empty() || scheme.empty()
               ? std::nullopt
               : t_.lookup({"table", "scheme", "node_kind"}, {table, scheme, node_kind}, depth_col);
  };
  const std::optional<double> node = value("interior"), leaf = value("leaf");
  r.set("thesis_rays_scene", node ? "modern_room" : "");
  if (node) r.set("thesis_rays_per_node", *node);
  else r.set("thesis_rays_per_node", "");
  if (leaf) r.set("thesis_rays_per_leaf", *leaf);
  else r.set("thesis_rays_per_leaf", "");
}

std::string thesis_scene(const std::string& scene) {
  for (const char* s : {"sponza", "sibenik_lucy", "conference"})
    if (scene == s) return s;
  return "";
}

std::optional<double> ThesisTable::lookup(const std::vector<std::string>& key_cols,
                                          const std::vector<std::string>& key_vals, const std::string& col) const {
  auto index = [&](const std::string& c) {
    return size_t(std::find(columns.begin(), columns.end(), c) - columns.begin());
  };
  const size_t vc = index(col);
  if (vc >= columns.size()) return std::nullopt;
  for (const auto& row : rows) {
    bool ok = row.size() == columns.size();
    for (size_t k = 0; ok && k < key_cols.size(); ++k) {
      const size_t i = index(key_cols[k]);
      ok = i < row.size() && row[i] == key_vals[k];
    }
    if (!ok) continue;
    char* end = nullptr;
    const double v = std::strtod(row[vc].c_str(), &end);
    if (end != row[vc].c_str()) return v;
  }
  return std::nullopt;
}

ThesisTable load_thesis_table(const std::string& file) {
  const char* env = std::getenv("TRAVBENCH_REFERENCE_DIR");
  const std::string dir = env ? env : TRAVBENCH_REFERENCE_DIR;
  std::ifstream in(dir + "/" + file);
  ThesisTable t;
  if (!in) {
    std::fprintf(stderr, "travbench: note: thesis table %s/%s not found; thesis columns left empty\n", dir.c_str(),
                 file.c_str());
    return t;
  }
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    if (t.columns.empty()) t.columns = cells;
    else t.rows.push_back(cells);
  }
  return t;
}

}  // namespace tb
