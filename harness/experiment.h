// The `travbench run` sweep: for each workload and scheme, trace the same rays `reps` times,
// compare with the reference, optionally count and cache-simulate, one Record per cell.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "harness/records.h"
#include "traversal/traverser.h"
#include "workloads/workload.h"

namespace tb {

class CellStream;  // harness/sweep.h

struct RunOptions {
  std::vector<std::string> schemes;
  std::vector<std::string> workloads;
  int threads = 1;
  int reps = 5;
  bool stats = false;
  bool cache = false;
  std::string cache_config = "l1=32K:8,l2=256K:8,l3=2M:16";
  std::string cache_policy = "plru";
  uint32_t width = 512, height = 512, view = 0;
  uint64_t seed = 1;
  SchemeConfig scheme_config;
  bool progress = true;
  // Time each workload's schemes round by round (measure_interleaved, `reps` rounds) instead of one
  // scheme's repetitions after another's; adds speed_base (the first scheme) and
  // speed_ratio_median/_min/_max, the per-round speed ratios to it (set_interleaved_speed).
  bool interleave = false;
  // Where each finished cell goes as it completes (harness/sweep.h); measure_cell appends to it
  // (the tables' cells), run_experiment appends its rows itself and skips the cells it holds.
  CellStream* cells = nullptr;
};

// A scene with its structure cache, reference and generated workloads: what several tables share.
class Bench {
 public:
  explicit Bench(Scene scene);
  const Scene& scene() const { return scene_; }
  StructureCache& cache() { return cache_; }
  const Traverser& reference() const { return *reference_; }
  // Generates (once) the rays of a workload and their reference hits.
  const RayBatch& rays(const WorkloadSpec& spec);
  const std::vector<Hit>& reference_hits(const WorkloadSpec& spec, int threads = 2);

 private:
  Scene scene_;
  StructureCache cache_;
  std::unique_ptr<Traverser> reference_;
  std::map<std::string, RayBatch> batches_;
  std::map<std::string, std::vector<Hit>> ref_hits_;
};

// Key of a workload spec including the view, size and seed.
std::string spec_key(const WorkloadSpec& s);

// Measures one (workload, scheme) cell: throughput, accuracy, and counters/cache on request.
// `entry` (a table's scheme entry as given, e.g. cwbvh_single:full_top=0) labels the row: its
// scheme and params columns, and the row `table --resume` expects; empty: the scheme's name.
Record measure_cell(Bench& bench, const WorkloadSpec& spec, Traverser& scheme, const RunOptions& opt,
                    const std::string& entry = {});
// The same for rays from elsewhere (`travbench trace` of a ray file): `ref` are the reference's
// hits on `batch`, `workload` labels the row, `hits` receives the scheme's hits.
Record measure_rays(Bench& bench, const std::string& workload, const RayBatch& batch,
                    const std::vector<Hit>& ref, Traverser& scheme, const RunOptions& opt, std::vector<Hit>& hits);
// The columns every row of measure_rays (a `run` row) starts with, in order; `run --resume` refuses
// a CSV whose header does not start with them.
std::vector<std::string> run_lead_columns(const RunOptions& opt);
// The reference's hits on a batch that is not one of the bench's workloads.
std::vector<Hit> reference_hits_of(const Bench& bench, const RayBatch& batch, int threads);

// Every scheme of opt.schemes on every workload; --param keys are checked against the run's
// schemes as a whole (check_run_params), each scheme sees those it declares.

// With opt.cells, a cell the stream already holds (a resumed sweep) is not measured again, and the
// result is the stream's rows (the resumed ones first).
std::vector<Record> run_experiment(Bench& bench, const RunOptions& opt);
// A cell's speed from interleaved rounds (measure_interleaved): reps = the rounds, mrays_median,
// _min, _max and mrays_samples over them, and per round the ratio to `base`, the scheme whose trace
// took base_sec in the same rounds: speed_base, speed_ratio_median, _min, _max (a ratio of one
// round compares two traces seconds apart, not two runs minutes apart).
void set_interleaved_speed(Record& r, const std::vector<double>& sec, const std::vector<double>& base_sec, size_t rays,
                           const std::string& base);
// Mrays/s values as the mrays_samples column writes them (';'-separated, run order).
std::string samples_text(const std::vector<double>& mrays);
// The `params` column: the scheme's parameters as the run gave them (its declared keys only).
std::string params_text(const std::string& scheme, const SchemeConfig& cfg);

}  // namespace tb
