// Scene files -> tb::Scene. One entry point (load_scene_file) dispatches on the extension; the
// per-format loaders are declared here too so that tests and tools can call them directly.
//
// Primitive ids are triangle indices in the order the loader produces them (DESIGN.md, "File
// formats"): faces in file order, a polygon (v0..vn) becoming the fan (v0,v{i-1},v{i}). Every loader
// keeps every face of the file, degenerate ones included, so that ids stay comparable with other
// tools; anything it cannot represent faithfully is an InputError, never a silently dropped face.
#pragma once
#include <string>
#include <vector>

#include "structures/scene.h"

namespace tb {

// .gltf/.glb (tinygltf), .obj/.off/.stl/.ply (own parsers, see mesh_loader.cpp for why not OpenMesh);
// the extension is matched case-insensitively. Validates the geometry, names the scene after the
// file's stem and attaches camera views: those of a scenes.json beside the file when it has an entry
// for this file, otherwise Scene::ensure_views(). Any problem -> InputError "<path>: <what>".
Scene load_scene_file(const std::string& path);

// True when load_scene_file knows the path's extension (lets the CLI tell a file from a built-in
// scene name without touching the disk).
bool has_scene_file_extension(const std::string& path);
// What load_scene_file checks before reading: an existing, readable, non-empty regular file with a
// known extension; InputError "<path>: <what>" otherwise. Cheap, so commands check it up front.
void check_scene_file(const std::string& path);
// The files loading the scene file `path` reads as a whole: the file, the scenes.json beside
// it when there is one (its camera views), and a glTF file's external buffers and images. What a
// command must not write over; `role` says which of the three each is (for the refusal's message).
struct SceneFileInput {
  enum class Role { scene, views, external };
  std::string path;
  Role role;
};
std::vector<SceneFileInput> scene_file_inputs(const std::string& path);

// The views that the scenes.json in the scene file's directory lists for that file (named view1,
// view2, ...); empty when there is no scenes.json or no entry with views for the file. A scenes.json
// that exists but cannot be parsed, or a malformed view in this file's entry, is an InputError.
std::vector<CameraView> views_from_scenes_json(const std::string& scene_path);

// Per-format loaders. They fill name, positions and triangles (no views) and report every malformed
// input as an InputError; load_scene_file adds validation and views.
Scene load_gltf(const std::string& path);  // glTF 2.0, .gltf (JSON) or .glb (binary)
Scene load_obj(const std::string& path);   // Wavefront OBJ: v and f lines
Scene load_off(const std::string& path);   // Geomview OFF (ASCII)
Scene load_stl(const std::string& path);   // STL, ASCII or binary
Scene load_ply(const std::string& path);   // PLY, ASCII or binary (either byte order)
// .obj/.off/.ply/.stl through OpenMesh's readers (faces in reading order, fanned like the above).
// It is the independent second reading that the tests compare the parsers above against; it is not
// used for untrusted input because OpenMesh's readers drop or invent faces on some inputs (see
// mesh_loader.cpp). It still reports what it can detect as InputError.
Scene load_mesh_openmesh(const std::string& path);

namespace detail {
// Whole file as bytes; InputError when it is missing, a directory, unreadable or empty.
std::string read_file_bytes(const std::string& path);
// Throws InputError unless path names an existing, non-empty regular file.
void check_regular_file(const std::string& path);
// "<path>: <what>" with line breaks in what folded, so every loader error is one line.
std::string error_line(const std::string& path, const std::string& what);
// File name without directory and last extension.
std::string file_stem(const std::string& path);
}  // namespace detail

}  // namespace tb
