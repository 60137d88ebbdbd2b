#include "traversal/params.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "structures/scene.h"

namespace tb {
namespace {

std::string number_text(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

bool parse_integer(const std::string& v, long long& out) {
  if (v.empty()) return false;
  try {
    size_t used = 0;
    out = std::stoll(v, &used);
    return used == v.size();
  } catch (const std::exception&) {
    return false;
  }
}

bool parse_real(const std::string& v, double& out) {
  if (v.empty()) return false;
  try {
    size_t used = 0;
    out = std::stod(v, &used);
    return used == v.size() && std::isfinite(out);
  } catch (const std::exception&) {
    return false;
  }
}

std::string normalised(const std::string& s) {
  std::string out;
  for (char c : s)
    if (c != '_' && c != '-') out.push_back(char(std::tolower(static_cast<unsigned char>(c))));
  return out;
}

size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

}  // namespace

std::string ParamSpec::type_text() const {
  switch (type) {
    case ParamType::boolean: return "0|1";
    case ParamType::choice: break;
    case ParamType::real: return "number in [" + number_text(lo) + ", " + number_text(hi) + "]";
    case ParamType::integer: break;
  }
  if (!allowed.empty()) {  // a choice, or an integer restricted to a few values
    std::string s;
    for (const auto& a : allowed) s += (s.empty() ? "" : "|") + a;
    return s;
  }
  // Integer bounds in full (%g printed 2^20 as 1.04858e+06).
  return "integer in [" + std::to_string(static_cast<long long>(lo)) + ", " + std::to_string(static_cast<long long>(hi)) + "]";
}

void ParamSpec::check(const std::string& value) const {
  bool ok = false;
  switch (type) {
    case ParamType::boolean: ok = value == "0" || value == "1" || value == "true" || value == "false"; break;
    case ParamType::choice: ok = std::find(allowed.begin(), allowed.end(), value) != allowed.end(); break;
    case ParamType::real: {
      double v = 0;
      ok = parse_real(value, v) && v >= lo && v <= hi;
      break;
    }
    case ParamType::integer: {
      long long v = 0;
      ok = parse_integer(value, v) &&
           (allowed.empty() ? double(v) >= lo && double(v) <= hi
                            : std::find(allowed.begin(), allowed.end(), std::to_string(v)) != allowed.end());
      break;
    }
  }
  if (!ok) throw InputError("parameter " + name + "=" + value + ": expected " + type_text());
}

ParamSpec int_param(std::string name, int fallback, int lo, int hi, std::string doc) {
  return {std::move(name), ParamType::integer, double(lo), double(hi), {}, std::to_string(fallback), std::move(doc)};
}

ParamSpec int_choice_param(std::string name, int fallback, std::vector<int> allowed, std::string doc) {
  std::vector<std::string> a;
  for (int v : allowed) a.push_back(std::to_string(v));
  return {std::move(name), ParamType::integer, 0, 0, std::move(a), std::to_string(fallback), std::move(doc)};
}

ParamSpec bool_param(std::string name, bool fallback, std::string doc) {
  return {std::move(name), ParamType::boolean, 0, 1, {}, fallback ? "1" : "0", std::move(doc)};
}

ParamSpec choice_param(std::string name, std::string fallback, std::vector<std::string> allowed, std::string doc) {
  return {std::move(name), ParamType::choice, 0, 0, std::move(allowed), std::move(fallback), std::move(doc)};
}

ParamSpec real_param(std::string name, double fallback, double lo, double hi, std::string doc) {
  return {std::move(name), ParamType::real, lo, hi, {}, number_text(fallback), std::move(doc)};
}

ParamSpec auto_default(ParamSpec spec, const std::string& how) {
  spec.fallback.clear();
  spec.doc += " (default: " + how + ")";
  return spec;
}

ParamSpecs operator+(ParamSpecs a, const ParamSpecs& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

const ParamSpec* find_param(const ParamSpecs& specs, const std::string& name) {
  for (const auto& s : specs)
    if (s.name == name) return &s;
  return nullptr;
}

ParamSpec& param_named(ParamSpecs& specs, const std::string& name) {
  for (auto& s : specs)
    if (s.name == name) return s;
  throw std::logic_error("no parameter named " + name + " to refine");
}

std::string closest_name(const std::string& key, const std::vector<std::string>& names) {
  const std::string k = normalised(key);
  std::string best;
  size_t best_d = SIZE_MAX;
  for (const auto& n : names) {
    const size_t d = edit_distance(k, normalised(n));
    if (d < best_d) best_d = d, best = n;
  }
  return best_d * 3 <= std::max<size_t>(k.size(), 3) ? best : std::string();
}

std::string join_names(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

int param_to_int(const std::string& v) {
  long long x = 0;
  if (!parse_integer(v, x) || x < INT32_MIN || x > INT32_MAX) throw InputError("'" + v + "' is not an integer");
  return int(x);
}

bool param_to_bool(const std::string& v) {
  if (v == "1" || v == "true") return true;
  if (v == "0" || v == "false") return false;
  throw InputError("'" + v + "' is not 0 or 1");
}

double param_to_real(const std::string& v) {
  double x = 0;
  if (!parse_real(v, x)) throw InputError("'" + v + "' is not a number");
  return x;
}

}  // namespace tb
