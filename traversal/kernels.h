// Ray/box and ray/triangle kernels shared by every scheme.
//
// Defaults are robust: the watertight triangle test of Woop, Benthin and Wald (JCGT 2013) and the
// conservative slab test of Ize (JCGT 2013, "Robust BVH Ray Traversal": the far distance is
// padded by 1 + 2*gamma(3) so rounding can never cull a box the ray really enters). The fast
// non-robust variants stay available as named alternatives so the suite can measure what
// robustness costs (issue "Accuracy"): Moller-Trumbore (1997), and the precomputed-plane test the
// thesis' MBVH/RS kernel uses (Appendix C; Havel & Herout 2010), with an exact or an
// approximate (rcpps, 12-bit) reciprocal.
#pragma once
#include <immintrin.h>

#include <cmath>
#include <cstdint>
#include <string_view>
#include <vector>

#include "structures/vec3.h"
#include "workloads/ray_batch.h"

namespace tb {

enum class TriKernel : uint8_t { watertight, moller, plane, plane_rcp };
inline constexpr TriKernel kAllTriKernels[] = {TriKernel::watertight, TriKernel::moller, TriKernel::plane,
                                               TriKernel::plane_rcp};
std::string_view kernel_name(TriKernel k);
TriKernel parse_kernel(std::string_view name);  // throws InputError on unknown names

// gamma(n) of Pharr/Jakob/Humphreys: bound on the relative error of n float operations.
inline constexpr float kUlp = 0x1p-24f;
inline constexpr float gamma_f(int n) { return (n * kUlp) / (1 - n * kUlp); }
// Ize 2013: pad the far slab distance by 1 + 2*gamma(3).
inline constexpr float kFarPad = 1.f + 2.f * gamma_f(3);

// Per-ray data the kernels precompute once.
struct RayCtx {
  Vec3 org, dir, inv;
  int near_x, near_y, near_z;  // 1 where the direction's sign bit is set: enter through hi
  // Watertight shear (Woop et al. 2013, §3): permute so z is the dominant direction axis.
  int kx, ky, kz;
  float sx, sy, sz;
  explicit RayCtx(const Ray& r) : org(r.org), dir(r.dir) {
    // 1/(+-0) = +-inf (also for denormals under DAZ): the slab test below is NaN-aware.
    inv = {1.f / r.dir.x, 1.f / r.dir.y, 1.f / r.dir.z};
    near_x = std::signbit(inv.x), near_y = std::signbit(inv.y), near_z = std::signbit(inv.z);
    Vec3 a{std::fabs(dir.x), std::fabs(dir.y), std::fabs(dir.z)};
    kz = a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (dir[kz] < 0.f) std::swap(kx, ky);  // keep the winding so backfaces are not culled
    sx = dir[kx] / dir[kz];
    sy = dir[ky] / dir[kz];
    sz = 1.f / dir[kz];
  }
};

// Conservative slab test (Williams et al. 2005 sign-selected slabs, Ize 2013 padding); returns
// the entry distance or +inf on a miss. tfar is the current closest hit (or ray tmax).
// A zero direction component gives inv = +-inf, and (plane - org) * inf is NaN exactly when the
// origin lies on that slab plane, where the ray runs inside the closed slab for every t. The
// max/min below keep their first argument when the second is NaN (std::max(a, b) is
// a < b ? b : a), so such a slab constrains nothing — the right answer, with no branch.
inline float box_entry(const RayCtx& r, const Vec3& lo, const Vec3& hi, float tmin, float tfar) {
  const float nx = ((r.near_x ? hi.x : lo.x) - r.org.x) * r.inv.x;
  const float fx = ((r.near_x ? lo.x : hi.x) - r.org.x) * r.inv.x;
  const float ny = ((r.near_y ? hi.y : lo.y) - r.org.y) * r.inv.y;
  const float fy = ((r.near_y ? lo.y : hi.y) - r.org.y) * r.inv.y;
  const float nz = ((r.near_z ? hi.z : lo.z) - r.org.z) * r.inv.z;
  const float fz = ((r.near_z ? lo.z : hi.z) - r.org.z) * r.inv.z;
  const float tn = std::max(std::max(std::max(tmin, nx), ny), nz);
  const float tf = std::min(std::min(std::min(tfar, fx * kFarPad), fy * kFarPad), fz * kFarPad);
  return tn <= tf ? tn : INFINITY;
}

// Triangles in the order a structure stores them, with what each kernel needs.
struct TriVerts {
  Vec3 v0, v1, v2;
};
// Precomputed planes (thesis Appendix C): plane n.x = d, and two edge planes whose values at the
// hit point are the barycentric coordinates u, v.
struct alignas(16) PlaneTri {
  Vec3 n; float nd;
  Vec3 u; float ud;
  Vec3 v; float vd;
};
static_assert(sizeof(PlaneTri) == 48);

struct TriangleSet {
  std::vector<TriVerts> verts;      // always present
  std::vector<PlaneTri> planes;     // only for the plane kernels
  std::vector<uint32_t> prim_id;    // stored position -> scene triangle index
  size_t size() const { return verts.size(); }
  // `order[i]` = scene triangle stored at position i.
  template <class SceneT>
  void build(const SceneT& scene, const std::vector<uint32_t>& order, TriKernel k);
  const void* data_at(uint32_t i, TriKernel k) const {
    return k == TriKernel::plane || k == TriKernel::plane_rcp ? static_cast<const void*>(&planes[i])
                                                                : static_cast<const void*>(&verts[i]);
  }
  static constexpr uint32_t bytes(TriKernel k) {
    return k == TriKernel::plane || k == TriKernel::plane_rcp ? sizeof(PlaneTri) : sizeof(TriVerts);
  }
};
PlaneTri make_plane_tri(const TriVerts& t);

// Distance along the ray to the plane of `tri`, for a candidate that already passed a watertight
// inside test (one or two per ray): NaN when the ray is parallel to the plane.
// Why not T/det: the sheared distance loses up to ~1e-3 relative on long, thin triangles (the edge
// functions cancel), and even the float plane equation loses eps * |edge| / cos(angle) on grazing
// hits — both beyond the suite's 1e-5 accuracy bar on real scenes (measured on lucy, conference).
// Differences of floats are exact in double, so this is accurate to the last bit of the float
// result. SIMD kernels call it for the lanes that hit.
inline float exact_plane_distance(const Vec3& org, const Vec3& dir, const TriVerts& tri) {
  const double ax = double(tri.v0.x) - org.x, ay = double(tri.v0.y) - org.y, az = double(tri.v0.z) - org.z;
  const double e1x = double(tri.v1.x) - tri.v0.x, e1y = double(tri.v1.y) - tri.v0.y, e1z = double(tri.v1.z) - tri.v0.z;
  const double e2x = double(tri.v2.x) - tri.v0.x, e2y = double(tri.v2.y) - tri.v0.y, e2z = double(tri.v2.z) - tri.v0.z;
  const double nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
  const double dn = nx * dir.x + ny * dir.y + nz * dir.z;
  return dn != 0.0 ? float((nx * ax + ny * ay + nz * az) / dn) : NAN;
}

// Watertight test. On a hit with tmin <= t < hit.t, updates hit (t, u, v) and returns true.
inline bool intersect_watertight(const RayCtx& r, const TriVerts& tri, float tmin, Hit& hit) {
  const Vec3 A = tri.v0 - r.org, B = tri.v1 - r.org, C = tri.v2 - r.org;
  const float Ax = A[r.kx] - r.sx * A[r.kz], Ay = A[r.ky] - r.sy * A[r.kz];
  const float Bx = B[r.kx] - r.sx * B[r.kz], By = B[r.ky] - r.sy * B[r.kz];
  const float Cx = C[r.kx] - r.sx * C[r.kz], Cy = C[r.ky] - r.sy * C[r.kz];
  float U = Cx * By - Cy * Bx, V = Ax * Cy - Ay * Cx, W = Bx * Ay - By * Ax;
  if (U == 0.f || V == 0.f || W == 0.f) [[unlikely]] {
    // An edge passes (numerically) through the ray: decide in double so neighbours agree (§4).
    U = float(double(Cx) * By - double(Cy) * Bx);
    V = float(double(Ax) * Cy - double(Ay) * Cx);
    W = float(double(Bx) * Ay - double(By) * Ax);
  }
  if ((U < 0.f || V < 0.f || W < 0.f) && (U > 0.f || V > 0.f || W > 0.f)) return false;
  const float det = U + V + W;
  if (det == 0.f) return false;  // degenerate or edge-on: never a hit
  // See exact_plane_distance: the sheared T/det is only the fallback for edge-on triangles.
  const float inv_det = 1.f / det;
  float t = exact_plane_distance(r.org, r.dir, tri);
  if (std::isnan(t)) t = r.sz * (U * A[r.kz] + V * B[r.kz] + W * C[r.kz]) * inv_det;
  if (!(t >= tmin && t < hit.t)) return false;
  hit.t = t;
  hit.u = V * inv_det;
  hit.v = W * inv_det;
  return true;
}

// Moller-Trumbore (1997): fast, not watertight (rays through shared edges can leak).
inline bool intersect_moller(const RayCtx& r, const TriVerts& tri, float tmin, Hit& hit) {
  const Vec3 e1 = tri.v1 - tri.v0, e2 = tri.v2 - tri.v0;
  const Vec3 p = cross(r.dir, e2);
  const float det = dot(e1, p);
  if (std::fabs(det) < 1e-20f) return false;
  const float inv_det = 1.f / det;
  const Vec3 s = r.org - tri.v0;
  const float u = dot(s, p) * inv_det;
  if (u < 0.f || u > 1.f) return false;
  const Vec3 q = cross(s, e1);
  const float v = dot(r.dir, q) * inv_det;
  if (v < 0.f || u + v > 1.f) return false;
  const float t = dot(e2, q) * inv_det;
  if (!(t >= tmin && t < hit.t)) return false;
  hit.t = t; hit.u = u; hit.v = v;
  return true;
}

// Precomputed-plane test (Appendix C): t from the plane, barycentrics from two edge planes
// evaluated at the hit point. kApproxRcp uses rcpps (12 bits) for 1/(n.d) as the thesis does.
template <bool kApproxRcp>
inline bool intersect_plane(const RayCtx& r, const PlaneTri& tri, float tmin, Hit& hit) {
  const float dn = dot(r.dir, tri.n);
  if (dn == 0.f) return false;
  float rcp;
  if constexpr (kApproxRcp) rcp = _mm_cvtss_f32(_mm_rcp_ss(_mm_set_ss(dn)));
  else rcp = 1.f / dn;
  const float t = (tri.nd - dot(r.org, tri.n)) * rcp;
  if (!(t >= tmin && t < hit.t)) return false;
  const Vec3 p = r.org + r.dir * t;
  const float u = dot(p, tri.u) + tri.ud;
  if (u < 0.f || u > 1.f) return false;
  const float v = dot(p, tri.v) + tri.vd;
  if (v < 0.f || u + v > 1.f) return false;
  hit.t = t; hit.u = u; hit.v = v;
  return true;
}

// Tests stored triangle i with kernel K; on a closer hit records it (prim = scene index).
template <TriKernel K>
inline bool intersect_tri(const RayCtx& r, const TriangleSet& ts, uint32_t i, float tmin, Hit& hit) {
  bool h;
  if constexpr (K == TriKernel::watertight) h = intersect_watertight(r, ts.verts[i], tmin, hit);
  else if constexpr (K == TriKernel::moller) h = intersect_moller(r, ts.verts[i], tmin, hit);
  else h = intersect_plane<K == TriKernel::plane_rcp>(r, ts.planes[i], tmin, hit);
  if (h) hit.prim = ts.prim_id[i];
  return h;
}

// Calls f(std::integral_constant<TriKernel, K>{}) for the runtime kernel k: how a scheme turns
// its `--kernel` option into a template argument without copying itself.
template <class F>
decltype(auto) dispatch_kernel(TriKernel k, F&& f) {
  switch (k) {
    case TriKernel::moller: return f(std::integral_constant<TriKernel, TriKernel::moller>{});
    case TriKernel::plane: return f(std::integral_constant<TriKernel, TriKernel::plane>{});
    case TriKernel::plane_rcp: return f(std::integral_constant<TriKernel, TriKernel::plane_rcp>{});
    default: return f(std::integral_constant<TriKernel, TriKernel::watertight>{});
  }
}

template <class SceneT>
void TriangleSet::build(const SceneT& scene, const std::vector<uint32_t>& order, TriKernel k) {
  verts.resize(order.size());
  prim_id = order;
  for (size_t i = 0; i < order.size(); ++i)
    verts[i] = {scene.vertex(order[i], 0), scene.vertex(order[i], 1), scene.vertex(order[i], 2)};
  planes.clear();
  if (k == TriKernel::plane || k == TriKernel::plane_rcp) {
    planes.resize(verts.size());
    for (size_t i = 0; i < verts.size(); ++i) planes[i] = make_plane_tri(verts[i]);
  }
}

}  // namespace tb
