#include "workloads/ray_batch.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "structures/scene.h"

namespace tb {

void RayBatch::group_uniform(uint32_t n) {
  packet_size = n;
  packet_begin.clear();
  for (uint32_t i = 0; i < rays.size(); i += n) packet_begin.push_back(i);
  packet_begin.push_back(uint32_t(rays.size()));
}

void RayBatch::append(const RayBatch& b) {
  const uint32_t base = uint32_t(rays.size());
  rays.insert(rays.end(), b.rays.begin(), b.rays.end());
  for (size_t p = 1; p < b.packet_begin.size(); ++p) packet_begin.push_back(base + b.packet_begin[p]);
  pixel.clear();
  common_origin = false;
}

void RayBatch::validate() const {
  if (packet_begin.empty() || packet_begin.front() != 0 || packet_begin.back() != rays.size())
    throw InputError("ray batch: packet table does not cover the rays");
  for (size_t p = 1; p < packet_begin.size(); ++p)
    if (packet_begin[p] < packet_begin[p - 1]) throw InputError("ray batch: packet table is not increasing");
  auto g = [](float v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", double(v));
    return std::string(buf);
  };
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& r = rays[i];
    if (!is_finite(r.org) || !is_finite(r.dir) || std::isnan(r.tmin) || std::isnan(r.tmax) ||
        std::isinf(r.tmin))
      throw InputError("ray " + std::to_string(i) + " has a NaN or Inf component");
    if (r.dir.x == 0.f && r.dir.y == 0.f && r.dir.z == 0.f)
      throw InputError("ray " + std::to_string(i) + " has a zero direction");
    if (r.tmin < 0.f) throw InputError("ray " + std::to_string(i) + " has a negative tmin");
    // The traceable range (structures/vec3.h, kCoordLimit: why, there).
    const float c[8] = {r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z, r.tmin, r.tmax};
    for (int k = 0; k < 8; ++k) {
      static const char* const kField[8] = {"org.x", "org.y", "org.z", "dir.x", "dir.y", "dir.z", "tmin", "tmax"};
      if (is_denormal(c[k]))
        throw InputError("ray " + std::to_string(i) + ": " + kField[k] + " is a denormal (" + g(c[k]) +
                         "), which every tracing thread reads as 0 (DAZ)");
      if (k < 6 && std::fabs(c[k]) > kCoordLimit)
        throw InputError("ray " + std::to_string(i) + ": " + kField[k] + " = " + g(c[k]) +
                         " is beyond +-2^56 (7.2e16), the range travbench traces");
    }
    if (max_abs(r.dir) < 1.f / kCoordLimit)
      throw InputError("ray " + std::to_string(i) + " has a direction shorter than 2^-56 (1.4e-17) in every component");
  }
}

}  // namespace tb
