// embree_packet8: Embree 3's 8-wide packet kernel, rtcIntersect8, over consecutive groups of 8
// rays of each of the batch's packets (in the Fig. 16 layout those are 2x4 pixel blocks).
#include "traversal/embree_common.h"

namespace tb {
namespace {

class EmbreePacket8 final : public EmbreeScheme<EmbreePacket8> {
 public:
  explicit EmbreePacket8(const SchemeConfig& cfg) : EmbreeScheme(cfg) {}
  std::string_view name() const override { return "embree_packet8"; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    RTCIntersectContext ctx = coherence_context(batch);
    alignas(32) RTCRayHit8 rh;
    alignas(32) int valid[8];
    for (uint32_t p = range.first; p < range.last; ++p) {
      for (uint32_t base = batch.packet_begin[p]; base < batch.packet_begin[p + 1]; base += 8) {
        const uint32_t n = std::min<uint32_t>(8, batch.packet_begin[p + 1] - base);
        for (uint32_t j = 0; j < 8; ++j) {
          const Ray& r = batch.rays[base + std::min(j, n - 1)];
          if (j < n) probe.read(&r, sizeof(Ray));
          valid[j] = j < n ? -1 : 0;
          rh.ray.org_x[j] = r.org.x; rh.ray.org_y[j] = r.org.y; rh.ray.org_z[j] = r.org.z;
          rh.ray.dir_x[j] = r.dir.x; rh.ray.dir_y[j] = r.dir.y; rh.ray.dir_z[j] = r.dir.z;
          rh.ray.tnear[j] = r.tmin; rh.ray.tfar[j] = r.tmax;
          rh.ray.time[j] = 0.f; rh.ray.mask[j] = 0xFFFFFFFFu; rh.ray.id[j] = j; rh.ray.flags[j] = 0;
          rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
          rh.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect8(valid, scene_->get(), &ctx, &rh);
        for (uint32_t j = 0; j < n; ++j) {
          hits[base + j] = rh.hit.geomID[j] == RTC_INVALID_GEOMETRY_ID
                               ? Hit{}
                               : Hit{rh.ray.tfar[j], rh.hit.primID[j], rh.hit.u[j], rh.hit.v[j]};
          probe.write(&hits[base + j], sizeof(Hit));
        }
        if constexpr (P::enabled) if (probe.counts) probe.counts->rays += n;
      }
    }
  }
};

}  // namespace

std::unique_ptr<Traverser> make_embree_packet8(const SchemeConfig& cfg) {
  return std::make_unique<EmbreePacket8>(cfg);
}
ParamSpecs params_embree_packet8() { return embree_param_specs(); }

}  // namespace tb
