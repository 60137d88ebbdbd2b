#include "traversal/registry.h"

#include <set>
#include <sstream>
#include <stdexcept>

namespace tb {

#define TB_SCHEME(name, desc, kernels, baseline) \
  std::unique_ptr<Traverser> make_##name(const SchemeConfig&);  \
  ParamSpecs params_##name();
#include "traversal/schemes.def"
#undef TB_SCHEME

const std::vector<SchemeInfo>& schemes() {
  static const std::vector<SchemeInfo> list = {
#define TB_SCHEME(name, desc, kernels, baseline) {#name, desc, kernels, baseline, make_##name, params_##name()},
#include "traversal/schemes.def"
#undef TB_SCHEME
  };
  return list;
}

std::string scheme_name_of(const std::string& entry) { return entry.substr(0, entry.find(':')); }

const SchemeInfo& find_scheme(const std::string& entry) {
  const std::string name = scheme_name_of(entry);
  std::vector<std::string> known;
  for (const auto& s : schemes()) {
    if (s.name == name) return s;
    known.push_back(s.name);
  }
  const std::string near = closest_name(name, known);
  throw InputError("unknown scheme '" + name + "'" + (near.empty() ? "" : " (did you mean " + near + "?)") +
                   " (known: " + join_names(known) + ")");
}

namespace {

std::vector<std::string> names_of(const ParamSpecs& specs) {
  std::vector<std::string> out;
  for (const auto& s : specs) out.push_back(s.name);
  return out;
}

// "unknown parameter 'leafsize' for scheme bvh_single (did you mean leaf_size?); valid: bins, leaf_size"
[[noreturn]] void unknown_param(const std::string& key, const std::vector<std::string>& valid, const std::string& who) {
  const std::string near = closest_name(key, valid);
  throw InputError("unknown parameter '" + key + "' for " + who + (near.empty() ? "" : " (did you mean " + near + "?)") +
                   "; " + (valid.empty() ? "it takes none" : "valid: " + join_names(valid)) +
                   " (see travbench list params)");
}

}  // namespace

std::unique_ptr<Traverser> make_scheme(const std::string& name, const SchemeConfig& cfg) {
  SchemeConfig resolved = resolve_config(name, cfg);
  try {
    return find_scheme(name).make(resolved);
  } catch (const InputError& e) {  // a combination of parameters the scheme refuses: name it
    throw InputError("scheme " + name + ": " + e.what());
  }
}

SchemeConfig resolve_config(const std::string& name, const SchemeConfig& given) {
  const SchemeInfo& info = find_scheme(name);
  SchemeConfig cfg = given;  // with the entry's own parameters, if `name` carries any
  for (const auto& [key, value] : config_for(name, SchemeConfig{}).params) cfg.params[key] = value;
  if (!info.kernels && cfg.kernel != TriKernel::watertight)
    throw InputError("scheme '" + name + "' has its own triangle test and does not take --kernel " +
                     std::string(kernel_name(cfg.kernel)));
  SchemeConfig resolved;
  resolved.kernel = cfg.kernel;
  resolved.declared = &info.params;
  for (const auto& [key, value] : cfg.params) {
    const ParamSpec* spec = find_param(info.params, key);
    if (!spec) unknown_param(key, names_of(info.params), "scheme " + name);
    spec->check(value);
    resolved.params[key] = value;
  }
  for (const auto& spec : info.params)
    if (!spec.fallback.empty()) resolved.params.emplace(spec.name, spec.fallback);
  return resolved;
}

void check_run_params(const std::vector<std::string>& names, const SchemeConfig& cfg, const ParamSpecs& extra) {
  std::set<std::string> seen;
  std::vector<std::string> valid;
  auto add = [&](const ParamSpecs& specs) {
    for (const auto& s : specs)
      if (seen.insert(s.name).second) valid.push_back(s.name);
  };
  for (const auto& n : names) add(find_scheme(n).params);
  add(extra);
  for (const auto& [key, value] : cfg.params) {
    if (seen.count(key)) {
      if (const ParamSpec* e = find_param(extra, key)) e->check(value);
      continue;
    }
    unknown_param(key, valid, (names.size() == 1 ? "scheme " : "schemes ") + join_names(names));
  }
}

SchemeConfig config_for(const std::string& entry, const SchemeConfig& run_cfg) {
  const SchemeInfo& info = find_scheme(entry);
  SchemeConfig c;
  c.kernel = run_cfg.kernel;
  for (const auto& [key, value] : run_cfg.params)
    if (find_param(info.params, key)) c.params[key] = value;
  // The entry's own parameters (NAME:KEY=VALUE:...), each declared by this scheme, override; each
  // at most once (a second value would silently win, and the row's params would hide the first).
  std::set<std::string> own;
  for (size_t at = entry.find(':'); at != std::string::npos;) {
    const size_t end = entry.find(':', at + 1);
    const std::string kv = entry.substr(at + 1, end == std::string::npos ? std::string::npos : end - at - 1);
    const size_t eq = kv.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InputError("scheme entry '" + entry + "': '" + kv + "' is not KEY=VALUE (NAME:KEY=VALUE[:KEY=VALUE...])");
    const std::string key = kv.substr(0, eq);
    const ParamSpec* spec = find_param(info.params, key);
    if (!spec) unknown_param(key, names_of(info.params), "scheme " + info.name);
    if (!own.insert(key).second)
      throw InputError("scheme entry '" + entry + "': parameter '" + key + "' is given twice");
    spec->check(kv.substr(eq + 1));
    c.params[key] = kv.substr(eq + 1);
    at = end;
  }
  return c;
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
    if (item == "all") throw InputError("--schemes: 'all' stands alone (every scheme), not in a list ('" + list + "')");
    config_for(item, {});  // the name and the entry's own parameters
    out.push_back(item);
  }
  if (out.empty()) throw InputError("--schemes is empty");
  return out;
}

// ---- SchemeConfig getters: values were checked by make_scheme against the declared specs.

const std::string* SchemeConfig::value(const std::string& key) const {
  if (declared && !find_param(*declared, key))
    throw std::logic_error("scheme reads parameter '" + key + "' that it does not declare (params_<scheme>())");
  auto it = params.find(key);
  return it == params.end() ? nullptr : &it->second;
}

namespace {
const std::string& required(const std::string* v, const std::string& key) {
  if (!v) throw std::logic_error("parameter '" + key + "' has no default: read it with find_*()");
  return *v;
}
}  // namespace

int SchemeConfig::get_int(const std::string& key) const { return param_to_int(required(value(key), key)); }
bool SchemeConfig::get_bool(const std::string& key) const { return param_to_bool(required(value(key), key)); }
double SchemeConfig::get_real(const std::string& key) const { return param_to_real(required(value(key), key)); }
const std::string& SchemeConfig::get_choice(const std::string& key) const { return required(value(key), key); }
std::optional<int> SchemeConfig::find_int(const std::string& key) const {
  const std::string* v = value(key);
  return v ? std::optional<int>(param_to_int(*v)) : std::nullopt;
}
std::optional<bool> SchemeConfig::find_bool(const std::string& key) const {
  const std::string* v = value(key);
  return v ? std::optional<bool>(param_to_bool(*v)) : std::nullopt;
}
std::optional<std::string> SchemeConfig::find_choice(const std::string& key) const {
  const std::string* v = value(key);
  return v ? std::optional<std::string>(*v) : std::nullopt;
}
bool SchemeConfig::changed(const std::string& key) const {
  const std::string* v = value(key);
  if (!declared || !v) return false;
  const ParamSpec& spec = *find_param(*declared, key);
  if (spec.fallback.empty()) return true;  // no fixed default: given
  switch (spec.type) {
    case ParamType::integer: return param_to_int(*v) != param_to_int(spec.fallback);
    case ParamType::boolean: return param_to_bool(*v) != param_to_bool(spec.fallback);
    case ParamType::real: return param_to_real(*v) != param_to_real(spec.fallback);
    case ParamType::choice: break;
  }
  return *v != spec.fallback;
}
void SchemeConfig::refuse_if_changed(const std::string& key, const std::string& why) const {
  if (changed(key)) throw InputError("parameter '" + key + "' " + why);
}

}  // namespace tb
