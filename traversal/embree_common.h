// Embree 3 as the baseline of every comparison. One device per process (one build thread, so
// build times compare with our single-threaded builders), scenes built at high quality by default
// (`--param quality=low|medium|high`), cached per scene and mode. Robust mode
// (RTC_SCENE_FLAG_ROBUST) is the default so the baseline leaks no more than our watertight
// kernels; `--param robust=0` gives Embree's fast default mode, the only one in which its HIGH
// quality build makes spatial splits (Debian's Embree 3.13.5).
#pragma once
#include <embree3/rtcore.h>

#include <memory>
#include <string>

#include "traversal/traverser.h"

namespace tb {

enum class EmbreeQuality { low, medium, high };

class EmbreeScene {
 public:
  EmbreeScene(const Scene& scene, EmbreeQuality quality, bool robust);
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

RTCDevice embree_device();
std::shared_ptr<const EmbreeScene> fetch_embree_scene(const Scene& scene, StructureCache& cache,
                                                      EmbreeQuality quality, bool robust);
// The three Embree schemes' parameters: `robust` (0|1) and `quality` (low|medium|high; only high
// builds spatial splits, and only in fast mode, robust=0), and their values.
ParamSpecs embree_param_specs();
bool embree_robust(const SchemeConfig& cfg);
EmbreeQuality embree_quality(const SchemeConfig& cfg);

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
  explicit EmbreeScheme(const SchemeConfig& cfg) : robust_(embree_robust(cfg)), quality_(embree_quality(cfg)) {}
  void prepare(const Scene& scene, StructureCache& cache) override {
    scene_ = fetch_embree_scene(scene, cache, quality_, robust_);
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
  std::shared_ptr<const EmbreeScene> scene_;
};

}  // namespace tb
