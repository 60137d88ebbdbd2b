// The command line contract (DESIGN.md): list output, run -> CSV columns, bad input -> one-line
// error and a non-zero exit, never a crash.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <regex>
#include <map>
#include <set>
#include <thread>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "harness/compare.h"
#include "harness/records.h"
#include "harness/sweep.h"
#include "test_util.h"
#include "workloads/ray_file.h"

namespace tb {
namespace {

struct Result {
  int code;
  std::string out;
};

Result travbench(const std::string& args) {
  const std::string cmd = std::string(TRAVBENCH_BINARY) + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  char buf[4096];
  while (size_t n = fread(buf, 1, sizeof buf, p)) out.append(buf, n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), out};
}

TEST(CLI, ListIsScriptable) {
  const Result r = travbench("list schemes");
  EXPECT_EQ(r.code, 0);
  for (const auto& s : schemes()) EXPECT_NE(r.out.find(s.name + "\n"), std::string::npos) << s.name;
  EXPECT_EQ(r.out.find(':'), std::string::npos) << "no headings in a single list";
  const Result all = travbench("list");
  EXPECT_NE(all.out.find("schemes:"), std::string::npos);
  EXPECT_NE(all.out.find("workloads:"), std::string::npos);
}

TEST(CLI, RunWritesRequiredColumnsForEveryScheme) {
  const auto dir = test::temp_dir("cli_run");
  const std::string csv = (dir / "out.csv").string();
  const Result r = travbench("run --scene sphere --schemes all --workloads primary,bounce:1 --reps 1 --width 32 "
                             "--height 32 --stats --csv " + csv);
  ASSERT_EQ(r.code, 0) << r.out;
  std::ifstream f(csv);
  std::string header;
  std::getline(f, header);
  for (const char* col : {"scene", "triangles", "workload", "scheme", "rays", "threads", "reps", "mrays_median",
                          "mrays_min", "mrays_max", "mismatch_rate", "false_miss", "false_hit", "nodes_per_ray",
                          "rays_per_node"})
    EXPECT_NE(header.find(col), std::string::npos) << col;
  int rows = 0;
  for (std::string line; std::getline(f, line);) ++rows;
  EXPECT_EQ(rows, int(2 * schemes().size()));
  EXPECT_TRUE(std::filesystem::exists(dir / "out.json"));
  std::filesystem::remove_all(dir);
}

// The build table counts the pages each structure's build faulted in (median over the reps) beside
// its CPU time, which includes the kernel's time for those faults (docs/PERFORMANCE.md, session 28).
TEST(CLI, BuildTableCountsEachBuildsPageFaults) {
  const auto dir = test::temp_dir("cli_build");
  const std::string csv = (dir / "build.csv").string();
  const Result r = travbench("table build --scene sphere --schemes bvh_single,mbvh8_single --reps 1 --csv " + csv);
  ASSERT_EQ(r.code, 0) << r.out;
  const CsvTable t = read_csv(csv);
  const int structure = t.column("structure"), faults = t.column("build_page_faults"), cpu = t.column("build_cpu_ms");
  ASSERT_GE(faults, 0);
  ASSERT_GE(structure, 0);
  std::set<std::string> counted;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    const std::string& name = t.at(i, structure);
    if (name.rfind("two-level", 0) == 0) continue;  // Table 1's rows time frames, not one structure
    const std::optional<double> n = parse_number(t.at(i, faults));
    ASSERT_TRUE(n) << name << ": '" << t.at(i, faults) << "'";
    // Cold (the default): the allocator's free memory goes back to the system before every build,
    // so each faults in the memory it uses, Embree's too (which ran in memory our rows had freed).
    EXPECT_GT(*n, 0) << name;
    EXPECT_EQ(*n, std::floor(*n)) << name;
    EXPECT_TRUE(parse_number(t.at(i, cpu))) << name;
    counted.insert(name);
  }
  EXPECT_EQ(counted, (std::set<std::string>{"bvh_single", "mbvh8_single", "embree low", "embree medium", "embree high",
                                            "embree high fast"}));
  // `warm`: the column says how each row was timed (0 by default); the parameter is the build
  // table's own, refused elsewhere and outside 0|1.
  auto warm_values = [&](const std::string& path) {
    const CsvTable w = read_csv(path);
    std::set<std::string> v;
    for (size_t i = 0; i < w.rows.size(); ++i)
      if (w.at(i, w.column("structure")).rfind("two-level", 0) != 0) v.insert(w.at(i, w.column("warm")));
    return v;
  };
  EXPECT_EQ(warm_values(csv), std::set<std::string>{"0"});
  const std::string warm_csv = (dir / "warm.csv").string();
  ASSERT_EQ(travbench("table build --scene sphere --schemes bvh_single --reps 2 --param warm=1 --csv " + warm_csv).code, 0);
  EXPECT_EQ(warm_values(warm_csv), std::set<std::string>{"1"});
  // `two_level=0` leaves out the thesis' Table 1 rows, and only those.
  const std::string rows_csv = (dir / "rows.csv").string();
  ASSERT_EQ(travbench("table build --scene sphere --schemes bvh_single --reps 1 --param two_level=0 --csv " + rows_csv).code, 0);
  const CsvTable rows = read_csv(rows_csv);
  std::set<std::string> names;
  for (size_t i = 0; i < rows.rows.size(); ++i) names.insert(rows.at(i, rows.column("structure")));
  EXPECT_EQ(names, (std::set<std::string>{"bvh_single", "embree low", "embree medium", "embree high", "embree high fast"}));
  bool table1 = false;
  const CsvTable all = read_csv(warm_csv);
  for (size_t i = 0; i < all.rows.size(); ++i) table1 |= all.at(i, all.column("structure")).rfind("two-level", 0) == 0;
  EXPECT_TRUE(table1);
  EXPECT_EQ(travbench("table build --scene sphere --reps 1 --param warm=2 --csv " + warm_csv).code, 2);
  EXPECT_EQ(travbench("table bounce --scene sphere --reps 1 --param warm=1 --csv " + (dir / "b.csv").string()).code, 2);
  std::filesystem::remove_all(dir);
}

TEST(CLI, RaysAndTraceRoundTrip) {
  const auto dir = test::temp_dir("cli_rays");
  const std::string rays = (dir / "r.bin").string(), hits = (dir / "h.bin").string();
  ASSERT_EQ(travbench("rays --scene room --workload bounce:1 --width 32 --height 32 --out " + rays).code, 0);
  const Result t = travbench("trace --scene room --scheme bvh_single --rays " + rays + " --hits " + hits);
  EXPECT_EQ(t.code, 0) << t.out;
  EXPECT_GT(std::filesystem::file_size(hits), 16u);
  std::filesystem::remove_all(dir);
}

// `rays --camera thesis` writes the rays `table divergence` traces by default (thesis Tables 2-4's
// camera), for a built-in scene too; `--camera view` (the default) the view's own.
TEST(CLI, RaysOnTheThesisCameraAreTheDivergenceTablesRays) {
  const auto dir = test::temp_dir("cli_rays_camera");
  const std::string thesis = (dir / "t.bin").string(), view = (dir / "v.bin").string();
  const std::string args = "rays --scene room --workload divergence:8 --width 64 --height 32 --view 2 --out ";
  ASSERT_EQ(travbench(args + thesis + " --camera thesis").code, 0);
  ASSERT_EQ(travbench(args + view).code, 0);
  Bench bench(make_builtin_scene("room"));
  WorkloadSpec spec = parse_workload("divergence:8");
  spec.width = 64, spec.height = 32, spec.view = 1, spec.hfov_deg = thesis_hfov_deg();
  const RayBatch want = primary_rays(bench.scene(), spec, 8.f), got = read_rays(thesis), own = read_rays(view);
  ASSERT_EQ(got.size(), want.size());
  EXPECT_EQ(std::memcmp(got.rays.data(), want.rays.data(), want.size() * sizeof(Ray)), 0);
  EXPECT_EQ(got.packet_begin, want.packet_begin);
  ASSERT_EQ(own.size(), want.size());
  EXPECT_NE(std::memcmp(own.rays.data(), want.rays.data(), want.size() * sizeof(Ray)), 0);
  std::filesystem::remove_all(dir);
}

// `trace --reps N --csv F` times a ray file made elsewhere like `run` times a cell: the same
// columns, the reps asked for, accuracy against the reference on those rays.
TEST(CLI, TraceTimesARayFileIntoTheRunColumns) {
  const auto dir = test::temp_dir("cli_trace_csv");
  const std::string rays = (dir / "r.bin").string(), csv = (dir / "f.csv").string(), hits = (dir / "h.bin").string();
  ASSERT_EQ(travbench("rays --scene room --workload bounce:1 --width 32 --height 32 --out " + rays).code, 0);
  const Result t = travbench("trace --scene room --scheme bvh_single --rays " + rays + " --reps 3 --csv " + csv +
                             " --hits " + hits + " --param leaf_size=8");
  ASSERT_EQ(t.code, 0) << t.out;
  std::ifstream f(csv);
  std::string header, row;
  std::getline(f, header);
  std::getline(f, row);
  auto column = [&](const std::string& name) {
    std::stringstream hs(header), rs(row);
    for (std::string h, v; std::getline(hs, h, ',') && std::getline(rs, v, ',');)
      if (h == name) return v;
    return std::string("<missing>");
  };
  for (const char* col : {"scene", "triangles", "workload", "scheme", "kernel", "rays", "threads", "reps",
                          "mrays_median", "mrays_min", "mrays_max", "mismatch_rate", "false_miss", "false_hit",
                          "prepare_ms"})
    EXPECT_NE(column(col), "<missing>") << col << " in " << header;
  EXPECT_EQ(column("reps"), "3");
  EXPECT_EQ(column("scheme"), "bvh_single");
  EXPECT_EQ(column("workload"), "file:r.bin");
  EXPECT_EQ(column("false_miss"), "0");
  EXPECT_LE(std::stod(column("mrays_min")), std::stod(column("mrays_median")));
  EXPECT_LE(std::stod(column("mrays_median")), std::stod(column("mrays_max")));
  EXPECT_GT(std::stoull(column("rays")), 0u);
  EXPECT_GT(std::filesystem::file_size(hits), 16u);
  EXPECT_TRUE(std::filesystem::exists(dir / "f.json"));
  std::filesystem::remove_all(dir);
}

// `rays --pathtrace` writes one path-traced frame's rays (stdout: rays per iteration and kind), and
// `trace --cache --csv` replays them through the cache simulator (scripts/pathtrace_reads.sh).
TEST(CLI, PathTracedFrameRaysReplayThroughTheCacheSimulator) {
  const auto dir = test::temp_dir("cli_pt_rays");
  const std::string rays = (dir / "pt.bin").string(), csv = (dir / "pt.csv").string();
  const Result r = travbench("rays --scene room --pathtrace Ref --spp 1 --width 32 --height 32 --out " + rays);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("iteration,kind,rays,packets"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0,pathtrace:ext,1024,"), std::string::npos) << r.out;
  uint64_t total = 0;
  std::stringstream ss(r.out);
  for (std::string line; std::getline(ss, line);) {
    if (line.find(",pathtrace:") == std::string::npos) continue;
    std::stringstream ls(line);
    std::string iteration, kind, count;
    std::getline(ls, iteration, ',');
    std::getline(ls, kind, ',');
    std::getline(ls, count, ',');
    total += std::stoull(count);
  }
  EXPECT_GT(total, 1024u) << "shadow rays and later segments follow the camera rays";
  const Result t = travbench("trace --scene room --scheme mbvh_rs --param width=4 --rays " + rays + " --cache --csv " + csv);
  ASSERT_EQ(t.code, 0) << t.out;
  std::ifstream f(csv);
  std::string header, row;
  std::getline(f, header);
  std::getline(f, row);
  EXPECT_NE(header.find("l1_read_hit_m"), std::string::npos) << header;
  EXPECT_NE(row.find("," + std::to_string(total) + ","), std::string::npos) << "the rays column holds every ray: " << row;
  EXPECT_NE(travbench("trace --scene room --scheme mbvh_rs --rays " + rays + " --cache --hits " + (dir / "h.bin").string()).code, 0)
      << "--cache without --csv has nowhere to go";
  EXPECT_NE(travbench("rays --scene room --width 32 --height 32 --out " + rays).code, 0) << "neither --workload nor --pathtrace";
  std::filesystem::remove_all(dir);
}

TEST(CLI, ListParamsPrintsEachSchemesDeclaredParameters) {
  const Result one = travbench("list params bvh_single");
  EXPECT_EQ(one.code, 0) << one.out;
  EXPECT_NE(one.out.find("leaf_size"), std::string::npos) << one.out;
  EXPECT_NE(one.out.find("[1, 64]"), std::string::npos) << one.out;
  EXPECT_EQ(one.out.find("queue"), std::string::npos) << "only bvh_single's: " << one.out;
  const Result all = travbench("list params");
  EXPECT_EQ(all.code, 0);
  for (const auto& s : schemes()) {
    EXPECT_NE(all.out.find(s.name + ":"), std::string::npos) << s.name;
    for (const auto& p : s.params) EXPECT_NE(all.out.find(p.name), std::string::npos) << s.name << " " << p.name;
  }
}

// A parameter of a multi-scheme run is fine when one scheme of the run declares it (the others
// ignore it); the typo of the issue fails with the right name.
TEST(CLI, RunParametersAreCheckedAgainstTheRunsSchemes) {
  const auto dir = test::temp_dir("cli_params");
  const std::string csv = " --csv " + (dir / "x.csv").string();
  const std::string run = "run --scene sphere --workloads primary --reps 1 --width 16 --height 16 ";
  const Result ok = travbench(run + "--schemes bvh_single,embree_single --param leaf_size=8" + csv);
  EXPECT_EQ(ok.code, 0) << ok.out;
  const Result typo = travbench(run + "--schemes bvh_single --param leafsize=8" + csv);
  EXPECT_NE(typo.code, 0);
  EXPECT_LT(typo.code, 128);
  EXPECT_NE(typo.out.find("leaf_size"), std::string::npos) << typo.out;
  const Result none = travbench(run + "--schemes bvh_single,embree_single --param queue=64" + csv);
  EXPECT_NE(none.code, 0) << none.out;
  const Result range = travbench(run + "--schemes bvh_single --param bins=1" + csv);
  EXPECT_NE(range.code, 0) << range.out;
  EXPECT_NE(range.out.find("bins=1"), std::string::npos) << range.out;
  std::filesystem::remove_all(dir);
}

// Two runs of the same binary compare as "same" cells; a run with another parameter set has no
// matching cells; the regression gate and --csv work; bad files are refused.
TEST(CLI, CompareTwoRuns) {
  const std::string dir = test::temp_dir("cli_compare").string();
  const std::string a = dir + "/a.csv", b = dir + "/b.csv", c = dir + "/c.csv", out = dir + "/cmp.csv";
  const std::string run = "run --scene sphere --schemes bvh_single,mbvh8_single --workloads primary --width 32 --height 32 --reps 5 --csv ";
  ASSERT_EQ(travbench(run + a).code, 0);
  ASSERT_EQ(travbench(run + b).code, 0);
  ASSERT_EQ(travbench(run + c + " --param leaf_size=8").code, 0);
  const Result r = travbench("compare " + a + " " + b + " --csv " + out);
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("summary: 2 matched cells"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("Mann-Whitney"), std::string::npos) << r.out;
  std::ifstream f(out);
  std::string header;
  std::getline(f, header);
  for (const char* col : {"ratio", "p_value", "verdict", "delta_false_miss"})
    EXPECT_NE(header.find(col), std::string::npos) << col << " in " << header;
  const Result other = travbench("compare " + a + " " + c);
  EXPECT_NE(other.out.find("only in base"), std::string::npos) << other.out;
  EXPECT_NE(other.out.find("only in new"), std::string::npos) << other.out;
  const Result bad = travbench("compare " + a + " " + dir + "/missing.csv");
  EXPECT_NE(bad.code, 0);
}

std::vector<std::string> lines_of(const std::string& path) {
  std::ifstream f(path);
  std::vector<std::string> lines;
  for (std::string line; std::getline(f, line);) lines.push_back(line);
  return lines;
}

// The rows of a CSV travbench wrote (no quoted fields), each as column -> value.
std::vector<std::map<std::string, std::string>> rows_of(const std::string& path) {
  const std::vector<std::string> lines = lines_of(path);
  std::vector<std::map<std::string, std::string>> rows;
  if (lines.empty()) return rows;
  std::vector<std::string> head;
  std::stringstream hs(lines[0]);
  for (std::string h; std::getline(hs, h, ',');) head.push_back(h);
  for (size_t i = 1; i < lines.size(); ++i) {
    std::map<std::string, std::string>& row = rows.emplace_back();
    std::stringstream rs(lines[i]);
    size_t c = 0;
    for (std::string v; std::getline(rs, v, ',') && c < head.size(); ++c) row[head[c]] = v;
  }
  return rows;
}

// The (workload, scheme) cells of a run CSV, each once: a duplicate fails the test.
std::set<std::string> cells_of(const std::string& path) {
  const std::vector<std::string> lines = lines_of(path);
  std::set<std::string> cells;
  if (lines.empty()) return cells;
  std::vector<std::string> head;
  std::stringstream hs(lines[0]);
  for (std::string h; std::getline(hs, h, ',');) head.push_back(h);
  for (size_t i = 1; i < lines.size(); ++i) {
    std::stringstream rs(lines[i]);
    std::string workload, scheme;
    size_t c = 0;
    for (std::string v; std::getline(rs, v, ','); ++c) {
      if (c < head.size() && head[c] == "workload") workload = v;
      if (c < head.size() && head[c] == "scheme") scheme = v;
    }
    EXPECT_TRUE(cells.insert(workload + "/" + scheme).second) << "duplicate row " << lines[i];
  }
  return cells;
}

// Starts travbench with `args` and SIGKILLs it as soon as `csv` holds a row; false when it ended
// on its own first.
bool killed_after_first_row(const std::string& args, const std::string& csv) {
  const pid_t pid = fork();
  if (pid < 0) return false;
  if (pid == 0) {
    const std::string cmd = "exec " + std::string(TRAVBENCH_BINARY) + " " + args + " >/dev/null 2>&1";
    execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  const auto t0 = std::chrono::steady_clock::now();
  while (lines_of(csv).size() < 2 && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60))
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFSIGNALED(status);
}

// Issue 20, "sweeps that lose nothing": a run killed with SIGKILL after its first cells keeps
// every finished cell (whole rows, header once), and --resume completes it with no duplicate
// row and the cells an uninterrupted run has. Enough repetitions that the sweep is still running
// when the first row appears; the kill then lands between or inside later cells.
TEST(CLI, KilledRunKeepsItsCellsAndResumeCompletesIt) {
  const auto dir = test::temp_dir("cli_resume");
  const std::string csv = (dir / "k.csv").string(), full = (dir / "full.csv").string();
  const std::string sweep = "run --scene sphere --schemes bvh_single,mbvh8_single,kd_single --workloads "
                            "primary,bounce:1,shadow --width 64 --height 64 --csv ";
  ASSERT_TRUE(killed_after_first_row(sweep + csv + " --reps 20", csv)) << "the sweep ended before the kill";
  const std::set<std::string> kept = cells_of(csv);
  ASSERT_GE(kept.size(), 1u);
  ASSERT_LT(kept.size(), 9u);
  const std::string sidecar = (dir / "k.json").string();
  ASSERT_TRUE(std::filesystem::exists(sidecar)) << "the sidecar is written first";
  EXPECT_NE(lines_of(sidecar).size(), 0u);

  // Other settings than the killed sweep's: refused, saying which.
  const Result other = travbench(sweep + csv + " --reps 2 --resume");
  EXPECT_EQ(other.code, 2) << other.out;
  EXPECT_NE(other.out.find("reps"), std::string::npos) << other.out;
  const Result resumed = travbench(sweep + csv + " --reps 20 --resume");
  ASSERT_EQ(resumed.code, 0) << resumed.out;
  EXPECT_NE(resumed.out.find("in the CSV already"), std::string::npos) << resumed.out;
  ASSERT_EQ(travbench(sweep + full + " --reps 1").code, 0);
  const std::set<std::string> done = cells_of(csv);
  EXPECT_EQ(done, cells_of(full));
  EXPECT_EQ(done.size(), 9u);
  for (const auto& c : kept) EXPECT_TRUE(done.count(c)) << c;
  const std::vector<std::string> lines = lines_of(csv);
  for (size_t i = 1; i < lines.size(); ++i) EXPECT_NE(lines[i].rfind("scene,", 0), 0u) << "header written twice";
  std::ifstream js(sidecar);
  const std::string meta((std::istreambuf_iterator<char>(js)), std::istreambuf_iterator<char>());
  EXPECT_NE(meta.find("\"complete\""), std::string::npos) << meta;
  std::filesystem::remove_all(dir);
}

// Every sidecar names the build (a revision taken at build time, "-dirty" when the code differed
// from it) and the huge-page setting the structures were measured under.
TEST(CLI, ProvenanceNamesTheRevisionAndThePageSetting) {
  const nlohmann::json p = provenance();
  const std::string rev = p.at("git_revision");
  EXPECT_TRUE(rev == "unknown" || std::regex_match(rev, std::regex("[0-9a-f]{7,40}(-dirty)?"))) << rev;
  const std::string thp = p.at("transparent_hugepages");
  EXPECT_FALSE(thp.empty());
  EXPECT_EQ(thp.find('['), std::string::npos) << thp;
  const std::string id = p.at("cpu_id");  // e.g. "AuthenticAMD family 25 model 1 stepping 1, no avx512f"
  EXPECT_TRUE(std::regex_search(id, std::regex(" family [0-9?]+ model [0-9?]+ stepping [0-9?]+, (no )?avx512f$"))) << id;
}

// The command exited with `code` and its output says `needle`.
void expect_says(const Result& r, int code, const std::string& needle) {
  EXPECT_EQ(r.code, code) << r.out;
  EXPECT_NE(r.out.find(needle), std::string::npos) << r.out;
}

// `run --interleave` times each workload's schemes round by round in one process: every row has
// --reps samples, and its speed_ratio columns are the per-round ratios to the first scheme (1 for
// that scheme itself, and the median of the ratios lies within their min and max); the sidecar
// says the run was interleaved. Resuming such a run is refused (its cells are timed together).
// The same scheme twice, once with a parameter of its own (NAME:KEY=VALUE), gives two rows.
TEST(CLI, InterleavedRunGivesPerRoundRatiosToTheFirstScheme) {
  const auto dir = test::temp_dir("cli_interleave");
  const std::string csv = (dir / "i.csv").string();
  const std::string sweep = "run --scene sphere --schemes mbvh8_single,bvh_single,bvh_single:leaf_size=1 --workloads "
                            "primary,bounce:1 --width 32 --height 32 --reps 3 --interleave --csv " + csv;
  const Result r = travbench(sweep);
  ASSERT_EQ(r.code, 0) << r.out;
  const std::vector<std::string> lines = lines_of(csv);
  ASSERT_EQ(lines.size(), 7u);
  const auto rows = rows_of(csv);
  for (size_t i = 1; i < lines.size(); ++i) {
    auto row = rows[i - 1];
    EXPECT_EQ(row["reps"], "3") << lines[i];
    EXPECT_EQ(std::count(row["mrays_samples"].begin(), row["mrays_samples"].end(), ';'), 2) << lines[i];
    EXPECT_EQ(row["speed_base"], "mbvh8_single") << lines[i];
    const double med = std::stod(row["speed_ratio_median"]), lo = std::stod(row["speed_ratio_min"]),
                 hi = std::stod(row["speed_ratio_max"]);
    EXPECT_GT(lo, 0.0) << lines[i];
    EXPECT_LE(lo, med) << lines[i];
    EXPECT_LE(med, hi) << lines[i];
    if (row["scheme"] == "mbvh8_single") {
      EXPECT_EQ(med, 1.0) << lines[i];
    }
    // A scheme entry with parameters of its own is a row of its own, naming them.
    EXPECT_EQ(row["params"], row["scheme"] == "bvh_single:leaf_size=1" ? "leaf_size=1" : "") << lines[i];
    EXPECT_EQ(row["mismatch_rate"], "0") << lines[i];
  }
  std::ifstream js((dir / "i.json").string());
  const nlohmann::json meta = nlohmann::json::parse(js);
  EXPECT_EQ(meta.at("interleave"), true);
  expect_says(travbench(sweep + " --resume"), 2, "--interleave");
  std::filesystem::remove_all(dir);
}

// A printed table shows "no rays" for the speed of a row without rays (`table scaling --scene
// sphere` printed a column of 0 Mrays/s for bounce:2 of a convex scene); the CSV keeps the 0.
TEST(CLI, PrintedTablesSayNoRaysInsteadOfASpeedOfZero) {
  Record empty, full;
  empty.set("scheme", "a").set("rays", 0).set("mrays_median", 0.0).set("mismatch_rate", 0.0);
  full.set("scheme", "b").set("rays", 10).set("mrays_median", 2.5).set("mismatch_rate", 0.0);
  char buf[512] = {};
  FILE* f = fmemopen(buf, sizeof buf - 1, "w");
  ASSERT_NE(f, nullptr);
  print_table({empty, full}, {"scheme", "mrays_median", "mismatch_rate"}, f);
  std::fclose(f);
  std::vector<std::string> lines;
  std::stringstream ss(buf);
  for (std::string l; std::getline(ss, l);) lines.push_back(l);
  ASSERT_EQ(lines.size(), 3u) << buf;
  EXPECT_NE(lines[1].find("no rays"), std::string::npos) << lines[1];
  EXPECT_NE(lines[1].find(" 0 "), std::string::npos) << lines[1];  // mismatch_rate is still a number
  EXPECT_NE(lines[2].find("2.5"), std::string::npos) << lines[2];
  EXPECT_EQ(lines[2].find("no rays"), std::string::npos) << lines[2];
}

// A workload without rays (the sphere is convex: every bounce:1 ray escapes, so bounce:2 has none)
// has no speed to compare: its interleaved rows say nan in the ratio columns, not the ratio of two
// traces of nothing (a goal script read such a ratio as 1.6x before).
TEST(CLI, InterleavedRunWithoutRaysHasNoSpeedRatio) {
  const auto dir = test::temp_dir("cli_interleave_empty");
  const std::string csv = (dir / "e.csv").string();
  const Result r = travbench("run --scene sphere --schemes mbvh8_single,bvh_single --workloads bounce:1,bounce:2 "
                             "--width 32 --height 32 --reps 3 --interleave --csv " + csv);
  ASSERT_EQ(r.code, 0) << r.out;
  const auto rows = rows_of(csv);
  ASSERT_EQ(rows.size(), 4u);
  int empty = 0;
  for (auto row : rows) {
    const bool none = row["rays"] == "0";
    EXPECT_EQ(none, row["workload"] == "bounce:2") << row["scheme"] << " " << row["workload"];
    for (const char* k : {"speed_ratio_median", "speed_ratio_min", "speed_ratio_max"})
      EXPECT_EQ(std::isnan(std::stod(row[k])), none) << k << ": " << row["scheme"] << " " << row["workload"];
    empty += none;
  }
  EXPECT_EQ(empty, 2);
  // The progress lines say "no rays" too, interleaved or not (they printed "0 Mrays/s").
  const Result plain = travbench("run --scene sphere --schemes mbvh8_single,bvh_single --workloads bounce:1,bounce:2 "
                                 "--width 32 --height 32 --reps 1 --csv " + (dir / "p.csv").string());
  ASSERT_EQ(plain.code, 0) << plain.out;
  for (const Result* run : {&r, &plain}) {
    std::stringstream ss(run->out);
    int said = 0;
    for (std::string l; std::getline(ss, l);) {
      if (l.find("_single ") == std::string::npos) continue;  // the progress lines of the two schemes
      const bool none = l.find("bounce:2") != std::string::npos;
      EXPECT_EQ(l.find("no rays") != std::string::npos, none) << l;
      EXPECT_EQ(l.find("Mrays/s") != std::string::npos, !none) << l;
      said += none;
    }
    EXPECT_EQ(said, 2) << run->out;
  }
  std::filesystem::remove_all(dir);
}

// A table streams its measured cells too: killed after the first, its CSV holds whole rows under
// one header and the sidecar says the table did not finish; `table --resume` completes it with
// the rows (and no duplicate) of an uninterrupted table, refuses other settings naming the one
// that differs, and has nothing to do for a finished table. Tables that do not stream refuse it.
TEST(CLI, KilledTableKeepsItsCellsAndResumeCompletesIt) {
  const auto dir = test::temp_dir("cli_table_kill");
  const std::string csv = (dir / "b.csv").string(), full = (dir / "full.csv").string();
  const std::string table = "table bounce --scene sphere --schemes bvh_single,mbvh8_single --width 64 --height 64 --csv ";
  ASSERT_TRUE(killed_after_first_row(table + csv + " --reps 20", csv)) << "the table ended before the kill";
  const std::vector<std::string> lines = lines_of(csv);
  ASSERT_GE(lines.size(), 2u);
  EXPECT_LT(lines.size(), 9u);
  auto fields = [](const std::string& line) { return std::count(line.begin(), line.end(), ',') + 1; };
  for (size_t i = 1; i < lines.size(); ++i) EXPECT_EQ(fields(lines[i]), fields(lines[0])) << lines[i];
  std::ifstream js(dir / "b.json");
  const std::string meta((std::istreambuf_iterator<char>(js)), std::istreambuf_iterator<char>());
  EXPECT_NE(meta.find("\"running\""), std::string::npos) << meta;
  // A table that fails before it measures anything (a bad --param) leaves the CSV there as it was.
  const Result bad = travbench("table bounce --scene sphere --param bogus=1 --csv " + csv);
  EXPECT_EQ(bad.code, 2) << bad.out;
  EXPECT_EQ(lines_of(csv), lines);
  const std::set<std::string> kept = cells_of(csv);

  expect_says(travbench(table + csv + " --reps 2 --resume"), 2, "sweep.reps 20, this sweep has 2");
  EXPECT_EQ(lines_of(csv), lines);
  const Result resumed = travbench(table + csv + " --reps 20 --resume");
  ASSERT_EQ(resumed.code, 0) << resumed.out;
  EXPECT_NE(resumed.out.find("resuming, " + std::to_string(kept.size()) + " cells there already"), std::string::npos)
      << resumed.out;
  ASSERT_EQ(travbench(table + full + " --reps 1").code, 0);
  const std::set<std::string> done = cells_of(csv);
  EXPECT_EQ(done, cells_of(full));
  EXPECT_EQ(lines_of(csv).size(), lines_of(full).size());
  EXPECT_EQ(lines_of(csv)[0], lines_of(full)[0]) << "the finished table's columns";
  for (const auto& c : kept) EXPECT_TRUE(done.count(c)) << c;
  // Finished: nothing to resume, the files stay as they are.
  const std::vector<std::string> finished = lines_of(csv);
  expect_says(travbench(table + csv + " --reps 20 --resume"), 0, "nothing to resume");
  EXPECT_EQ(lines_of(csv), finished);
  expect_says(travbench(table + csv + " --reps 3 --resume"), 2, "sweep.reps");
  expect_says(travbench("table build --scene sphere --reps 1 --resume --csv " + (dir / "build.csv").string()), 2,
              "--resume is not available");
  std::filesystem::remove_all(dir);
}

// The pieces of `table --resume` below the CLI: kept rows are replayed in order and each must be
// the table's cell at its place; a scene of the same name but other content is refused.
TEST(CellStream, TableReplayChecksCellOrderAndSceneContent) {
  const auto dir = test::temp_dir("cellstream_replay");
  const std::string csv = (dir / "t.csv").string();
  const nlohmann::json meta = {{"command", "table test"}};
  const Scene scene = load_scene("sphere");
  auto cell = [&](const char* workload) {
    Record r;
    r.set("scene", scene.name).set("workload", workload).set("scheme", "bvh_single").set("mrays_median", 1.5);
    return r;
  };
  {
    CellStream s(csv, meta, false, {"command"});
    s.check_scene(scene);
    s.append(cell("primary"));
    s.append(cell("shadow"));
  }  // "killed": never finished
  {
    CellStream s(csv, meta, true, {"command"});
    EXPECT_EQ(s.resumed(), 2u);
    s.check_scene(scene);
    const Record* first = s.replay(scene.name, "primary", "bvh_single");
    ASSERT_NE(first, nullptr);
    EXPECT_EQ(*first->get("mrays_median"), "1.5");
    EXPECT_NE(s.replay(scene.name, "shadow", "bvh_single"), nullptr);
    EXPECT_EQ(s.replay(scene.name, "rnd", "bvh_single"), nullptr);  // used up: measure it
  }
  {
    CellStream s(csv, meta, true, {"command"});
    EXPECT_THROW(s.replay(scene.name, "shadow", "bvh_single"), InputError);  // the table's cells changed
    Scene moved = scene;
    moved.positions[0].x += 1;
    EXPECT_THROW(s.check_scene(moved), InputError);
  }
  EXPECT_THROW(CellStream(csv, {{"command", "table other"}}, true, {"command"}), InputError);
  std::filesystem::remove_all(dir);
}

// A kept row's values are checked as `run --resume` and `compare` check them: a damaged speed or
// accuracy value is refused with its row and column, not printed and plotted as measured (the
// bounce table printed "abc" Mrays/s for such a row and finished with status complete).
TEST(CellStream, TableReplayRefusesDamagedValues) {
  const auto dir = test::temp_dir("cellstream_values");
  const std::string csv = (dir / "t.csv").string();
  const nlohmann::json meta = {{"command", "table test"}};
  auto expect_refused = [&](const char* col, const std::string& value, const std::string& says) {
    {
      CellStream s(csv, meta, false, {"command"});
      Record r;
      r.set("scene", "sphere").set("workload", "primary").set("scheme", "bvh_single").set("rays", 64);
      r.set("mrays_median", 1.5).set("mrays_min", 1.25).set("mismatch_rate", 0).set("false_miss", 0).set(col, value);
      s.append(r);
    }
    CellStream s(csv, meta, true, {"command"});
    try {
      s.replay("sphere", "primary", "bvh_single");
      ADD_FAILURE() << col << " '" << value << "' was kept";
    } catch (const InputError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("row 2"), std::string::npos) << m;
      EXPECT_NE(m.find(std::string(col) + " '" + value + "'"), std::string::npos) << m;
      EXPECT_NE(m.find(says), std::string::npos) << m;
    }
    std::filesystem::remove(csv);
    std::filesystem::remove(sidecar_path(csv));
  };
  expect_refused("mrays_median", "abc", "not a speed");
  expect_refused("mrays_median", "nan", "not a speed");
  expect_refused("mrays_min", "-3", "not a speed");
  expect_refused("mrays_median", "0", "not a speed");  // 64 rays: 0 Mrays/s was not measured
  expect_refused("mismatch_rate", "1.5", "a rate");
  expect_refused("false_miss", "-1", "a count");
  expect_refused("false_miss", "inf", "a count");
  // An empty speed is a table row that timed nothing, and stays.
  {
    CellStream s(csv, meta, false, {"command"});
    Record r;
    r.set("scene", "sphere").set("workload", "primary").set("scheme", "simt").set("mrays_median", "");
    s.append(r);
  }
  CellStream s(csv, meta, true, {"command"});
  EXPECT_NE(s.replay("sphere", "primary", "simt"), nullptr);
  std::filesystem::remove_all(dir);
}

TEST(CLI, BadInputGivesOneLineAndNonZeroExit) {
  const auto dir = test::temp_dir("cli_bad");
  std::ofstream(dir / "bad.bin") << "not rays";
  std::ofstream(dir / "bad.obj") << "v 0 0 0\nv 1 0 0\nf 1 2 9\n";
  const std::vector<std::string> cases = {
      "run --scene nowhere --schemes all --csv /tmp/x.csv",
      "run --scene room --schemes bvh_single,warp_drive --csv /tmp/x.csv",
      "run --scene room --schemes bvh_single --workloads bounce:0 --csv /tmp/x.csv",
      "run --scene room --schemes bvh_single --kernel fastest --csv /tmp/x.csv",
      "run --scene " + (dir / "missing.obj").string() + " --csv /tmp/x.csv",
      "run --scene " + (dir / "bad.obj").string() + " --csv /tmp/x.csv",
      "run --scene spheres:0 --csv /tmp/x.csv",
      "trace --scene room --scheme bvh_single --rays " + (dir / "bad.bin").string() + " --hits /tmp/h.bin",
      "trace --scene room --scheme bvh_single --rays " + dir.string() + " --hits /tmp/h.bin",
      "run --scene room --threads 0 --csv /tmp/x.csv",
      "table nonsense --csv /tmp/x.csv",
  };
  for (const auto& c : cases) {
    const Result r = travbench(c);
    EXPECT_NE(r.code, 0) << c;
    EXPECT_LT(r.code, 128) << "crashed: " << c;
    EXPECT_FALSE(r.out.empty()) << c;
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tb
