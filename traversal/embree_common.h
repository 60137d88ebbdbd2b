// Embree 3 as the baseline of every comparison. One device per process (one build thread, so
// build times compare with our single-threaded builders), scenes built at high quality by default
// (`--param quality=low|medium|high`), cached per scene and mode. Robust mode
// (RTC_SCENE_FLAG_ROBUST) is the default so the baseline leaks no more than our watertight
// kernels; `--param robust=0` gives Embree's fast default mode, the only one in which its HIGH
// quality build makes spatial splits (Debian's Embree 3.13.5). `--param isa=...` (default:
// Embree's own run-time choice, the best ISA the CPU has) is an explicit opt-in for like-for-like
// comparisons across machines: an AVX-512 host runs avx512::BVH8Triangle4vIntersector1Pluecker
// for embree_single, the AVX2 reference machine avx2:: (docs/PERFORMANCE.md, session 8).
#pragma once
#include <embree3/rtcore.h>

#include <memory>
#include <string>

#include "traversal/traverser.h"

namespace tb {

enum class EmbreeQuality { low, medium, high };

class EmbreeScene {
 public:
  // isa: the device that builds it (embree_device: "default" or an ISA name).
  EmbreeScene(const Scene& scene, EmbreeQuality quality, bool robust, const std::string& isa = "default");
  EmbreeScene(EmbreeScene&& o) noexcept : scene_(o.scene_), bytes_(o.bytes_) { o.scene_ = nullptr; }
  EmbreeScene(const EmbreeScene&) = delete;
  ~EmbreeScene();
  RTCScene get() const { return scene_; }
  // Device memory the scene added, from Embree's memory monitor: `prims` what the geometry's
  // vertex and index buffers took, `nodes` what rtcCommitScene allocated — the BVH with Embree's
  // own leaf primitives (triangle4v/4i copies), which the monitor cannot tell apart.
  StructureBytes bytes() const { return bytes_; }

 private:
  RTCScene scene_ = nullptr;
  StructureBytes bytes_;
};

// One device per ISA: "default" lets Embree pick the best ISA of the CPU; another name is passed as
// Embree's device config `isa=NAME` after checking that the CPU has it (an unknown name makes
// Embree 3.13.5 fall back to SSE2 silently, one the CPU lacks would fault at the first kernel),
// InputError otherwise.
RTCDevice embree_device(const std::string& isa = "default");
std::shared_ptr<const EmbreeScene> fetch_embree_scene(const Scene& scene, StructureCache& cache,
                                                      EmbreeQuality quality, bool robust,
                                                      const std::string& isa = "default");
// The three Embree schemes' parameters: `robust` (0|1), `quality` (low|medium|high; only high
// builds spatial splits, and only in fast mode, robust=0) and `isa` (default|sse2|sse4.2|avx|avx2|
// avx512), and their values.
ParamSpecs embree_param_specs();
bool embree_robust(const SchemeConfig& cfg);
EmbreeQuality embree_quality(const SchemeConfig& cfg);
const std::string& embree_isa(const SchemeConfig& cfg);

inline void to_embree(const Ray& r, RTCRayHit& rh) {
  rh.ray.org_x = r.org.x; rh.ray.org_y = r.org.y; rh.ray.org_z = r.org.z;
  rh.ray.dir_x = r.dir.x; rh.ray.dir_y = r.dir.y; rh.ray.dir_z = r.dir.z;
  rh.ray.tnear = r.tmin; rh.ray.tfar = r.tmax;
  rh.ray.time = 0.f; rh.ray.mask = 0xFFFFFFFFu; rh.ray.id = 0; rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

inline Hit from_embree(const RTCRayHit& rh) {
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return Hit{};
  return Hit{rh.ray.tfar, rh.hit.primID, rh.hit.u, rh.hit.v};
}

// Base for the three Embree schemes: config, the cached scene, its memory; Derived provides name()
// and `template <class P> void run(batch, range, hits, probe) const`.
template <class Derived>
class EmbreeScheme : public TraverserBase<Derived> {
 public:
  explicit EmbreeScheme(const SchemeConfig& cfg)
      : robust_(embree_robust(cfg)), quality_(embree_quality(cfg)), isa_(embree_isa(cfg)) {}
  void prepare(const Scene& scene, StructureCache& cache) override {
    scene_ = fetch_embree_scene(scene, cache, quality_, robust_, isa_);
  }
  StructureBytes memory() const override { return scene_ ? scene_->bytes() : StructureBytes{}; }

 protected:
  // An intersect context flagged coherent for common-origin (primary) batches, incoherent otherwise.
  static RTCIntersectContext coherence_context(const RayBatch& batch) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = batch.common_origin ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    return ctx;
  }
  bool robust_;
  EmbreeQuality quality_;
  std::string isa_;
  std::shared_ptr<const EmbreeScene> scene_;
};

}  // namespace tb
