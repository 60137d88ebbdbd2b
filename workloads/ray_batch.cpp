#include "workloads/ray_batch.h"

#include <cmath>

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
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& r = rays[i];
    if (!is_finite(r.org) || !is_finite(r.dir) || std::isnan(r.tmin) || std::isnan(r.tmax) ||
        std::isinf(r.tmin))
      throw InputError("ray " + std::to_string(i) + " has a NaN or Inf component");
    if (r.dir.x == 0.f && r.dir.y == 0.f && r.dir.z == 0.f)
      throw InputError("ray " + std::to_string(i) + " has a zero direction");
    if (r.tmin < 0.f) throw InputError("ray " + std::to_string(i) + " has a negative tmin");
  }
}

}  // namespace tb
