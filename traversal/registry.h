// Scheme registry: name -> factory and declared parameters, one TB_SCHEME line per scheme in
// traversal/schemes.def. `travbench list schemes`, `list params` and `--schemes all` read it.
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
  std::function<std::unique_ptr<Traverser>(const SchemeConfig&)> make;  // takes a resolved config
  ParamSpecs params;      // the --param keys the scheme reads
};

const std::vector<SchemeInfo>& schemes();
// A scheme entry of a run: a registered name, optionally with parameters of its own after it,
// NAME:KEY=VALUE[:KEY=VALUE...] (e.g. embree_single:robust=0), so one run can time the same scheme
// in two configurations, interleaved (`run --schemes embree_single,embree_single:robust=0`). Its
// own parameters override the run's --param values for it alone. find_scheme, make_scheme,
// resolve_config, check_run_params and config_for take entries; the scheme's name() stays the
// registered name.
std::string scheme_name_of(const std::string& entry);
const SchemeInfo& find_scheme(const std::string& entry);  // throws InputError on unknown names
// Makes one scheme. Every key of cfg.params must be one the scheme declares and every value
// within its declared range (InputError naming the valid keys, and the closest one to a typo).
std::unique_ptr<Traverser> make_scheme(const std::string& name, const SchemeConfig& cfg = {});
// What make_scheme hands the scheme's factory: cfg checked as above, `declared` set, defaults filled.
SchemeConfig resolve_config(const std::string& name, const SchemeConfig& cfg);
// The parameters of a run with several schemes share one key space. check_run_params throws
// InputError unless every key is declared by at least one of `names` (or is one of `extra`, the
// caller's own parameters, e.g. a table's); config_for then gives scheme `name` the keys it
// declares, so the others are ignored by it.
void check_run_params(const std::vector<std::string>& names, const SchemeConfig& cfg, const ParamSpecs& extra = {});
SchemeConfig config_for(const std::string& name, const SchemeConfig& run_cfg);
// "all" -> every registered scheme; otherwise the comma-separated entries, each checked (its name,
// and its own parameters against what the scheme declares).
std::vector<std::string> expand_scheme_list(const std::string& list);

}  // namespace tb
