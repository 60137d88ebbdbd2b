// The command line contract (DESIGN.md): list output, run -> CSV columns, bad input -> one-line
// error and a non-zero exit, never a crash.
#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <sstream>

#include "test_util.h"

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

TEST(CLI, RaysAndTraceRoundTrip) {
  const auto dir = test::temp_dir("cli_rays");
  const std::string rays = (dir / "r.bin").string(), hits = (dir / "h.bin").string();
  ASSERT_EQ(travbench("rays --scene room --workload bounce:1 --width 32 --height 32 --out " + rays).code, 0);
  const Result t = travbench("trace --scene room --scheme bvh_single --rays " + rays + " --hits " + hits);
  EXPECT_EQ(t.code, 0) << t.out;
  EXPECT_GT(std::filesystem::file_size(hits), 16u);
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
