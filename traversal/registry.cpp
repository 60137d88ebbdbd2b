#include "traversal/registry.h"

#include <sstream>

namespace tb {

#define TB_SCHEME(name, desc, kernels, baseline) std::unique_ptr<Traverser> make_##name(const SchemeConfig&);
#include "traversal/schemes.def"
#undef TB_SCHEME

const std::vector<SchemeInfo>& schemes() {
  static const std::vector<SchemeInfo> list = {
#define TB_SCHEME(name, desc, kernels, baseline) {#name, desc, kernels, baseline, make_##name},
#include "traversal/schemes.def"
#undef TB_SCHEME
  };
  return list;
}

const SchemeInfo& find_scheme(const std::string& name) {
  for (const auto& s : schemes())
    if (s.name == name) return s;
  std::string known;
  for (const auto& s : schemes()) known += (known.empty() ? "" : ", ") + s.name;
  throw InputError("unknown scheme '" + name + "' (known: " + known + ")");
}

std::unique_ptr<Traverser> make_scheme(const std::string& name, const SchemeConfig& cfg) {
  const SchemeInfo& info = find_scheme(name);
  if (!info.kernels && cfg.kernel != TriKernel::watertight)
    throw InputError("scheme '" + name + "' has its own triangle test and does not take --kernel " +
                     std::string(kernel_name(cfg.kernel)));
  return info.make(cfg);
}

std::vector<std::string> expand_scheme_list(const std::string& list) {
  std::vector<std::string> out;
  if (list == "all") {
    for (const auto& s : schemes()) out.push_back(s.name);
    return out;
  }
  std::stringstream ss(list);
  for (std::string item; std::getline(ss, item, ',');) {
    if (item.empty()) continue;
    find_scheme(item);
    out.push_back(item);
  }
  if (out.empty()) throw InputError("--schemes is empty");
  return out;
}

int SchemeConfig::get_int(const std::string& key, int fallback) const {
  auto it = params.find(key);
  if (it == params.end()) return fallback;
  try {
    size_t used = 0;
    int v = std::stoi(it->second, &used);
    if (used != it->second.size()) throw std::invalid_argument(key);
    return v;
  } catch (const std::exception&) {
    throw InputError("parameter " + key + "=" + it->second + " is not an integer");
  }
}

}  // namespace tb
