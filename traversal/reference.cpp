// reference: the ground truth every scheme is measured against (docs/ACCURACY.md). It is the
// exact oracle (traversal/exact.h): each hit decided as exact rational arithmetic on the stored
// float32 ray and triangles would decide it (a double filter with a certified error bound, GMP
// rationals where the bound cannot decide), over the default BVH as a conservative culling
// structure. The reported t is the exact t rounded to the nearest float; at equal exact t the
// lowest primitive id wins. Slower than a float kernel on purpose; correctness first.
#include <optional>

#include "traversal/bvh_common.h"
#include "traversal/exact.h"

namespace tb {
namespace {

class Reference final : public TraverserBase<Reference> {
 public:
  explicit Reference(const SchemeConfig&) {}
  std::string_view name() const override { return "reference"; }
  void prepare(const Scene& scene, StructureCache& cache) override { oracle_.emplace(scene, cache); }
  // The culling BVH, and the scene's vertex and index arrays the exact test reads.
  StructureBytes memory() const override {
    if (!oracle_) return {};
    const Scene& s = oracle_->scene();
    return {oracle_->bvh().stats.bytes,
            s.positions.size() * sizeof(s.positions[0]) + s.triangles.size() * sizeof(s.triangles[0])};
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    for (uint32_t i = batch.packet_begin[range.first]; i < batch.packet_begin[range.last]; ++i) {
      uint64_t tests = 0;
      hits[i] = oracle_->closest(batch.rays[i], P::enabled ? &tests : nullptr);
      if constexpr (P::enabled)
        if (probe.counts) probe.counts->rays++, probe.counts->tri_tests += tests;
    }
  }

 private:
  std::optional<ExactOracle> oracle_;
};

}  // namespace

std::unique_ptr<Traverser> make_reference(const SchemeConfig& cfg) { return std::make_unique<Reference>(cfg); }
ParamSpecs params_reference() { return {}; }

}  // namespace tb
