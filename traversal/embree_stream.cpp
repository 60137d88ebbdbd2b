// embree_stream: Embree 3's stream API, rtcIntersect1M, one stream per packet of the batch.
// The context is flagged coherent for common-origin (primary) workloads, incoherent otherwise.
#include <vector>

#include "traversal/embree_common.h"

namespace tb {
namespace {

class EmbreeStream final : public EmbreeScheme<EmbreeStream> {
 public:
  explicit EmbreeStream(const SchemeConfig& cfg) : EmbreeScheme(cfg) {}
  std::string_view name() const override { return "embree_stream"; }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    RTCIntersectContext ctx = coherence_context(batch);
    std::vector<RTCRayHit> stream;
    for (uint32_t p = range.first; p < range.last; ++p) {
      const uint32_t b = batch.packet_begin[p], n = batch.packet_rays(p);
      stream.resize(n);
      for (uint32_t j = 0; j < n; ++j) {
        probe.read(&batch.rays[b + j], sizeof(Ray));
        to_embree(batch.rays[b + j], stream[j]);
      }
      if (n) rtcIntersect1M(scene_->get(), &ctx, stream.data(), n, sizeof(RTCRayHit));
      for (uint32_t j = 0; j < n; ++j) {
        hits[b + j] = from_embree(stream[j]);
        probe.write(&hits[b + j], sizeof(Hit));
      }
      if constexpr (P::enabled) if (probe.counts) probe.counts->rays += n;
    }
  }
};

}  // namespace

std::unique_ptr<Traverser> make_embree_stream(const SchemeConfig& cfg) { return std::make_unique<EmbreeStream>(cfg); }
ParamSpecs params_embree_stream() { return embree_param_specs(); }

}  // namespace tb
