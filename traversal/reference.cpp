// reference: the ground truth every scheme is measured against (DESIGN.md "Correctness").
// Watertight ray/triangle test (Woop, Benthin, Wald 2013) evaluated in double precision, over a
// BVH whose boxes are tested conservatively in double (Ize 2013 padding), so no box is culled
// that the ray enters and no shared edge or vertex leaks. Slow on purpose; never optimise it.
#include "traversal/bvh_common.h"

namespace tb {
namespace {

struct DVec {
  double x, y, z;
  double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};
DVec dv(Vec3 v) { return {v.x, v.y, v.z}; }
DVec operator-(DVec a, DVec b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }

struct DRay {
  DVec org, dir, inv;
  int kx, ky, kz;
  double sx, sy, sz;
  explicit DRay(const Ray& r) : org(dv(r.org)), dir(dv(r.dir)) {
    auto rcp = [](double d) { return d == 0.0 ? std::copysign(1e300, d) : 1.0 / d; };
    inv = {rcp(dir.x), rcp(dir.y), rcp(dir.z)};
    double ax = std::fabs(dir.x), ay = std::fabs(dir.y), az = std::fabs(dir.z);
    kz = ax >= ay ? (ax >= az ? 0 : 2) : (ay >= az ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (dir[kz] < 0) std::swap(kx, ky);
    sx = dir[kx] / dir[kz];
    sy = dir[ky] / dir[kz];
    sz = 1.0 / dir[kz];
  }
};

// Conservative in double: the far distance is padded far beyond the error of three roundings.
bool box_hit(const DRay& r, const BVHNode& n, double tmin, double tfar) {
  double tn = tmin, tf = tfar;
  for (int a = 0; a < 3; ++a) {
    double t0 = (double(n.lo[a]) - r.org[a]) * r.inv[a];
    double t1 = (double(n.hi[a]) - r.org[a]) * r.inv[a];
    if (t0 > t1) std::swap(t0, t1);
    tn = std::max(tn, t0);
    tf = std::min(tf, t1 * (1.0 + 1e-12));
  }
  return tn <= tf;
}

bool tri_hit(const DRay& r, const Scene& s, uint32_t tri, double tmin, double& tbest, double& u, double& v) {
  const DVec A = dv(s.vertex(tri, 0)) - r.org, B = dv(s.vertex(tri, 1)) - r.org, C = dv(s.vertex(tri, 2)) - r.org;
  const double Ax = A[r.kx] - r.sx * A[r.kz], Ay = A[r.ky] - r.sy * A[r.kz];
  const double Bx = B[r.kx] - r.sx * B[r.kz], By = B[r.ky] - r.sy * B[r.kz];
  const double Cx = C[r.kx] - r.sx * C[r.kz], Cy = C[r.ky] - r.sy * C[r.kz];
  const double U = Cx * By - Cy * Bx, V = Ax * Cy - Ay * Cx, W = Bx * Ay - By * Ax;
  if ((U < 0 || V < 0 || W < 0) && (U > 0 || V > 0 || W > 0)) return false;
  const double det = U + V + W;
  if (det == 0) return false;
  const double T = U * r.sz * A[r.kz] + V * r.sz * B[r.kz] + W * r.sz * C[r.kz];
  const double t = T / det;
  if (!(t >= tmin && t < tbest)) return false;
  tbest = t;
  u = V / det;
  v = W / det;
  return true;
}

class Reference final : public TraverserBase<Reference> {
 public:
  explicit Reference(const SchemeConfig&) {}
  std::string_view name() const override { return "reference"; }
  void prepare(const Scene& scene, StructureCache& cache) override {
    scene_ = &scene;
    bvh_ = cache.get<BVH>(BVHBuildParams{}.key(), [&] { return BVH::build(scene, BVHBuildParams{}); });
  }

  template <class P>
  void run(const RayBatch& batch, PacketRange range, std::span<Hit> hits, P& probe) const {
    const BVHNode* nodes = bvh_->nodes.data();
    std::vector<uint32_t> stack;
    for (uint32_t i = batch.packet_begin[range.first]; i < batch.packet_begin[range.last]; ++i) {
      const Ray& ray = batch.rays[i];
      if constexpr (P::enabled) if (probe.counts) probe.counts->rays++;
      const DRay r(ray);
      double tbest = ray.tmax, u = 0, v = 0;
      uint32_t prim = kNoHit;
      stack.assign(1, 0);
      while (!stack.empty()) {
        const BVHNode& n = nodes[stack.back()];
        stack.pop_back();
        if (!box_hit(r, n, ray.tmin, tbest)) continue;
        if (n.is_leaf()) {
          probe.leaf(&n, sizeof n);
          for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) {
            if constexpr (P::enabled) if (probe.counts) probe.counts->tri_tests++;
            if (tri_hit(r, *scene_, bvh_->prim_index[k], ray.tmin, tbest, u, v)) prim = bvh_->prim_index[k];
          }
        } else {
          probe.node(&n, sizeof n);
          stack.push_back(n.left_first + 1);
          stack.push_back(n.left_first);
        }
      }
      hits[i] = prim == kNoHit ? Hit{} : Hit{float(tbest), prim, float(u), float(v)};
    }
  }

 private:
  const Scene* scene_ = nullptr;
  std::shared_ptr<const BVH> bvh_;
};

}  // namespace

std::unique_ptr<Traverser> make_reference(const SchemeConfig& cfg) { return std::make_unique<Reference>(cfg); }
ParamSpecs params_reference() { return {}; }

}  // namespace tb
