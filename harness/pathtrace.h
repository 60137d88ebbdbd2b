// A small path tracer over any registered traverser, and the path-tracing schemes of thesis
// chapter 6 that drive it (Bikker 2012, §6.2.2-§6.4, Tables 14-15; docs/PATHTRACE.md):
//   Ref      Alg. 6.1: Russian roulette (survival = albedo, Arvo & Kirk) + explicit light sampling
//   PR       path regeneration (Novák et al. 2010, §6.3.1): a lane whose path ended starts the
//            pixel's next sample at the next iteration, until the pixel's spp are started
//   DPT      deterministic path termination (§6.3.2, Alg. 6.2): no roulette, sample idx of spp
//            ends after d_max(idx) = floor(log2(spp - idx)) + 1 segments, throughput x 1/(1 - 0.5)
//   SPT      streaming path tracing (Van Antwerpen 2011, §6.3.3): one stream of N samples,
//            compacted after every extension, refilled with new primary rays
//   RIS      Ref with resampled importance sampling of the light (Talbot et al. 2005, Alg. 6.3)
//   RIS/MIS  RIS plus multiple importance sampling: the extension ray doubles as the BRDF sample
//            of the direct light (balance heuristic, §6.4.3)
// Every driver shares one wavefront step: gather the active lanes' rays into packets, trace them
// with Traverser::trace (closest hit), shade, then trace the shadow rays the same way.
//
// Layering: harness/ drives traversal/ through the Traverser interface only. The interface has no
// any-hit entry; occlusion is closest hit with tmax = distance to the light point (exact, slower
// than an early-out any-hit; adding one would mean a second entry in every registered scheme).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "structures/scene.h"
#include "traversal/traverser.h"

namespace tb {

// One-sided emitting parallelogram {corner + a e1 + b e2 : a, b in [0, 1]}, emitting toward
// n = normalize(e1 x e2). Lights are not scene geometry: extension rays test them analytically,
// and they do not occlude each other.
struct AreaLight {
  Vec3 corner, e1, e2, n;
  Vec3 radiance;
  float area = 0;
};

// What the experiment needs of a scene's look: one diffuse albedo for every triangle (Scene keeps
// no per-triangle materials), a constant sky radiance for rays that leave the scene, and area lights.
struct Lighting {
  std::string source;  // "description:<scene>" or "default"
  Vec3 albedo{0.6f, 0.6f, 0.6f};
  Vec3 sky{0, 0, 0};
  std::vector<AreaLight> lights;
  uint64_t hash() const;  // FNV-1a over every value (the converged image's cache key)
};
// The scene's description (harness/pathtrace.cpp keeps a short table, by scene name, in
// coordinates relative to the scene's bounds) or the documented default: a dim sky and one square
// light under the top of the bounds, facing down (docs/PATHTRACE.md).
Lighting scene_lighting(const Scene& scene);

enum class PtMethod { ref, pr, dpt, spt, ris, ris_mis };
const std::vector<std::string>& pt_method_names();  // Ref, PR, DPT, SPT, RIS, RIS/MIS
PtMethod parse_pt_method(const std::string& name);  // InputError on an unknown name
std::string pt_method_name(PtMethod m);

struct PtOptions {
  uint32_t width = 512, height = 512, view = 0;
  uint32_t spp = 8;
  uint64_t seed = 1;
  // Independent random numbers per rendering: each sample's generator is keyed by (seed, salt,
  // pixel, sample index). The table salts with method, spp and repetition, so every rendering it
  // makes is an independent estimate (the converged image's two halves have salts of their own).
  std::string salt;
  uint32_t ris_per_light = 2;  // RIS candidates per light (§6.4.2: "two points on each light source")
  // When set, receives a copy of every batch handed to Traverser::trace, in trace order (each
  // iteration's extension rays, then its shadow rays), packets kept; workload "pathtrace:ext" or
  // "pathtrace:shadow", depth = the iteration (for Ref/RIS/DPT at 1 spp: the path segment). It lets
  // a frame's rays be replayed through any scheme, the cache simulator or callgrind
  // (`travbench rays --pathtrace`, scripts/pathtrace_reads.sh: the ray count behind thesis Table 11).
  std::vector<RayBatch>* traced = nullptr;
};

// Counters of one rendering. Utilisation (docs/PATHTRACE.md):
//   util       rays handed to Traverser::trace / (kPtPacket x packets handed): how full the packets
//              of the CPU batch kernels are (mbvh_rs, raygrid trace a packet's rays together).
//              Ref/PR/DPT/RIS: one packet per 16x16 tile per iteration holding the tile's active
//              lanes; SPT: the compacted stream cut into packets of kPtPacket.
//   warp_util  modelled SIMT utilisation of the path loop (thesis Fig. 33/35): lanes in warps of 32
//              fixed lanes (a tile's pixels; SPT: stream positions); active lanes / 32 over every
//              warp-iteration in which the warp has an active lane. Traversal divergence inside a
//              warp is the simt table's subject, not modelled here.
// Both over extension rays (the "find nearest" of Alg. 6.1); the shadow phase is counted apart.
inline constexpr uint32_t kPtPacket = 256, kPtWarp = 32;
struct PtStats {
  uint64_t ext_rays = 0, shadow_rays = 0;
  uint64_t ext_packets = 0, shadow_packets = 0;
  uint64_t warp_slots = 0, warp_active = 0;
  uint64_t iterations = 0;
  double trace_s = 0, total_s = 0;
  // The rendering thread's CPU time: on a shared machine wall time mostly measures the other load.
  double cpu_s = 0;
  double util() const { return ext_packets ? double(ext_rays) / double(ext_packets * kPtPacket) : 0; }
  double shadow_util() const {
    return shadow_packets ? double(shadow_rays) / double(shadow_packets * kPtPacket) : 0;
  }
  double warp_util() const { return warp_slots ? double(warp_active) / double(warp_slots) : 0; }
};

// Linear radiance per pixel (RGB), the mean over the samples.
struct PtImage {
  uint32_t width = 0, height = 0;
  std::vector<float> rgb;
};

// The image split by the path vertex a contribution comes from (docs/PATHTRACE.md, "by depth"):
// image k holds what vertex k added — k = 0: the camera ray reaching a light or the sky; k >= 1:
// the light sample at the k-th surface hit plus the light or sky reached by the ray leaving it —
// and the last image every k >= kPtDepths - 1. The images sum to the rendering. It shows where
// DPT's truncation (no vertex past log2(spp) + 1) and its fixed 50% survival cost energy and noise.
inline constexpr uint32_t kPtDepths = 7;

// Renders view `opt.view` with `method`; the traverser must be prepared on `scene`. Throws
// InputError for spp 0, an empty image or a missing view. Deterministic given (opt, lighting).
// by_depth, when given, receives kPtDepths images (above).
PtImage render_pathtrace(const Scene& scene, const Traverser& tracer, const Lighting& lighting, PtMethod method,
                         const PtOptions& opt, PtStats* stats = nullptr, std::vector<PtImage>* by_depth = nullptr);

// Root mean squared error over R, G, B of every pixel, in units of 1/255 of radiance 1 (display
// white), on linear unclamped values (thesis §6.2.5: rmse against a converged image).
double pt_rmse(const PtImage& a, const PtImage& b);
// Mean over pixels and channels.
double pt_mean(const PtImage& img);
// Display: clamp to [0, 1], gamma 1/2.2, 8-bit RGB; written with write_rgb_png (harness/image.h).
void write_pt_png(const std::string& path, const PtImage& img);
// Raw cache of a converged image: a small header (magic, width, height) then the floats.
void save_pt_image(const std::string& path, const PtImage& img);
// False when missing or malformed: a size the file does not hold (checked before anything is
// allocated), a pixel value that is not a radiance (finite, >= 0). `why`, when given, says what
// is malformed (empty when the file is missing); `img` is set only on success.
bool load_pt_image(const std::string& path, PtImage& img, std::string* why = nullptr);

}  // namespace tb
