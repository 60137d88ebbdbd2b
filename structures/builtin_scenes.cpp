#include "structures/builtin_scenes.h"

#include <charconv>
#include <cmath>
#include <system_error>
#include <numbers>
#include <random>

#include "structures/scene_loader.h"

namespace tb {

uint32_t MeshBuilder::vertex(Vec3 p) {
  scene.positions.push_back(p);
  return uint32_t(scene.positions.size() - 1);
}

void MeshBuilder::box(Vec3 lo, Vec3 hi) {
  uint32_t v[8];
  for (int i = 0; i < 8; ++i) v[i] = vertex({i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z});
  const int f[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (auto& q : f) {
    tri(v[q[0]], v[q[1]], v[q[2]]);
    tri(v[q[0]], v[q[2]], v[q[3]]);
  }
}

void MeshBuilder::sphere(Vec3 c, float r, int slices, int stacks) {
  const float pi = std::numbers::pi_v<float>;
  const uint32_t top = vertex(c + Vec3{0, r, 0});
  const uint32_t ring0 = uint32_t(scene.positions.size());
  for (int s = 1; s < stacks; ++s) {
    const float th = pi * s / stacks;
    for (int k = 0; k < slices; ++k) {
      const float ph = 2 * pi * k / slices;
      vertex(c + Vec3{r * std::sin(th) * std::cos(ph), r * std::cos(th), r * std::sin(th) * std::sin(ph)});
    }
  }
  const uint32_t bottom = vertex(c - Vec3{0, r, 0});
  auto at = [&](int s, int k) { return ring0 + uint32_t((s - 1) * slices + (k % slices)); };
  for (int k = 0; k < slices; ++k) {
    tri(top, at(1, k + 1), at(1, k));
    tri(bottom, at(stacks - 1, k), at(stacks - 1, k + 1));
  }
  for (int s = 1; s < stacks - 1; ++s)
    for (int k = 0; k < slices; ++k) {
      tri(at(s, k), at(s, k + 1), at(s + 1, k + 1));
      tri(at(s, k), at(s + 1, k + 1), at(s + 1, k));
    }
}

void MeshBuilder::torus(Vec3 c, float R, float r, int major, int minor) {
  const float pi = std::numbers::pi_v<float>;
  const uint32_t base = uint32_t(scene.positions.size());
  for (int i = 0; i < major; ++i)
    for (int j = 0; j < minor; ++j) {
      const float u = 2 * pi * i / major, v = 2 * pi * j / minor;
      vertex(c + Vec3{(R + r * std::cos(v)) * std::cos(u), r * std::sin(v), (R + r * std::cos(v)) * std::sin(u)});
    }
  auto at = [&](int i, int j) { return base + uint32_t((i % major) * minor + (j % minor)); };
  for (int i = 0; i < major; ++i)
    for (int j = 0; j < minor; ++j) {
      tri(at(i, j), at(i + 1, j), at(i + 1, j + 1));
      tri(at(i, j), at(i + 1, j + 1), at(i, j + 1));
    }
}

void MeshBuilder::cylinder(Vec3 b, float r, float h, int n) {
  const float pi = std::numbers::pi_v<float>;
  const uint32_t cb = vertex(b), ct = vertex(b + Vec3{0, h, 0});
  const uint32_t base = uint32_t(scene.positions.size());
  for (int k = 0; k < n; ++k) {
    const float a = 2 * pi * k / n;
    vertex(b + Vec3{r * std::cos(a), 0, r * std::sin(a)});
    vertex(b + Vec3{r * std::cos(a), h, r * std::sin(a)});
  }
  for (int k = 0; k < n; ++k) {
    const uint32_t b0 = base + 2 * k, t0 = b0 + 1, b1 = base + 2 * ((k + 1) % n), t1 = b1 + 1;
    tri(b0, b1, t1);
    tri(b0, t1, t0);
    tri(cb, b1, b0);
    tri(ct, t0, t1);
  }
}

namespace {

// Occluded interior: a closed hall with two rows of pillars carrying arches, tables and
// cabinets, a gallery floor — most of the geometry is hidden from any one viewpoint.
Scene room() {
  Scene s;
  s.name = "room";
  MeshBuilder m{s};
  m.box({-20, 0, -10}, {20, 12, 10});  // the hall itself, seen from inside
  for (int i = 0; i < 7; ++i) {
    const float x = -15 + 5 * i;
    for (float z : {-5.f, 5.f}) {
      m.cylinder({x, 0, z}, 0.6f, 7, 48);
      m.box({x - 0.9f, 0, z - 0.9f}, {x + 0.9f, 0.5f, z + 0.9f});  // plinth
      if (i < 6) {  // a ring arch between this pillar and the next: a torus stood upright in x-y
        Scene arch;
        MeshBuilder a{arch};
        a.torus({0, 0, 0}, 2.5f, 0.35f, 64, 16);
        for (auto& p : arch.positions) p = Vec3{p.x + x + 2.5f, 7 + p.z, z + p.y};
        const uint32_t off = uint32_t(s.positions.size());
        s.positions.insert(s.positions.end(), arch.positions.begin(), arch.positions.end());
        for (auto t : arch.triangles) s.triangles.push_back({t[0] + off, t[1] + off, t[2] + off});
      }
    }
  }
  m.box({-20, 8, -10}, {20, 8.4f, -6.5f});  // gallery floors on both sides
  m.box({-20, 8, 6.5f}, {20, 8.4f, 10});
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  for (int i = 0; i < 24; ++i) {  // tables: top and four legs
    const float x = -17 + 34 * U(rng), z = -3.5f + 7 * U(rng), w = 0.6f + 0.8f * U(rng), d = 0.4f + 0.5f * U(rng);
    m.box({x - w, 0.9f, z - d}, {x + w, 1.0f, z + d});
    for (float sx : {-1.f, 1.f})
      for (float sz : {-1.f, 1.f})
        m.box({x + sx * (w - 0.1f) - 0.05f, 0, z + sz * (d - 0.1f) - 0.05f},
              {x + sx * (w - 0.1f) + 0.05f, 0.9f, z + sz * (d - 0.1f) + 0.05f});
    m.sphere({x, 1.25f, z}, 0.25f, 32, 16);  // something on the table
  }
  for (int i = 0; i < 12; ++i) {  // cabinets against the walls
    const float x = -18 + 3 * i, z = (i % 2) ? 9.2f : -9.2f;
    m.box({x, 0, z - 0.7f}, {x + 1.6f, 2.2f, z + 0.7f});
  }
  s.views = {{"view1", {-18, 2, 0}, {10, 3, 0}, {0, 1, 0}, 60},
             {"view2", {16, 9.5f, 8}, {-8, 1, -2}, {0, 1, 0}, 65},
             {"view3", {-0.8f, 1.7f, -7.6f}, {0, 4, 9}, {0, 1, 0}, 70}};
  return s;
}

// "Teapot in a stadium" (Haines): a dense, detailed object in a huge, sparse enclosure.
Scene stadium() {
  Scene s;
  s.name = "stadium";
  MeshBuilder m{s};
  m.box({-500, 0, -300}, {500, 150, 300});  // the stadium: 1000 x 150 x 600 units
  for (int i = 0; i < 8; ++i) {              // stands: a few big steps along the long sides
    const float h = 10.f * (i + 1), zin = 250.f - 6.f * i;
    m.box({-450, 0, zin}, {450, h, zin + 6});
    m.box({-450, 0, -zin - 6}, {450, h, -zin});
  }
  // The "teapot": a 1-unit object made of a knotty stack of tori and a sphere, ~60k triangles.
  m.sphere({0, 0.5f, 0}, 0.35f, 128, 64);
  for (int k = 0; k < 6; ++k) m.torus({0, 0.15f + 0.12f * k, 0}, 0.4f - 0.02f * k, 0.05f, 96, 24);
  m.cylinder({0.4f, 0.3f, 0}, 0.04f, 0.5f, 32);  // spout
  s.views = {{"view1", {0, 0.8f, 2.5f}, {0, 0.4f, 0}, {0, 1, 0}, 45},
             {"view2", {-400, 80, 200}, {0, 0, 0}, {0, 1, 0}, 60},
             {"view3", {3, 1.5f, -3}, {0, 0.4f, 0}, {0, 1, 0}, 50}};
  return s;
}

// N triangles (approximately) as closed spheres of 960 triangles on a jittered grid.
Scene spheres(uint64_t n) {
  Scene s;
  s.name = "spheres:" + std::to_string(n);
  MeshBuilder m{s};
  const int slices = 24, stacks = 21;  // 2 * 24 * 20 = 960 triangles per sphere
  const uint64_t count = std::max<uint64_t>(1, (n + 480) / 960);
  const int side = int(std::ceil(std::cbrt(double(count))));
  std::mt19937 rng(1234);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  s.positions.reserve(count * (slices * (stacks - 1) + 2));
  s.triangles.reserve(count * 960);
  uint64_t made = 0;
  for (int x = 0; x < side && made < count; ++x)
    for (int y = 0; y < side && made < count; ++y)
      for (int z = 0; z < side && made < count; ++z, ++made) {
        const Vec3 c{x + 0.2f + 0.6f * U(rng), y + 0.2f + 0.6f * U(rng), z + 0.2f + 0.6f * U(rng)};
        m.sphere(c * 4.f, 0.4f + 1.0f * U(rng), slices, stacks);
      }
  const float e = 4.f * side;
  s.views = {{"view1", {-0.2f * e, 0.5f * e, -0.2f * e}, {0.5f * e, 0.5f * e, 0.5f * e}, {0, 1, 0}, 60},
             {"view2", {1.3f * e, 1.2f * e, 1.3f * e}, {0.5f * e, 0.5f * e, 0.5f * e}, {0, 1, 0}, 50},
             {"view3", {0.5f * e, 0.5f * e, 0.5f * e}, {e, 0.6f * e, 0.3f * e}, {0, 1, 0}, 70}};
  return s;
}

// One closed, welded UV sphere of ~9k triangles: the "rays from inside must hit" case.
Scene sphere() {
  Scene s;
  s.name = "sphere";
  MeshBuilder{s}.sphere({0, 0, 0}, 1.f, 96, 48);
  s.views = {{"view1", {0, 0, 3.5f}, {0, 0, 0}, {0, 1, 0}, 45},
             {"view2", {2.5f, 2, 2}, {0, 0, 0}, {0, 1, 0}, 45},
             {"view3", {0, 0, 0}, {0, 0, 1}, {0, 1, 0}, 90}};
  return s;
}

}  // namespace

std::vector<std::string> builtin_scene_names() { return {"room", "stadium", "spheres:N", "sphere"}; }

bool is_builtin_scene(const std::string& name) {
  return name == "room" || name == "stadium" || name == "sphere" || name.rfind("spheres:", 0) == 0;
}

namespace {

// N of "spheres:N"; InputError unless it is an integer in range.
unsigned long long spheres_count(const std::string& name) {
  const std::string arg = name.substr(8);
  char* end = nullptr;
  const unsigned long long n = std::strtoull(arg.c_str(), &end, 10);
  if (arg.empty() || *end != '\0' || n < 1 || n > 50'000'000ull)
    throw InputError("scene '" + name + "': N must be an integer in [1, 50000000]");
  return n;
}

// InputError unless `name` is a built-in scene name (spheres:N with N in range).
void check_builtin_name(const std::string& name) {
  if (name.rfind("spheres:", 0) == 0) spheres_count(name);
  else if (!is_builtin_scene(name))
    throw InputError("unknown scene '" + name + "' (built-in: room, stadium, spheres:N, sphere; or a path to a "
                     ".gltf/.glb/.obj/.ply/.off/.stl file)");
}

// "S@dx,dy,dz" -> S, with the offset in `off` when given; InputError on a malformed offset.
std::string strip_offset(const std::string& arg, Vec3* off = nullptr) {
  const auto at = arg.rfind('@');
  if (at == std::string::npos) return arg;
  Vec3 o;
  // Three decimal numbers and nothing else, parsed by std::from_chars: no whitespace, no hex
  // floats (sscanf's %f took both, where the OBJ loader refuses them), no trailing text.
  const std::string spec = arg.substr(at + 1);
  const char *p = spec.data(), *end = spec.data() + spec.size();
  bool ok = true;
  for (int a = 0; a < 3 && ok; ++a) {
    const auto r = std::from_chars(p, end, o[a], std::chars_format::general);
    ok = r.ec == std::errc() && r.ptr != p && (a < 2 ? r.ptr < end && *r.ptr == ',' : r.ptr == end);
    p = r.ptr + 1;
  }
  if (!ok || !is_finite(o) || !in_coord_range(o))
    throw InputError("scene '" + arg + "': expected NAME@dx,dy,dz for a translated scene (|d| <= 2^56)");
  if (off) *off = o;
  return arg.substr(0, at);
}

// Every offset of "S@a,b,c@d,e,f" (load_scene applies them from the last), each checked -> S.
std::string strip_offsets(const std::string& arg) {
  std::string base = arg;
  for (std::string next = strip_offset(base); next != base; next = strip_offset(base)) base = next;
  return base;
}

// A scene argument without its offsets names a built-in scene: a built-in name, or any bare word
// (no '.', no '/'), which is then reported as an unknown scene name rather than a missing file.
bool names_builtin(const std::string& name) {
  return is_builtin_scene(name) || (name.find('.') == std::string::npos && name.find('/') == std::string::npos);
}

}  // namespace

Scene make_builtin_scene(const std::string& name) {
  check_builtin_name(name);
  Scene s;
  if (name == "room") s = room();
  else if (name == "stadium") s = stadium();
  else if (name == "sphere") s = sphere();
  else s = spheres(spheres_count(name));
  s.validate();
  return s;
}

std::string scene_file_of(const std::string& arg) {
  const std::string base = strip_offsets(arg);
  return names_builtin(base) ? std::string() : base;
}

void check_scene_arg(const std::string& arg) {
  if (arg.empty()) throw InputError("empty scene name");
  const std::string base = strip_offsets(arg);
  if (names_builtin(base)) check_builtin_name(base);
  else check_scene_file(base);
}

Scene load_scene(const std::string& arg) {
  // "S@dx,dy,dz": scene S translated by (dx, dy, dz), the huge-offset hard case.
  Vec3 off;
  if (const std::string base = strip_offset(arg, &off); base != arg) {
    Scene s = load_scene(base);
    // A translation so far that float spacing collapses every triangle to zero area traces an
    // empty scene, not the one named: refused rather than reported as misses. (Some collapsed
    // triangles are the point of the huge-offset hard case, sphere@1483760,...: kept.)
    const size_t had_area = s.triangles_with_area();
    s.translate(off);
    const size_t keeps_area = s.triangles_with_area();
    if (had_area > 0 && keeps_area == 0)
      throw InputError("scene '" + arg + "': the translation collapses all " + std::to_string(had_area) +
                       " triangles to zero area in float (offset too large for the scene's size)");
    s.name += arg.substr(base.size());
    s.validate();
    return s;
  }
  return names_builtin(arg) ? make_builtin_scene(arg) : load_scene_file(arg);
}

}  // namespace tb
