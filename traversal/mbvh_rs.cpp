// mbvh_rs: Tsakok's Multi-BVH Ray Stream tracing (HPG 2009; thesis §2.2 Alg. 2.9, Appendix C.1)
// over the scene's MBVH. A stream of rays descends the tree together: a task is (node, SIMD lane,
// ray count); its rays are popped from that lane's stack of active-ray indices, each is tested
// against the node's child boxes with one SIMD test, and every ray that enters child i is pushed
// onto lane i's stack — so a child's stream holds only the rays that enter it (no inactive rays,
// unlike partition traversal). One task per entered child goes onto the task stack, ordered by
// the mean entry distance of their rays (`task_order`; the thesis sums them, Alg. 2.10's sorting
// network), so the nearest is traced first. Leaves intersect every ray of their stream. A stream
// that has shrunk to one ray continues with ordinary single-ray traversal of that subtree
// (thesis: "falls back to efficient single ray traversal when the size of a stream drops to
// one"). The kernel is traversal/mbvh_stream.h, shared with raygrid (which runs it on the rays of
// an octree leaf's queue over that leaf's mini-MBVH, thesis §5.3).
//
// Streams are consecutive packets of the batch, grouped up to `stream` rays (parameter); a packet
// larger than that is cut. Unless the batch is coherent already (camera rays, first bounces), its
// rays are first sorted by the Morton cell of their origins (`sort`, traversal/ray_order.h: ray
// reordering, Pharr et al. 1997, Moon et al. 2010), so that a stream holds rays that start near
// each other and share the nodes they visit: bounce:3, in-process interleaved rounds against
// sort=none, sponza 1.05-1.15x, sibenik 1.10x, sibenik_lucy and crytek_sponza_partial 1.22x,
// conference 1.00x (docs/PERFORMANCE.md, "Session 36"); the thesis tables run sort=none. A
// stream's rays are copied into SoA arrays and their per-ray constants computed eight rays per
// AVX2 instruction into a 128-byte record per ray (mbvh_stream::prepare).
//
// The default stream is 8192 rays, not the thesis' 256 (Tsakok and the thesis found 256-1024
// best on their machines, §5.2.4; the thesis tables still run 256, harness/tables.cpp):
// a longer stream shares the upper levels of the tree among more rays (the thesis' Table 8: few
// rays per node is what limits the scheme), and today's L2 holds it. Measured on bounce:3 at
// 512x512, 2 interleaved rounds, mbvh_rs / mbvh8_single with stream = 256 / 2048 / 8192 / 65536:
// conference 1.29 / 1.39 / 1.46 / 1.17, sponza 1.00 / 1.23 / 1.32 / 0.99, sibenik 0.92 / 1.18 /
// 1.33 / 0.99 (docs/PERFORMANCE.md, "Session 12"). Past the knee the stream's records (then 96
// bytes a ray, 156 since session 18's per-ray records) leave L2: the simulated cache on sponza put
// it between 8192 and 16384 rays for a 512 KB L2 (Zen 3: 7.9 vs 34 L3 hits per ray) and between
// 16384 and 65536 for that VM's 2 MB; with the larger records it prefers 4096 for a 512 KB L2
// (reads only, not yet timed there: docs/PERFORMANCE.md, "Session 18").
//
// `width`: 4 = the thesis' SSE layout (MBVH<4,4>, greedy collapse, leaves merged up to 4
// triangles); 8 = AVX2 nodes (MBVH<8,4>, SAH-optimal collapse of Ylitie et al. 2017 as
// mbvh8_single, leaves up to `merge` (default 8) triangles in 4-wide blocks, tested two rays per
// AVX2 pass). On bounce:3 width=8 ran 1.2-1.35x the 4-wide streams (conference, sponza,
// crytek_sponza_partial, dragon_100k), mostly from visiting far fewer nodes per ray; it is the
// default. A call holds its scratch alone (pooled across calls), so concurrent calls on disjoint
// ranges are safe.
#include "traversal/mbvh_fetch.h"
#include "traversal/mbvh_traverse.h"
#include "traversal/bvh_common.h"
#include "traversal/mbvh_stream.h"
#include "traversal/ray_order.h"
#include "traversal/scratch_pool.h"

namespace tb {
namespace {

// 8 wide by default: measured 1.2-1.35x the 4-wide stream on bounce:3 of the real scenes (see the
// header comment); width=4 gives the thesis' layout (tests/test_mbvh.cpp pins it there to compare
// with mbvh4_single's tree).
constexpr int kDefaultWidth = 8;
// sort: auto sorts a call of kMinSortedStreams streams' worth of rays or more whose neighbouring
// rays mostly start in different cells of the order (bounce:2 and later 84-94% on sponza,
// conference, room, stadium; first-bounce rays 1-5%, which sorting slowed by 7-13%); origin
// sorts every call; none keeps the batch's packets (the thesis' streams).
enum class Sort { auto_, origin, none };
Sort sort_of(const std::string& v) { return v == "auto" ? Sort::auto_ : v == "origin" ? Sort::origin : Sort::none; }
constexpr double kMinChange = 0.5;
// The fewest streams' worth of rays in a batch (or call) that sort=auto sorts: the order pays only
// by regrouping rays among streams. At one or two streams it cost 2-4% (two-thread chunks of about
// one stream each, sorted on their own before batch_order, sponza and sibenik_lucy; buddha's
// 17939 bounce:2 rays).
constexpr uint32_t kMinSortedStreams = 4;
// Rays per stream: see the header comment.
constexpr int kDefaultStream = 8192;
// 4: the thesis' greedy collapse with merged 4-triangle leaves; 8: the SAH collapse
// (mbvh8_single's) with leaves of up to 8 triangles (two blocks). bounce:3, rays/s relative
// to mbvh8_single, merge 4 / 8 / 16: conference 1.12 / 1.23 / 1.26, sponza 1.16 / 1.25 / 1.11.
// spatial: the 8-wide streams trace the spatial-split tree (structures/bvh_spatial.h), as
// mbvh8_single does; the 4-wide ones the thesis' plain one. In-process rounds, mbvh_rs spatial=1 /
// spatial=0 (docs/PERFORMANCE.md, "Session 39"): bounce:3 sponza 1.10-1.12, crytek_sponza_partial
// 1.04-1.05, conference 1.03, sibenik 1.00-1.03, dragon_100k and buddha_100k 1.01-1.04, sponza turned
// 23 degrees off the axes 1.22; sibenik_lucy, room, stadium and the held-out-shaped scene 0.99-1.01,
// spheres:1000000 0.96-0.98; primary rays sponza 1.27, stadium 1.11. Until session 36's ordered
// streams it had measured slower (session 17).
constexpr MBVHDefaults kDefaults4{4, 4, false, 0, false, false}, kDefaults8{4, 8, true, 0, true, false};

class MBVHRayStream final : public MBVHScheme<MBVHRayStream, MBVHData<4, 4>, MBVHData<8, 4>> {
 public:
  // width=4: layout 0 with the thesis' defaults; width=8: layout 1.
  explicit MBVHRayStream(const SchemeConfig& cfg)
      : MBVHScheme(cfg, cfg.get_int("width") == 4 ? kDefaults4 : kDefaults8, cfg.get_int("width") == 4 ? 0 : 1),
        stream_(cfg.get_int("stream")), order_(mbvh_stream::order_of(cfg)), sort_(sort_of(cfg.get_choice("sort"))) {}
  std::string_view name() const override { return "mbvh_rs"; }
  std::string structure_info() const override { return MBVHScheme::structure_info() + " stream=" + std::to_string(stream_); }
  // A stream is formed from the rays of one call: multi-threaded runs hand out chunks of 16
  // packets unless asked for more, which would cut every stream to about a thousand rays.
  uint32_t preferred_chunk_rays() const override { return uint32_t(stream_); }
  // A multi-threaded trace (harness/trace_runner.h's trace_batch) asks for the whole batch's order
  // once and hands its threads chunks of about one stream (preferred_chunk_rays) of the batch
  // gathered into it, so the streams are those a single-threaded trace sorts the batch into: the
  // order is the same for any thread count. (Sorting each thread's chunk on its own regrouped
  // nothing: a chunk is one stream.)
  bool batch_order(const RayBatch& batch, RayOrder& order) const override {
    const uint32_t n = uint32_t(batch.size());
    if (!sorts(batch, n)) return false;
    NullProbe p;
    order.sort(batch.rays, 0, n, sort_ == Sort::auto_ ? kMinChange : 0.0, p);
    return order.moved();
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    dispatch_kernel(cfg_.kernel, [&](auto k) {
      data_.visit([&](const auto& d) {
        run_kernel<std::decay_t<decltype(d)>::kN, decltype(k)::value>(d, batch, range, hits, probe);
      });
    });
  }

 private:
  // The stream's rays: SoA fields (prepare's input, eight rays per load) and the per-ray records
  // the traversal reads (mbvh_stream::RayRecord, with the hits).
  enum Field : uint32_t { kOX, kOY, kOZ, kDX, kDY, kDZ, kTmin, kFields };
  struct Scratch {
    size_t mp = 0;  // the field arrays' stride (mbvh_stream::field_stride)
    aligned_vector<float> f;
    aligned_vector<mbvh_stream::RayRecord> rec;
    mbvh_stream::Scratch st;
    RayOrder order;         // sort: the call's rays in the Morton order of their origins' cells
    std::vector<Ray> rays;  // ... gathered in that order
    std::vector<Hit> hits;  // ... and their hits, in the same order
  };

  template <int N, TriKernel K, class P>
  void run_kernel(const MBVHData<N, 4>& d, const RayBatch& batch, PacketRange range, std::span<Hit> hits,
                  P& probe) const {
    // The scratch is sized for the longest stream this call can form: a call with fewer rays
    // than `stream` (a small chunk, a scene most rays leave) must not allocate and clear stacks
    // for the full stream (bunny bounce:3 with stream=65536 ran at a fourteenth of the speed).
    const uint32_t S = std::max<uint32_t>(
        1, std::min<uint32_t>(uint32_t(stream_), batch.packet_begin[range.last] - batch.packet_begin[range.first]));
    // Pooled: sized and faulted in by an earlier call, grown only (scratch_pool.h).
    std::unique_ptr<Scratch> sp = pool_.acquire();
    Scratch& s = *sp;
    s.mp = mbvh_stream::field_stride(S);
    if (s.f.size() < kFields * s.mp) s.f.resize(kFields * s.mp);
    if (s.rec.size() < (S + 7) / 8 * 8) s.rec.resize((S + 7) / 8 * 8);
    s.st.reserve(N, d.mbvh->stats.max_depth + 1, S);

    if (!trace_sorted<N, K>(d, batch, range, hits, S, s, probe)) {
      uint32_t begin = batch.packet_begin[range.first], end = begin;
      auto stream = [&](uint32_t from, uint32_t to) {
        trace_stream<N, K>(d, &batch.rays[from], to - from, &hits[from], s, probe);
      };
      for (uint32_t p = range.first; p < range.last; ++p) {
        const uint32_t pend = batch.packet_begin[p + 1];
        if (pend - begin > S && end > begin) {  // this packet does not fit: flush what we have
          stream(begin, end);
          begin = end;
        }
        while (pend - begin > S) {  // a packet larger than a stream is cut
          stream(begin, begin + S);
          begin += S;
        }
        end = pend;
      }
      if (end > begin) stream(begin, end);
    }
    pool_.release(std::move(sp));
  }

  // sort=origin (and auto): streams of S consecutive rays in the order of their origins (packets
  // ignored: the order groups the rays that start near each other, wherever their pixels were).
  // The rays are gathered into that order first and the hits scattered back last (ray_order.h's
  // gather_rays and scatter_hits: loops of their own that fetch ahead). False, having traced
  // nothing, when the call is not to be sorted (`sorts`) or the order keeps the batch's own (a
  // coherent batch under sort=auto; every ray in one cell). The scratch grows by 53 bytes a ray
  // of the call.
  template <int N, TriKernel K, class P>
  bool trace_sorted(const MBVHData<N, 4>& d, const RayBatch& batch, PacketRange range, std::span<Hit> hits,
                    uint32_t S, Scratch& s, P& probe) const {
    const uint32_t first = batch.packet_begin[range.first], n = batch.packet_begin[range.last] - first;
    if (!sorts(batch, n)) return false;
    s.order.sort(batch.rays, first, first + n, sort_ == Sort::auto_ ? kMinChange : 0.0, probe);
    if (!s.order.moved()) return false;
    s.rays.resize(n);
    s.hits.resize(n);
    gather_rays(s.order, batch.rays, 0, n, s.rays.data(), probe);
    for (uint32_t b = 0; b < n; b += S)
      trace_stream<N, K>(d, s.rays.data() + b, std::min(S, n - b), s.hits.data() + b, s, probe);
    scatter_hits(s.order, s.hits.data(), 0, n, hits, probe);
    return true;
  }

  // Whether a call of n rays of `batch` may be sorted (RayOrder::sort then decides whether the
  // rays are coherent already): not under sort=none, not a batch whose rays share one origin
  // (camera rays: nothing to sort), not one already in a scheme's order (RayBatch::ordered: the
  // chunks of a multi-threaded trace, batch_order), and under sort=auto only a call of
  // kMinSortedStreams streams or more.
  bool sorts(const RayBatch& batch, uint32_t n) const {
    return sort_ != Sort::none && !batch.common_origin && !batch.ordered &&
           !(sort_ == Sort::auto_ && uint64_t(n) < uint64_t(kMinSortedStreams) * uint64_t(stream_));
  }

  // Algorithm 2.9 on the n rays at `rays`, their hits to `out`.
  template <int N, TriKernel K, class P>
  void trace_stream(const MBVHData<N, 4>& d, const Ray* rays, uint32_t n, Hit* out, Scratch& s, P& probe) const {
    if constexpr (P::enabled)
      if (probe.counts) probe.counts->rays += n;
    float* f = s.f.data();
    const size_t mp = s.mp;
    const mbvh_stream::Rays v{f + kOX * mp, f + kOY * mp, f + kOZ * mp, f + kDX * mp, f + kDY * mp, f + kDZ * mp,
                              f + kTmin * mp, nullptr, nullptr, nullptr, s.rec.data()};
    for (uint32_t j = 0; j < n; ++j) {
      const Ray& ray = rays[j];
      probe.read(&ray, sizeof(Ray));
      f[kOX * mp + j] = ray.org.x, f[kOY * mp + j] = ray.org.y, f[kOZ * mp + j] = ray.org.z;
      f[kDX * mp + j] = ray.dir.x, f[kDY * mp + j] = ray.dir.y, f[kDZ * mp + j] = ray.dir.z;
      f[kTmin * mp + j] = ray.tmin;
      if constexpr (P::enabled) {
        for (uint32_t k = 0; k < kFields; ++k) probe.write(&f[k * mp + j], 4);
        probe.write(&s.rec[j], sizeof(mbvh_stream::RayRecord));
      }
      s.rec[j].hit = initial_hit(ray);
    }
    mbvh_stream::prepare(v, n, d.mbvh->coord_bound);
    mbvh_stream::trace<N, K>(*d.mbvh, d.tris.get(), s.st, v, n, 0, order_, probe);
    for (uint32_t j = 0; j < n; ++j) {
      Hit& h = out[j];
      h = finish_hit(s.rec[j].hit);
      probe.write(&h, sizeof(Hit));
    }
  }

  int stream_;
  mbvh_stream::Order order_;
  Sort sort_;
  ScratchPool<Scratch> pool_;  // one record per concurrent call
};

}  // namespace

std::unique_ptr<Traverser> make_mbvh_rs(const SchemeConfig& cfg) { return std::make_unique<MBVHRayStream>(cfg); }
ParamSpecs params_mbvh_rs() {
  ParamSpecs p = mbvh_param_specs(kDefaults8);
  ParamSpec &merge = param_named(p, "merge"), &collapse = param_named(p, "collapse"), &spatial = param_named(p, "spatial");
  merge = auto_default(merge, "4 with width=4, 8 with width=8");
  collapse = auto_default(collapse, "greedy with width=4, sah with width=8");
  spatial = auto_default(spatial, "0 with width=4 (the thesis' tree), 1 with width=8");
  return p + ParamSpecs{int_choice_param("width", kDefaultWidth, {4, 8}, "MBVH width: 4 (the thesis' SSE layout) or 8 (AVX2)"),
                        int_param("stream", kDefaultStream, 1, 65536,
                                  "most rays per stream (consecutive packets of the batch; the thesis tables run 256)"),
                        mbvh_stream::order_param(),
                        choice_param("sort", "auto", {"auto", "origin", "none"},
                                     "stream order: origin = the call's rays sorted by the Morton cell of their origins "
                                     "(traversal/ray_order.h, timed); auto = origin for incoherent batches (bounce:2 on) "
                                     "of " + std::to_string(kMinSortedStreams) +
                                         " streams or more; none = the batch's packets in turn (the thesis)")};
}

}  // namespace tb
