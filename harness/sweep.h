// Sweeps that lose nothing (issue 20): a sweep's cells go to its CSV as each one finishes, so a
// run killed after 50 minutes (Ctrl-C, SIGKILL, a full disk, a reboot) keeps every finished cell,
// and `run --resume` measures only the cells the CSV does not hold yet.
//
// The sidecar JSON is written first, before the first row (status "running", with the sweep's
// identity: scene hash, git revision, image size, seed, reps, ...), and rewritten at the end
// (status "complete"). Each
// row is one write(2) of the whole line followed by fsync(2): after a kill the file ends at a row
// boundary, or (a kill inside the write) with one torn line, which a resume cuts off.
//
// `table --resume` (tables have no cell key: their rows get their identifying columns after
// measure_cell) replays the kept rows in the order the table measures its cells, checking each
// against the cell's scene, workload and scheme, and checks each scene's content hash as the
// table loads it.
#pragma once
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "harness/records.h"

namespace tb {

struct Scene;  // structures/scene.h

// Identity of a cell within one sweep: what differs between the cells of a `run` (the sweep-wide
// settings are in the sidecar and checked as a whole on resume).
std::string cell_key(const std::string& workload, const std::string& scheme, const std::string& kernel,
                     const std::string& view, const std::string& params);
std::string cell_key(const Record& r);
struct RunOptions;
// The key of `run`'s cell of workload `workload` (its name) and scheme entry `entry` under `opt`.
std::string run_cell_key(const RunOptions& opt, const std::string& workload, const std::string& entry);

class CellStream {
 public:
  // Opens `path` for a new sweep (truncating it) or, with `resume`, keeps its cells when its
  // sidecar's values of every key of `must_match` equal those of `meta`; otherwise throws
  // InputError saying which value differs (or that the sidecar is missing). A missing CSV with
  // `resume` starts a fresh sweep. Nothing is written until the first row: then the sidecar
  // (provenance + meta, status "running"), then the CSV.
  CellStream(std::string path, nlohmann::json meta, bool resume, const std::vector<std::string>& must_match);
  ~CellStream();
  CellStream(const CellStream&) = delete;
  CellStream& operator=(const CellStream&) = delete;

  bool has(const std::string& key) const { return keys_.count(key) != 0; }
  // Appends one row (flushed and fsync'd). A row with a column the header lacks rewrites the
  // file with the union of the columns (atomically: temporary file, fsync, rename).
  void append(const Record& r);
  // Every row: the resumed ones first, then the appended ones, in order.
  const std::vector<Record>& records() const { return records_; }
  size_t resumed() const { return resumed_; }
  // The header of the kept CSV (empty for a fresh sweep).
  const std::vector<std::string>& columns() const { return cols_; }
  // Keeps only the resumed rows i with keep[i]; the file is rewritten without the others before
  // anything is added to it (a sweep that fails first leaves it as it was).
  void keep_resumed(const std::vector<bool>& keep);
  // Rewrites the sidecar with status "complete" and `extra` merged in.
  void finish(const nlohmann::json& extra = nlohmann::json::object());

  // For tables. The kept row that is the table's next cell, or nullptr once the kept rows are
  // used up (then the cell is measured); throws InputError when the kept row is another cell
  // (the table's cells changed).
  const Record* replay(const std::string& scene, const std::string& workload, const std::string& scheme);
  // Records a scene's content hash in the sidecar (scene_hashes; hashed once per name); throws
  // InputError on resume when the interrupted sweep loaded another scene of that name.
  void check_scene(const Scene& scene);
  // After the table's own write_csv replaced the files: adds this sweep's identity (meta keys
  // its sidecar lacks) so that a --resume of the finished table can be checked.
  void finish_table();
  // Whether `csv`'s sidecar says its sweep finished (status "complete").
  static bool complete(const std::string& csv);

 private:
  void open();
  void rewrite();
  std::string text() const;  // the whole CSV: header and every row
  std::string path_;
  nlohmann::json meta_;
  int fd_ = -1;
  std::vector<std::string> cols_;
  std::vector<Record> records_;
  std::set<std::string> keys_;
  size_t resumed_ = 0;
  size_t replayed_ = 0;
  nlohmann::json old_hashes_ = nlohmann::json::object();  // scene_hashes of the resumed sweep
  bool empty_file_ = true;  // nothing (not even a header) on disk yet
  bool pruned_ = false;     // keep_resumed dropped rows the file still holds
};

class Bench;
// `travbench run`: every cell of `opt` on `bench` into `csv` as it finishes; with `resume`, the
// cells `csv` holds already are kept when the sweep is the same (scene hash, git revision, image
// size, seed, view, reps, threads, kernel, --param values, --stats/--cache settings), else
// InputError saying which differs. Of the kept rows only the cells of this sweep stay (the others
// are dropped, with a note); a header other than a run's, a cell twice or a speed that is not one
// is refused (InputError naming the row). `scene_arg` is the scene as the user named it (sidecar).
std::vector<Record> run_sweep(Bench& bench, RunOptions opt, const std::string& scene_arg, const std::string& csv,
                              bool resume);

}  // namespace tb
