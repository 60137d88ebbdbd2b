// Bad input, end to end: every input path of the travbench binary (option values, scene files of
// every format, ray files, din traces) must answer bad input with exactly one line on stderr that
// names the option or file and what is wrong, and a non-zero exit status; never a signal, a hang, a
// sanitizer report or an unbounded allocation. The per-format details (every message of every
// parser) are in test_loaders.cpp, test_workloads.cpp (RayFile) and test_cachesim.cpp; this suite
// checks the same classes through the command line, adds what those do not cover (huge declared
// counts, FIFOs, paths through a file, zero-triangle scenes of every format), replays the fuzzers'
// committed findings and seeds, and checks that degenerate triangles are kept and never hit.
// tests/README.md has the table of bad-input classes and where each is covered.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "cachesim/din_trace.h"
#include "harness/trace_runner.h"
#include "structures/scene_loader.h"
#include "cli_test.h"
#include "test_util.h"
#include "traversal/registry.h"
#include "workloads/ray_file.h"

namespace fs = std::filesystem;

namespace tb {
namespace {

// ---------------------------------------------------------------------------------------------
// Helpers

// The binary under `timeout`, one-line error contract: tests/cli_test.h.
class BadInput : public test::CliTest {};
using test::CliResult;

template <class T>
void put(std::string& b, T v) {
  b.append(reinterpret_cast<const char*>(&v), sizeof v);
}

std::string ray_file(const std::vector<Ray>& rays, uint32_t packet_size = 4, uint64_t count_override = ~0ull,
                     uint32_t packet_count = 0, const std::vector<uint32_t>& table = {}) {
  std::string b = "TBRAYS1";
  b.push_back('\0');
  put<uint64_t>(b, count_override == ~0ull ? rays.size() : count_override);
  put<uint32_t>(b, packet_size);
  put<uint32_t>(b, packet_count);
  for (const Ray& r : rays)
    for (float v : {r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z, r.tmin, r.tmax}) put(b, v);
  for (uint32_t t : table) put(b, t);
  return b;
}

const std::vector<Ray> kTwoRays = {{{0, 0, -5}, 0, {0, 0, 1}, 1e30f}, {{0.1f, 0, -5}, 0, {0, 0, 1}, 1e30f}};

// A minimal .gltf: one triangle in a base64 data buffer; `patch` edits the JSON text.
std::string gltf_triangle(const std::string& accessor_extra = "", const std::string& buffer = "") {
  // 3 float3 positions: (0,0,0) (1,0,0) (0,1,0), base64 of 36 bytes.
  const std::string b64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA";
  const std::string buf = buffer.empty()
                              ? R"({"byteLength": 36, "uri": "data:application/octet-stream;base64,)" + b64 + R"("})"
                              : buffer;
  return R"({"asset": {"version": "2.0"}, "buffers": [)" + buf +
         R"(], "bufferViews": [{"buffer": 0, "byteLength": 36}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 3)" + accessor_extra +
         R"(}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}]})";
}

// ---------------------------------------------------------------------------------------------
// Option values: validated while parsing, before any work; the message names the option.

TEST_F(BadInput, OptionValuesAreValidatedAndNamed) {
  const std::string csv = " --csv " + path("x.csv");
  const std::string rays = "rays --scene sphere --workload primary --width 16 --height 16 --out " + path("r.bin");
  fs::create_directories(dir_ / "adir");
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"run --scene room --threads 0" + csv, {"--threads"}},
      {"run --scene room --threads 257" + csv, {"--threads"}},
      {"run --scene room --threads two" + csv, {"--threads"}},
      {"run --scene room --reps 0" + csv, {"--reps"}},
      {"run --scene room --reps 1001" + csv, {"--reps"}},
      {"run --scene room --seed -1" + csv, {"--seed"}},
      {rays + " --width 8", {"--width"}},
      {rays + " --height 16385", {"--height"}},
      {rays + " --width -16", {"--width"}},
      {rays + " --view 0", {"--view"}},
      {rays + " --view 4", {"--view 4", "3 camera views"}},  // range ok, but the scene has 3 views
      // A view given to workloads no view changes would label their rows with it: refused.
      {"run --scene room --workloads primary,rnd2 --view 2" + csv, {"--view", "'rnd2'", "without --view"}},
      {"rays --scene room --workload hard:edges --view 2 --out " + path("r.bin"), {"--view", "'hard:edges'"}},
      // The thesis camera changes only the rays traced through the camera's pixels.
      {"rays --scene room --workload rnd2 --camera thesis --out " + path("r.bin"), {"--camera thesis", "'rnd2'"}},
      {rays + " --camera fisheye", {"--camera"}},
      {"trace --scene room --scheme bvh_single --rays " + path("r.bin") + " --stats --hits " + path("h.bin"),
       {"--stats needs --csv"}},
      {"run --scene room --workloads divergence:0" + csv, {"--workloads", "divergence:0"}},
      {"run --scene room --workloads divergence:4096" + csv, {"--workloads", "divergence"}},
      {"run --scene room --workloads primary,bounce:0" + csv, {"--workloads", "bounce:0"}},
      {"run --scene room --workloads bounce:x" + csv, {"--workloads", "bounce:x"}},
      {"run --scene room --workloads bounce:2/1.5" + csv, {"--workloads", "survival", "(0, 1]"}},
      {"table divergence --schemes bvh_ranged --param tile=4" + csv, {"tile=4", "16|8"}},
      {"table divergence --schemes bvh_ranged --param camera=wide" + csv, {"camera=wide", "thesis|view"}},
      {"run --scene room --workloads primary,warp" + csv, {"--workloads", "warp"}},
      {"run --scene room --workloads ," + csv, {"--workloads", "empty"}},
      {"rays --scene room --workload bounce:17 --out " + path("r.bin"), {"--workload", "bounce:17"}},
      {"rays --scene room --workload hard:nonsense --out " + path("r.bin"), {"--workload", "hard:nonsense"}},
      {"run --scene room --kernel fastest" + csv, {"--kernel", "fastest"}},
      {"run --scene room --schemes bvh_single,warp_drive" + csv, {"--schemes", "warp_drive"}},
      {"run --scene room --schemes ," + csv, {"--schemes"}},
      {"trace --scene room --scheme warp_drive --rays x --hits " + path("h.bin"), {"--scheme", "warp_drive"}},
      {"run --scene room --param leaf_size" + csv, {"--param", "leaf_size"}},
      {"run --scene room --param =4" + csv, {"--param"}},
      // Declared parameters (traversal/params.h): a typo names the closest key, a bad value the range.
      {"run --scene room --schemes bvh_single --param leafsize=8" + csv, {"leafsize", "did you mean leaf_size"}},
      {"run --scene room --schemes bvh_single --param leaf_size=0" + csv, {"leaf_size=0", "[1, 64]"}},
      {"run --scene room --schemes bvh_single --param leaf_size=4.5" + csv, {"leaf_size=4.5", "integer"}},
      {"run --scene room --schemes mbvh8_single --param collapse=best" + csv, {"collapse=best", "greedy|sah"}},
      {"run --scene room --schemes mbvh_rs --param width=6" + csv, {"width=6", "4|8"}},
      {"run --scene room --schemes bvh_masked --param split=2" + csv, {"split=2", "0|1"}},
      // ... and a key no scheme of the run declares, even when another registered scheme does.
      {"run --scene room --schemes bvh_single,embree_single --param queue=64" + csv,
       {"queue", "bvh_single, embree_single", "leaf_size", "robust"}},
      {"trace --scene room --scheme bvh_single --rays x --hits " + path("h.bin") + " --param stream=8",
       {"stream", "scheme bvh_single"}},
      {"table raygrid --param sweep=2" + csv, {"sweep=2"}},
      // table pathtrace (issue 22): its own parameters' ranges and their relation.
      {"table pathtrace --scene room --param min_spp=0" + csv, {"min_spp=0", "[1, 4096]"}},
      {"table pathtrace --scene room --param ref_spp=x" + csv, {"ref_spp=x", "integer"}},
      {"table pathtrace --scene room --param min_spp=16 --param max_spp=8" + csv, {"min_spp", "max_spp"}},
      // Options a subcommand does not use are not offered.
      {rays + " --reps 3", {"--reps"}},
      {rays + " --kernel moller", {"--kernel"}},
      {rays + " --threads 2", {"--threads"}},
      {rays + " --param leaf_size=4", {"--param"}},
      {"trace --scene room --scheme bvh_single --rays x --width 64 --hits " + path("h.bin"), {"--width"}},
      {"trace --scene room --scheme bvh_single --rays x", {"--hits", "--csv"}},
      {"list schemes bvh_single", {"list params"}},
      {"list params warp_drive", {"warp_drive"}},
      {"run --scene room --cache --cache-config l1=33K:8" + csv, {"--cache-config", "power of two"}},
      {"run --scene room --cache --cache-policy fifo" + csv, {"--cache-policy", "fifo"}},
      // Options that only mean something with another: refused without it, never ignored.
      {"run --scene room --cache-config l1=32K:8" + csv, {"--cache-config", "--cache"}},
      {"trace --scene room --scheme bvh_single --rays x --cache-policy lru --csv " + path("t.csv"),
       {"--cache-policy", "--cache"}},
      {"rays --scene room --workload primary --spp 4 --out " + path("r.bin"), {"--spp", "--pathtrace"}},
      {"cachesim --config l1=32K:8,l2=100K:8 --trace -", {"--config", "power of two"}},
      {"cachesim --config l1=32K:8:48 --trace -", {"--config", "line size"}},
      {"cachesim --config l1=32K:3 --trace -", {"--config", "associativity"}},
      {"cachesim --config l1=32K:8,l2=256K:8:32 --trace -", {"--config", "line size"}},
      {"cachesim --policy fifo --trace -", {"--policy", "fifo"}},
      {"run --scene room --csv " + path("no/such/dir/x.csv"), {"--csv", "does not exist"}},
      {"run --scene room --csv " + path("adir"), {"--csv", "is a directory"}},
      {"rays --scene room --workload primary --out " + path("adir"), {"--out", "is a directory"}},
      {"trace --scene room --scheme bvh_single --rays x --hits " + path("nodir/h.bin"), {"--hits", "does not exist"}},
      {"run --scene room --schemes bvh_single" + csv + " --bogus", {"--bogus"}},
      {"run --schemes bvh_single" + csv, {"--scene", "required"}},
      {"run --scene room", {"--csv", "required"}},
      {"run --scene \"\"" + csv, {"--scene"}},
      {"table nonsense" + csv, {"nonsense"}},
      {"list nonsense", {"nonsense"}},
      {"frobnicate", {"subcommand"}},
      {"", {"subcommand"}},
  };
  for (const auto& [args, needles] : cases) expect_rejected(args, needles);
}

TEST_F(BadInput, UnknownNamesAreOneLine) {
  const std::string csv = " --csv " + path("x.csv");
  expect_rejected("run --scene nowhere" + csv, {"--scene", "unknown scene 'nowhere'"});
  expect_rejected("run --scene spheres:0" + csv, {"--scene", "spheres:0"});
  expect_rejected("run --scene spheres:x" + csv, {"--scene", "spheres:x"});
  expect_rejected("run --scene sphere@1,2" + csv, {"--scene", "sphere@1,2"});
  expect_rejected("run --scene sphere@nan,0,0" + csv, {"--scene", "sphere@nan,0,0"});
  expect_rejected("run --scene sphere@1e39,0,0" + csv, {"--scene"});
  // Trailing text after the offset was ignored; an offset that flattens every triangle to zero
  // area (float spacing at 1e30 is 2^70) traced an empty scene.
  expect_rejected("run --scene sphere@1,2,3xyz" + csv, {"--scene", "sphere@1,2,3xyz"});
  expect_rejected("run --scene sphere@1,2,3,4" + csv, {"--scene", "sphere@1,2,3,4"});
  expect_rejected("run --scene sphere@1e16,1e16,1e16" + csv, {"--scene", "collapses all"});
  expect_rejected("run --scene sphere@1e17,0,0" + csv, {"--scene", "2^56"});
  // The offset is three decimal numbers and nothing else: sscanf took whitespace and hex floats.
  expect_rejected("run --scene 'sphere@ 1,2,3'" + csv, {"--scene"});
  expect_rejected("run --scene sphere@0x10,0,0" + csv, {"--scene", "sphere@0x10,0,0"});
  expect_rejected("run --scene sphere@1,+2,3" + csv, {"--scene"});
  // A first word that is no subcommand is named; 'all' is not a scheme inside a list.
  expect_rejected("warp_drive --scene sphere" + csv, {"unknown subcommand 'warp_drive'", "run"});
  expect_rejected("run --scene sphere --schemes all,bvh_single" + csv, {"--schemes", "'all' stands alone"});
}

// A parameter that changes nothing under the values of the others is refused, naming why (every
// option works or is refused; found by an audit of every scheme's parameters, session 37).
TEST_F(BadInput, ParametersThatChangeNothingAreRefused) {
  const std::string run = "run --scene room --workloads primary --width 16 --height 16 --reps 1 --csv " + path("x.csv") +
                          " --schemes ";
  expect_rejected(run + "mbvh4_single:tri_cost=50", {"tri_cost", "collapse=greedy"});
  expect_rejected(run + "mbvh_rs:width=4:prim_cost=20", {"prim_cost", "collapse=greedy"});
  expect_rejected(run + "mbvh8_single:prim_share=0.5", {"prim_share", "prim_cost"});
  expect_rejected(run + "mbvh8_single:tri_width=4:small=4", {"small", "tri_width=4"});
  expect_rejected(run + "mbvh8_single:tri_width=4:order=sort", {"order", "tri_width=4"});
  expect_rejected(run + "mbvh8_single:order=branching:prefetch=on", {"prefetch", "order=branching"});
  expect_rejected(run + "mbvh8_single:prefetch=off:llc_mib=8", {"llc_mib", "prefetch=off"});
  expect_rejected(run + "cwbvh_single:order=octant:prefetch=on", {"prefetch", "order=octant"});
  expect_rejected(run + "bvh_ranged:subfrusta=0", {"subfrusta", "tricull"});
  expect_rejected(run + "treelet_queue:small=4", {"small must be 0"});
  expect_rejected("table pathtrace --scene room --threads 2 --csv " + path("p.csv"), {"--threads"});
  // Where they act, the same values are taken.
  for (const std::string ok : {"mbvh4_single:collapse=sah:tri_cost=50", "mbvh8_single:prim_cost=20:prim_share=0.5",
                               "mbvh8_single:order=sort:prefetch=on", "bvh_ranged:tricull=1:subfrusta=0",
                               "treelet_queue:tree=mbvh8:small=4"}) {
    const CliResult r = travbench(run + ok);
    EXPECT_EQ(r.code, 0) << ok << ": " << r.err;
  }
}

// A scene whose every triangle is degenerate traces nothing: refused when it loads (it ran every
// cell with every ray a miss, and only rnd2 failed, after the other cells), in any format.
TEST_F(BadInput, SceneOfOnlyDegenerateTrianglesIsRefused) {
  const std::string tail = " --workload primary --width 16 --height 16 --out " + path("r.bin");
  for (const auto& [name, text] : std::vector<std::pair<std::string, std::string>>{
           {"point.obj", "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\nf 1 2 3\n"},
           {"line.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n"},
           {"denormal.obj", "v 0 0 0\nv 1e-40 0 0\nv 0 1e-40 0\nf 1 2 3\n"},
           {"line.off", "OFF\n3 1 0\n0 0 0\n1 1 1\n2 2 2\n3 0 1 2\n"}}) {
    SCOPED_TRACE(name);
    write(name, text);
    expect_rejected("rays --scene " + path(name) + tail, {"--scene", name, "degenerate", "nothing a ray can hit"});
  }
  // One real triangle among them is a scene (DegenerateTrianglesAreKeptAndNeverHit).
  write("one.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 2 2\nf 1 2 3\nf 4 4 4\n");
  EXPECT_EQ(travbench("rays --scene " + path("one.obj") + tail).code, 0);
  // Triangles with area in float, but a scene too small for the kernels' products (vec3.h,
  // kMinSceneExtent): every scheme gave false hits and misses on one 1e-18 across.
  write("tiny.obj", "v 1e-18 1e-18 1e-18\nv 2e-18 1e-18 1e-18\nv 1e-18 2e-18 1e-18\nf 1 2 3\n");
  expect_rejected("rays --scene " + path("tiny.obj") + tail, {"--scene", "tiny.obj", "below 2^-51"});
  write("small.obj", "v 1e-12 1e-12 1e-12\nv 2e-12 1e-12 1e-12\nv 1e-12 2e-12 1e-12\nf 1 2 3\n");
  EXPECT_EQ(travbench("rays --scene " + path("small.obj") + tail).code, 0);
}

// ---------------------------------------------------------------------------------------------
// Scene files through the CLI: every class of bad file, every format.

TEST_F(BadInput, SceneFilesAreRejectedWithFileAndReason) {
  const std::string tail = " --workload primary --width 16 --height 16 --out " + path("r.bin");
  auto expect_scene = [&](const std::string& name, const std::string& bytes, const std::vector<std::string>& needles) {
    write(name, bytes);
    std::vector<std::string> n = needles;
    n.push_back("--scene");
    n.push_back(name);
    expect_rejected("rays --scene " + path(name) + tail, n);
  };
  const std::string v3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  // Truncated files.
  expect_scene("trunc.obj", v3 + "f 1 2", {"face has 2 vertices"});
  expect_scene("trunc.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n", {"file ends after 2 of 3 vertices"});
  expect_scene("trunc.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", {"no 'end_header'"});
  expect_scene("trunc.stl", "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n", {"truncated"});
  expect_scene("trunc.gltf", gltf_triangle().substr(0, 100), {"invalid glTF file"});
  // Wrong magic / not the format its extension says.
  expect_scene("magic.ply", "plx\nformat ascii 1.0\nend_header\n", {"not a PLY file"});
  expect_scene("magic.off", "hello world\n", {"not an OFF file"});
  expect_scene("magic.stl", "hello", {"not an STL file"});
  expect_scene("magic.glb", "glTF\x02\0\0\0garbage", {"invalid GLB file"});
  // Counts that do not match the size.
  {
    std::string stl(80, '\0');
    put<uint32_t>(stl, 1000);
    stl += std::string(50, '\0');
    expect_scene("count.stl", stl, {"declares 1000 triangles"});
  }
  expect_scene("count.off", "OFF\n100 1 0\n0 0 0\n", {"more than a"});
  // Indices out of range.
  expect_scene("oor.obj", v3 + "f 1 2 4\n", {"face uses vertex 4"});
  expect_scene("oor.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", {"vertex index 3 is out of range"});
  expect_scene("oor.ply",
               "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
               "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
               {"vertex index 7"});
  expect_scene("oor.gltf", gltf_triangle().replace(gltf_triangle().find("\"POSITION\": 0"), 13, "\"POSITION\": 5"),
               {"accessor 5 does not exist"});
  // NaN / Inf coordinates.
  expect_scene("nan.obj", "v 0 nan 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", {"NaN or Inf"});
  expect_scene("inf.off", "OFF\n3 1 0\n0 0 0\n1e39 0 0\n0 1 0\n3 0 1 2\n", {"NaN or Inf"});
  expect_scene("inf.ply",
               "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
               "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n",
               {"vertex 1 has a NaN or Inf"});
  // Coordinates beyond the traceable range (structures/vec3.h, kCoordLimit), every format's path.
  expect_scene("far.obj", "v 1e20 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", {"vertex 0", "beyond +-2^56"});
  expect_scene("far.off", "OFF\n3 1 0\n0 0 0\n1 -8e16 0\n0 1 0\n3 0 1 2\n", {"vertex 1", "beyond +-2^56"});
  {
    std::string stl(80, '\0');
    put<uint32_t>(stl, 1);
    for (float f : {0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, std::numeric_limits<float>::infinity(), 0.f})
      put(stl, f);
    put<uint16_t>(stl, 0);
    expect_scene("inf.stl", stl, {"NaN or Inf"});
  }
  // Empty meshes and zero-triangle scenes, every format.
  expect_scene("empty.obj", "", {"file is empty"});
  expect_scene("verts.obj", v3, {"has no triangles"});
  expect_scene("zero.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", {"has no triangles"});
  expect_scene("zero.ply",
               "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
               "element face 0\nproperty list uchar int vertex_indices\nend_header\n",
               {"declares no faces"});
  expect_scene("zero.stl", "solid empty\nendsolid empty\n", {"has no triangles"});
  {
    std::string stl(80, '\0');
    put<uint32_t>(stl, 0);
    expect_scene("zerobin.stl", stl, {"has no triangles"});
  }
  expect_scene("zero.gltf", R"({"asset": {"version": "2.0"}})", {"has no triangles"});
  expect_scene("lines.gltf", gltf_triangle().replace(gltf_triangle().find("}]}]"), 1, ", \"mode\": 1}"),
               {"lines.gltf", "mesh 0 primitive 0: is mode 1 (LINES)"});  // refused by name (issue 20)
  // Missing buffers in glTF.
  expect_scene("missingbuf.gltf", gltf_triangle("", R"({"byteLength": 36, "uri": "missing.bin"})"), {"missing.bin"});
  expect_scene("nobuffer.gltf", gltf_triangle("", R"({"byteLength": 36})"), {"invalid glTF file"});
  {
    std::string g = gltf_triangle();
    g.replace(g.find("\"buffer\": 0"), 11, "\"buffer\": 3");
    expect_scene("bufindex.gltf", g, {"names buffer 3"});
  }
  {  // GLB whose JSON declares a buffer but which has no BIN chunk
    std::string js = R"({"asset": {"version": "2.0"}, "buffers": [{"byteLength": 36}], "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 3}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}]})";
    while (js.size() % 4) js.push_back(' ');
    std::string glb = "glTF";
    put<uint32_t>(glb, 2);
    put<uint32_t>(glb, static_cast<uint32_t>(20 + js.size()));
    put<uint32_t>(glb, static_cast<uint32_t>(js.size()));
    put<uint32_t>(glb, 0x4E4F534Au);
    glb += js;
    expect_scene("nobin.glb", glb, {"invalid GLB file"});
  }
  // Huge declared counts: rejected from the header, without allocating what they declare.
  expect_scene("huge.off", "OFF\n9223372036854775807 9223372036854775807 0\n0 0 0\n", {"more than a"});
  expect_scene("huge2.off", "OFF\n2 9223372036854775807\n0 0 0\n", {"more than a"});
  expect_scene("huge.ply",
               "ply\nformat binary_little_endian 1.0\nelement vertex 4294967295\nproperty float x\nproperty float y\n"
               "property float z\nelement face 4294967295\nproperty list uchar int vertex_indices\nend_header\n",
               {"more than 2^32-2 vertices"});
  expect_scene("huge2.ply",
               "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
               "property float z\nelement face 4000000000\nproperty list uchar int vertex_indices\nend_header\n",
               {"more than the"});
  {
    std::string stl(80, '\0');
    put<uint32_t>(stl, 0xFFFFFFFFu);
    expect_scene("huge.stl", stl, {"declares 4294967295 triangles"});
  }
  expect_scene("huge.gltf", gltf_triangle().replace(gltf_triangle().find("\"count\": 3"), 10, "\"count\": 4294967290"),
               {"do not fit"});
  {  // an accessor without bufferView is all zeros: nothing bounds its count but this check
    const std::string g = R"({"asset": {"version": "2.0"},
      "accessors": [{"componentType": 5126, "type": "VEC3", "count": 4000000000}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}]})";
    expect_scene("hugezeros.gltf", g, {"has no bufferView but declares 4000000000 elements"});
    const std::string gi = R"({"asset": {"version": "2.0"},
      "accessors": [{"componentType": 5126, "type": "VEC3", "count": 3},
                    {"componentType": 5125, "type": "SCALAR", "count": 4000000000}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}], "nodes": [{"mesh": 0}]})";
    expect_scene("hugeidx.gltf", gi, {"accessor[1]"});  // tinygltf wants a bufferView for indices
  }
  // Unknown extension.
  expect_scene("scene.fbx", v3, {"unknown scene file extension"});
}

TEST_F(BadInput, PathsThatAreNotReadableFiles) {
  const std::string tail = " --workload primary --width 16 --height 16 --out " + path("r.bin");
  std::ofstream(dir_ / "file.obj") << "v 0 0 0\n";
  for (const char* ext : {".obj", ".off", ".ply", ".stl", ".gltf", ".glb"}) fs::create_directories(dir_ / (std::string("dir") + ext));
  ASSERT_EQ(::mkfifo(path("fifo.obj").c_str(), 0600), 0);
  ASSERT_EQ(::mkfifo(path("fifo.bin").c_str(), 0600), 0);
  ASSERT_EQ(::mkfifo(path("fifo.bin2").c_str(), 0600), 0);
  for (const char* ext : {".obj", ".off", ".ply", ".stl", ".gltf", ".glb"})
    expect_rejected("rays --scene " + path(std::string("dir") + ext) + tail, {"--scene", "is a directory"});
  expect_rejected("rays --scene " + path("dir.obj") + tail, {"is a directory"});
  expect_rejected("rays --scene " + path("missing.ply") + tail, {"file not found"});
  expect_rejected("rays --scene " + path("file.obj/inner.obj") + tail, {"file.obj/inner.obj"});  // ENOTDIR
  expect_rejected("rays --scene " + path("fifo.obj") + tail, {"not a regular file"});          // would block
  // A glTF buffer URI naming a FIFO, a directory or the glTF's own directory must not block or crash.
  for (const std::string uri : {"fifo.bin", "dir.obj", "."}) {
    write("ext.gltf", gltf_triangle("", R"({"byteLength": 36, "uri": ")" + uri + R"("})"));
    expect_rejected("rays --scene " + path("ext.gltf") + tail, {"ext.gltf"});
  }
  // Ray files.
  const std::string trace = "trace --scene sphere --scheme bvh_single --hits " + path("h.bin") + " --rays ";
  expect_rejected(trace + dir_.string(), {"is a directory"});
  expect_rejected(trace + path("missing.bin"), {"missing.bin", "cannot open"});
  expect_rejected(trace + path("file.obj/r.bin"), {"r.bin"});
  expect_rejected(trace + path("fifo.bin2"), {"not a regular file"});
  // Din traces.
  expect_rejected("cachesim --trace " + dir_.string(), {"is a directory"});
  expect_rejected("cachesim --trace " + path("missing.din"), {"missing.din"});
  if (::geteuid() != 0) {  // root reads everything: the permission case only means something otherwise
    write("secret.obj", "v 0 0 0\n");
    ::chmod(path("secret.obj").c_str(), 0);
    expect_rejected("rays --scene " + path("secret.obj") + tail, {"cannot open"});
    write("secret.bin", ray_file(kTwoRays));
    ::chmod(path("secret.bin").c_str(), 0);
    expect_rejected(trace + path("secret.bin"), {"cannot open"});
  }
}

// ---------------------------------------------------------------------------------------------
// Ray files through the CLI (the reader's own cases are in test_workloads.cpp, RayFile).

TEST_F(BadInput, RayFilesAreRejectedWithFileAndReason) {
  const std::string trace = "trace --scene sphere --scheme bvh_single --hits " + path("h.bin") + " --rays ";
  auto expect_rays = [&](const std::string& name, const std::string& bytes, const std::vector<std::string>& needles) {
    write(name, bytes);
    std::vector<std::string> n = needles;
    n.push_back(name);
    expect_rejected(trace + path(name), n);
  };
  const std::string good = ray_file(kTwoRays);
  {  // the good file traces
    write("good.bin", good);
    const CliResult r = travbench(trace + path("good.bin"));
    EXPECT_EQ(r.code, 0) << r.err;
  }
  expect_rays("empty.bin", "", {"too short"});
  expect_rays("trunc.bin", good.substr(0, good.size() - 4), {"header says 2 rays"});
  expect_rays("header.bin", good.substr(0, 20), {"too short"});
  std::string magic = good;
  magic[2] = 'X';
  expect_rays("magic.bin", magic, {"bad magic"});
  expect_rays("hits.bin", "TBHITS1" + std::string(1, '\0') + good.substr(8), {"bad magic"});
  expect_rays("huge.bin", ray_file(kTwoRays, 4, 0x0800000000000000ull), {"header says 576460752303423488 rays"});
  expect_rays("huge2.bin", ray_file(kTwoRays, 4, ~0ull - 1), {"rays"});
  expect_rays("extra.bin", good + "x", {"header says 2 rays"});
  expect_rays("packet0.bin", ray_file(kTwoRays, 0), {"packet size is 0"});
  expect_rays("table.bin", ray_file(kTwoRays, 4, ~0ull, 1, {0, 1}), {"packet table"});
  expect_rays("table2.bin", ray_file(kTwoRays, 4, ~0ull, 2, {0, 2, 1}), {"packet table"});
  expect_rays("table3.bin", ray_file(kTwoRays, 4, ~0ull, 0xFFFFFFFFu, {0, 2}), {"packets"});
  auto bad_ray = [&](const char* name, Ray r, const char* needle) {
    std::vector<Ray> rays = kTwoRays;
    rays[1] = r;
    expect_rays(name, ray_file(rays), {needle});
  };
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  bad_ray("nanorg.bin", {{nan, 0, 0}, 0, {0, 0, 1}, 1}, "ray 1 has a NaN or Inf");
  bad_ray("infdir.bin", {{0, 0, 0}, 0, {0, inf, 1}, 1}, "ray 1 has a NaN or Inf");
  bad_ray("nantmax.bin", {{0, 0, 0}, 0, {0, 0, 1}, nan}, "ray 1 has a NaN or Inf");
  bad_ray("inftmin.bin", {{0, 0, 0}, inf, {0, 0, 1}, inf}, "ray 1 has a NaN or Inf");
  bad_ray("zerodir.bin", {{0, 0, 0}, 0, {0, -0.f, 0}, 1}, "ray 1 has a zero direction");
  bad_ray("negtmin.bin", {{0, 0, 0}, -1, {0, 0, 1}, 1}, "ray 1 has a negative tmin");
  // Beyond the traceable range (structures/vec3.h, kCoordLimit): these crashed mbvh8_single,
  // treelet_queue, mbvh_rs and raygrid (an all-denormal direction is a zero one under DAZ, a
  // huge one has a reciprocal flushed to 0: every node test entered every child slot) and abort
  // Embree (its ray.valid() assertion) beyond 1.844e18.
  bad_ray("denormdir.bin", {{0, 0, 5}, 0, {0, 0, -1e-38f}, 1e30f}, "ray 1: dir.z is a denormal");
  bad_ray("denormorg.bin", {{1e-40f, 0, 5}, 0, {0, 0, -1}, 1e30f}, "ray 1: org.x is a denormal");
  bad_ray("denormtmin.bin", {{0, 0, 5}, 1e-40f, {0, 0, -1}, 1e30f}, "ray 1: tmin is a denormal");
  bad_ray("hugedir.bin", {{0, 0, 5}, 0, {3e38f, 3e38f, -3e38f}, 1}, "ray 1: dir.x = 3e+38 is beyond +-2^56");
  bad_ray("hugeorg.bin", {{3e38f, 3e38f, 3e38f}, 0, {-1, -1, -1}, 3.4e38f}, "ray 1: org.x = 3e+38 is beyond");
  bad_ray("farorg.bin", {{0, -1e19f, 0}, 0, {0, 1, 0}, 3.4e38f}, "ray 1: org.y = -1e+19 is beyond");
  bad_ray("shortdir.bin", {{0, 0, 5}, 0, {1e-18f, 0, -1e-18f}, 1e30f}, "ray 1 has a direction shorter than 2^-56");
  // A count whose size wraps 64 bits (2^59 rays of 32 bytes): the size it needs, not the wrapped one.
  std::string huge = good;
  const uint64_t count = uint64_t(1) << 59;
  std::memcpy(huge.data() + 8, &count, 8);
  expect_rays("hugecount.bin", huge, {"header says 576460752303423488 rays", "needs 18446744073709551"});
}

// ---------------------------------------------------------------------------------------------
// Din traces through the CLI (the reader's own cases are in test_cachesim.cpp).

TEST_F(BadInput, DinTracesAreRejectedWithFileLineAndReason) {
  auto expect_din = [&](const std::string& name, const std::string& text, const std::vector<std::string>& needles) {
    write(name, text);
    std::vector<std::string> n = needles;
    n.push_back(name);
    expect_rejected("cachesim --trace " + path(name), n);
  };
  expect_din("label.din", "0 10\n7 20\n", {":2:", "label '7'"});
  expect_din("escape.din", "3 10\n", {":1:", "escape label 3"});
  expect_din("flush.din", "4 10\n", {":1:", "escape label 4"});
  expect_din("noaddr.din", "0 10\n1\n", {":2:", "missing hex address"});
  expect_din("hex.din", "0 10g\n", {":1:", "not hexadecimal"});
  expect_din("wide.din", "0 1ffffffffffffffff\n", {":1:", "does not fit in 64 bits"});
  expect_din("binary.din", std::string("0 10\n\x01\x02\x03 4\n", 11), {":2:"});
  // Empty and comment-only traces are valid (zero accesses), not errors.
  write("empty.din", "");
  const CliResult r = travbench("cachesim --trace " + path("empty.din"));
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("L1 reads=0"), std::string::npos) << r.out;
}

// ---------------------------------------------------------------------------------------------
// Degenerate triangles: kept by every loader (ids stay those of the file) and never hit by any
// scheme, whatever the ray.

TEST_F(BadInput, DegenerateTrianglesAreKeptAndNeverHit) {
  // Triangle 0: a real unit triangle in z = 0. Triangles 1..6 are degenerate, in z = 0.5 on the
  // line y = 0.25: a repeated index, three equal indices, two coincident corners, three collinear
  // corners (a zero-area sliver) and a quad with a repeated corner, whose fan gives two more.
  // Triangle 7: a real triangle in z = 1, behind the degenerate ones.
  const std::string obj =
      "v 0 0 0\nv 1 0 0\nv 0 1 0\n"                                  // 1-3
      "v 0.25 0.25 0.5\nv 0.75 0.25 0.5\nv 0.25 0.25 0.5\n"          // 4-6: 4 and 6 coincide
      "v -1 -1 1\nv 3 -1 1\nv -1 3 1\n"                              // 7-9
      "v 0.5 0.25 0.5\n"                                              // 10: on the line of 4 and 5
      "f 1 2 3\nf 4 5 4\nf 4 4 4\nf 4 5 6\nf 4 5 10\nf 4 5 5 6\nf 7 8 9\n";
  Scene s = load_scene_file(write("degenerate.obj", obj));
  ASSERT_EQ(s.num_triangles(), 8u);  // every face kept; the quad became two fan triangles
  // OFF and STL keep them too (STL welds equal corners, which makes them index-degenerate).
  Scene off = load_scene_file(write("degenerate.off", "OFF\n4 3 0\n0 0 0\n1 0 0\n0 1 0\n2 0 0\n3 0 1 2\n3 0 1 1\n3 0 1 3\n"));
  EXPECT_EQ(off.num_triangles(), 3u);
  Scene stl = load_scene_file(write("degenerate.stl",
                                    "solid d\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                                    "endloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0 0 0\n"
                                    "vertex 1 0 0\nendloop\nendfacet\nendsolid d\n"));
  ASSERT_EQ(stl.num_triangles(), 2u);
  EXPECT_EQ(stl.triangles[1][0], stl.triangles[1][1]);

  // Rays straight down the z axis through points of the degenerate triangles (their corners, edge
  // midpoints), along their line, across it, and nearly grazing; every hit must be triangle 0 or 7.
  RayBatch b;
  const Vec3 pts[] = {{0.25f, 0.25f, 0}, {0.75f, 0.25f, 0}, {0.5f, 0.25f, 0}, {0.3f, 0.25f, 0}, {0.1f, 0.1f, 0}};
  for (Vec3 p : pts) {
    for (float sgn : {1.f, -1.f}) {
      b.rays.push_back({{p.x, p.y, sgn * 5}, 0, {0, 0, -sgn}, 1e30f});  // through the point
      b.rays.push_back({{p.x - 2, p.y, 0.5f}, 0, {1, 0, 0}, 1e30f});   // along the sliver's line
      b.rays.push_back({{p.x, p.y - 2, 0.5f}, 0, {0, 1, 0}, 1e30f});   // across it, in its plane
      b.rays.push_back({{p.x, p.y, 0.5f + sgn}, 0, {0.001f, 0, -sgn}, 1e30f});
    }
  }
  b.group_uniform(4);
  b.validate();
  Bench bench(std::move(s));
  for (const auto& info : schemes()) {
    SCOPED_TRACE(info.name);
    auto t = make_scheme(info.name);
    t->prepare(bench.scene(), bench.cache());
    std::vector<Hit> hits(b.size());
    trace_batch(*t, b, hits, 1);
    size_t hit_count = 0;
    for (size_t i = 0; i < hits.size(); ++i) {
      if (!hits[i].hit()) continue;
      ++hit_count;
      EXPECT_TRUE(hits[i].prim == 0 || hits[i].prim == 7) << "ray " << i << " hit degenerate triangle " << hits[i].prim;
    }
    EXPECT_GT(hit_count, 0u);  // the real triangles are still hit
  }
}

// ---------------------------------------------------------------------------------------------
// Fuzzing: the committed seeds and findings (tests/fuzz/corpus/<target>/, tests/fuzz/regressions/
// <target>/) replayed through the same entry points as the fuzz targets (tests/fuzz/fuzz_*.cpp):
// each must load or raise a one-line InputError.

fs::path fuzz_dir() { return fs::path(__FILE__).parent_path() / "fuzz"; }

void replay(const std::string& target, const std::string& bytes, const fs::path& work) {
  auto one_line = [](const InputError& e) { EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what(); };
  try {
    if (target == "mesh" || target == "gltf") {
      static const char* const kExt[4] = {".obj", ".off", ".ply", ".stl"};
      if (target == "mesh" && bytes.empty()) return;
      const std::string name = target == "gltf" ? "in.gltf" : std::string("in") + kExt[static_cast<unsigned char>(bytes[0]) % 4];
      std::ofstream(work / name, std::ios::binary) << (target == "gltf" ? bytes : bytes.substr(1));
      Scene s = load_scene_file((work / name).string());
      EXPECT_GT(s.num_triangles(), 0u);
    } else if (target == "rays") {
      std::ofstream(work / "in.bin", std::ios::binary) << bytes;
      if (bytes.rfind(std::string("TBHITS1\0", 8), 0) == 0) {
        read_hits((work / "in.bin").string());
      } else {
        // A file that loads survives a write/read round trip unchanged, packet table included.
        const RayBatch b = read_rays((work / "in.bin").string());
        write_rays((work / "again.bin").string(), b);
        const RayBatch c = read_rays((work / "again.bin").string());
        EXPECT_EQ(c.packet_begin, b.packet_begin);
        ASSERT_EQ(c.rays.size(), b.rays.size());
        if (!b.rays.empty()) {
          EXPECT_EQ(std::memcmp(c.rays.data(), b.rays.data(), b.rays.size() * sizeof(Ray)), 0);
        }
      }
    } else if (target == "din") {
      std::istringstream in(bytes);
      cachesim::Hierarchy h(cachesim::parse_config("l1=1K:2,l2=4K:4"));
      cachesim::replay_din(in, h, "fuzz.din");
    }
  } catch (const InputError& e) {
    one_line(e);
  }
}

TEST_F(BadInput, FuzzRegressionsLoadOrRaiseInputError) {
  size_t files = 0;
  for (const char* sub : {"regressions", "corpus"})
    for (const char* target : {"mesh", "gltf", "rays", "din"}) {
      const fs::path d = fuzz_dir() / sub / target;
      if (!fs::is_directory(d)) continue;
      for (const auto& entry : fs::directory_iterator(d)) {
        if (!entry.is_regular_file() || entry.path().filename() == "README.md") continue;
        SCOPED_TRACE(entry.path().string());
        std::ifstream f(entry.path(), std::ios::binary);
        const std::string bytes((std::istreambuf_iterator<char>(f)), {});
        replay(target, bytes, dir_);
        ++files;
      }
    }
  EXPECT_GT(files, 10u) << "no fuzz corpus found under " << fuzz_dir();
}

}  // namespace
}  // namespace tb
