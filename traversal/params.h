// Declared scheme parameters (issue 15, part 5): every scheme lists the `--param key=value`
// options it reads, with their type, range or allowed values, default and a one-line doc. The
// registry (traversal/registry.cpp) checks what the user gave against that list before the scheme
// is made, so a typo such as `leafsize=8` is an error that names `leaf_size`, not a silent default
// (the idea of pbrt-v4's ParameterDictionary::ReportUnused).
#pragma once
#include <optional>
#include <string>
#include <vector>

namespace tb {

enum class ParamType { integer, boolean, choice, real };

struct ParamSpec {
  std::string name;
  ParamType type = ParamType::integer;
  double lo = 0, hi = 0;             // integer and real: the inclusive range
  std::vector<std::string> allowed;  // choice: the values; integer: when not empty, the only values
  // The default as the user would write it; empty when it depends on other parameters (the doc
  // says how), in which case the scheme reads the parameter with SchemeConfig::find_*.
  std::string fallback;
  std::string doc;

  // Throws InputError when `value` is not of this parameter's type and range.
  void check(const std::string& value) const;
  // "int in [1, 64]", "0|1", "greedy|sah", ...
  std::string type_text() const;
};
using ParamSpecs = std::vector<ParamSpec>;

ParamSpec int_param(std::string name, int fallback, int lo, int hi, std::string doc);
// An integer restricted to a few values (e.g. a SIMD width of 4 or 8).
ParamSpec int_choice_param(std::string name, int fallback, std::vector<int> allowed, std::string doc);
ParamSpec bool_param(std::string name, bool fallback, std::string doc);
ParamSpec choice_param(std::string name, std::string fallback, std::vector<std::string> allowed, std::string doc);
ParamSpec real_param(std::string name, double fallback, double lo, double hi, std::string doc);
// A parameter whose default depends on others: `spec` with its default cleared and `how` appended
// to the doc.
ParamSpec auto_default(ParamSpec spec, const std::string& how);

ParamSpecs operator+(ParamSpecs a, const ParamSpecs& b);
const ParamSpec* find_param(const ParamSpecs& specs, const std::string& name);
// The spec called `name`, to refine one inherited from a shared list (a scheme narrowing a range
// or clearing a default); throws std::logic_error when the list has none (a programming error).
ParamSpec& param_named(ParamSpecs& specs, const std::string& name);

// The name in `names` closest to `key` by edit distance (case-insensitive, '_' and '-' ignored),
// or "" when none is plausibly meant (more than a third of the letters differ).
std::string closest_name(const std::string& key, const std::vector<std::string>& names);
// "leaf_size", "bins, leaf_size" ... for error messages.
std::string join_names(const std::vector<std::string>& names);

// Value parsers shared by SchemeConfig and the tables' own parameters (values already checked).
int param_to_int(const std::string& v);
bool param_to_bool(const std::string& v);
double param_to_real(const std::string& v);

}  // namespace tb
