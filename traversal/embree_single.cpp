// embree_single: Embree 3's single-ray kernel, rtcIntersect1, one call per ray.
#include "traversal/embree_common.h"

namespace tb {
namespace {

class EmbreeSingle final : public EmbreeScheme<EmbreeSingle> {
 public:
  explicit EmbreeSingle(const SchemeConfig& cfg) : EmbreeScheme(cfg) {}
  std::string_view name() const override { return "embree_single"; }

  // Embree's internals cannot be instrumented: the probe sees only ray reads and hit writes.
  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (uint32_t i = batch.packet_begin[range.first]; i < batch.packet_begin[range.last]; ++i) {
      probe.read(&batch.rays[i], sizeof(Ray));
      if constexpr (P::enabled) if (probe.counts) probe.counts->rays++;
      RTCRayHit rh;
      to_embree(batch.rays[i], rh);
      rtcIntersect1(scene_->get(), &ctx, &rh);
      hits[i] = from_embree(rh);
      probe.write(&hits[i], sizeof(Hit));
    }
  }
};

}  // namespace

std::unique_ptr<Traverser> make_embree_single(const SchemeConfig& cfg) { return std::make_unique<EmbreeSingle>(cfg); }
ParamSpecs params_embree_single() { return embree_param_specs(); }

}  // namespace tb
