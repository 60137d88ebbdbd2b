// The three Embree 3 baselines, one per entry point of its API (one class: they share the cached
// scene, the parameters and the ray conversion and differ only in the call):
//   embree_single  — rtcIntersect1, one call per ray;
//   embree_packet8 — rtcIntersect8 over consecutive groups of 8 rays of each of the batch's packets
//                    (in the Fig. 16 layout those are 2x4 pixel blocks);
//   embree_stream  — rtcIntersect1M, one stream per packet of the batch.
// The packet and stream contexts are flagged coherent for common-origin (primary) batches,
// incoherent otherwise. Embree's internals cannot be instrumented: the probe sees only ray reads
// and hit writes.
#include <vector>

#include "traversal/embree_common.h"

namespace tb {
namespace {

enum class EmbreeApi { single, packet8, stream };

template <EmbreeApi A>
class EmbreeBaseline final : public EmbreeScheme<EmbreeBaseline<A>> {
  using Base = EmbreeScheme<EmbreeBaseline<A>>;

 public:
  using Base::Base;
  std::string_view name() const override {
    return A == EmbreeApi::single ? "embree_single" : A == EmbreeApi::packet8 ? "embree_packet8" : "embree_stream";
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const RTCScene scene = this->scene_->get();
    if constexpr (A == EmbreeApi::single) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      for_each_ray(batch, range, hits, probe, [&](const Ray& ray, Hit& hit) {
        RTCRayHit rh;
        to_embree(ray, rh);
        rtcIntersect1(scene, &ctx, &rh);
        hit = from_embree(rh);
      });
      return;
    }
    RTCIntersectContext ctx = Base::coherence_context(batch);
    std::vector<RTCRayHit> stream;  // per call: safe for concurrent calls on disjoint ranges
    for (uint32_t p = range.first; p < range.last; ++p) {
      const uint32_t b = batch.packet_begin[p], n = batch.packet_rays(p);
      for (uint32_t j = 0; j < n; ++j) probe.read(&batch.rays[b + j], sizeof(Ray));
      if constexpr (A == EmbreeApi::packet8) {
        for (uint32_t g = 0; g < n; g += 8) packet8(scene, ctx, &batch.rays[b + g], std::min(8u, n - g), &hits[b + g]);
      } else {
        stream.resize(n);
        for (uint32_t j = 0; j < n; ++j) to_embree(batch.rays[b + j], stream[j]);
        if (n) rtcIntersect1M(scene, &ctx, stream.data(), n, sizeof(RTCRayHit));
        for (uint32_t j = 0; j < n; ++j) hits[b + j] = from_embree(stream[j]);
      }
      for (uint32_t j = 0; j < n; ++j) probe.write(&hits[b + j], sizeof(Hit));
      if constexpr (P::enabled) if (probe.counts) probe.counts->rays += n;
    }
  }

 private:
  // n <= 8 rays through rtcIntersect8; the unused lanes repeat the last ray and are masked off.
  static void packet8(RTCScene scene, RTCIntersectContext& ctx, const Ray* rays, uint32_t n, Hit* out) {
    alignas(32) RTCRayHit8 rh;
    alignas(32) int valid[8];
    for (uint32_t j = 0; j < 8; ++j) {
      RTCRayHit one;
      to_embree(rays[std::min(j, n - 1)], one);
      valid[j] = j < n ? -1 : 0;
      rh.ray.org_x[j] = one.ray.org_x; rh.ray.org_y[j] = one.ray.org_y; rh.ray.org_z[j] = one.ray.org_z;
      rh.ray.dir_x[j] = one.ray.dir_x; rh.ray.dir_y[j] = one.ray.dir_y; rh.ray.dir_z[j] = one.ray.dir_z;
      rh.ray.tnear[j] = one.ray.tnear; rh.ray.tfar[j] = one.ray.tfar;
      rh.ray.time[j] = 0.f; rh.ray.mask[j] = one.ray.mask; rh.ray.id[j] = j; rh.ray.flags[j] = 0;
      rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect8(valid, scene, &ctx, &rh);
    for (uint32_t j = 0; j < n; ++j)
      out[j] = rh.hit.geomID[j] == RTC_INVALID_GEOMETRY_ID ? Hit{}
                                                            : Hit{rh.ray.tfar[j], rh.hit.primID[j], rh.hit.u[j], rh.hit.v[j]};
  }
};

}  // namespace

std::unique_ptr<Traverser> make_embree_single(const SchemeConfig& cfg) {
  return std::make_unique<EmbreeBaseline<EmbreeApi::single>>(cfg);
}
std::unique_ptr<Traverser> make_embree_packet8(const SchemeConfig& cfg) {
  return std::make_unique<EmbreeBaseline<EmbreeApi::packet8>>(cfg);
}
std::unique_ptr<Traverser> make_embree_stream(const SchemeConfig& cfg) {
  return std::make_unique<EmbreeBaseline<EmbreeApi::stream>>(cfg);
}
ParamSpecs params_embree_single() { return embree_param_specs(); }
ParamSpecs params_embree_packet8() { return embree_param_specs(); }
ParamSpecs params_embree_stream() { return embree_param_specs(); }

}  // namespace tb
