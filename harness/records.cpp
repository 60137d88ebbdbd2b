#include "harness/records.h"

#include <fcntl.h>
#include <sched.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <thread>

#include "structures/scene.h"

#include "travbench_git_rev.h"  // TRAVBENCH_GIT_REV, generated at build time (cmake/git_revision.cmake)
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

// The processor, from the first block of /proc/cpuinfo: `name` its marketing name ("unknown"
// without one), `id` what tells machines apart beyond it (a VM may name only "AMD EPYC"): vendor,
// family, model and stepping, and whether it has AVX-512 (-march=native then compiles for it, and
// Embree's default ISA uses it), so that results from different machines are not compared by mistake.
struct CpuInfo {
  std::string name, id;
};
CpuInfo cpu_info() {
  std::ifstream f("/proc/cpuinfo");
  std::string name = "unknown", vendor = "?", family = "?", model = "?", stepping = "?", avx512 = "no avx512f";
  auto value = [](const std::string& line) {
    const size_t c = line.find(':');
    return c == std::string::npos ? std::string() : line.substr(std::min(line.size(), c + 2));
  };
  for (std::string line; std::getline(f, line) && !line.empty();) {  // the first processor's block
    if (line.rfind("model name", 0) == 0) name = value(line);
    else if (line.rfind("vendor_id", 0) == 0) vendor = value(line);
    else if (line.rfind("cpu family", 0) == 0) family = value(line);
    else if (line.rfind("model\t", 0) == 0 || line.rfind("model :", 0) == 0) model = value(line);
    else if (line.rfind("stepping", 0) == 0) stepping = value(line);
    else if (line.rfind("flags", 0) == 0 && (" " + value(line) + " ").find(" avx512f ") != std::string::npos)
      avx512 = "avx512f";
  }
  return {name, vendor + " family " + family + " model " + model + " stepping " + stepping + ", " + avx512};
}

// Linux's transparent-huge-page mode (the bracketed word of its setting: always, madvise or never):
// the finished structures ask for huge pages (structures/aligned.h), and large-scene speeds
// depend on whether they get them, so a result records the setting it was measured under.
std::string transparent_hugepages() {
  std::ifstream f("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string line;
  if (!std::getline(f, line)) return "unavailable";
  const size_t a = line.find('['), b = line.find(']');
  return a != std::string::npos && b != std::string::npos && b > a ? line.substr(a + 1, b - a - 1) : line;
}

// The CPUs the process may run on (its affinity, e.g. "1" under `taskset -c 1`, "0-1" unpinned):
// on a shared VM one core can be slowed by another tenant on its caches while the other is not,
// and cache-bound schemes (the ray streams) suffer more than the rest, so a timing records where
// it ran (docs/PERFORMANCE.md, session 20).
std::string cpu_affinity() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return "unavailable";
  std::string out;
  for (int c = 0; c < CPU_SETSIZE; ++c) {
    if (!CPU_ISSET(c, &set)) continue;
    int e = c;
    while (e + 1 < CPU_SETSIZE && CPU_ISSET(e + 1, &set)) ++e;
    out += (out.empty() ? "" : ",") + std::to_string(c) + (e > c ? "-" + std::to_string(e) : "");
    c = e;
  }
  return out;
}

}  // namespace

nlohmann::json provenance() {
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char date[32];
  std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  const CpuInfo cpu = cpu_info();
  return {{"cpu", cpu.name},
          {"cpu_id", cpu.id},
          {"hardware_threads", std::thread::hardware_concurrency()},
          {"cpu_affinity", cpu_affinity()},
          {"compiler", std::string("g++ ") + __VERSION__},
          {"flags", TRAVBENCH_CXX_FLAGS},
          {"embree_version", TRAVBENCH_EMBREE_VERSION},
          {"git_revision", TRAVBENCH_GIT_REV},
          {"transparent_hugepages", transparent_hugepages()},
          {"date", date}};
}

std::vector<std::string> columns_of(const std::vector<Record>& records) {
  std::vector<std::string> cols;
  for (const auto& r : records)
    for (const auto& f : r.fields())
      if (std::find(cols.begin(), cols.end(), f.first) == cols.end()) cols.push_back(f.first);
  return cols;
}

std::string csv_line(const std::vector<std::string>& cols, const Record* r) {
  std::string line;
  for (size_t i = 0; i < cols.size(); ++i) {
    const std::string* v = r ? r->get(cols[i]) : &cols[i];
    // Appended in two steps: `"," + std::string&&` inlines an insert at the front that GCC 12
    // misreads as an overlapping memcpy (a -Wrestrict false positive).
    if (i) line += ',';
    if (v) line += quote(*v);
  }
  return line + "\n";
}

std::string sidecar_path(const std::string& csv_path) {
  std::string json_path = csv_path;
  if (json_path.size() > 4 && json_path.substr(json_path.size() - 4) == ".csv") json_path.resize(json_path.size() - 4);
  return json_path + ".json";
}

namespace {

namespace fs = std::filesystem;

// Two paths name one file: the same inode when both exist (hard links, ./x, links to it), else the
// same path once the existing part is resolved (an output named twice that does not exist yet).
bool same_file(const std::string& a, const std::string& b) {
  std::error_code ec;
  const fs::path ta = output_target(a), tb_ = output_target(b);
  if (fs::exists(ta, ec) && fs::exists(tb_, ec)) return fs::equivalent(ta, tb_, ec) && !ec;
  const fs::path ca = fs::weakly_canonical(fs::absolute(ta, ec), ec), cb = fs::weakly_canonical(fs::absolute(tb_, ec), ec);
  return ca == cb;
}

}  // namespace

void check_distinct_files(const std::vector<FileArg>& inputs, const std::vector<FileArg>& outputs) {
  for (size_t o = 0; o < outputs.size(); ++o) {
    auto clash = [&](const FileArg& other, const char* consequence) {
      if (!other.path.empty() && same_file(outputs[o].path, other.path))
        throw InputError(outputs[o].what + " '" + outputs[o].path + "' is the same file as " + other.what + " '" +
                         other.path + "' (" + consequence + "); give another path");
    };
    if (outputs[o].path.empty()) continue;
    for (const FileArg& in : inputs) clash(in, "an input: writing would destroy it");
    for (size_t e = 0; e < o; ++e) clash(outputs[e], "another output: only one of the two would be kept");
  }
}

void write_sidecar(const std::string& csv_path, const nlohmann::json& meta) {
  write_file_durably(sidecar_path(csv_path), meta.dump(2) + "\n");
}

void write_csv(const std::string& path, const std::vector<Record>& records, const nlohmann::json& extra) {
  const std::vector<std::string> cols = columns_of(records);
  std::string text = csv_line(cols, nullptr);
  for (const auto& r : records) text += csv_line(cols, &r);
  write_file_durably(path, text);
  nlohmann::json meta = provenance();
  meta.update(extra);
  meta["status"] = "complete";
  meta["rows"] = records.size();
  write_sidecar(path, meta);
}

namespace {
// What a printed table shows in a cell: a speed column of a row that traced no rays (bounce:k of a
// scene whose rays all escaped before bounce k) says so instead of "0", which reads as a result.
// The CSV keeps the 0 with the row's `rays` = 0.
std::string shown_value(const Record& r, const std::string& column) {
  const std::string* v = r.get(column);
  if (!v) return "";
  const std::string* rays = r.get("rays");
  if (rays && *rays == "0" && column.rfind("mrays", 0) == 0) return "no rays";
  return *v;
}
}  // namespace

std::string speed_text(const Record& r) {
  const std::string v = shown_value(r, "mrays_median");
  return v == "no rays" ? v : v + " Mrays/s";
}

void print_table(const std::vector<Record>& records, const std::vector<std::string>& columns, FILE* out) {
  std::vector<size_t> w(columns.size());
  for (size_t i = 0; i < columns.size(); ++i) {
    w[i] = columns[i].size();
    for (const auto& r : records) w[i] = std::max(w[i], shown_value(r, columns[i]).size());
  }
  for (size_t i = 0; i < columns.size(); ++i) std::fprintf(out, "%-*s  ", int(w[i]), columns[i].c_str());
  std::fprintf(out, "\n");
  for (const auto& r : records) {
    for (size_t i = 0; i < columns.size(); ++i) std::fprintf(out, "%-*s  ", int(w[i]), shown_value(r, columns[i]).c_str());
    std::fprintf(out, "\n");
  }
}

}  // namespace tb
