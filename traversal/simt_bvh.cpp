// simt_bvh: GPU-style traversal on the CPU: 32-lane warps in lock-step running Aila & Laine 2009's
// while-while or if-if kernel over the binary BVH in the GPU node layout, per-lane stacks,
// persistent threads refilling finished lanes (traversal/simt.h; thesis ch. 6). One warp per
// trace() call works through the call's rays; it exists to show that the warp executor returns
// the reference's hits on every workload and hard case (the registry tests run it), and it is
// what `travbench table simt` models (traversal/simt_model.h). Its timed path runs the executor
// with the null observer; it is not a fast CPU scheme (a CPU pays for every idle lane's mask test).
#include "traversal/simt_model.h"

namespace tb {
namespace {

class SimtBVH final : public TraverserBase<SimtBVH> {
 public:
  explicit SimtBVH(const SchemeConfig& cfg) : cfg_(cfg), params_(bvh_params(cfg)), opt_(simt_options(cfg)) {}
  std::string_view name() const override { return "simt_bvh"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    data_ = fetch_gpu_bvh(scene, cache, params_, cfg_.kernel);
  }
  std::string structure_info() const override { return data_.gpu->describe(); }
  StructureBytes memory() const override {
    return {data_.gpu->bytes(), data_.bvh.tris->size() * (TriangleSet::bytes(cfg_.kernel) + sizeof(uint32_t))};
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    RayPool pool{batch.packet_begin[range.first], batch.packet_begin[range.last]};
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      constexpr TriKernel K = decltype(k)::value;
      if constexpr (P::enabled) {
        ProbeObserver<P> obs{probe};
        Warp<K, ProbeObserver<P>> w(*data_.gpu, *data_.bvh.tris, batch, hits, pool, opt_, obs);
        while (w.step() != StepKind::done) {}
      } else {
        NullWarpObserver obs;
        Warp<K, NullWarpObserver> w(*data_.gpu, *data_.bvh.tris, batch, hits, pool, opt_, obs);
        while (w.step() != StepKind::done) {}
      }
    });
  }

 private:
  // The instrumented path: the CPU probe's counters and cache (per lane access, as the CPU
  // schemes count them; the warp-level counters are the model's, simt_model.h).
  template <class P>
  struct ProbeObserver {
    static constexpr bool enabled = true;
    P& probe;
    void node(const void* p, uint32_t bytes) { probe.node(p, bytes); }
    void tri(const void* p, uint32_t bytes) { probe.tris(p, bytes); }
    void ray(const void* p, uint32_t bytes) {
      probe.read(p, bytes);
      if (probe.counts) probe.counts->rays++;
    }
    void store(const void* p, uint32_t bytes) { probe.write(p, bytes); }
    void step(StepKind, uint32_t) {}
  };

  SchemeConfig cfg_;
  BVHBuildParams params_;
  SimtOptions opt_;
  GPUBVHData data_;
};

}  // namespace

std::unique_ptr<Traverser> make_simt_bvh(const SchemeConfig& cfg) { return std::make_unique<SimtBVH>(cfg); }
ParamSpecs params_simt_bvh() { return bvh_param_specs() + simt_option_specs(); }

}  // namespace tb
