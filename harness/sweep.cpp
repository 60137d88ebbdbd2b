#include "harness/sweep.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "harness/compare.h"  // read_csv, is_speed, is_accuracy_value
#include "harness/experiment.h"
#include "structures/scene.h"  // InputError

namespace tb {

std::string cell_key(const std::string& workload, const std::string& scheme, const std::string& kernel,
                     const std::string& view, const std::string& params) {
  return workload + "|" + scheme + "|" + kernel + "|" + view + "|" + params;
}

std::string cell_key(const Record& r) {
  auto f = [&](const char* k) { const std::string* v = r.get(k); return v ? *v : std::string(); };
  return cell_key(f("workload"), f("scheme"), f("kernel"), f("view"), f("params"));
}

std::string run_cell_key(const RunOptions& opt, const std::string& workload, const std::string& entry) {
  return cell_key(workload, entry, std::string(kernel_name(opt.scheme_config.kernel)), std::to_string(opt.view + 1),
                  params_text(entry, opt.scheme_config));
}

namespace {

void write_all(int fd, const std::string& text, const std::string& path) {
  for (size_t off = 0; off < text.size();) {
    const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
    if (n <= 0) throw InputError(path + ": write failed (" + std::strerror(errno) + ")");
    off += size_t(n);
  }
  if (::fsync(fd) != 0) throw InputError(path + ": fsync failed (" + std::strerror(errno) + ")");
}

// Drops a torn last line (a kill inside write(2)): the file then ends at a row boundary.
void cut_torn_line(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (text.empty() || text.back() == '\n') return;
  const size_t keep = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
  std::filesystem::resize_file(path, keep);
}

std::string shown(const nlohmann::json& j) { return j.is_null() ? "(none)" : j.dump(); }

// The values a resumed row brings into the finished file, checked as `compare` checks them: the
// speeds are speeds, and the error columns (the accuracy kinds every figure is published with)
// are counts or rates >= 0. A kept row is trusted otherwise; one damaged by hand or by another
// tool would have been printed and plotted as measured (`table --resume` printed "abc" Mrays/s).
// speeds_required: a run row has them all; a table row may leave one empty (nothing timed).
void check_kept_values(const Record& r, const std::string& where, bool speeds_required) {
  const std::string fix = " (remove the CSV or drop --resume)";
  auto f = [&](const char* k) { const std::string* v = r.get(k); return v ? *v : std::string(); };
  const bool no_rays = f("rays") == "0";
  for (const char* col : {"mrays_median", "mrays_min", "mrays_max"})
    if ((speeds_required || !f(col).empty()) && !is_speed(f(col), no_rays))
      throw InputError("--resume: " + where + ": " + col + " '" + f(col) +
                       "' is not a speed (Mrays/s: a finite number > 0, or 0 for a cell without rays)" + fix);
  for (const char* col : kAccuracyColumns)
    if (!f(col).empty() && !is_accuracy_value(f(col), col))
      throw InputError("--resume: " + where + ": " + col + " '" + f(col) + "' is not " + accuracy_value_kind(col) + fix);
}

}  // namespace

CellStream::CellStream(std::string path, nlohmann::json meta, bool resume, const std::vector<std::string>& must_match)
    : path_(std::move(path)), meta_(provenance()) {
  meta_.update(meta);
  std::error_code ec;
  if (resume && std::filesystem::exists(path_, ec)) {
    nlohmann::json old;
    {
      std::ifstream js(sidecar_path(path_));
      if (!js) throw InputError("--resume: " + sidecar_path(path_) + " is missing, so the cells of " + path_ +
                                " cannot be shown to belong to this sweep; remove the CSV or drop --resume");
      try {
        js >> old;
      } catch (const std::exception&) {
        throw InputError("--resume: " + sidecar_path(path_) + " is not valid JSON");
      }
    }
    if (old.contains("scene_hashes") && old["scene_hashes"].is_object()) old_hashes_ = old["scene_hashes"];
    for (const auto& k : must_match) {
      const nlohmann::json a = old.contains(k) ? old[k] : nlohmann::json(), b = meta_.contains(k) ? meta_[k] : nlohmann::json();
      if (a == b) continue;
      std::string what = k;
      nlohmann::json was = a, is = b;
      if (a.is_object() && b.is_object())  // name the setting inside (a table's "sweep")
        for (const auto& [sub, v] : b.items())
          if (!a.contains(sub) || a[sub] != v) {
            what = k + "." + sub, was = a.contains(sub) ? a[sub] : nlohmann::json(), is = v;
            break;
          }
      throw InputError("--resume: " + path_ + " was written with " + what + " " + shown(was) + ", this sweep has " +
                       shown(is) + "; its cells would not be comparable (remove the CSV or drop --resume)");
    }
    cut_torn_line(path_);
    if (std::filesystem::file_size(path_) > 0) {
      const CsvTable t = read_csv(path_);
      cols_ = t.header;
      for (const auto& row : t.rows) {
        Record r;
        for (size_t c = 0; c < cols_.size(); ++c) r.set(cols_[c], row[c]);
        keys_.insert(cell_key(r));
        records_.push_back(std::move(r));
      }
      resumed_ = records_.size();
    }
  }
  empty_file_ = cols_.empty();
}

// On the first row (or at the end of a sweep without any): a sweep that fails before it measures
// anything (a bad --param a table checks, a scheme that cannot be built) leaves an older CSV of the
// same name as it was.
void CellStream::open() {
  if (fd_ >= 0) return;
  // Rows keep_resumed dropped leave the file first (before the descriptor: the rewrite renames a
  // new file over the old one).
  if (pruned_) write_file_durably(path_, text()), pruned_ = false;
  fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC | (empty_file_ ? O_TRUNC : O_APPEND), 0644);
  if (fd_ < 0) throw InputError(path_ + ": cannot open for writing (" + std::strerror(errno) + ")");
  meta_["status"] = "running";
  write_sidecar(path_, meta_);
}

CellStream::~CellStream() {
  if (fd_ >= 0) ::close(fd_);
}

std::string CellStream::text() const {
  std::string text = csv_line(cols_, nullptr);
  for (const auto& r : records_) text += csv_line(cols_, &r);
  return text;
}

void CellStream::keep_resumed(const std::vector<bool>& keep) {
  std::vector<Record> kept;
  for (size_t i = 0; i < records_.size(); ++i)
    if (i >= resumed_ || keep.at(i)) kept.push_back(std::move(records_[i]));
  pruned_ = pruned_ || kept.size() < records_.size();
  resumed_ -= records_.size() - kept.size();
  records_ = std::move(kept);
  keys_.clear();
  for (const auto& r : records_) keys_.insert(cell_key(r));
}

void CellStream::rewrite() {
  write_file_durably(path_, text());
  empty_file_ = false;
  ::close(fd_);
  fd_ = ::open(path_.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (fd_ < 0) throw InputError(path_ + ": cannot reopen (" + std::strerror(errno) + ")");
}

void CellStream::append(const Record& r) {
  open();
  records_.push_back(r);
  keys_.insert(cell_key(r));
  bool new_column = false;
  for (const auto& f : r.fields())
    if (std::find(cols_.begin(), cols_.end(), f.first) == cols_.end()) cols_.push_back(f.first), new_column = true;
  if (new_column && !empty_file_) return rewrite();
  // The header goes with the first row of a fresh file; a resumed file already has one.
  write_all(fd_, (empty_file_ ? csv_line(cols_, nullptr) : std::string()) + csv_line(cols_, &r), path_);
  empty_file_ = false;
}

void CellStream::finish(const nlohmann::json& extra) {
  open();
  meta_.update(extra);
  meta_["status"] = "complete";
  meta_["rows"] = records_.size();
  meta_["resumed_rows"] = resumed_;
  write_sidecar(path_, meta_);
}

const Record* CellStream::replay(const std::string& scene, const std::string& workload, const std::string& scheme) {
  if (replayed_ >= resumed_) return nullptr;
  const Record& r = records_[replayed_];
  auto f = [&](const char* k) { const std::string* v = r.get(k); return v ? *v : std::string(); };
  if (f("scene") != scene || f("workload") != workload || f("scheme") != scheme)
    throw InputError("--resume: row " + std::to_string(replayed_ + 2) + " of " + path_ + " is " + f("scene") + " / " +
                     f("workload") + " / " + f("scheme") + ", this table's cell there is " + scene + " / " + workload +
                     " / " + scheme + "; the table's cells changed (remove the CSV or drop --resume)");
  check_kept_values(r, path_ + ": row " + std::to_string(replayed_ + 2) + " (" + workload + " / " + scheme + ")", false);
  return &records_[replayed_++];
}

void CellStream::check_scene(const Scene& scene) {
  const std::string& name = scene.name;
  nlohmann::json& hashes = meta_["scene_hashes"];
  if (hashes.contains(name)) return;
  const std::string h = std::to_string(scene.content_hash());
  if (old_hashes_.contains(name) && old_hashes_[name] != h)
    throw InputError("--resume: " + path_ + " was measured on another scene '" + name + "' (content hash " +
                     old_hashes_[name].dump() + ", now " + h + "); its cells would not be comparable (remove the CSV "
                     "or drop --resume)");
  hashes[name] = h;
  if (fd_ >= 0) write_sidecar(path_, meta_);  // a later scene of a table: the sidecar knows it now
}

void CellStream::finish_table() {
  nlohmann::json done;
  std::ifstream js(sidecar_path(path_));
  try {
    js >> done;
  } catch (const std::exception&) {
    return;  // the table wrote no sidecar (no --csv): nothing to add to
  }
  for (const auto& [k, v] : meta_.items())
    if (!done.contains(k) && k != "status") done[k] = v;
  write_sidecar(path_, done);
}

bool CellStream::complete(const std::string& csv) {
  std::error_code ec;
  if (!std::filesystem::exists(csv, ec)) return false;
  std::ifstream js(sidecar_path(csv));
  nlohmann::json meta;
  try {
    js >> meta;
  } catch (const std::exception&) {
    return false;
  }
  return meta.value("status", "") == "complete";
}

namespace {

// What `run --resume` keeps of a CSV. It must be a run's CSV (the header starts as a run row
// does: read by another header, a row's values land in the wrong columns and its cell key is
// nonsense); each cell of this sweep at most once (the finished CSV would hold it twice) with
// speeds that are speeds (compare would take a nan as a measurement). Rows of cells this sweep
// does not have (another scheme, workload or view) are dropped, with a note: the finished CSV
// holds this sweep's cells, nothing else.
void check_resumed_rows(CellStream& stream, const RunOptions& opt, const std::string& csv) {
  const std::string fix = " (remove the CSV or drop --resume)";
  const std::vector<std::string>& cols = stream.columns();
  const std::vector<std::string> lead = run_lead_columns(opt);
  for (size_t i = 0; i < lead.size(); ++i)
    if (i >= cols.size() || cols[i] != lead[i])
      throw InputError("--resume: " + csv + " does not have the header this run writes: its column " +
                       std::to_string(i + 1) + " is " + (i < cols.size() ? "'" + cols[i] + "'" : "missing") +
                       ", a run writes '" + lead[i] + "' there" + fix);
  for (size_t i = 0; i < cols.size(); ++i)
    if (std::find(cols.begin(), cols.begin() + std::ptrdiff_t(i), cols[i]) != cols.begin() + std::ptrdiff_t(i))
      throw InputError("--resume: " + csv + ": column '" + cols[i] + "' appears twice in its header" + fix);
  std::set<std::string> sweep;
  for (const auto& w : opt.workloads)
    for (const auto& s : opt.schemes) sweep.insert(run_cell_key(opt, parse_workload(w).name(), s));
  std::map<std::string, size_t> seen;  // cell key -> its line in the CSV
  std::vector<bool> keep(stream.resumed(), false);
  size_t dropped = 0;
  std::string first_dropped;
  for (size_t i = 0; i < stream.resumed(); ++i) {
    const Record& r = stream.records()[i];
    auto f = [&](const char* k) { const std::string* v = r.get(k); return v ? *v : std::string(); };
    const size_t line = i + 2;  // the header is line 1
    const std::string cell = "row " + std::to_string(line) + " (" + f("workload") + " / " + f("scheme") +
                             (f("params").empty() ? "" : " / " + f("params")) + ")";
    const std::string key = cell_key(r);
    if (!sweep.count(key)) {
      if (dropped++ == 0) first_dropped = cell;
      continue;
    }
    if (const auto [it, fresh] = seen.emplace(key, line); !fresh)
      throw InputError("--resume: " + csv + ": " + cell + " is the cell of row " + std::to_string(it->second) +
                       " again; a sweep measures a cell once" + fix);
    check_kept_values(r, csv + ": " + cell, true);
    keep[i] = true;
  }
  if (dropped == 0) return;
  std::fprintf(stderr, "%s: --resume drops %zu row(s) that are no cell of this sweep (first: %s)\n", csv.c_str(),
               dropped, first_dropped.c_str());
  stream.keep_resumed(keep);
}

}  // namespace

std::vector<Record> run_sweep(Bench& bench, RunOptions opt, const std::string& scene_arg, const std::string& csv,
                              bool resume) {
  const nlohmann::json meta = {{"command", "run"},
                               {"scene", scene_arg},
                               {"scene_hash", bench.scene().content_hash()},
                               {"seed", opt.seed},
                               {"width", opt.width},
                               {"height", opt.height},
                               {"view", opt.view + 1},
                               {"reps", opt.reps},
                               {"threads", opt.threads},
                               {"kernel", std::string(kernel_name(opt.scheme_config.kernel))},
                               {"params", opt.scheme_config.params},
                               {"stats", opt.stats},
                               {"interleave", opt.interleave},
                               {"cache", opt.cache ? opt.cache_config + " " + opt.cache_policy : ""},
                               // This command's scheme entries (each with its own parameters, which
                               // `params` above does not hold) and workloads.
                               {"schemes", opt.schemes},
                               {"workloads", opt.workloads}};
  // Schemes and workloads may differ: a resume may finish a sweep or extend it by more cells.
  CellStream stream(csv, meta, resume,
                    {"command", "scene_hash", "git_revision", "seed", "width", "height", "view", "reps", "threads",
                     "kernel", "params", "stats", "cache"});
  if (!stream.columns().empty()) check_resumed_rows(stream, opt, csv);
  if (stream.resumed())
    std::fprintf(stderr, "%s: resuming, %zu cells there already\n", csv.c_str(), stream.resumed());
  opt.cells = &stream;
  std::vector<Record> records = run_experiment(bench, opt);
  stream.finish();
  return records;
}

}  // namespace tb
