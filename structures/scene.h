// Scene: what a traversal experiment needs and nothing more — vertex positions, triangle
// indices, and the camera views of the divergence experiments (thesis §3.4: three views per scene).
#pragma once
#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "structures/vec3.h"

namespace tb {

struct CameraView {
  std::string name;
  Vec3 eye, target, up{0, 1, 0};
  float vfov_deg = 60.f;
};

// Any scene, workload or CLI input that is malformed raises this; the CLI prints its message
// (one line) and exits non-zero.
struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Scene {
  std::string name;
  std::vector<Vec3> positions;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<CameraView> views;  // views[0] is the default camera

  size_t num_triangles() const { return triangles.size(); }
  Vec3 vertex(uint32_t tri, int corner) const { return positions[triangles[tri][corner]]; }
  AABB bounds() const;
  AABB triangle_bounds(uint32_t tri) const;
  // Rejects NaN/Inf coordinates, coordinates outside the traceable range (vec3.h, kCoordLimit),
  // out-of-range indices, empty scenes and scenes whose every triangle is degenerate
  // (triangles_with_area() == 0: every ray would miss) with an InputError.
  void validate() const;
  // The triangles a ray can hit: a cross product of two edges in float with a component at least
  // FLT_MIN (a denormal normal is zero to a tracing thread's flush-to-zero arithmetic, and so is
  // every edge function of such a triangle).
  size_t triangles_with_area() const;
  // Reads denormal coordinates as 0, as every tracing thread would (DAZ): a file's 1e-40 is
  // traced and checked against the exact reference as the same 0 (the file loaders call it).
  void flush_denormals();
  // FNV-1a over positions and indices: identifies the geometry in provenance records.
  uint64_t content_hash() const;
  // Derives three views from the bounds (outside three corners, looking at the centre) when the
  // scene has none.
  void ensure_views();
  void translate(Vec3 offset);
};

}  // namespace tb
