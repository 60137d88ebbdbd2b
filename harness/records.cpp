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
    line += (i ? "," : "") + (v ? quote(*v) : std::string());
  }
  return line + "\n";
}

std::string sidecar_path(const std::string& csv_path) {
  std::string json_path = csv_path;
  if (json_path.size() > 4 && json_path.substr(json_path.size() - 4) == ".csv") json_path.resize(json_path.size() - 4);
  return json_path + ".json";
}

// Written to a temporary file beside `path`, fsync'd, then renamed over it: a reader (or a kill)
// sees the old file or the new one, never half of either.
void write_file_durably(const std::string& path, const std::string& text) {
  // The rename replaces whatever `path` names: a device, FIFO or socket there would be swapped for a
  // regular file and the write reported done without ever reaching it (as root, `--csv /dev/full`
  // exited 0 and left /dev/full a regular file). Only a regular file, or nothing, is replaced.
  struct stat st;
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
    throw InputError(path + ": is " +
                     (S_ISDIR(st.st_mode)                          ? "a directory"
                      : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device"
                      : S_ISFIFO(st.st_mode)                       ? "a FIFO"
                                                                   : "not a regular file") +
                     ", not a file it can replace: cannot write the output there");
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw InputError(path + ": cannot open for writing (" + std::strerror(errno) + ")");
  bool ok = true;
  for (size_t off = 0; ok && off < text.size();) {
    const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
    ok = n > 0;
    off += ok ? size_t(n) : 0;
  }
  ok = ok && ::fsync(fd) == 0;
  const int err = errno;
  ok = ::close(fd) == 0 && ok;
  if (!ok || std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw InputError(path + ": write failed (" + std::strerror(ok ? errno : err) + ")");
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
