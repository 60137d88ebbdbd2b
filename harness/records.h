// Tidy result rows: one record per measured cell, columns in first-seen order, written as CSV
// with a provenance sidecar JSON (machine, compiler, flags, Embree version, git revision, the
// transparent-huge-page setting, date).
#pragma once
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "structures/output_file.h"

namespace tb {

class Record {
 public:
  Record& set(const std::string& key, const std::string& value);
  Record& set(const std::string& key, const char* value) { return set(key, std::string(value)); }
  Record& set(const std::string& key, double value);
  Record& set(const std::string& key, uint64_t value) { return set(key, std::to_string(value)); }
  Record& set(const std::string& key, int value) { return set(key, std::to_string(value)); }
  Record& set(const std::string& key, uint32_t value) { return set(key, std::to_string(value)); }
  const std::string* get(const std::string& key) const;
  const std::vector<std::pair<std::string, std::string>>& fields() const { return fields_; }

 private:
  std::vector<std::pair<std::string, std::string>> fields_;
};

// Writes `records` to `path` (CSV, RFC 4180 quoting) and `path` with .json for .csv (the
// provenance sidecar, `extra` merged into it, status "complete"); both replace the old files
// atomically. Throws InputError when the file cannot be written.
void write_csv(const std::string& path, const std::vector<Record>& records, const nlohmann::json& extra = {});
nlohmann::json provenance();
// The pieces write_csv is made of, shared with the streaming writer of harness/sweep.h.
std::vector<std::string> columns_of(const std::vector<Record>& records);  // first-seen order
std::string csv_line(const std::vector<std::string>& cols, const Record* r);  // nullptr: the header
std::string sidecar_path(const std::string& csv_path);                     // x.csv -> x.json

// A file argument of a command, for messages: what it is ("--csv", "the sidecar of --csv") and its path.
struct FileArg {
  std::string what, path;
};
// InputError when an output is the same file as an input or as an earlier output (empty paths
// are skipped): writing it would destroy the input, or keep only one of the two outputs.
void check_distinct_files(const std::vector<FileArg>& inputs, const std::vector<FileArg>& outputs);
void write_sidecar(const std::string& csv_path, const nlohmann::json& meta);
// Prints records as an aligned text table (the terminal view of a CSV).
void print_table(const std::vector<Record>& records, const std::vector<std::string>& columns, FILE* out);
// A row's speed for a progress line: "<mrays_median> Mrays/s", or "no rays" for a row that traced
// none (as print_table shows it; the CSV keeps the 0 with `rays` = 0).
std::string speed_text(const Record& r);

}  // namespace tb
