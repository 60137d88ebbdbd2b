#include "harness/records.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <thread>

#include "structures/scene.h"

#ifndef TRAVBENCH_GIT_REV
#define TRAVBENCH_GIT_REV "unknown"
#endif
#ifndef TRAVBENCH_CXX_FLAGS
#define TRAVBENCH_CXX_FLAGS ""
#endif
#ifndef TRAVBENCH_EMBREE_VERSION
#define TRAVBENCH_EMBREE_VERSION ""
#endif

namespace tb {

Record& Record::set(const std::string& key, const std::string& value) {
  for (auto& f : fields_)
    if (f.first == key) return f.second = value, *this;
  fields_.emplace_back(key, value);
  return *this;
}

Record& Record::set(const std::string& key, double value) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", value);
  return set(key, std::string(buf));
}

const std::string* Record::get(const std::string& key) const {
  for (const auto& f : fields_)
    if (f.first == key) return &f.second;
  return nullptr;
}

namespace {

std::string quote(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

std::string cpu_model() {
  std::ifstream f("/proc/cpuinfo");
  for (std::string line; std::getline(f, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

}  // namespace

nlohmann::json provenance() {
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char date[32];
  std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return {{"cpu", cpu_model()},
          {"hardware_threads", std::thread::hardware_concurrency()},
          {"compiler", std::string("g++ ") + __VERSION__},
          {"flags", TRAVBENCH_CXX_FLAGS},
          {"embree_version", TRAVBENCH_EMBREE_VERSION},
          {"git_revision", TRAVBENCH_GIT_REV},
          {"date", date}};
}

void write_csv(const std::string& path, const std::vector<Record>& records, const nlohmann::json& extra) {
  std::vector<std::string> cols;
  for (const auto& r : records)
    for (const auto& f : r.fields())
      if (std::find(cols.begin(), cols.end(), f.first) == cols.end()) cols.push_back(f.first);
  std::ofstream out(path);
  if (!out) throw InputError(path + ": cannot open for writing");
  for (size_t i = 0; i < cols.size(); ++i) out << (i ? "," : "") << quote(cols[i]);
  out << "\n";
  for (const auto& r : records) {
    for (size_t i = 0; i < cols.size(); ++i) {
      const std::string* v = r.get(cols[i]);
      out << (i ? "," : "") << (v ? quote(*v) : "");
    }
    out << "\n";
  }
  if (!out) throw InputError(path + ": write failed");
  nlohmann::json meta = provenance();
  meta.update(extra);
  std::string json_path = path;
  if (json_path.size() > 4 && json_path.substr(json_path.size() - 4) == ".csv") json_path.resize(json_path.size() - 4);
  std::ofstream js(json_path + ".json");
  js << meta.dump(2) << "\n";
}

void print_table(const std::vector<Record>& records, const std::vector<std::string>& columns, FILE* out) {
  std::vector<size_t> w(columns.size());
  for (size_t i = 0; i < columns.size(); ++i) {
    w[i] = columns[i].size();
    for (const auto& r : records)
      if (const std::string* v = r.get(columns[i])) w[i] = std::max(w[i], v->size());
  }
  for (size_t i = 0; i < columns.size(); ++i) std::fprintf(out, "%-*s  ", int(w[i]), columns[i].c_str());
  std::fprintf(out, "\n");
  for (const auto& r : records) {
    for (size_t i = 0; i < columns.size(); ++i) {
      const std::string* v = r.get(columns[i]);
      std::fprintf(out, "%-*s  ", int(w[i]), v ? v->c_str() : "");
    }
    std::fprintf(out, "\n");
  }
}

}  // namespace tb
