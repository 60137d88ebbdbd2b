#include "structures/scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

namespace tb {

AABB Scene::bounds() const {
  AABB b;
  for (const auto& t : triangles)
    for (uint32_t i : t) b.grow(positions[i]);
  return b;
}

AABB Scene::triangle_bounds(uint32_t tri) const {
  AABB b;
  for (int c = 0; c < 3; ++c) b.grow(vertex(tri, c));
  return b;
}

void Scene::validate() const {
  if (triangles.empty()) throw InputError("scene '" + name + "' has no triangles");
  for (size_t i = 0; i < positions.size(); ++i) {
    if (!is_finite(positions[i]))
      throw InputError("scene '" + name + "': vertex " + std::to_string(i) + " has a NaN or Inf coordinate");
    // The traceable range (vec3.h, kCoordLimit; the file loaders flush denormals first).
    if (!in_coord_range(positions[i])) {
      const bool big = max_abs(positions[i]) > kCoordLimit;
      throw InputError("scene '" + name + "': vertex " + std::to_string(i) + " has a " +
                       (big ? "coordinate beyond +-2^56 (7.2e16)" : "denormal coordinate") +
                       ", outside the range travbench traces");
    }
  }
  for (size_t t = 0; t < triangles.size(); ++t)
    for (uint32_t i : triangles[t])
      if (i >= positions.size())
        throw InputError("scene '" + name + "': triangle " + std::to_string(t) + " uses vertex index " +
                         std::to_string(i) + " but there are " + std::to_string(positions.size()) + " vertices");
  if (triangles_with_area() == 0)
    throw InputError("scene '" + name + "': all " + std::to_string(triangles.size()) +
                     " triangles are degenerate (zero area in float): nothing a ray can hit");
  if (const Vec3 e = bounds().extent(); std::max({e.x, e.y, e.z}) < kMinSceneExtent) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", double(std::max({e.x, e.y, e.z})));
    throw InputError("scene '" + name + "' is " + buf +
                     " across, below 2^-51 (4.4e-16), where the float kernels' products of coordinates "
                     "underflow (scale the scene up)");
  }
}

size_t Scene::triangles_with_area() const {
  size_t n = 0;
  for (uint32_t t = 0; t < num_triangles(); ++t)
    n += max_abs(cross(vertex(t, 1) - vertex(t, 0), vertex(t, 2) - vertex(t, 0))) >= std::numeric_limits<float>::min();
  return n;
}

uint64_t Scene::content_hash() const {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&](const void* data, size_t n) {
    auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  };
  mix(positions.data(), positions.size() * sizeof(Vec3));
  mix(triangles.data(), triangles.size() * sizeof(triangles[0]));
  return h;
}

void Scene::ensure_views() {
  if (!views.empty()) return;
  AABB b = bounds();
  Vec3 c = b.centre(), e = b.extent();
  // A scene without extent (every vertex on one point) or far thinner than its distance from the
  // origin would put the eye on the centre in float (a zero view direction): its corners are then
  // placed 2^-12 of the centre's magnitude (or 1) away.
  const float m = max_abs(c);
  if (std::max({e.x, e.y, e.z}) <= m * 0x1p-20f) {
    const float s = m > 0.f ? m * 0x1p-12f : 1.f;
    e = {s, s, s};
  }
  // Three corners at 0.9x the half-diagonal beyond the box, all looking at the centre.
  const Vec3 dirs[3] = {{1, 0.6f, 1}, {-1, 0.4f, 0.8f}, {0.7f, 0.9f, -1}};
  const char* names[3] = {"corner1", "corner2", "corner3"};
  for (int i = 0; i < 3; ++i) {
    Vec3 eye = c + dirs[i] * e * 0.95f;
    // A scene near the edge of the traceable range keeps its eyes inside it (vec3.h, kCoordLimit).
    for (int a = 0; a < 3; ++a) eye[a] = std::clamp(eye[a], -kCoordLimit, kCoordLimit);
    views.push_back({names[i], eye, c, {0, 1, 0}, 60.f});
  }
}

void Scene::flush_denormals() {
  for (auto& p : positions)
    for (int a = 0; a < 3; ++a)
      if (is_denormal(p[a])) p[a] = 0.f;
}

void Scene::translate(Vec3 offset) {
  for (auto& p : positions) p = p + offset;
  for (auto& v : views) {
    v.eye = v.eye + offset;
    v.target = v.target + offset;
  }
}

}  // namespace tb
