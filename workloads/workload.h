// Generated ray workloads of controlled divergence (thesis §3.4, §5.2.3, §6.2.1).
#pragma once
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "structures/scene.h"
#include "workloads/ray_batch.h"

namespace tb {

// Closest hits of every ray of a batch (hits[i] for batch.rays[i]). Workloads that follow paths
// (bounce, shadow) trace them with the reference through this, so workloads/ needs nothing from
// traversal/ (layers point down; harness/ passes the reference scheme in).
using ClosestHitFn = std::function<void(const RayBatch&, std::span<Hit>)>;

struct WorkloadSpec {
  std::string kind;   // primary, divergence, rnd, rnd2, bounce, shadow, hard:*
  int param = 1;      // D for divergence, k for bounce
  // divergence only: the side of the square tiles whose top-left corner D scales the ray angles
  // about ("divergence:D/T"; 16 = the 16x16 packets of thesis §3.4, 8 = the 8x8 tiles of Table 12,
  // §6.2.1; docs/WORKLOADS.md argues the corner).
  uint32_t tile = 16;
  // bounce only: the Russian-roulette survival probability at each surface ("bounce:k/p"; 1 = no
  // roulette, docs/WORKLOADS.md argues the default). The thesis' path tracer (Alg. 6.1) uses it.
  double survival = 1.0;
  // Camera workloads: the horizontal field of view in degrees that replaces the view's vfov, or 0
  // for the view's own. The thesis tables set thesis_hfov_deg(), the camera of Tables 2-4.
  double hfov_deg = 0;
  uint32_t width = 512, height = 512;
  uint32_t view = 0;  // index into scene.views
  uint64_t seed = 1;
  std::string name() const;  // canonical name, e.g. "divergence:8", "divergence:8/8"
};

// Thesis §3.4, Tables 2-4: "Divergence is in multiples of 0.034 degrees between adjacent rays",
// measured at 1280x800. The horizontal field of view that puts the two pixels beside the image
// centre of a 1280-pixel-wide pinhole camera 0.034 degrees apart (41.6 degrees).
inline constexpr double kThesisRayDeg = 0.034;
inline constexpr uint32_t kThesisWidth = 1280, kThesisHeight = 800;
double thesis_hfov_deg();
// The angle in degrees between the rays through the two pixels beside the centre of the image of
// spec's camera (spec.width, spec.height, spec.hfov_deg or the view's vfov): divergence:D puts
// adjacent rays of a tile D times this apart at the tile's corner (the deg_per_ray column).
double centre_pixel_deg(const Scene& scene, const WorkloadSpec& spec);

// Parses "primary", "divergence:D", "rnd", "rnd2", "bounce:k", "shadow" (and the hard cases);
// throws InputError naming the problem.
WorkloadSpec parse_workload(const std::string& text);
std::vector<std::string> workload_names();
// Whether the rays depend on the camera view (spec.view): every workload but rnd2 (origins on the
// scene's surfaces) and the hard cases (built from the scene's triangles). `--view` is refused for
// the others rather than recorded on rows whose rays it did not change.
bool uses_view(const WorkloadSpec& spec);
// Whether the rays are one per camera pixel, each ray's pixel known (primary, divergence, bounce,
// shadow): decided by kind, since a batch of no rays has as many pixels as rays whatever made it.
bool from_camera_pixels(const WorkloadSpec& spec);

// Generates the rays. Bounce and shadow workloads trace their paths with `reference` (the
// reference scheme prepared on this scene); the others ignore it. Deterministic given the spec
// (seed included).
RayBatch generate_workload(const Scene& scene, const WorkloadSpec& spec, const ClosestHitFn& reference);

// Primary rays in 16x16 packets, Fig. 16 layout (thesis §3.3): each packet is four 8x8 quadrants
// of 64 rays, each quadrant sixteen 2x2 groups. D scales the angle between adjacent rays of a
// tile (spec.tile x spec.tile pixels, aligned within the packet) about the tile's top-left corner
// (§3.4), so D > 1 tiles overlap the tiles right of and below them and, but for the right column
// and bottom row of tiles, touch the same geometry as D = 1.
RayBatch primary_rays(const Scene& scene, const WorkloadSpec& spec, float divergence);

// Pixel of the i-th ray (0..255) of a 16x16 packet in the Fig. 16 layout.
inline void fig16_pixel(uint32_t i, uint32_t& x, uint32_t& y) {
  const uint32_t q = i >> 6, g = (i >> 2) & 15, k = i & 3;
  x = (q & 1) * 8 + (g & 3) * 2 + (k & 1);
  y = (q >> 1) * 8 + (g >> 2) * 2 + (k >> 1);
}

// Deterministic per-ray random numbers, independent of threading and generation order.
struct Rng {
  uint64_t state;
  Rng(uint64_t seed, uint64_t stream) : state(seed * 0x9E3779B97F4A7C15ull ^ (stream + 0x632BE59BD9B4E019ull)) {
    next();
    next();
  }
  uint64_t next() {  // splitmix64
    uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  float uniform() { return float(next() >> 40) * 0x1p-24f; }  // [0, 1)
};

// Sampling helpers shared by the path workloads (bounce, shadow) and the path tracer of
// harness/pathtrace (thesis ch. 6): one definition each, in workload.cpp.
// Orthonormal basis (t, b) around the unit vector n (Duff et al. 2017).
void basis(Vec3 n, Vec3& t, Vec3& b);
// Cosine-weighted direction in the hemisphere around n (Malley's method): pdf cos(theta) / pi.
Vec3 cosine_hemisphere(Vec3 n, Rng& rng);
// A point on a surface and its geometric normal, from a hit's barycentrics.
struct SurfacePoint {
  Vec3 p, n;
  float eps;  // offset that clears the surface: relative to the triangle's size and position
};
SurfacePoint surface_point(const Scene& s, uint32_t tri, float u, float v);

}  // namespace tb
