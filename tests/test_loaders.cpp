// Scene file loaders: every format's happy path with exact primitive ids, the camera views from
// scenes.json, and bad input of every kind (which must be a one-line InputError, never a crash or a
// silently different scene). Small files are written into a temporary directory per test; the real
// scenes of ../shared/scenes are checked against their scenes.json when that folder exists.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "structures/scene_loader.h"
#include "workloads/workload.h"

namespace fs = std::filesystem;
using nlohmann::json;
using tb::InputError;
using tb::Scene;
using tb::Vec3;

namespace {

// ---------------------------------------------------------------------------------------------
// Helpers

class LoaderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static std::atomic<int> counter{0};
    dir_ = fs::temp_directory_path() /
           ("travbench_loaders_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string write(const std::string& name, const std::string& bytes) {
    fs::path p = dir_ / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << bytes;
    return p.string();
  }
  fs::path dir_;
};

// Loads path expecting an InputError whose single-line message contains needle.
void expect_input_error(const std::string& path, const std::string& needle) {
  SCOPED_TRACE(path);
  try {
    Scene s = tb::load_scene_file(path);
    ADD_FAILURE() << "no InputError; loaded " << s.num_triangles() << " triangles";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(needle), std::string::npos) << "message: " << m << "\nexpected to contain: " << needle;
    EXPECT_EQ(m.find('\n'), std::string::npos) << "message is not one line: " << m;
    EXPECT_NE(m.find(fs::path(path).filename().string()), std::string::npos) << "message does not name the file: " << m;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
  }
}

// A one-spot corruption of a good file: `len` bytes, from `skip` bytes after the first `anchor`,
// become `with`.
std::string edited(std::string text, std::string_view anchor, size_t skip, size_t len, std::string_view with) {
  const size_t at = text.find(anchor);
  if (at == std::string::npos) {
    ADD_FAILURE() << "'" << anchor << "' is not in the file to corrupt";
    return text;
  }
  return text.replace(at + skip, len, with);
}

std::array<Vec3, 3> corners(const Scene& s, size_t t) {
  return {s.vertex(static_cast<uint32_t>(t), 0), s.vertex(static_cast<uint32_t>(t), 1), s.vertex(static_cast<uint32_t>(t), 2)};
}

// For meshes whose vertex k sits at x = k: the triangle as the x coordinates of its corners. (Such
// meshes put vertex k at y = k^2, so that their triangles have area: a scene of only degenerate
// triangles is refused.)
std::vector<std::array<float, 3>> triangles_by_x(const Scene& s) {
  std::vector<std::array<float, 3>> out;
  for (size_t t = 0; t < s.num_triangles(); ++t) {
    auto c = corners(s, t);
    out.push_back({c[0].x, c[1].x, c[2].x});
  }
  return out;
}

void expect_near(Vec3 a, Vec3 b, float tol = 1e-5f) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

// Vertex lines with vertex k at (k, k % 2, 0), so every index is identifiable by x.
std::string obj_line_vertices(int n) {
  std::string s;
  for (int k = 0; k < n; ++k) s += "v " + std::to_string(k) + " " + std::to_string(k % 2) + " 0\n";
  return s;
}

template <class T>
void put(std::string& b, T v) {
  b.append(reinterpret_cast<const char*>(&v), sizeof v);
}
template <class T>
void put_be(std::string& b, T v) {
  char tmp[sizeof v];
  std::memcpy(tmp, &v, sizeof v);
  for (size_t i = 0; i < sizeof v; ++i) b.push_back(tmp[sizeof v - 1 - i]);
}

std::string base64(const std::string& in) {
  static const char* tbl = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    uint32_t v = (uint8_t(in[i]) << 16) | (uint8_t(in[i + 1]) << 8) | uint8_t(in[i + 2]);
    for (int k = 3; k >= 0; --k) out += tbl[(v >> (6 * k)) & 63];
  }
  if (i + 1 == in.size()) {
    uint32_t v = uint8_t(in[i]) << 16;
    out += tbl[(v >> 18) & 63];
    out += tbl[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == in.size()) {
    uint32_t v = (uint8_t(in[i]) << 16) | (uint8_t(in[i + 1]) << 8);
    out += tbl[(v >> 18) & 63];
    out += tbl[(v >> 12) & 63];
    out += tbl[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

// Builds a glTF document with one buffer, written either as .gltf (base64 data URI) or .glb.
struct Gltf {
  std::string bin;
  json j = {{"asset", {{"version", "2.0"}}},
            {"bufferViews", json::array()},
            {"accessors", json::array()},
            {"meshes", json::array()},
            {"nodes", json::array()}};

  int view(const std::string& bytes, int stride = 0) {
    while (bin.size() % 4) bin.push_back('\0');
    json v = {{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes.size()}};
    if (stride) v["byteStride"] = stride;
    bin += bytes;
    j["bufferViews"].push_back(v);
    return static_cast<int>(j["bufferViews"].size()) - 1;
  }
  int accessor(int view, int component, const char* type, size_t count, size_t offset = 0) {
    json a = {{"bufferView", view}, {"componentType", component}, {"type", type}, {"count", count}};
    if (offset) a["byteOffset"] = offset;
    j["accessors"].push_back(a);
    return static_cast<int>(j["accessors"].size()) - 1;
  }
  int positions(const std::vector<Vec3>& p) {
    std::string b;
    for (Vec3 v : p) {
      put(b, v.x);
      put(b, v.y);
      put(b, v.z);
    }
    return accessor(view(b), 5126, "VEC3", p.size());
  }
  template <class T>
  int indices(const std::vector<T>& idx) {
    std::string b;
    for (T i : idx) put(b, i);
    const int comp = sizeof(T) == 1 ? 5121 : (sizeof(T) == 2 ? 5123 : 5125);
    return accessor(view(b), comp, "SCALAR", idx.size());
  }
  static json prim(int pos, int idx = -1, int mode = -1) {
    json p = {{"attributes", {{"POSITION", pos}}}};
    if (idx >= 0) p["indices"] = idx;
    if (mode >= 0) p["mode"] = mode;
    return p;
  }
  int mesh(std::vector<json> prims) {
    j["meshes"].push_back({{"primitives", prims}});
    return static_cast<int>(j["meshes"].size()) - 1;
  }
  int node(json n) {
    j["nodes"].push_back(n);
    return static_cast<int>(j["nodes"].size()) - 1;
  }
  void padded() {
    while (bin.size() % 4) bin.push_back('\0');
  }
  std::string gltf_text() {
    padded();
    json d = j;
    d["buffers"] = json::array({{{"byteLength", bin.size()}, {"uri", "data:application/octet-stream;base64," + base64(bin)}}});
    return d.dump();
  }
  std::string glb_bytes() {
    padded();
    json d = j;
    d["buffers"] = json::array({{{"byteLength", bin.size()}}});
    std::string js = d.dump();
    while (js.size() % 4) js.push_back(' ');
    std::string out = "glTF";
    put<uint32_t>(out, 2);
    put<uint32_t>(out, static_cast<uint32_t>(12 + 8 + js.size() + 8 + bin.size()));
    put<uint32_t>(out, static_cast<uint32_t>(js.size()));
    put<uint32_t>(out, 0x4E4F534Au);  // "JSON"
    out += js;
    put<uint32_t>(out, static_cast<uint32_t>(bin.size()));
    put<uint32_t>(out, 0x004E4942u);  // "BIN\0"
    out += bin;
    return out;
  }
};

// A glTF with a uint16-indexed mesh, a non-indexed mesh, TRS transforms and a nested node.
Gltf transformed_gltf() {
  Gltf g;
  const int pa = g.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  const int ia = g.indices<uint16_t>({0, 1, 2});
  const int pb = g.positions({{0, 0, 0}, {0, 0, 1}, {1, 0, 0}});
  const int m0 = g.mesh({Gltf::prim(pa, ia)});
  const int m1 = g.mesh({Gltf::prim(pb)});
  const double h = std::sqrt(0.5);
  // node 0: translate (10,0,0), mesh 0, child node 1 (scale 2, rotate 90 deg about z, mesh 1)
  g.node({{"translation", {10, 0, 0}}, {"mesh", m0}, {"children", {1}}});
  g.node({{"scale", {2, 2, 2}}, {"rotation", {0, 0, h, h}}, {"mesh", m1}});
  // node 2: column-major matrix translating by (0,5,0), mesh 0
  g.node({{"matrix", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 5, 0, 1}}, {"mesh", m0}});
  g.j["scenes"] = json::array({{{"nodes", {0, 2}}}});
  g.j["scene"] = 0;
  return g;
}

void expect_transformed_gltf(const Scene& s) {
  ASSERT_EQ(s.num_triangles(), 3u);
  // node 0 (pre-order: parent before child)
  auto c = corners(s, 0);
  expect_near(c[0], {10, 0, 0});
  expect_near(c[1], {11, 0, 0});
  expect_near(c[2], {10, 1, 0});
  // node 1 under node 0: T(10,0,0) * Rz(90) * S(2)
  c = corners(s, 1);
  expect_near(c[0], {10, 0, 0});
  expect_near(c[1], {10, 0, 2});
  expect_near(c[2], {10, 2, 0});
  // node 2: matrix
  c = corners(s, 2);
  expect_near(c[0], {0, 5, 0});
  expect_near(c[1], {1, 5, 0});
  expect_near(c[2], {0, 6, 0});
}

const char* kPlyAsciiHeader =
    "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 5\nproperty float x\nproperty float y\n"
    "property float z\nproperty float nx\nproperty uchar red\nelement face 2\n"
    "property list uchar int vertex_indices\nend_header\n";

std::string ply_ascii_body() { return "0 0 0 1 255\n1 1 0 1 0\n2 0 0 1 0\n3 1 0 1 0\n4 0 0 1 0\n4 0 1 2 3\n3 4 3 2\n"; }

// Binary PLY: 4 vertices (x = k), one quad and one triangle; double extra property to check strides.
std::string ply_binary(bool big_endian) {
  std::string b = std::string("ply\nformat ") + (big_endian ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                  "property double quality\nelement face 2\nproperty list uchar uint vertex_indices\nend_header\n";
  auto f = [&](float v) { big_endian ? put_be(b, v) : put(b, v); };
  auto d = [&](double v) { big_endian ? put_be(b, v) : put(b, v); };
  auto u = [&](uint32_t v) { big_endian ? put_be(b, v) : put(b, v); };
  for (int k = 0; k < 4; ++k) {
    f(float(k));
    f(float(k % 2));
    f(0.f);
    d(0.5);
  }
  b.push_back(4);
  for (uint32_t i : {0u, 1u, 2u, 3u}) u(i);
  b.push_back(3);
  for (uint32_t i : {3u, 2u, 1u}) u(i);
  return b;
}

std::string stl_ascii_facet(Vec3 a, Vec3 b, Vec3 c) {
  auto v = [](Vec3 p) {
    return "      vertex " + std::to_string(p.x) + " " + std::to_string(p.y) + " " + std::to_string(p.z) + "\n";
  };
  return "  facet normal 0 0 1\n    outer loop\n" + v(a) + v(b) + v(c) + "    endloop\n  endfacet\n";
}

std::string stl_binary(const std::vector<std::array<Vec3, 3>>& tris, const std::string& header = "binary stl") {
  std::string b = header;
  b.resize(80, '\0');
  put<uint32_t>(b, static_cast<uint32_t>(tris.size()));
  for (const auto& t : tris) {
    for (float n : {0.f, 0.f, 1.f}) put(b, n);
    for (Vec3 p : t) {
      put(b, p.x);
      put(b, p.y);
      put(b, p.z);
    }
    put<uint16_t>(b, 0);
  }
  return b;
}

using X3 = std::array<float, 3>;

// ---------------------------------------------------------------------------------------------
// OBJ

TEST_F(LoaderTest, ObjPolygonsBecomeFansInFileOrder) {
  // Quad, pentagon (with v/vt and v/vt/vn forms), a degenerate triangle (kept: ids must match the
  // file) and a v//vn triangle, mixed with lines every OBJ loader must skip.
  const std::string obj = "# comment\r\nmtllib x.mtl\r\no thing\r\n" + obj_line_vertices(7) +
                          "vt 0 0\nvn 0 0 1\ng group\nusemtl m\ns 1\n"
                          "f 1 2 3 4\r\n"
                          "f\t3/1 4/1 5/1/1 6/1/1 7/1/1\n"
                          "l 1 2\n"
                          "f 1 2 2\n"
                          "f 5//1 6//1 7//1   \n";
  Scene s = tb::load_scene_file(write("poly.obj", obj));
  EXPECT_EQ(s.name, "poly");
  EXPECT_EQ(s.positions.size(), 7u);
  const std::vector<X3> expected = {{0, 1, 2}, {0, 2, 3}, {2, 3, 4}, {2, 4, 5}, {2, 5, 6}, {0, 1, 1}, {4, 5, 6}};
  EXPECT_EQ(triangles_by_x(s), expected);
  // The indices themselves are the file's (0-based), not just the positions.
  EXPECT_EQ(s.triangles[3], (std::array<uint32_t, 3>{2, 4, 5}));
}

TEST_F(LoaderTest, ObjNegativeAndForwardIndices) {
  // Relative indices refer to the vertices defined so far; positive ones may point forward.
  const std::string obj = "f 1 2 3\n" + obj_line_vertices(3) + "f -3 -2 -1\nv 3 0 0\nv 4 0 0\nv 5 0 0\nf -1 -2 -3 1\n";
  Scene s = tb::load_scene_file(write("neg.obj", obj));
  const std::vector<X3> expected = {{0, 1, 2}, {0, 1, 2}, {5, 4, 3}, {5, 3, 0}};
  EXPECT_EQ(triangles_by_x(s), expected);
}

TEST_F(LoaderTest, ObjUppercaseExtensionAndExponents) {
  Scene s = tb::load_scene_file(write("CAPS.OBJ", "v +1e0 0 0\nv 2.5E+1 0 0\nv 0 1 1e-50\nf 1 2 3\n"));
  ASSERT_EQ(s.num_triangles(), 1u);
  EXPECT_EQ(s.positions[1].x, 25.f);
  EXPECT_EQ(s.positions[2].z, 0.f);  // below float range: rounds to zero instead of failing
}

TEST_F(LoaderTest, ObjBadInput) {
  const std::string v3 = obj_line_vertices(3);
  expect_input_error(write("oor.obj", v3 + "f 1 2 9\n"), "face uses vertex 9 but the file defines only 3");
  expect_input_error(write("zero.obj", v3 + "f 0 1 2\n"), "index 0 is invalid");
  expect_input_error(write("relbad.obj", v3 + "f -1 -2 -4\n"), "points before the first vertex");
  expect_input_error(write("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), "line 1: vertex 1 has a NaN or Inf");
  expect_input_error(write("inf.obj", "v 1 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n"), "line 2: vertex 2 has a NaN or Inf");
  expect_input_error(write("word.obj", "v 1 x 0\n"), "vertex coordinate 'x' is not a number");
  expect_input_error(write("badidx.obj", v3 + "f 1 2 a\n"), "face vertex 'a' is not an index");
  // The texture and normal indices carry no geometry, but only the four OBJ forms are vertices.
  for (const char* bad : {"3////", "3/", "3//", "3/1/", "3/x", "3/1/1/1", "3//x", "3/1x"})
    expect_input_error(write("badform.obj", v3 + "f 1 2 " + bad + "\n"), "is not v, v/vt, v//vn or v/vt/vn");
  EXPECT_EQ(tb::load_scene_file(write("forms.obj", v3 + "f 1 2/5 3//-1\nf 1/2/3 2/-1/4 3\n")).num_triangles(), 2u);
  expect_input_error(write("twovert.obj", v3 + "f 1 2\n"), "face has 2 vertices");
  expect_input_error(write("shortv.obj", "v 1 2\n"), "vertex needs three coordinates");
  // Truncation in the middle of the last line.
  const std::string full = v3 + "v 3 0 0\nf 1 2 3\nf 2 3 4\n";
  expect_input_error(write("trunc.obj", full.substr(0, full.size() - 3)), "face has 2 vertices");
  expect_input_error(write("trunc2.obj", full.substr(0, 10)), "vertex needs three coordinates");
  expect_input_error(write("novfaces.obj", v3), "has no triangles");
  expect_input_error(write("garbage.obj", std::string("\x7f\x45\x4c\x46\x02\x01\x01\0\0\0", 10)), "has no triangles");
}

// ---------------------------------------------------------------------------------------------
// OFF

TEST_F(LoaderTest, OffPolygonsCommentsAndColours) {
  std::string off = "COFF\n# a comment\n\n7 3 0 # counts\n";
  for (int k = 0; k < 7; ++k) off += std::to_string(k) + " " + std::to_string(k % 2) + " 0 1 1 1 1\n";
  off += "4 0 1 2 3 255 0 0\n5 2 3 4 5 6\n# between faces\n3 4 5 6\n";
  Scene s = tb::load_scene_file(write("poly.off", off));
  const std::vector<X3> expected = {{0, 1, 2}, {0, 2, 3}, {2, 3, 4}, {2, 4, 5}, {2, 5, 6}, {4, 5, 6}};
  EXPECT_EQ(triangles_by_x(s), expected);
}

TEST_F(LoaderTest, OffHeaderVariants) {
  // Counts on the keyword line, and no keyword at all.
  Scene a = tb::load_scene_file(write("a.off", "OFF 3 1 0\n0 0 0\n1 0 0\n2 1 0\n3 0 1 2\n"));
  Scene b = tb::load_scene_file(write("b.off", "3 1 0\n0 0 0\n1 0 0\n2 1 0\n3 2 1 0\n"));
  EXPECT_EQ(triangles_by_x(a), (std::vector<X3>{{0, 1, 2}}));
  EXPECT_EQ(triangles_by_x(b), (std::vector<X3>{{2, 1, 0}}));
}

TEST_F(LoaderTest, OffBadInput) {
  const std::string head = "OFF\n3 2 0\n0 0 0\n1 0 0\n2 1 0\n";
  expect_input_error(write("truncv.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n"), "file ends after 2 of 3 vertices");
  expect_input_error(write("truncf.off", head + "3 0 1 2\n"), "file ends after 1 of 2 faces");
  expect_input_error(write("truncline.off", head + "3 0 1 2\n3 0 1"), "fewer than its 3 vertices");
  expect_input_error(write("oor.off", head + "3 0 1 2\n3 0 1 3\n"), "vertex index 3 is out of range");
  expect_input_error(write("negidx.off", head + "3 0 1 2\n3 0 -1 2\n"), "vertex index -1 is out of range");
  expect_input_error(write("nan.off", "OFF\n3 1 0\nnan 0 0\n1 0 0\n2 1 0\n3 0 1 2\n"), "vertex 0 has a NaN or Inf");
  expect_input_error(write("word.off", "OFF\n3 1 0\n0 zero 0\n1 0 0\n2 1 0\n3 0 1 2\n"), "'zero' is not a number");
  expect_input_error(write("line.off", head + "2 0 1\n3 0 1 2\n"), "face has 2 vertices");
  expect_input_error(write("hello.off", "hello world\n"), "not an OFF file");
  expect_input_error(write("four.off", "4OFF\n1 0 0\n0 0 0 0\n"), "not supported");
  expect_input_error(write("binary.off", "OFF BINARY\n"), "binary OFF is not supported");
  expect_input_error(write("huge.off", "OFF\n99999999 1 0\n0 0 0\n"), "more than a");
  expect_input_error(write("nocounts.off", "OFF\n"), "no vertex/face counts");
  expect_input_error(write("zero.off", "OFF\n0 0 0\n"), "has no triangles");
}

// ---------------------------------------------------------------------------------------------
// PLY (OpenMesh)

TEST_F(LoaderTest, PlyAsciiWithExtraProperties) {
  Scene s = tb::load_scene_file(write("a.ply", kPlyAsciiHeader + ply_ascii_body()));
  EXPECT_EQ(s.positions.size(), 5u);
  const std::vector<X3> expected = {{0, 1, 2}, {0, 2, 3}, {4, 3, 2}};
  EXPECT_EQ(triangles_by_x(s), expected);
}

TEST_F(LoaderTest, PlyBinaryBothEndians) {
  const std::vector<X3> expected = {{0, 1, 2}, {0, 2, 3}, {3, 2, 1}};
  for (bool be : {false, true}) {
    Scene s = tb::load_scene_file(write(be ? "be.ply" : "le.ply", ply_binary(be)));
    EXPECT_EQ(triangles_by_x(s), expected) << (be ? "big endian" : "little endian");
    EXPECT_EQ(s.positions[3].y, 1.f);
  }
}

TEST_F(LoaderTest, PlyBadInput) {
  const std::string good = kPlyAsciiHeader + ply_ascii_body();
  expect_input_error(write("trunc.ply", good.substr(0, good.size() - 8)), "truncated");
  expect_input_error(write("truncface.ply", std::string(kPlyAsciiHeader) + "0 0 0 1 255\n1 1 0 1 0\n2 0 0 1 0\n3 1 0 1 0\n4 0 0 1 0\n4 0 1 2 3\n"),
                     "truncated");
  const std::string bin = ply_binary(false);
  expect_input_error(write("truncbin.ply", bin.substr(0, bin.size() - 5)), "truncated");
  // One-spot corruptions of the good ASCII file ("3 4 3 2" is its last face, "end_header\n" + 11
  // the first vertex's x).
  struct Edit {
    const char* file;
    std::string_view anchor;
    size_t skip, len;
    std::string_view with;
    const char* needle;
  };
  const Edit edits[] = {
      {"oor.ply", "3 4 3 2", 0, 7, "3 4 3 9", "uses vertex index 9 but there are 5 vertices"},
      {"nanascii.ply", "end_header\n", 11, 1, "nan", "vertex 0 has a NaN or Inf"},
      {"word.ply", "end_header\n", 11, 1, "zero", "'zero' is not a number"},
      {"neglist.ply", "3 4 3 2", 0, 1, "-4", "list length -4 is negative"},
      {"longlist.ply", "3 4 3 2", 0, 1, "200", "longer than the rest of the file"},
      {"shortface.ply", "3 4 3 2", 0, 7, "2 4 3  ", "face 1 has 2 vertices"},
      // Values the header does not declare were ignored: a third face, an extra index on the last.
      {"moreface.ply", "3 4 3 2", 0, 7, "3 4 3 2\n3 0 1 2", "values after the 2 'face' elements"},
      {"extravalue.ply", "3 4 3 2", 0, 7, "3 4 3 2 7", "values after the 2 'face' elements"},
      // Header corruption: OpenMesh's own header parser loops forever on these.
      {"version.ply", "1.0", 0, 1, {"\0", 1}, "control character in the header"},
      {"count.ply", "vertex 5", 0, 8, "vertex x", "malformed element declaration"},
      {"keyword.ply", "property float y", 0, 8, "prperty ", "unknown keyword 'prperty'"},
  };
  for (const Edit& e : edits) expect_input_error(write(e.file, edited(good, e.anchor, e.skip, e.len, e.with)), e.needle);
  std::string nan_bin = ply_binary(false);
  const float qnan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&nan_bin[nan_bin.find("end_header\n") + 11 + 20 + 4], &qnan, 4);  // vertex 1, y
  expect_input_error(write("nanbin.ply", nan_bin), "vertex 1 has a NaN or Inf");
  expect_input_error(write("hello.ply", "hello world\n"), "not a PLY file");
  expect_input_error(write("noend.ply", "ply\nformat ascii 1.0\nelement vertex 3\n"), "no 'end_header'");
  expect_input_error(write("noface.ply",
                           "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                           "property float z\nend_header\n0 0 0\n"),
                     "declares no faces");
  expect_input_error(write("huge.ply",
                           "ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
                           "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"),
                     "more than the 0-byte body");
  expect_input_error(write("fmt.ply", "ply\nformat ascii 2.0\nend_header\n"), "PLY header line 2");
  expect_input_error(write("noxyz.ply",
                           "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nelement face 1\n"
                           "property list uchar int vertex_indices\nend_header\n0\n3 0 0 0\n"),
                     "lacks an x, y or z");
}

TEST_F(LoaderTest, OpenMeshPathReportsBadPly) {
  const std::string good = kPlyAsciiHeader + ply_ascii_body();
  Scene s = tb::load_mesh_openmesh(write("good.ply", good));
  EXPECT_EQ(triangles_by_x(s), (std::vector<X3>{{0, 1, 2}, {0, 2, 3}, {4, 3, 2}}));
  auto expect_om_error = [&](const std::string& name, const std::string& bytes, const std::string& needle) {
    try {
      tb::load_mesh_openmesh(write(name, bytes));
      ADD_FAILURE() << name << ": no InputError";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_om_error("trunc.ply", good.substr(0, good.size() - 8), "truncated");
  const std::string bin = ply_binary(false);
  expect_om_error("truncbin.ply", bin.substr(0, bin.size() - 5), "truncated");
  expect_om_error("oor.ply", edited(good, "3 4 3 2", 0, 7, "3 4 3 9"), "uses vertex index 9");
  expect_om_error("version.ply", edited(good, "1.0", 0, 1, {"\0", 1}), "control character in the header");
}

// ---------------------------------------------------------------------------------------------
// STL

TEST_F(LoaderTest, StlAsciiKeepsDegenerateFacetsAndSharesCorners) {
  const std::string stl = "solid test\n" + stl_ascii_facet({0, 0, 0}, {1, 0, 0}, {0, 1, 0}) +
                          stl_ascii_facet({1, 0, 0}, {1, 0, 0}, {0, 1, 0}) +  // degenerate: kept, id 1
                          stl_ascii_facet({1, 0, 0}, {1, 1, 0}, {0, 1, 0}) + "endsolid test\n";
  Scene s = tb::load_scene_file(write("a.stl", stl));
  ASSERT_EQ(s.num_triangles(), 3u);
  EXPECT_EQ(s.positions.size(), 4u);  // corners shared by exact position
  expect_near(corners(s, 1)[0], {1, 0, 0});
  expect_near(corners(s, 1)[1], {1, 0, 0});
  expect_near(corners(s, 2)[1], {1, 1, 0});
}

TEST_F(LoaderTest, StlBinaryIncludingSolidHeader) {
  const std::vector<std::array<Vec3, 3>> tris = {{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}}, {{{1, 0, 0}, {1, 1, 0}, {0, 1, 0}}}};
  for (const std::string header : {"binary stl", "solid but binary"}) {
    Scene s = tb::load_scene_file(write("b.stl", stl_binary(tris, header)));
    ASSERT_EQ(s.num_triangles(), 2u) << header;
    EXPECT_EQ(s.positions.size(), 4u);
    expect_near(corners(s, 1)[1], {1, 1, 0});
  }
}

TEST_F(LoaderTest, StlBadInput) {
  const std::string good = "solid t\n" + stl_ascii_facet({0, 0, 0}, {1, 0, 0}, {0, 1, 0}) +
                           stl_ascii_facet({1, 0, 0}, {1, 1, 0}, {0, 1, 0}) + "endsolid t\n";
  expect_input_error(write("trunc.stl", good.substr(0, good.size() - 40)), "truncated");
  expect_input_error(write("noend.stl", good.substr(0, good.find("endsolid"))), "without 'endsolid'");
  expect_input_error(write("quad.stl", edited(good, "endloop", 0, 0, "vertex 5 5 5\n")), "more than 3 vertices");
  expect_input_error(write("nan.stl", edited(good, "vertex ", 7, 8, "nan")), "NaN or Inf");
  const std::vector<std::array<Vec3, 3>> tris = {{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}}, {{{1, 0, 0}, {1, 1, 0}, {0, 1, 0}}}};
  const std::string bin = stl_binary(tris);
  expect_input_error(write("truncbin.stl", bin.substr(0, bin.size() - 10)), "declares 2 triangles");
  const std::string solidbin = stl_binary(tris, "solid header");
  expect_input_error(write("truncsolidbin.stl", solidbin.substr(0, solidbin.size() - 10)), "binary STL whose header");
  auto nanbin = stl_binary({{{{0, 0, 0}, {1, 0, 0}, {0, std::numeric_limits<float>::infinity(), 0}}}});
  expect_input_error(write("nanbin.stl", nanbin), "facet 0 has a NaN or Inf");
  expect_input_error(write("hello.stl", "hello"), "not an STL file");
  expect_input_error(write("empty_solid.stl", "solid x\nendsolid x\n"), "has no triangles");
}

// ---------------------------------------------------------------------------------------------
// Our parsers agree with OpenMesh's readers on well-formed files (OpenMesh drops degenerate faces,
// so these inputs have none): same triangles, same corners, same order.

TEST_F(LoaderTest, OwnParsersMatchOpenMeshOnCleanFiles) {
  std::string off = "OFF\n7 2 0\n";
  for (int k = 0; k < 7; ++k) off += std::to_string(k) + " " + std::to_string(k % 2) + " 0\n";
  off += "4 0 1 2 3\n5 2 3 4 5 6\n";
  const std::string stl = "solid t\n" + stl_ascii_facet({0, 0, 0}, {1, 0, 0}, {0, 1, 0}) +
                          stl_ascii_facet({1, 0, 0}, {1, 1, 0}, {0, 1, 0}) + "endsolid t\n";
  const std::vector<std::string> files = {
      write("c.obj", obj_line_vertices(7) + "f 1 2 3 4\nf 3/1 4/1 5/1 6/1 7/1\nf -1 -2 -3\n"), write("c.off", off),
      write("c.stl", stl), write("c.ply", kPlyAsciiHeader + ply_ascii_body()), write("le.ply", ply_binary(false)),
      write("be.ply", ply_binary(true))};
  for (const std::string& f : files) {
    SCOPED_TRACE(f);
    Scene ours = tb::load_scene_file(f);
    Scene om = tb::load_mesh_openmesh(f);
    ASSERT_EQ(ours.num_triangles(), om.num_triangles());
    for (size_t t = 0; t < ours.num_triangles(); ++t) EXPECT_EQ(corners(ours, t), corners(om, t)) << "triangle " << t;
  }
}

// ---------------------------------------------------------------------------------------------
// glTF

TEST_F(LoaderTest, GltfTransformsIndexedAndNonIndexed) {
  Gltf g = transformed_gltf();
  Scene s = tb::load_scene_file(write("t.gltf", g.gltf_text()));
  EXPECT_EQ(s.name, "t");
  expect_transformed_gltf(s);
}

TEST_F(LoaderTest, GlbMatchesGltf) {
  Gltf g = transformed_gltf();
  Scene s = tb::load_scene_file(write("t.glb", g.glb_bytes()));
  expect_transformed_gltf(s);
  Scene upper = tb::load_scene_file(write("T2.GLB", g.glb_bytes()));
  EXPECT_EQ(upper.triangles, s.triangles);
}

TEST_F(LoaderTest, GltfIndexTypesStrideStripsAndFans) {
  Gltf g;
  const int p4 = g.positions({{0, 0, 0}, {1, 1, 0}, {2, 4, 0}, {3, 9, 0}});
  const int i8 = g.indices<uint8_t>({0, 1, 2});
  const int i32 = g.indices<uint32_t>({3, 2, 1});
  // Interleaved position + normal, 24-byte stride, positions x = 10..12.
  std::string inter;
  for (int k = 0; k < 3; ++k)
    for (float v : {10.f + float(k), 0.f, 0.f, 0.f, 0.f, 1.f}) put(inter, v);
  const int iv = g.view(inter, 24);
  const int pint = g.accessor(iv, 5126, "VEC3", 3);
  const int nint = g.accessor(iv, 5126, "VEC3", 3, 12);
  json interleaved = Gltf::prim(pint);
  interleaved["attributes"]["NORMAL"] = nint;
  const int mesh = g.mesh({Gltf::prim(p4, i8), Gltf::prim(p4, i32), interleaved,
                           Gltf::prim(p4, -1, 5),   // strip 0 1 2 3 -> (0,1,2) (1,3,2)
                           Gltf::prim(p4, -1, 6)});  // fan 0 1 2 3 -> (1,2,0) (2,3,0)
  g.node({{"mesh", mesh}});
  // No "scenes": the root nodes are drawn.
  Scene s = tb::load_scene_file(write("modes.gltf", g.gltf_text()));
  const std::vector<X3> expected = {{0, 1, 2}, {3, 2, 1}, {10, 11, 12}, {0, 1, 2}, {1, 3, 2}, {1, 2, 0}, {2, 3, 0}};
  EXPECT_EQ(triangles_by_x(s), expected);
}

TEST_F(LoaderTest, GltfDefaultSceneAndNodelessMeshes) {
  Gltf g;
  const int pa = g.positions({{0, 0, 0}, {1, 1, 0}, {2, 4, 0}});
  const int pb = g.positions({{5, 25, 0}, {6, 36, 0}, {7, 49, 0}});
  const int ma = g.mesh({Gltf::prim(pa)});
  const int mb = g.mesh({Gltf::prim(pb)});
  g.node({{"mesh", ma}});
  g.node({{"mesh", mb}});
  g.j["scenes"] = json::array({{{"nodes", {0}}}, {{"nodes", {1}}}});
  g.j["scene"] = 1;
  Scene s = tb::load_scene_file(write("scenes.gltf", g.gltf_text()));
  EXPECT_EQ(triangles_by_x(s), (std::vector<X3>{{5, 6, 7}}));

  g.j.erase("scene");  // no default: scene 0
  Scene s0 = tb::load_scene_file(write("scene0.gltf", g.gltf_text()));
  EXPECT_EQ(triangles_by_x(s0), (std::vector<X3>{{0, 1, 2}}));

  g.j.erase("scenes");
  g.j["nodes"] = json::array();  // no nodes at all: every mesh once
  Scene all = tb::load_scene_file(write("nodeless.gltf", g.gltf_text()));
  EXPECT_EQ(triangles_by_x(all), (std::vector<X3>{{0, 1, 2}, {5, 6, 7}}));
}

TEST_F(LoaderTest, GltfQuantizedAndBufferlessPositions) {
  Gltf g;
  // KHR_mesh_quantization: unsigned short positions (stride 8 keeps vertex attributes 4-aligned)...
  std::string us;
  for (uint16_t v : {0, 0, 0, 0, 2, 0, 0, 0, 0, 3, 0, 0}) put(us, v);
  const int pus = g.accessor(g.view(us, 8), 5123, "VEC3", 3);
  // ... and normalised signed bytes (127 -> 1, -128 -> -1), stride 4.
  std::string sb;
  for (int8_t v : {0, 0, 0, 0, 127, 0, 0, 0, 0, -128, 0, 0}) put(sb, v);
  g.j["accessors"].push_back({{"bufferView", g.view(sb, 4)}, {"componentType", 5120}, {"type", "VEC3"},
                              {"count", 3}, {"normalized", true}});
  const int psb = static_cast<int>(g.j["accessors"].size()) - 1;
  // An accessor without bufferView holds zeros (glTF 2.0 §3.6.2.3).
  g.j["accessors"].push_back({{"componentType", 5126}, {"type", "VEC3"}, {"count", 3}});
  const int pzero = static_cast<int>(g.j["accessors"].size()) - 1;
  g.node({{"mesh", g.mesh({Gltf::prim(pus), Gltf::prim(psb), Gltf::prim(pzero)})}});
  g.j["extensionsUsed"] = {"KHR_mesh_quantization"};
  g.j["extensionsRequired"] = {"KHR_mesh_quantization"};
  Scene s = tb::load_scene_file(write("quant.gltf", g.gltf_text()));
  ASSERT_EQ(s.num_triangles(), 3u);
  expect_near(corners(s, 0)[1], {2, 0, 0});
  expect_near(corners(s, 0)[2], {0, 3, 0});
  expect_near(corners(s, 1)[1], {1, 0, 0});
  expect_near(corners(s, 1)[2], {0, -1, 0});
  for (int c = 0; c < 3; ++c) expect_near(corners(s, 2)[c], {0, 0, 0});
}

// Sparse accessors (glTF 2.0 §3.6.2.4): the base elements with some replaced, over a bufferView or
// over zeros (no bufferView).
TEST_F(LoaderTest, GltfSparseAccessors) {
  Gltf g;
  const int base = g.positions({{0, 0, 0}, {1, 1, 0}, {2, 4, 0}});
  std::string idx, val;
  put<uint16_t>(idx, 2);
  for (float v : {7.f, 49.f, 0.f}) put(val, v);
  const int iv = g.view(idx), vv = g.view(val);
  g.j["accessors"][base]["sparse"] = {{"count", 1},
                                      {"indices", {{"bufferView", iv}, {"componentType", 5123}}},
                                      {"values", {{"bufferView", vv}}}};
  std::string idx2, val2;
  put<uint8_t>(idx2, 1);
  put<uint8_t>(idx2, 2);
  for (float v : {3.f, 9.f, 0.f, 4.f, 16.f, 0.f}) put(val2, v);
  const int iv2 = g.view(idx2), vv2 = g.view(val2);
  g.j["accessors"].push_back({{"componentType", 5126}, {"type", "VEC3"}, {"count", 3},
                              {"sparse", {{"count", 2},
                                          {"indices", {{"bufferView", iv2}, {"componentType", 5121}}},
                                          {"values", {{"bufferView", vv2}}}}}});
  const int zeros = static_cast<int>(g.j["accessors"].size()) - 1;
  g.node({{"mesh", g.mesh({Gltf::prim(base), Gltf::prim(zeros)})}});
  Scene s = tb::load_scene_file(write("sparse.gltf", g.gltf_text()));
  EXPECT_EQ(triangles_by_x(s), (std::vector<X3>{{0, 1, 7}, {0, 3, 4}}));
}

// A glTF file's perspective cameras are its views (world matrices through the node hierarchy; the
// camera looks down local -Z, +Y up), in depth-first node order; orthographic ones are left out;
// a scenes.json entry for the file still wins.
TEST_F(LoaderTest, GltfCamerasBecomeViews) {
  Gltf g;
  g.node({{"mesh", g.mesh({Gltf::prim(g.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}))})}});
  g.j["cameras"] = json::array({{{"type", "perspective"}, {"name", "front"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.1}}}},
                                {{"type", "perspective"}, {"perspective", {{"yfov", 1.2}, {"znear", 0.1}}}},
                                {{"type", "orthographic"}, {"orthographic", {{"xmag", 1}, {"ymag", 1}, {"znear", 0.1}, {"zfar", 9}}}}});
  g.node({{"translation", {0, 0, 5}}, {"camera", 0}});
  const double h = std::sqrt(0.5);  // child: 90 degrees about +Y, so local -Z looks down world -X
  g.node({{"translation", {10, 0, 0}}, {"children", {3}}});
  g.node({{"rotation", {0, h, 0, h}}, {"camera", 1}});
  g.node({{"camera", 2}});
  g.j["scenes"] = json::array({{{"nodes", {0, 1, 2, 4}}}});
  const std::string path = write("cams/cameras.gltf", g.gltf_text());
  Scene s = tb::load_scene_file(path);
  ASSERT_EQ(s.views.size(), 2u);
  EXPECT_EQ(s.views[0].name, "front");
  expect_near(s.views[0].eye, {0, 0, 5});
  expect_near(s.views[0].target, {0, 0, 4});
  expect_near(s.views[0].up, {0, 1, 0});
  EXPECT_NEAR(s.views[0].vfov_deg, 0.8 * 180 / M_PI, 1e-4);
  expect_near(s.views[1].eye, {10, 0, 0});
  expect_near(s.views[1].target, {9, 0, 0});
  EXPECT_NEAR(s.views[1].vfov_deg, 1.2 * 180 / M_PI, 1e-4);
  // --view 2 is the second camera: its primary rays start at its eye.
  tb::WorkloadSpec spec = tb::parse_workload("primary");
  spec.width = spec.height = 16;
  spec.view = 1;
  const tb::RayBatch b = tb::primary_rays(s, spec, 1.f);
  expect_near(b.rays[0].org, {10, 0, 0});
  EXPECT_LT(b.rays[0].dir.x, -0.5f);
  write("cams/scenes.json", R"([{"file": "cameras.gltf", "views": [{"eye": [0, 0, 9], "target": [0, 0, 0]}]}])");
  EXPECT_EQ(tb::load_scene_file(path).views.size(), 1u);
}

TEST_F(LoaderTest, GltfBadInput) {
  const std::string good = transformed_gltf().gltf_text();
  expect_input_error(write("trunc.gltf", good.substr(0, good.size() / 2)), "invalid glTF file");
  expect_input_error(write("malformed.gltf", "{ \"asset\": { \"version\": \"2.0\" }, "), "invalid glTF file");
  expect_input_error(write("notjson.gltf", "hello"), "invalid glTF file");

  const std::string glb = transformed_gltf().glb_bytes();
  expect_input_error(write("trunc.glb", glb.substr(0, glb.size() - 20)), "invalid GLB file");
  expect_input_error(write("header.glb", glb.substr(0, 10)), "invalid GLB file");
  expect_input_error(write("notglb.glb", "definitely not binary glTF"), "invalid glTF file");

  {  // external buffer that does not exist
    json d = json::parse(good);
    d["buffers"][0]["uri"] = "missing.bin";
    expect_input_error(write("missingbuf.gltf", d.dump()), "missing.bin");
  }
  {  // accessor larger than its buffer view
    json d = json::parse(good);
    d["accessors"][0]["count"] = 1000;
    expect_input_error(write("bigaccessor.gltf", d.dump()), "1000 elements at offset 0 with stride 12 do not fit");
  }
  {  // accessor reaching past the view through byteOffset
    json d = json::parse(good);
    d["accessors"][2]["byteOffset"] = 32;
    expect_input_error(write("offset.gltf", d.dump()), "do not fit in bufferView");
  }
  {  // accessor index that does not exist
    json d = json::parse(good);
    d["meshes"][1]["primitives"][0]["attributes"]["POSITION"] = 17;
    expect_input_error(write("noaccessor.gltf", d.dump()), "accessor 17 does not exist");
  }
  {  // buffer view past the end of the buffer
    json d = json::parse(good);
    d["bufferViews"][2]["byteLength"] = 4096;
    expect_input_error(write("bigview.gltf", d.dump()), "runs past the end of buffer 0");
  }
  {  // index out of range
    Gltf g;
    const int p = g.positions({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}});
    const int i = g.indices<uint16_t>({0, 1, 5});
    g.node({{"mesh", g.mesh({Gltf::prim(p, i)})}});
    expect_input_error(write("oorindex.gltf", g.gltf_text()), "mesh 0 primitive 0: index 2 is 5, out of range for 3 vertices");
  }
  {  // index count not a multiple of 3
    Gltf g;
    const int p = g.positions({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}});
    const int i = g.indices<uint16_t>({0, 1, 2, 1});
    g.node({{"mesh", g.mesh({Gltf::prim(p, i)})}});
    expect_input_error(write("count.gltf", g.gltf_text()), "not a multiple of 3");
  }
  {  // NaN position
    Gltf g;
    const int p = g.positions({{0, 0, 0}, {std::numeric_limits<float>::quiet_NaN(), 0, 0}, {2, 0, 0}});
    g.node({{"mesh", g.mesh({Gltf::prim(p)})}});
    expect_input_error(write("nan.gltf", g.gltf_text()), "vertex 1 is NaN or Inf");
  }
  {  // sparse accessors: an index past the accessor, values past their view, a signed index type
    json d = json::parse(good);
    // bufferView 1 holds the uint16 indices 0 1 2: sparse index 2 of a 3-element accessor is fine, of
    // a 2-element one it is not.
    d["accessors"][0]["count"] = 2;
    d["accessors"][0]["sparse"] = {{"count", 3},
                                   {"indices", {{"bufferView", 1}, {"componentType", 5123}}},
                                   {"values", {{"bufferView", 0}}}};
    expect_input_error(write("sparse_count.gltf", d.dump()), "sparse count 3 is not in 1..2");
    d["accessors"][0]["sparse"]["count"] = 2;
    d["accessors"][0]["sparse"]["indices"]["byteOffset"] = 2;  // indices 1 2
    expect_input_error(write("sparse_index.gltf", d.dump()), "sparse index 2 is out of range");
    d["accessors"][0]["sparse"]["indices"]["componentType"] = 5122;
    expect_input_error(write("sparse_type.gltf", d.dump()), "sparse indices must be unsigned");
    d["accessors"][0]["sparse"]["indices"] = {{"bufferView", 1}, {"componentType", 5123}};
    d["accessors"][0]["sparse"]["values"]["byteOffset"] = 30;
    expect_input_error(write("sparse_values.gltf", d.dump()), "sparse values");
  }
  {  // a camera node naming a camera that does not exist
    json d = json::parse(good);
    d["nodes"][2]["camera"] = 4;
    expect_input_error(write("nocamera.gltf", d.dump()), "camera 4 does not exist");
  }
  {  // node cycle
    json d = json::parse(good);
    d["nodes"][1]["children"] = {0};
    expect_input_error(write("cycle.gltf", d.dump()), "reached twice");
  }
  {  // missing node, missing mesh
    json d = json::parse(good);
    d["scenes"][0]["nodes"] = {0, 9};
    expect_input_error(write("nonode.gltf", d.dump()), "node 9 does not exist");
    json e = json::parse(good);
    e["nodes"][2]["mesh"] = 7;
    expect_input_error(write("nomesh.gltf", e.dump()), "mesh 7 does not exist");
  }
  {  // compressed geometry we cannot decode
    json d = json::parse(good);
    d["extensionsRequired"] = {"KHR_draco_mesh_compression"};
    d["extensionsUsed"] = {"KHR_draco_mesh_compression"};
    expect_input_error(write("draco.gltf", d.dump()), "KHR_draco_mesh_compression");
    // Used but not required, on a primitive with no uncompressed fallback: still refused by name.
    json e = json::parse(good);
    e["extensionsUsed"] = {"KHR_draco_mesh_compression"};
    json draco = {{"bufferView", 0}, {"attributes", {{"POSITION", 0}}}};
    json prim = {{"attributes", json::object()}};
    prim["extensions"]["KHR_draco_mesh_compression"] = draco;
    e["meshes"][0]["primitives"][0] = prim;
    expect_input_error(write("draco_prim.gltf", e.dump()), "Draco-compressed");
  }
  // Points and lines (modes 0-3) have no surface: refused, naming the mesh, the primitive and the
  // mode, whether the file has nothing else or mixes them with triangles (issue 20).
  for (int mode : {0, 1, 2, 3}) {
    static const char* const names[] = {"POINTS", "LINES", "LINE_LOOP", "LINE_STRIP"};
    const std::string why = std::string("is mode ") + std::to_string(mode) + " (" + names[mode] + ")";
    Gltf only;
    const int p = only.positions({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}});
    only.node({{"mesh", only.mesh({Gltf::prim(p, -1, mode)})}});
    expect_input_error(write("only_" + std::to_string(mode) + ".gltf", only.gltf_text()), "mesh 0 primitive 0: " + why);
    Gltf mixed;
    const int q = mixed.positions({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}});
    mixed.node({{"mesh", mixed.mesh({Gltf::prim(q)})}});
    mixed.node({{"mesh", mixed.mesh({Gltf::prim(q), Gltf::prim(q, -1, 4), Gltf::prim(q, -1, mode)})}});
    expect_input_error(write("mixed_" + std::to_string(mode) + ".gltf", mixed.gltf_text()), "mesh 1 primitive 2: " + why);
  }
}

// ---------------------------------------------------------------------------------------------
// Dispatch, generic bad input, views

TEST_F(LoaderTest, GenericBadInput) {
  for (const char* ext : {".obj", ".off", ".ply", ".stl", ".gltf", ".glb"}) {
    expect_input_error(write(std::string("empty") + ext, ""), "file is empty");
    fs::create_directories(dir_ / (std::string("dir") + ext));
    expect_input_error((dir_ / (std::string("dir") + ext)).string(), "is a directory");
    expect_input_error((dir_ / (std::string("missing") + ext)).string(), "file not found");
  }
  expect_input_error(write("scene.xyz", "v 0 0 0\n"), "unknown scene file extension '.xyz'");
  expect_input_error(write("noext", "v 0 0 0\n"), "file has no extension");
  EXPECT_TRUE(tb::has_scene_file_extension("a/b/c.GlB"));
  EXPECT_TRUE(tb::has_scene_file_extension("x.obj"));
  EXPECT_FALSE(tb::has_scene_file_extension("sponza"));
  EXPECT_FALSE(tb::has_scene_file_extension("x.fbx"));
}

TEST_F(LoaderTest, ViewsFromScenesJson) {
  const std::string tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  const std::string a = write("a.obj", tri);
  const std::string b = write("b.obj", tri);
  const std::string c = write("c.obj", tri);
  write("scenes.json", R"({
    "scene_a": {"file": "a.obj", "triangles": 1,
                "views": [{"eye": [1, 2, 3], "target": [0, 0, 0], "up": [0, 0, 1], "vfov_deg": 45},
                          {"eye": [4, 5, 6], "target": [0, 1, 0]}]},
    "scene_b": {"file": "b.obj", "triangles": 1}
  })");
  Scene sa = tb::load_scene_file(a);
  ASSERT_EQ(sa.views.size(), 2u);
  EXPECT_EQ(sa.views[0].name, "view1");
  EXPECT_EQ(sa.views[1].name, "view2");
  EXPECT_EQ(sa.views[0].eye, (Vec3{1, 2, 3}));
  EXPECT_EQ(sa.views[0].up, (Vec3{0, 0, 1}));
  EXPECT_EQ(sa.views[0].vfov_deg, 45.f);
  EXPECT_EQ(sa.views[1].target, (Vec3{0, 1, 0}));
  EXPECT_EQ(sa.views[1].up, (Vec3{0, 1, 0}));  // defaults when omitted
  EXPECT_EQ(sa.views[1].vfov_deg, 60.f);
  // An entry without views, and a file without entry, get the derived views.
  for (const std::string& p : {b, c}) {
    Scene s = tb::load_scene_file(p);
    EXPECT_EQ(s.views.size(), 3u);
    EXPECT_NE(s.views[0].name, "view1");
  }
}

TEST_F(LoaderTest, ScenesJsonListFormAndErrors) {
  const std::string tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  const std::string a = write("list/a.obj", tri);
  write("list/scenes.json", R"([{"file": "a.obj", "views": [{"eye": [0, 0, 5], "target": [0, 0, 0]}]}])");
  Scene s = tb::load_scene_file(a);
  ASSERT_EQ(s.views.size(), 1u);
  EXPECT_EQ(s.views[0].eye, (Vec3{0, 0, 5}));

  const std::string bad = write("bad/a.obj", tri);
  write("bad/scenes.json", "{ \"a\": ");
  expect_input_error(bad, "scenes.json: is not valid JSON");

  const std::string badview = write("badview/a.obj", tri);
  write("badview/scenes.json", R"({"a": {"file": "a.obj", "views": [{"eye": [0, 0], "target": [0, 0, 0]}]}})");
  expect_input_error(badview, "eye must be a list of three numbers");

  const std::string same = write("same/a.obj", tri);
  write("same/scenes.json", R"({"a": {"file": "a.obj", "views": [{"eye": [1, 1, 1], "target": [1, 1, 1]}]}})");
  expect_input_error(same, "eye equals target");

  // Views outside the traceable range, a vanishing field of view, and an eye far from its target
  // with a huge `up` (the parallel check overflowed in float and blamed `up`).
  const std::string far = write("far/a.obj", tri);
  write("far/scenes.json", R"({"a": {"file": "a.obj", "views": [{"eye": [0, 0, 1e20], "target": [0, 0, 0]}]}})");
  expect_input_error(far, "eye has a component beyond +-2^56");
  const std::string narrow = write("narrow/a.obj", tri);
  write("narrow/scenes.json",
        R"({"a": {"file": "a.obj", "views": [{"eye": [0, 0, 5], "target": [0, 0, 0], "vfov_deg": 1e-30}]}})");
  expect_input_error(narrow, "vfov_deg must be in [0.001, 180)");
  const std::string wide = write("wide/a.obj", tri);
  write("wide/scenes.json",
        R"({"a": {"file": "a.obj", "views": [{"eye": [0, 0, 7e16], "target": [0, 0, -7e16], "up": [1e16, 0, 0]}]}})");
  EXPECT_EQ(tb::load_scene_file(wide).views.size(), 1u);

  // A short `up` is the camera a unit one gives (the camera's absolute test took a fallback axis
  // and turned the image by 90 degrees); an `up` of denormals is zero, as to a tracing thread.
  auto primary_dirs = [&](const std::string& dir, const std::string& up) {
    const std::string obj = write(dir + "/a.obj", tri);
    write(dir + "/scenes.json", R"({"a": {"file": "a.obj", "views": [{"eye": [0.2, 0.2, -2], "target": [0.2, 0.2, 0], "up": )" +
                                    up + "}]}}");
    tb::WorkloadSpec spec = tb::parse_workload("primary");
    spec.width = spec.height = 16;
    std::vector<tb::Vec3> dirs;
    for (const tb::Ray& r : tb::generate_workload(tb::load_scene_file(obj), spec, nullptr).rays) dirs.push_back(r.dir);
    return dirs;
  };
  const std::vector<tb::Vec3> unit = primary_dirs("up1", "[0, 1, 0]");
  EXPECT_EQ(primary_dirs("up1e-10", "[0, 1e-10, 0]"), unit);
  EXPECT_EQ(primary_dirs("up1e-30", "[0, 1e-30, 0]"), unit);
  EXPECT_EQ(primary_dirs("up1e6", "[0, 1e6, 0]"), unit);
  const std::string denorm = write("updenorm/a.obj", tri);
  write("updenorm/scenes.json",
        R"({"a": {"file": "a.obj", "views": [{"eye": [0.2, 0.2, -2], "target": [0.2, 0.2, 0], "up": [0, 1e-40, 0]}]}})");
  expect_input_error(denorm, "up is zero or parallel");
}

// Derived views of scenes far thinner than their distance from the origin or near the edge of the
// traceable range: the eyes stay off the centre and inside the range, so every workload's rays are
// valid (they were "ray 0 has a NaN or Inf component" or "a zero direction" before). (A scene of
// one point, which this test also loaded, is now refused: SceneOfOnlyDegenerateTrianglesIsRefused.)
TEST_F(LoaderTest, DerivedViewsOfThinAndFarScenesGiveValidRays) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"tiny5.obj", "v 5 5 5\nv 5.00001 5 5\nv 5 5.00001 5\nf 1 2 3\n"},
      {"tinyfar.obj", "v 1e16 -1e16 3e16\nv 1.000001e16 -1e16 3e16\nv 1e16 -0.999999e16 3e16\nf 1 2 3\n"},
      {"edge.obj", "v 7e16 7e16 7e16\nv 6e16 7e16 7e16\nv 7e16 6e16 7e16\nf 1 2 3\n"},
      {"denormal.obj", "v 1e-40 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"},
  };
  for (const auto& [name, text] : cases) {
    Scene s = tb::load_scene_file(write("views/" + name, text));
    s.ensure_views();
    for (const auto& v : s.views) {
      EXPECT_FALSE(v.eye == v.target) << name;
      EXPECT_TRUE(tb::in_coord_range(v.eye)) << name;
    }
    for (const char* w : {"primary", "rnd"}) {
      tb::WorkloadSpec spec = tb::parse_workload(w);
      spec.width = spec.height = 16;
      EXPECT_NO_THROW(tb::generate_workload(s, spec, nullptr)) << name << " " << w;
    }
  }
  // A denormal coordinate is read as 0, as every tracing thread reads it (DAZ).
  EXPECT_EQ(tb::load_scene_file(write("views/denormal.obj", cases.back().second)).positions[0].x, 0.f);
}

// ---------------------------------------------------------------------------------------------
// Robustness: every prefix of a valid file (truncation at each byte) and a set of single-byte
// corruptions must either load (and then validate) or raise InputError — no crash, no other
// exception type, no hang.

TEST_F(LoaderTest, TruncatedAndCorruptedFilesLoadOrRaiseInputError) {
  std::string off = "OFF\n5 2 0\n";
  for (int k = 0; k < 5; ++k) off += std::to_string(k) + " " + std::to_string(k % 2) + " 0\n";
  off += "4 0 1 2 3\n3 4 3 2\n";
  const std::string stl_a = "solid t\n" + stl_ascii_facet({0, 0, 0}, {1, 0, 0}, {0, 1, 0}) + "endsolid t\n";
  const std::vector<std::pair<std::string, std::string>> samples = {
      {".obj", obj_line_vertices(5) + "f 1 2 3 4\nf -1 -2 -3\n"},
      {".off", off},
      {".ply", kPlyAsciiHeader + ply_ascii_body()},
      {".ply", ply_binary(false)},
      {".stl", stl_a},
      {".stl", stl_binary({{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}}})},
      {".gltf", transformed_gltf().gltf_text()},
      {".glb", transformed_gltf().glb_bytes()},
  };
  size_t loaded = 0, rejected = 0;
  auto attempt = [&](const std::string& ext, const std::string& bytes, const std::string& what) {
    const std::string p = write("fuzz" + ext, bytes);
    try {
      Scene s = tb::load_scene_file(p);
      ++loaded;
      EXPECT_GT(s.num_triangles(), 0u) << what;
    } catch (const InputError& e) {
      ++rejected;
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << what;
    } catch (const std::exception& e) {
      ADD_FAILURE() << what << ": unexpected exception " << e.what();
    }
  };
  for (size_t si = 0; si < samples.size(); ++si) {
    const auto& [ext, bytes] = samples[si];
    for (size_t n = 0; n < bytes.size(); ++n)
      attempt(ext, bytes.substr(0, n), "sample " + std::to_string(si) + " cut at " + std::to_string(n));
    const bool binary = ext == ".glb" || bytes.find('\0') != std::string::npos;
    const std::array<char, 3> values = binary ? std::array<char, 3>{'\0', '\xff', '9'} : std::array<char, 3>{'\0', '-', '\n'};
    for (size_t i = 0; i < bytes.size(); ++i)
      for (char c : values) {
        std::string b = bytes;
        b[i] = c;
        attempt(ext, b, "sample " + std::to_string(si) + " byte " + std::to_string(i) + " set to " + std::to_string(int(c)));
      }
  }
  EXPECT_GT(rejected, 0u);
  EXPECT_GT(loaded, 0u);
}

// ---------------------------------------------------------------------------------------------
// The real scenes

#ifdef TRAVBENCH_SHARED_SCENES
const char* kSharedScenes = TRAVBENCH_SHARED_SCENES;
#else
const char* kSharedScenes = "";
#endif

bool shared_scenes_present() { return kSharedScenes[0] && fs::exists(fs::path(kSharedScenes) / "scenes.json"); }

// A scene of scenes.json: its key, its entry and the path of its file.
struct SharedScene {
  std::string key;
  json entry;
  std::string path;
};

// The scenes of scenes.json whose files are present (a checkout may hold only some of them).
std::vector<SharedScene> present_shared_scenes() {
  std::ifstream in(fs::path(kSharedScenes) / "scenes.json");
  const json scenes = json::parse(in);
  std::vector<SharedScene> present;
  for (const auto& [key, entry] : scenes.items()) {
    std::string path = (fs::path(kSharedScenes) / entry["file"].get<std::string>()).string();
    if (fs::exists(path)) present.push_back({key, entry, std::move(path)});
  }
  return present;
}

TEST(LoaderRealScenes, CountsBoundsAndViewsMatchScenesJson) {
  if (!shared_scenes_present()) GTEST_SKIP() << "shared scenes folder not present";
  for (const auto& [key, entry, path] : present_shared_scenes()) {
    SCOPED_TRACE(path);
    const auto t0 = std::chrono::steady_clock::now();
    Scene s = tb::load_scene_file(path);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << "[ loaded   ] " << key << ": " << s.num_triangles() << " triangles in " << secs * 1e3 << " ms\n";
    EXPECT_EQ(s.num_triangles(), entry["triangles"].get<size_t>());
    EXPECT_EQ(s.positions.size(), entry["vertices"].get<size_t>());
    const tb::AABB b = s.bounds();
    for (int k = 0; k < 3; ++k) {
      const double lo = entry["bounds_lo"][k].get<double>(), hi = entry["bounds_hi"][k].get<double>();
      EXPECT_NEAR(b.lo[k], lo, 1e-3 * std::max(1.0, std::abs(lo)));  // scenes.json rounds to 4 decimals
      EXPECT_NEAR(b.hi[k], hi, 1e-3 * std::max(1.0, std::abs(hi)));
    }
    if (entry.contains("views")) {
      ASSERT_EQ(s.views.size(), entry["views"].size());
      EXPECT_EQ(s.views[0].name, "view1");
      EXPECT_FLOAT_EQ(s.views[0].eye.x, entry["views"][0]["eye"][0].get<float>());
      EXPECT_FLOAT_EQ(s.views[0].vfov_deg, entry["views"][0]["vfov_deg"].get<float>());
    } else {
      EXPECT_EQ(s.views.size(), 3u);
    }
  }
}

// The OBJ parser against OpenMesh's OBJ reader on every real scene: same triangles, same corner
// positions, same order (these files have no degenerate faces, which OpenMesh would drop).
TEST(LoaderRealScenes, ObjParserMatchesOpenMesh) {
  if (!shared_scenes_present()) GTEST_SKIP() << "shared scenes folder not present";
  for (const SharedScene& scene : present_shared_scenes()) {
    if (fs::path(scene.path).extension() != ".obj") continue;
    SCOPED_TRACE(scene.path);
    Scene ours = tb::load_obj(scene.path);
    Scene om = tb::load_mesh_openmesh(scene.path);
    ASSERT_EQ(ours.num_triangles(), om.num_triangles());
    size_t mismatches = 0;
    for (size_t t = 0; t < ours.num_triangles(); ++t) mismatches += corners(ours, t) != corners(om, t);
    EXPECT_EQ(mismatches, 0u);
  }
}

}  // namespace
