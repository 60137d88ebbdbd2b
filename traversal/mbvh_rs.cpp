// mbvh_rs: Tsakok's Multi-BVH Ray Stream tracing (HPG 2009; thesis §2.2 Alg. 2.9, Appendix C.1)
// over the 4-wide MBVH. A stream of rays descends the tree together: a task is (node, SIMD lane,
// ray count); its rays are popped from that lane's stack of active-ray indices, each is tested
// against the node's four child boxes with one SSE test, and every ray that enters child i is
// pushed onto lane i's stack — so a child's stream holds only the rays that enter it (no
// inactive rays, unlike partition traversal). One task per entered child goes onto the task
// stack, ordered by the summed entry distances of their rays (Alg. 2.10's sorting network), so
// the nearest is traced first. Leaves intersect every ray of their stream. A stream that has
// shrunk to one ray continues with ordinary single-ray traversal of that subtree (thesis: "falls
// back to efficient single ray traversal when the size of a stream drops to one").
//
// Streams are consecutive packets of the batch, grouped up to `stream` rays (parameter, default
// 256; Tsakok and the thesis found 256-1024 best, §5.2.4); a packet larger than that is cut.
// All scratch lives in the call, so concurrent calls on disjoint ranges are safe.
#include "structures/mbvh.h"

namespace tb {
namespace {

// One ray of a stream (the thesis' ERay): the box-test constants in the first cache line, the
// triangle-test constants in the second.
struct alignas(64) StreamRay {
  float ox, oy, oz, ix, iy, iz, fx, fy, fz, tmin;
  uint32_t near[3], far[3];  // rows of the sign-selected slab planes in MBVHNode::box
  Vec3 dir;
  float sx, sy, sz;
  int32_t kx, ky, kz;
};
static_assert(sizeof(StreamRay) == 128);

struct Task {
  uint32_t ref;    // MBVH child reference (interior node or leaf)
  uint32_t lane;   // the active-ray stack holding its rays
  uint32_t count;  // how many rays (on top of that stack)
};

class MBVHRayStream final : public TraverserBase<MBVHRayStream> {
 public:
  explicit MBVHRayStream(const SchemeConfig& cfg)
      : cfg_(cfg), params_(mbvh_params(cfg, 4, 4)), stream_(cfg.get_int("stream", 256)) {
    if (stream_ < 1 || stream_ > 65536) throw InputError("parameter stream must be in [1, 65536]");
  }
  std::string_view name() const override { return "mbvh_rs"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    data_ = fetch_mbvh<4, 4>(scene, cache, params_, cfg_.kernel);
  }
  std::string structure_info() const override {
    return data_.mbvh->stats.describe() + " stream=" + std::to_string(stream_);
  }
  size_t structure_bytes() const override { return mbvh_bytes(data_, cfg_.kernel); }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    dispatch_kernel(cfg_.kernel, [&](auto k) { run_kernel<decltype(k)::value>(batch, range, hits, probe); });
  }

 private:
  struct Scratch {
    std::vector<StreamRay> rays;
    std::vector<Hit> hits;
    std::vector<uint16_t> lanes[4];  // active-ray stacks, one per SIMD lane (child slot)
    std::vector<Task> tasks;
    std::vector<MBVHStackEntry> single;  // stack of the one-ray fallback
  };

  template <TriKernel K, class P>
  void run_kernel(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const uint32_t depth = data_.mbvh->stats.max_depth + 1;
    Scratch s;
    s.rays.resize(size_t(stream_));
    s.hits.resize(size_t(stream_));
    // Per lane at most one pending task per tree level (siblings use distinct lanes, and a
    // task's children are all consumed before its next sibling), each with at most a stream;
    // plus one slot for the unconditional write of the push below.
    for (auto& l : s.lanes) l.resize(size_t(depth + 1) * size_t(stream_) + 1);
    s.tasks.resize(size_t(3) * depth + 2);
    s.single.resize(size_t(3) * depth + 4 + 2);  // mbvh_traverse: (N-1) * depth + N slack

    const uint32_t S = uint32_t(stream_);
    uint32_t begin = batch.packet_begin[range.first], end = begin;
    for (uint32_t p = range.first; p < range.last; ++p) {
      const uint32_t pend = batch.packet_begin[p + 1];
      if (pend - begin > S && end > begin) {  // this packet does not fit: flush what we have
        trace_stream<K>(batch, begin, end, hits, s, probe);
        begin = end;
      }
      while (pend - begin > S) {  // a packet larger than a stream is cut
        trace_stream<K>(batch, begin, begin + S, hits, s, probe);
        begin += S;
      }
      end = pend;
    }
    if (end > begin) trace_stream<K>(batch, begin, end, hits, s, probe);
  }

  // Algorithm 2.9 on rays [first, last) of the batch.
  template <TriKernel K, class P>
  void trace_stream(const RayBatch& batch, uint32_t first, uint32_t last, std::span<Hit> out, Scratch& s,
                    P& probe) const {
    using S4 = mbvh_simd::V<4>;
    const MBVH<4, 4>& m = *data_.mbvh;
    const MBVHNode<4>* nodes = m.nodes.data();
    const uint32_t n = last - first;
    if constexpr (P::enabled)
      if (probe.counts) probe.counts->rays += n;
    for (uint32_t j = 0; j < n; ++j) {
      const Ray& ray = batch.rays[first + j];
      probe.read(&ray, sizeof(Ray));
      const RayCtx rc(ray);
      StreamRay& r = s.rays[j];
      r.ox = rc.org.x, r.oy = rc.org.y, r.oz = rc.org.z;
      r.ix = rc.inv.x, r.iy = rc.inv.y, r.iz = rc.inv.z;
      // Far planes use the Ize-padded reciprocal, as NodeRay does.
      r.fx = rc.inv.x * kFarPad, r.fy = rc.inv.y * kFarPad, r.fz = rc.inv.z * kFarPad;
      r.tmin = ray.tmin;
      for (int a = 0; a < 3; ++a) {
        const bool neg = std::signbit(rc.inv[a]);
        r.near[a] = uint32_t(((neg ? 3 : 0) + a) * 4);
        r.far[a] = uint32_t(((neg ? 0 : 3) + a) * 4);
      }
      r.dir = rc.dir;
      r.sx = rc.sx, r.sy = rc.sy, r.sz = rc.sz;
      r.kx = rc.kx, r.ky = rc.ky, r.kz = rc.kz;
      probe.write(&r, sizeof(StreamRay));
      s.hits[j] = initial_hit(ray);
    }

    // The one-ray fallback and the leaf test rebuild their per-ray constants from the stream ray.
    auto tri_ray = [&](const StreamRay& r) {
      return TriRay<4>(Vec3{r.ox, r.oy, r.oz}, r.dir, r.kx, r.ky, r.kz, r.sx, r.sy, r.sz, r.tmin);
    };
    auto single = [&](uint32_t id, uint32_t ref) {
      const StreamRay& r = s.rays[id];
      probe.read(&r, sizeof(StreamRay));
      const NodeRay<4> nr(Vec3{r.ox, r.oy, r.oz}, Vec3{r.ix, r.iy, r.iz}, r.tmin);
      if constexpr (K == TriKernel::watertight) {
        mbvh_traverse<4, 4, K>(m, nullptr, nr, tri_ray(r), nullptr, ref, s.hits[id], s.single.data(), probe);
      } else {
        const RayCtx rc(batch.rays[first + id]);
        mbvh_traverse<4, 4, K>(m, data_.tris.get(), nr, tri_ray(r), &rc, ref, s.hits[id], s.single.data(), probe);
      }
    };

    if (n == 1) {
      single(0, 0);
    } else {
      uint16_t* lane[4] = {s.lanes[0].data(), s.lanes[1].data(), s.lanes[2].data(), s.lanes[3].data()};
      uint32_t head[4] = {n, 0, 0, 0};
      for (uint32_t j = 0; j < n; ++j) lane[0][j] = uint16_t(j);
      Task* tasks = s.tasks.data();
      uint32_t ntasks = 0;
      tasks[ntasks++] = {0, 0, n};
      while (ntasks) {
        const Task t = tasks[--ntasks];
        probe.read(&tasks[ntasks], sizeof(Task));
        head[t.lane] -= t.count;
        uint16_t* list = lane[t.lane] + head[t.lane];
        if (t.count == 1) {
          probe.read(list, sizeof(uint16_t));
          single(list[0], t.ref);
          continue;
        }
        if (mbvh_ref::is_leaf(t.ref)) {
          probe_leaf(m, t.ref, probe, t.count);
          for (uint32_t i = 0; i < t.count; ++i) {
            probe.read(&list[i], sizeof(uint16_t));
            const uint32_t id = list[i];
            const StreamRay& r = s.rays[id];
            probe.read(&r, sizeof(StreamRay));
            if constexpr (K == TriKernel::watertight) {
              leaf_test<4, 4, K>(m, nullptr, tri_ray(r), nullptr, t.ref, s.hits[id]);
            } else {
              const RayCtx rc(batch.rays[first + id]);
              leaf_test<4, 4, K>(m, data_.tris.get(), tri_ray(r), &rc, t.ref, s.hits[id]);
            }
          }
          continue;
        }
        // Interior node: every ray of the task against the four children (box_test's
        // semantics; see mbvh.h for the NaN-aware operand order).
        const MBVHNode<4>& nd = nodes[t.ref];
        probe.node(&nd, sizeof(nd), t.count);
        const float* b = &nd.box[0][0];
        uint32_t h[4] = {head[0], head[1], head[2], head[3]};
        __m128 dsum = S4::zero();
        for (uint32_t i = 0; i < t.count; ++i) {
          probe.read(&list[i], sizeof(uint16_t));
          const uint16_t id = list[i];
          const StreamRay& r = s.rays[id];
          probe.read(&r, 64);
          const __m128 ox = S4::set1(r.ox), oy = S4::set1(r.oy), oz = S4::set1(r.oz);
          const __m128 tnx = S4::mul(S4::sub(S4::load(b + r.near[0]), ox), S4::set1(r.ix));
          const __m128 tny = S4::mul(S4::sub(S4::load(b + r.near[1]), oy), S4::set1(r.iy));
          const __m128 tnz = S4::mul(S4::sub(S4::load(b + r.near[2]), oz), S4::set1(r.iz));
          const __m128 tfx = S4::mul(S4::sub(S4::load(b + r.far[0]), ox), S4::set1(r.fx));
          const __m128 tfy = S4::mul(S4::sub(S4::load(b + r.far[1]), oy), S4::set1(r.fy));
          const __m128 tfz = S4::mul(S4::sub(S4::load(b + r.far[2]), oz), S4::set1(r.fz));
          const __m128 tn = S4::max(tnz, S4::max(tny, S4::max(tnx, S4::set1(r.tmin))));
          const __m128 tf = S4::min(tfz, S4::min(tfy, S4::min(tfx, S4::set1(s.hits[id].t))));
          const __m128 enter = S4::le(tn, tf);
          dsum = S4::add(dsum, S4::and_(tn, enter));
          const int mk = S4::mask(enter);
          // Branch-free push (Appendix C.1): write the id on every lane, advance the heads of
          // the lanes it entered. On the task's own lane the write lands at or below the slot
          // just read, so compaction in place is safe.
          lane[0][h[0]] = id, lane[1][h[1]] = id, lane[2][h[2]] = id, lane[3][h[3]] = id;
          if constexpr (P::enabled)
            for (int c = 0; c < 4; ++c)
              if (mk >> c & 1) probe.write(&lane[c][h[c]], sizeof(uint16_t));
          h[0] += mk & 1, h[1] += mk >> 1 & 1, h[2] += mk >> 2 & 1, h[3] += mk >> 3 & 1;
        }
        uint32_t cnt[4];
        int active = 0;
        for (int c = 0; c < 4; ++c) {
          cnt[c] = h[c] - head[c];
          head[c] = h[c];
          active |= int(cnt[c] != 0) << c;
        }
        if (!active) continue;
        if (!(active & (active - 1))) {
          const int c = std::countr_zero(unsigned(active));
          tasks[ntasks] = {nd.ref[c], uint32_t(c), cnt[c]};
          probe.write(&tasks[ntasks++], sizeof(Task));
          continue;
        }
        // Several children: order by summed entry distance with the sorting network, push
        // far-to-near so that the nearest is popped first.
        const __m128 act = _mm_castsi128_ps(_mm_cmpgt_epi32(
            _mm_setr_epi32(int(cnt[0]), int(cnt[1]), int(cnt[2]), int(cnt[3])), _mm_setzero_si128()));
        alignas(16) int32_t keys[4];
        _mm_store_si128(reinterpret_cast<__m128i*>(keys), mbvh_simd::sort4(mbvh_simd::sort_keys4(dsum, act)));
        for (int j = std::popcount(unsigned(active)) - 1; j >= 0; --j) {
          const uint32_t c = uint32_t(keys[j]) & 3;
          tasks[ntasks] = {nd.ref[c], c, cnt[c]};
          probe.write(&tasks[ntasks++], sizeof(Task));
        }
      }
    }
    for (uint32_t j = 0; j < n; ++j) {
      out[first + j] = finish_hit(s.hits[j]);
      probe.write(&out[first + j], sizeof(Hit));
    }
  }

  SchemeConfig cfg_;
  MBVHBuildParams params_;
  int stream_;
  MBVHData<4, 4> data_;
};

}  // namespace

std::unique_ptr<Traverser> make_mbvh_rs(const SchemeConfig& cfg) { return std::make_unique<MBVHRayStream>(cfg); }

}  // namespace tb
