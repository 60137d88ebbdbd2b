// Rays, hits and the batch every traverser consumes (DESIGN.md core types).
#pragma once
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "structures/vec3.h"

namespace tb {

struct Ray {
  Vec3 org;
  float tmin = 0.f;
  Vec3 dir;
  float tmax = std::numeric_limits<float>::infinity();
};
static_assert(sizeof(Ray) == 32);

inline constexpr uint32_t kNoHit = 0xFFFFFFFFu;

struct Hit {
  float t = std::numeric_limits<float>::infinity();
  uint32_t prim = kNoHit;
  float u = 0.f, v = 0.f;
  bool hit() const { return prim != kNoHit; }
};
static_assert(sizeof(Hit) == 16);

// Rays grouped in packets: packet p is rays [packet_begin[p], packet_begin[p+1]). Primary packets
// hold packet_size rays (16x16 = 256 in the thesis' Fig. 16 layout); bounce and shadow rays keep
// their pixel's packet, so those packets may be smaller (paths that left the scene are gone).
struct RayBatch {
  std::vector<Ray> rays;
  std::vector<uint32_t> packet_begin{0};
  uint32_t packet_size = 256;
  bool common_origin = false;  // every ray starts at one point (primary, divergence:D, rnd)
  // The rays are in the order a scheme asked to trace them in (Traverser::batch_order): a
  // multi-threaded trace's copy of a batch, which the scheme must not reorder again.
  bool ordered = false;
  uint32_t depth = 0;          // 0 = primary, k = k-th bounce (for statistics by depth)
  std::string workload;
  // Camera workloads (primary, divergence, bounce, shadow): the pixel y * width + x whose path each
  // ray continues, so per-ray costs map back to the image (`travbench image`); empty otherwise
  // (random rays, hard cases, ray files).
  std::vector<uint32_t> pixel;

  size_t size() const { return rays.size(); }
  uint32_t num_packets() const { return uint32_t(packet_begin.size() - 1); }
  uint32_t packet_rays(uint32_t p) const { return packet_begin[p + 1] - packet_begin[p]; }
  // Regroups into uniform packets of `n` rays (the last one may be short).
  void group_uniform(uint32_t n);
  // Appends b's rays after these, b's packets kept as packets of their own. The result is a ray
  // file's batch, not one camera image: pixels are dropped and common_origin cleared.
  void append(const RayBatch& b);
  // Rejects NaN/Inf and zero directions with an InputError naming the first bad ray.
  void validate() const;
};

// The packets [first, last) of a batch: the unit of work a thread traces.
struct PacketRange {
  uint32_t first = 0, last = 0;
  static PacketRange all(const RayBatch& b) { return {0, b.num_packets()}; }
};

}  // namespace tb
