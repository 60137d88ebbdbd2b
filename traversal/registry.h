// Scheme registry: name -> factory. `travbench list schemes` and `--schemes all` read it.
#pragma once
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "traversal/traverser.h"

namespace tb {

struct SchemeInfo {
  std::string name;
  std::string description;
  bool kernels = true;    // honours --kernel (Embree has its own kernels)
  bool baseline = false;  // an outside library: measured, not held to the accuracy bar
  std::function<std::unique_ptr<Traverser>(const SchemeConfig&)> make;
};

const std::vector<SchemeInfo>& schemes();
const SchemeInfo& find_scheme(const std::string& name);  // throws InputError on unknown names
std::unique_ptr<Traverser> make_scheme(const std::string& name, const SchemeConfig& cfg = {});
// "all" -> every registered scheme; otherwise the comma-separated names, each checked.
std::vector<std::string> expand_scheme_list(const std::string& list);

}  // namespace tb
