// Bad command lines that used to do damage or waste a run (test_bad_input.cpp has the rest of the
// contract): an output path that is a device, FIFO or socket (replaced by a regular file, or
// refused only after the whole run), a symlink (replaced by `compare`/`table`, written through by
// `run`), an output that is an input or another output of the same command, a seed beyond 64 bits,
// a parameter given twice, and table options that failed late or were ignored while the sidecar
// recorded them. Each is refused before any work, in one line, and leaves every file as it was.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>

#include "cli_test.h"
#include "harness/image.h"
#include "harness/records.h"
#include "structures/scene_loader.h"
#include "workloads/ray_file.h"

namespace fs = std::filesystem;

namespace tb {
namespace {

class BadInputCli : public test::CliTest {
 protected:
  std::string read(const std::string& name) const {
    std::ifstream f(path(name), std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(f)), {});
  }
  bool is_fifo(const std::string& name) const {
    struct stat st {};
    return ::lstat(path(name).c_str(), &st) == 0 && S_ISFIFO(st.st_mode);
  }
  // A bound Unix socket: a path that open() refuses (ENXIO) and a rename would replace.
  void make_socket(const std::string& name) const {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    ASSERT_GE(fd, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    ASSERT_LT(path(name).size(), sizeof addr.sun_path);
    std::strcpy(addr.sun_path, path(name).c_str());
    ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr), 0) << std::strerror(errno);
    ::close(fd);  // the socket file stays
  }
  // A small run CSV for `compare` (and a file to point links at).
  std::string run_csv(const std::string& name) const {
    const test::CliResult r = travbench("run --scene sphere --schemes bvh_single --workloads primary --reps 2 --width 16 "
                                        "--height 16 --csv " + path(name));
    EXPECT_EQ(r.code, 0) << r.err;
    return path(name);
  }
  std::string rays_file(const std::string& name) const {
    const test::CliResult r =
        travbench("rays --scene sphere --workload primary --width 16 --height 16 --out " + path(name));
    EXPECT_EQ(r.code, 0) << r.err;
    return path(name);
  }
  static constexpr const char* kTri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
};

// ---------------------------------------------------------------------------------------------
// 1. Output paths that are not regular files: refused while parsing, never replaced.

TEST_F(BadInputCli, OutputThatIsAFifoOrSocketIsRefusedAndKept) {
  const std::string a = run_csv("a.csv");
  ASSERT_EQ(::mkfifo(path("fifo.csv").c_str(), 0600), 0);
  make_socket("sock.csv");
  make_socket("side.json");
  // compare and table wrote <target>.tmp and renamed it over the FIFO.
  expect_rejected("compare " + a + " " + a + " --csv " + path("fifo.csv"), {"--csv", "fifo.csv", "a FIFO", "not a regular file"});
  EXPECT_TRUE(is_fifo("fifo.csv")) << "the FIFO was replaced";
  expect_rejected("table simt --scene sphere --width 16 --height 16 --csv " + path("fifo.csv"), {"--csv", "a FIFO"});
  EXPECT_TRUE(is_fifo("fifo.csv")) << "the FIFO was replaced";
  // run and trace failed only after the whole run (the socket cannot be opened).
  expect_rejected("run --scene sphere --schemes bvh_single --width 16 --height 16 --reps 1 --csv " + path("sock.csv"),
                  {"--csv", "a socket"});
  expect_rejected("trace --scene sphere --scheme bvh_single --rays " + rays_file("r.bin") + " --hits " + path("sock.csv"),
                  {"--hits", "a socket"});
  expect_rejected("rays --scene sphere --workload primary --out " + path("sock.csv"), {"--out", "a socket"});
  // The sidecar is an output too: x.csv's is x.json.
  expect_rejected("compare " + a + " " + a + " --csv " + path("side.csv"), {"sidecar", "side.json", "a socket"});
  expect_rejected("run --scene sphere --schemes bvh_single --csv " + path("side.csv"), {"sidecar", "a socket"});
  std::error_code ec;
  EXPECT_TRUE(fs::is_socket(fs::symlink_status(path("side.json"), ec)));
  EXPECT_TRUE(fs::is_socket(fs::symlink_status(path("sock.csv"), ec)));
  EXPECT_FALSE(fs::exists(dir_ / "side.csv"));
}

// write_file_durably, below every command, refuses a non-regular target the same way.
TEST_F(BadInputCli, DurableWriteRefusesANonRegularTarget) {
  ASSERT_EQ(::mkfifo(path("fifo").c_str(), 0600), 0);
  EXPECT_THROW(write_file_durably(path("fifo"), "x\n"), InputError);
  EXPECT_TRUE(is_fifo("fifo"));
  EXPECT_THROW(check_output_file(path("fifo")), InputError);
  EXPECT_NO_THROW(check_output_file(path("new.csv")));
}

// A durably written file gets the mode open(0644) would give under the process' umask (mkostemp
// makes the temporary 0600), and the umask is read without being changed (no moment in which a
// file another thread creates would get 0666).
TEST_F(BadInputCli, DurableWriteTakesTheUmaskWithoutChangingIt) {
  for (const mode_t mask : {mode_t(027), mode_t(022), mode_t(077)}) {
    const mode_t old = ::umask(mask);
    write_file_durably(path("mode.csv"), "x\n");
    const mode_t now = ::umask(old);
    struct stat st {};
    ASSERT_EQ(::stat(path("mode.csv").c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 0777, 0644 & ~mask) << "umask " << std::oct << mask;
    EXPECT_EQ(now, mask) << "the umask was changed";
  }
}

// Ray files, hit files and images are written like the CSVs (temporary + rename): a write that
// fails part-way (here the file-size limit, as a full disk would) leaves the old file whole and no
// temporary behind. They were written in place: a cut file with a valid header.
TEST_F(BadInputCli, AFailedWriteLeavesTheOldRayHitAndImageFiles) {
  auto batch_of = [](size_t n) {
    RayBatch b;
    for (size_t i = 0; i < n; ++i) b.rays.push_back(Ray{{float(i), 0, 0}, 0.f, {0, 0, 1}, 1e30f});
    b.group_uniform(4);
    return b;
  };
  write_rays(path("r.bin"), batch_of(2));
  write_hits(path("h.bin"), std::vector<Hit>(2));
  std::vector<uint8_t> rgb(64 * 64 * 3);
  std::mt19937 noise(7);
  for (uint8_t& c : rgb) c = uint8_t(noise());  // incompressible: ~12 KB of PNG
  write_rgb_png(path("i.png"), 2, 2, std::vector<uint8_t>(12, 200));
  const std::string rays = read("r.bin"), hits = read("h.bin"), png = read("i.png");
  ASSERT_LT(std::max({rays.size(), hits.size(), png.size()}), 512u);

  rlimit old{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // write() then fails with EFBIG
  rlimit small = old;
  small.rlim_cur = 1024;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  EXPECT_THROW(write_rays(path("r.bin"), batch_of(1000)), InputError);
  EXPECT_THROW(write_hits(path("h.bin"), std::vector<Hit>(1000)), InputError);
  EXPECT_THROW(write_rgb_png(path("i.png"), 64, 64, rgb), InputError);
  ::setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);

  EXPECT_EQ(read("r.bin"), rays);
  EXPECT_EQ(read("h.bin"), hits);
  EXPECT_EQ(read("i.png"), png);
  EXPECT_EQ(read_rays(path("r.bin")).size(), 2u);
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path() << " left behind";
}

// A symlink is written through by every command (run appended through it; compare replaced it).
TEST_F(BadInputCli, SymlinkOutputIsWrittenThroughNotReplaced) {
  const std::string a = run_csv("a.csv");
  write("real.csv", "old\n");
  fs::create_symlink("real.csv", dir_ / "link.csv");             // relative, as ln -s makes it
  fs::create_symlink(dir_ / "new_target.csv", dir_ / "dangling.csv");  // to a file not there yet
  const test::CliResult r = travbench("compare " + a + " " + a + " --csv " + path("link.csv"));
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::is_symlink(dir_ / "link.csv")) << "the link was replaced by a file";
  EXPECT_NE(read("real.csv"), "old\n");
  EXPECT_NE(read("real.csv").find("ratio"), std::string::npos) << read("real.csv");
  const test::CliResult d = travbench("compare " + a + " " + a + " --csv " + path("dangling.csv"));
  ASSERT_EQ(d.code, 0) << d.err;
  EXPECT_TRUE(fs::is_symlink(dir_ / "dangling.csv"));
  EXPECT_TRUE(fs::is_regular_file(dir_ / "new_target.csv"));
  // The same rule in the library: the target is what is written.
  fs::create_symlink("real.csv", dir_ / "link2.csv");
  write_file_durably(path("link2.csv"), "through\n");
  EXPECT_TRUE(fs::is_symlink(dir_ / "link2.csv"));
  EXPECT_EQ(read("real.csv"), "through\n");
  // A link to a FIFO is refused like the FIFO.
  ASSERT_EQ(::mkfifo(path("fifo").c_str(), 0600), 0);
  fs::create_symlink("fifo", dir_ / "to_fifo.csv");
  expect_rejected("compare " + a + " " + a + " --csv " + path("to_fifo.csv"), {"--csv", "a link to", "a FIFO"});
  EXPECT_TRUE(is_fifo("fifo"));
}

// ---------------------------------------------------------------------------------------------
// 2. An output that is an input, or another output of the same command.

TEST_F(BadInputCli, OutputThatIsAnInputIsRefusedAndTheInputKept) {
  const std::string rays = rays_file("r.bin");
  const std::string rays_bytes = read("r.bin");
  const std::string trace = "trace --scene sphere --scheme bvh_single --rays " + rays;
  expect_rejected(trace + " --hits " + rays, {"--hits", "--rays", "same file"});
  // The same file under another name: ./, a hard link, a symlink.
  expect_rejected(trace + " --hits " + (dir_ / "." / "r.bin").string(), {"--hits", "same file"});
  fs::create_hard_link(dir_ / "r.bin", dir_ / "hard.bin");
  expect_rejected(trace + " --hits " + path("hard.bin"), {"--hits", "same file"});
  fs::create_symlink("r.bin", dir_ / "soft.bin");
  expect_rejected(trace + " --hits " + path("soft.bin"), {"--hits", "same file"});
  expect_rejected(trace + " --csv " + rays, {"--csv", "same file"});
  // The sidecar of --csv r.csv is r.json.
  fs::copy_file(dir_ / "r.bin", dir_ / "r.json");
  expect_rejected("trace --scene sphere --scheme bvh_single --rays " + path("r.json") + " --csv " + path("r.csv"),
                  {"sidecar", "same file"});
  EXPECT_EQ(read("r.bin"), rays_bytes);
  EXPECT_EQ(read("r.json"), rays_bytes);

  const std::string scene = write("s.obj", kTri);
  expect_rejected("run --scene " + scene + " --schemes bvh_single --csv " + scene, {"--csv", "--scene", "same file"});
  expect_rejected("table bounce --scene " + scene + " --csv " + scene, {"--csv", "--scene", "same file"});
  expect_rejected("rays --scene " + scene + " --workload primary --out " + scene, {"--out", "--scene"});
  expect_rejected("image --scene " + scene + " --scheme bvh_single --metric nodes --out " + scene, {"--out", "--scene"});
  expect_rejected("run --scene " + scene + "@1,2,3 --schemes bvh_single --csv " + scene, {"--csv", "--scene"});
  // The scenes.json beside a scene file holds its views: an input too.
  write("scenes.json", "{}");
  expect_rejected("run --scene " + scene + " --schemes bvh_single --csv " + path("scenes.json"), {"scenes.json", "same file"});
  EXPECT_EQ(read("s.obj"), kTri);
  EXPECT_EQ(read("scenes.json"), "{}");
  // A glTF file's external buffer (its URI percent-encoded, resolved against the file's directory)
  // is an input too: writing over it would leave a scene that no longer loads.
  std::string positions(36, '\0');
  const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  std::memcpy(positions.data(), xyz, sizeof xyz);
  write("tri angle.bin", positions);
  const std::string gltf = write("ext.gltf", R"({"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36, "uri": "tri%20angle.bin"}],
  "bufferViews": [{"buffer": 0, "byteLength": 36}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 3}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}]})");
  EXPECT_EQ(travbench("run --scene " + gltf + " --schemes bvh_single --reps 1 --width 16 --height 16 --csv " + path("ok.csv")).code, 0)
      << "the external-buffer scene loads";
  const std::string buffer = "'" + path("tri angle.bin") + "'";  // a shell word
  expect_rejected("run --scene " + gltf + " --schemes bvh_single --csv " + buffer,
                  {"--csv", "external file", "same file"});
  expect_rejected("rays --scene " + gltf + " --workload primary --out " + buffer, {"--out", "external file"});
  // The same JSON as a .glb's JSON chunk (only the header and that chunk are read for the check).
  std::string json = read("ext.gltf");
  json.resize((json.size() + 3) / 4 * 4, ' ');
  const uint32_t head[5] = {0x46546C67u /* glTF */, 2, uint32_t(20 + json.size()), uint32_t(json.size()), 0x4E4F534Au /* JSON */};
  std::string glb(reinterpret_cast<const char*>(head), sizeof head);
  const std::string glb_path = write("ext.glb", glb + json);
  expect_rejected("rays --scene " + glb_path + " --workload primary --out " + buffer, {"--out", "external file"});
  EXPECT_EQ(read("tri angle.bin"), positions);
  // A buffer whose file happens to be called scenes.json (in another directory than the scene's
  // views file) is named as the external file it is: the loader says which role each input has.
  fs::create_directories(dir_ / "sub");
  write("sub/scenes.json", positions);
  std::string sub_json = read("ext.gltf");
  sub_json.replace(sub_json.find("tri%20angle.bin"), 15, "sub/scenes.json");
  const std::string sub_gltf = write("sub_ext.gltf", sub_json);
  expect_rejected("rays --scene " + sub_gltf + " --workload primary --out " + path("sub/scenes.json"),
                  {"--out", "external file"});
  EXPECT_EQ(read("sub/scenes.json"), positions);

  const std::string a = run_csv("a.csv"), b = run_csv("b.csv");
  const std::string a_bytes = read("a.csv");
  expect_rejected("compare " + a + " " + b + " --csv " + a, {"--csv", "base", "same file"});
  expect_rejected("compare " + a + " " + b + " --csv " + path("./b.csv"), {"--csv", "new", "same file"});
  EXPECT_EQ(read("a.csv"), a_bytes);
}

TEST_F(BadInputCli, TwoOutputsThatAreOneFileAreRefused) {
  const std::string rays = rays_file("r.bin");
  // trace wrote the CSV, then the hits over it, and said "wrote X" for the CSV.
  expect_rejected("trace --scene sphere --scheme bvh_single --rays " + rays + " --csv " + path("x.csv") + " --hits " +
                      path("x.csv"),
                  {"--hits", "--csv", "same file"});
  // ... or the hits over the CSV's sidecar.
  expect_rejected("trace --scene sphere --scheme bvh_single --rays " + rays + " --csv " + path("x.csv") + " --hits " +
                      path("x.json"),
                  {"--hits", "sidecar", "same file"});
  EXPECT_FALSE(fs::exists(dir_ / "x.csv"));
  EXPECT_FALSE(fs::exists(dir_ / "x.json"));
}

// ---------------------------------------------------------------------------------------------
// 3, 4. Values that were silently changed: a seed beyond 64 bits, a parameter given twice.

TEST_F(BadInputCli, SeedBeyond64BitsIsRefusedNotClamped) {
  const std::string rays = "rays --scene sphere --workload primary --width 16 --height 16 --out " + path("r.bin");
  expect_rejected(rays + " --seed 99999999999999999999999", {"--seed", "out of range", "18446744073709551615"});
  expect_rejected(rays + " --seed 18446744073709551616", {"--seed", "out of range"});
  expect_rejected("run --scene sphere --seed 99999999999999999999999 --csv " + path("x.csv"), {"--seed"});
  EXPECT_FALSE(fs::exists(dir_ / "r.bin"));
  const test::CliResult max = travbench(rays + " --seed 18446744073709551615");
  EXPECT_EQ(max.code, 0) << max.err;
}

TEST_F(BadInputCli, ParameterGivenTwiceIsRefused) {
  const std::string csv = " --csv " + path("x.csv");
  expect_rejected("run --scene sphere --schemes bvh_single --param leaf_size=4 --param leaf_size=8" + csv,
                  {"--param", "leaf_size", "twice"});
  expect_rejected("run --scene sphere --schemes bvh_single --param leaf_size=4 --param leaf_size=4" + csv,
                  {"leaf_size", "twice"});
  expect_rejected("run --scene sphere --schemes bvh_single:leaf_size=4:leaf_size=8" + csv,
                  {"--schemes", "leaf_size", "twice"});
  expect_rejected("table bounce --scene sphere --schemes bvh_single:leaf_size=4:leaf_size=8" + csv, {"leaf_size", "twice"});
  // trace's --scheme takes an entry too; it is checked while parsing, like --schemes.
  expect_rejected("trace --scene sphere --scheme bvh_single:leaf_size=4:leaf_size=8 --rays " + path("none.bin") +
                      " --hits " + path("h.bin"),
                  {"--scheme", "leaf_size", "twice"});
  expect_rejected("image --scene sphere --scheme bvh_single --metric nodes --param leaf_size=2 --param leaf_size=3 --out " +
                      path("h.png"),
                  {"leaf_size", "twice"});
  EXPECT_FALSE(fs::exists(dir_ / "x.csv"));
  // One value per key, and an entry's own value beside a run-wide one, stay fine.
  EXPECT_EQ(travbench("run --scene sphere --schemes bvh_single:leaf_size=4 --param leaf_size=8 --workloads primary "
                      "--width 16 --height 16 --reps 1" + csv)
                .code,
            0);
}

// ---------------------------------------------------------------------------------------------
// 5. Table options checked before the first cell, and those a table does not take refused.

TEST_F(BadInputCli, TableSceneFileIsCheckedBeforeAnyWork) {
  // table build ran its two-level builds (minutes) before "file not found".
  expect_rejected("table build --scene " + path("nonexist.obj") + " --csv " + path("b.csv"),
                  {"--scene", "nonexist.obj", "file not found"});
  expect_rejected("table scaling --scene " + path("nonexist.obj") + " --csv " + path("b.csv"), {"--scene", "file not found"});
  expect_rejected("run --scene " + path("nonexist.ply") + " --csv " + path("b.csv"), {"--scene", "file not found"});
  write("scene.fbx", kTri);
  expect_rejected("table build --scene " + path("scene.fbx") + " --csv " + path("b.csv"), {"--scene", "extension"});
  EXPECT_FALSE(fs::exists(dir_ / "b.csv"));
}

TEST_F(BadInputCli, TableKernelIsCheckedForEverySchemeBeforeTheFirstCell) {
  // scaling measured bvh_single ... mbvh8_packet, then refused cwbvh_single, leaving their cells.
  const std::string small = " --width 16 --height 16 --reps 1 --csv " + path("t.csv");
  expect_rejected("table scaling --scene sphere --kernel moller" + small, {"cwbvh_single", "--kernel moller"});
  expect_rejected("table cache --scene sphere --reps 1 --kernel moller --csv " + path("t.csv"), {"--kernel moller"});
  expect_rejected("table build --scene sphere --reps 1 --kernel moller --csv " + path("t.csv"), {"--kernel moller"});
  expect_rejected("table bandwidth --scene sphere --kernel plane" + small, {"--kernel plane"});
  EXPECT_FALSE(fs::exists(dir_ / "t.csv")) << "cells were measured before the refusal";
  // The tables whose Embree rows are anchors run them with their own test: still accepted.
  const test::CliResult ok =
      travbench("table bounce --scene sphere --schemes bvh_single,embree_single --kernel moller" + small);
  EXPECT_EQ(ok.code, 0) << ok.err;
}

TEST_F(BadInputCli, TableOptionsATableDoesNotTakeAreRefused) {
  const std::string csv = " --csv " + path("t.csv");
  // simt's warp model has no CPU timing: --threads and --reps changed nothing but the sidecar.
  expect_rejected("table simt --scene sphere --threads 4" + csv, {"table simt", "does not take --threads"});
  expect_rejected("table simt --scene sphere --reps 3" + csv, {"table simt", "--reps"});
  // build skipped Embree entries (its Embree rows are fixed) and ignored the image options.
  expect_rejected("table build --scene sphere --schemes embree_single" + csv, {"table build", "embree_single"});
  expect_rejected("table build --scene sphere --schemes bvh_single --width 64" + csv, {"table build", "--width"});
  expect_rejected("table build --scene sphere --threads 2" + csv, {"table build", "--threads"});
  expect_rejected("table cache --scene sphere --width 64" + csv, {"table cache", "--width", "512x512"});
  expect_rejected("table accuracy --scene sphere --kernel moller" + csv, {"table accuracy", "--kernel"});
  // build and cache capped --reps at 5 and 3 without a word: refused above.
  expect_rejected("table build --scene sphere --reps 6" + csv, {"table build takes --reps 1..5", "not 6"});
  expect_rejected("table cache --scene sphere --reps 4" + csv, {"table cache takes --reps 1..3", "not 4"});
  EXPECT_FALSE(fs::exists(dir_ / "t.csv"));
  EXPECT_FALSE(fs::exists(dir_ / "t.json"));
  // simt's lanes do run --kernel's triangle test: its rows say which.
  const test::CliResult simt = travbench("table simt --scene sphere --width 16 --height 16 --kernel moller" + csv);
  ASSERT_EQ(simt.code, 0) << simt.err;
  std::ifstream f(path("t.csv"));
  std::string header, row;
  std::getline(f, header);
  std::getline(f, row);
  EXPECT_NE(header.find(",kernel"), std::string::npos) << header;
  EXPECT_NE(row.find(",moller"), std::string::npos) << row;
}

// ---------------------------------------------------------------------------------------------
// 6. Usage errors exit 2 with one hint; CR-only OBJ files load.

TEST_F(BadInputCli, BadSchemesOrWorkloadsExitTwoWithOneHint) {
  for (const std::string& args : {"run --scene sphere --schemes warp_drive --csv " + path("x.csv"),
                                 "run --scene sphere --workloads warp --csv " + path("x.csv"),
                                 "run --scene sphere --threads 0 --csv " + path("x.csv"), std::string("run --scene sphere")}) {
    SCOPED_TRACE(args);
    expect_rejected(args, {"see travbench --help"});
    const test::CliResult r = travbench(args);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(r.err.find("--help"), r.err.rfind("--help")) << "the hint twice: " << r.err;
  }
  EXPECT_EQ(travbench("--help").code, 0);
}

TEST_F(BadInputCli, ObjWithCarriageReturnLineEndsLoads) {
  const std::string lf = "# a quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n";
  std::string cr = lf, crlf;
  for (char& c : cr)
    if (c == '\n') c = '\r';
  for (char c : lf) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  const Scene want = load_obj(write("lf.obj", lf));
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"cr.obj", cr}, {"crlf.obj", crlf}}) {
    SCOPED_TRACE(name);
    const Scene got = load_obj(write(name, text));
    EXPECT_EQ(got.triangles, want.triangles);
    EXPECT_EQ(got.positions.size(), want.positions.size());
  }
  // Line numbers in messages count CR-only lines too.
  try {
    load_obj(write("bad.obj", "v 0 0 0\rv 1 0 0\rf 1 2 9\r"));
    ADD_FAILURE() << "index 9 of 2 vertices accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 3:"), std::string::npos) << e.what();
  }
  const test::CliResult r =
      travbench("rays --scene " + path("cr.obj") + " --workload primary --width 16 --height 16 --out " + path("r.bin"));
  EXPECT_EQ(r.code, 0) << r.err;
}

}  // namespace
}  // namespace tb
