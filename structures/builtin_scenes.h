// Procedural scenes that need no files: an occluded interior, "teapot in a stadium", a scalable
// field of spheres (scaling curves up to ~10M triangles) and a single closed sphere (hard cases).
// Every mesh is closed and welded (shared vertices), so rays from inside must always hit.
#pragma once
#include <string>
#include <vector>

#include "structures/scene.h"

namespace tb {

// Names as accepted by make_builtin_scene: "room", "stadium", "spheres:N", "sphere".
std::vector<std::string> builtin_scene_names();
bool is_builtin_scene(const std::string& name);
Scene make_builtin_scene(const std::string& name);  // throws InputError on unknown names

// Resolves a scene argument: a built-in name or a path to a scene file, optionally followed by
// @dx,dy,dz to translate it (the huge-offset hard case, e.g. sphere@148376,1234,-223423).
Scene load_scene(const std::string& name_or_path);
// What load_scene would refuse without building or reading a scene: a malformed name, offset or
// spheres:N, an unknown built-in name, a scene file that is missing, not a readable regular file or
// of an unknown format (check_scene_file). Commands call it while parsing, before any work.
void check_scene_arg(const std::string& name_or_path);
// The scene file a scene argument names, its @dx,dy,dz offsets removed; "" for a built-in scene.
std::string scene_file_of(const std::string& name_or_path);

// Closed-mesh builders, used by the built-in scenes and by tests.
struct MeshBuilder {
  Scene& scene;
  uint32_t vertex(Vec3 p);
  void tri(uint32_t a, uint32_t b, uint32_t c) { scene.triangles.push_back({a, b, c}); }
  void box(Vec3 lo, Vec3 hi);
  // UV sphere with shared poles: 2 * slices * (stacks - 1) triangles.
  void sphere(Vec3 centre, float radius, int slices, int stacks);
  // Torus around the y axis: 2 * major * minor triangles.
  void torus(Vec3 centre, float major_radius, float minor_radius, int major, int minor);
  // Capped cylinder along y: 4 * segments triangles.
  void cylinder(Vec3 base, float radius, float height, int segments);
};

}  // namespace tb
