// Dispatch by extension, the checks every format shares, and camera views from scenes.json.
#include "structures/scene_loader.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>

namespace tb {

namespace fs = std::filesystem;

namespace detail {

std::string error_line(const std::string& path, const std::string& what) {
  // Library messages (tinygltf, OpenMesh) come with embedded line breaks; the CLI contract is one
  // line per error, so fold them into "; ".
  std::string out = path + ": ";
  bool pending_sep = false;
  for (char c : what) {
    if (c == '\n' || c == '\r') {
      pending_sep = true;
      continue;
    }
    if (pending_sep) {
      out += "; ";
      pending_sep = false;
    }
    out += c;
  }
  while (!out.empty() && (out.back() == ' ' || out.back() == ';')) out.pop_back();
  return out;
}

std::string file_stem(const std::string& path) { return fs::path(path).stem().string(); }

void check_regular_file(const std::string& path) {
  std::error_code ec;
  fs::file_status st = fs::status(path, ec);
  if (ec && ec != std::errc::no_such_file_or_directory)
    throw InputError(error_line(path, "cannot access file (" + ec.message() + ")"));
  if (!fs::exists(st)) throw InputError(error_line(path, "file not found"));
  if (fs::is_directory(st)) throw InputError(error_line(path, "is a directory, not a scene file"));
  if (!fs::is_regular_file(st)) throw InputError(error_line(path, "is not a regular file"));
  // Opening is the only reliable readability test (permissions, ACLs, root squash...).
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw InputError(error_line(path, std::string("cannot open file (") + std::strerror(errno) + ")"));
  std::fclose(f);
  if (fs::file_size(path, ec) == 0 && !ec) throw InputError(error_line(path, "file is empty"));
}

std::string read_file_bytes(const std::string& path) {
  check_regular_file(path);
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) throw InputError(error_line(path, std::string("cannot open file (") + std::strerror(errno) + ")"));
  std::string data;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f.get())) > 0) data.append(buf, n);
  if (std::ferror(f.get())) throw InputError(error_line(path, "read error"));
  if (data.empty()) throw InputError(error_line(path, "file is empty"));
  return data;
}

}  // namespace detail

namespace {

std::string lower_extension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

// scenes.json values are checked here rather than trusted: a typo there would otherwise become a
// camera full of NaNs deep inside a workload generator.
Vec3 json_vec3(const nlohmann::json& j, const std::string& json_path, const std::string& what) {
  if (!j.is_array() || j.size() != 3)
    throw InputError(detail::error_line(json_path, what + " must be a list of three numbers"));
  Vec3 v;
  for (int i = 0; i < 3; ++i) {
    if (!j[i].is_number()) throw InputError(detail::error_line(json_path, what + " must be a list of three numbers"));
    v[i] = j[i].get<float>();
  }
  if (!is_finite(v)) throw InputError(detail::error_line(json_path, what + " has a non-finite or out-of-range component"));
  if (max_abs(v) > kCoordLimit)
    throw InputError(detail::error_line(json_path, what + " has a component beyond +-2^56 (7.2e16), the range travbench traces"));
  return v;
}

// The views file of a scene file: scenes.json in its directory.
fs::path scenes_json_of(const std::string& scene_path) { return fs::path(scene_path).parent_path() / "scenes.json"; }

}  // namespace

bool has_scene_file_extension(const std::string& path) {
  std::string ext = lower_extension(path);
  return ext == ".gltf" || ext == ".glb" || ext == ".obj" || ext == ".ply" || ext == ".off" || ext == ".stl";
}

std::vector<CameraView> views_from_scenes_json(const std::string& scene_path) {
  const fs::path json_path = scenes_json_of(scene_path);
  std::error_code ec;
  if (!fs::is_regular_file(json_path, ec)) return {};
  const std::string jp = json_path.string();
  const std::string file_name = fs::path(scene_path).filename().string();
  const std::string purpose = " (read for the camera views of '" + file_name + "')";
  std::string text = detail::read_file_bytes(jp);
  nlohmann::json root = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (root.is_discarded()) throw InputError(detail::error_line(jp, "is not valid JSON" + purpose));

  // The shared file maps scene names to entries; a plain list of entries is accepted as well.
  std::vector<const nlohmann::json*> entries;
  if (root.is_object())
    for (const auto& [key, value] : root.items()) entries.push_back(&value);
  else if (root.is_array())
    for (const auto& value : root) entries.push_back(&value);
  else
    throw InputError(detail::error_line(jp, "must hold an object or a list of scene entries" + purpose));

  for (const nlohmann::json* e : entries) {
    if (!e->is_object()) continue;
    auto file = e->find("file");
    if (file == e->end() || !file->is_string() || file->get<std::string>() != file_name) continue;
    auto views = e->find("views");
    if (views == e->end()) continue;
    const std::string where = "entry for '" + file_name + "'";
    if (!views->is_array()) throw InputError(detail::error_line(jp, where + ": views must be a list"));
    std::vector<CameraView> out;
    for (size_t i = 0; i < views->size(); ++i) {
      const nlohmann::json& v = (*views)[i];
      const std::string vw = where + ", view " + std::to_string(i + 1);
      if (!v.is_object() || !v.contains("eye") || !v.contains("target"))
        throw InputError(detail::error_line(jp, vw + ": needs eye and target"));
      CameraView cv;
      cv.name = "view" + std::to_string(i + 1);
      cv.eye = json_vec3(v["eye"], jp, vw + ": eye");
      cv.target = json_vec3(v["target"], jp, vw + ": target");
      if (v.contains("up")) {
        cv.up = json_vec3(v["up"], jp, vw + ": up");
        // A denormal component is zero to a tracing thread (flush-to-zero, as for the vertices:
        // Scene::flush_denormals), so it is zero here too: an `up` of denormals is refused below.
        for (int a = 0; a < 3; ++a)
          if (is_denormal(cv.up[a])) cv.up[a] = 0.f;
      }
      if (v.contains("vfov_deg")) {
        if (!v["vfov_deg"].is_number()) throw InputError(detail::error_line(jp, vw + ": vfov_deg must be a number"));
        cv.vfov_deg = v["vfov_deg"].get<float>();
      }
      if (cv.eye == cv.target) throw InputError(detail::error_line(jp, vw + ": eye equals target"));
      // Below 1e-3 degrees a pixel's direction offsets vanish against the forward vector in float.
      if (!(cv.vfov_deg >= 1e-3f && cv.vfov_deg < 180.f))
        throw InputError(detail::error_line(jp, vw + ": vfov_deg must be in [0.001, 180)"));
      // In double: the float products of far-apart eyes and targets or of a huge `up` overflow.
      const double f[3] = {double(cv.target.x) - cv.eye.x, double(cv.target.y) - cv.eye.y, double(cv.target.z) - cv.eye.z};
      const double u[3] = {cv.up.x, cv.up.y, cv.up.z};
      const double side[3] = {f[1] * u[2] - f[2] * u[1], f[2] * u[0] - f[0] * u[2], f[0] * u[1] - f[1] * u[0]};
      auto len = [](const double* a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); };
      if (len(side) <= 1e-6 * len(f) * len(u))
        throw InputError(detail::error_line(jp, vw + ": up is zero or parallel to the view direction"));
      out.push_back(cv);
    }
    return out;
  }
  return {};
}

void check_scene_file(const std::string& path) {
  detail::check_regular_file(path);
  if (has_scene_file_extension(path)) return;
  const std::string ext = lower_extension(path);
  throw InputError(detail::error_line(
      path, (ext.empty() ? std::string("file has no extension") : "unknown scene file extension '" + ext + "'") +
                " (expected .gltf, .glb, .obj, .ply, .off or .stl)"));
}

namespace {

// %XX escapes of a glTF URI decoded (glTF 2.0 §3.3: URIs are RFC 3986; the loader resolves
// relative ones against the file's directory, as tinygltf does).
std::string percent_decoded(const std::string& uri) {
  std::string out;
  for (size_t i = 0; i < uri.size(); ++i) {
    if (uri[i] == '%' && i + 2 < uri.size() && std::isxdigit(static_cast<unsigned char>(uri[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(uri[i + 2]))) {
      out.push_back(static_cast<char>(std::stoi(uri.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      out.push_back(uri[i]);
    }
  }
  return out;
}

// The external files a glTF file names (buffers and images with a URI that is not a data: URI),
// resolved against its directory; only those that exist as regular files. The JSON of a .glb is
// its first chunk (glTF 2.0 §4.4: a 12-byte header, then the chunk's length and type "JSON").
// A file that does not parse names nothing here: loading it reports the error. Of a .glb only the
// header and the JSON chunk are read (the commands list their inputs before loading the scene, and
// the binary chunk may be most of a large file).
std::vector<std::string> gltf_external_files(const std::string& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return {};  // never open a FIFO or a device here
  const uintmax_t size = fs::file_size(path, ec);
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (ec || !f) return {};
  char head[20];
  const size_t got = std::fread(head, 1, sizeof head, f.get());
  std::string text;
  if (got == sizeof head && std::memcmp(head, "glTF", 4) == 0) {
    uint32_t length = 0;
    std::memcpy(&length, head + 12, 4);
    if (std::memcmp(head + 16, "JSON", 4) != 0 || length > size - sizeof head) return {};
    text.resize(length);
    if (std::fread(text.data(), 1, length, f.get()) != length) return {};
  } else {
    f.reset();
    try {
      text = detail::read_file_bytes(path);
    } catch (const InputError&) {
      return {};
    }
  }
  const nlohmann::json root = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  std::vector<std::string> files;
  if (!root.is_object()) return files;
  const fs::path dir = fs::path(path).parent_path();
  for (const char* key : {"buffers", "images"}) {
    const auto it = root.find(key);
    if (it == root.end() || !it->is_array()) continue;
    for (const nlohmann::json& e : *it) {
      if (!e.is_object() || !e.contains("uri") || !e["uri"].is_string()) continue;
      const std::string uri = e["uri"].get<std::string>();
      if (uri.rfind("data:", 0) == 0) continue;
      const fs::path f = dir / percent_decoded(uri);
      std::error_code ec;
      if (fs::is_regular_file(f, ec)) files.push_back(f.string());
    }
  }
  return files;
}

}  // namespace

std::vector<SceneFileInput> scene_file_inputs(const std::string& path) {
  using Role = SceneFileInput::Role;
  std::vector<SceneFileInput> files = {{path, Role::scene}};
  const fs::path json = scenes_json_of(path);
  std::error_code ec;
  if (fs::is_regular_file(json, ec)) files.push_back({json.string(), Role::views});
  const std::string ext = lower_extension(path);
  if (ext == ".gltf" || ext == ".glb")
    for (std::string& f : gltf_external_files(path)) files.push_back({std::move(f), Role::external});
  return files;
}

Scene load_scene_file(const std::string& path) {
  check_scene_file(path);
  const std::string ext = lower_extension(path);
  Scene s;
  if (ext == ".gltf" || ext == ".glb")
    s = load_gltf(path);
  else if (ext == ".obj")
    s = load_obj(path);
  else if (ext == ".off")
    s = load_off(path);
  else if (ext == ".stl")
    s = load_stl(path);
  else
    s = load_ply(path);
  s.name = detail::file_stem(path);
  s.flush_denormals();
  try {
    s.validate();
  } catch (const InputError& e) {
    throw InputError(detail::error_line(path, e.what()));
  }
  // Primitive ids are uint32 and 0xFFFFFFFF means "no hit" (DESIGN.md, hits file).
  if (s.triangles.size() >= 0xFFFFFFFFull || s.positions.size() >= 0xFFFFFFFFull)
    throw InputError(detail::error_line(path, "more than 2^32-2 triangles or vertices"));
  // scenes.json wins; without an entry there, the file's own cameras (glTF) are the views.
  if (std::vector<CameraView> listed = views_from_scenes_json(path); !listed.empty()) s.views = std::move(listed);
  s.ensure_views();
  return s;
}

}  // namespace tb
