// The exact oracle (traversal/exact.h, docs/ACCURACY.md).
//
// Formulation. With a = A - o, b = B - o, c = C - o (o the origin, d the direction):
//   U = det(d, b, c), V = det(d, c, a), W = det(d, a, b)   (signed volumes of the ray with each edge)
//   D = U + V + W = d . ((B - A) x (C - A))                 (zero: parallel ray or degenerate triangle)
//   T = det(a, b, c) = (A - o) . N                          (t = T / D)
// The ray meets the closed triangle iff U, V, W do not take both signs and D != 0 (two-sided,
// edges inclusive; the plane-crossing form of Plücker tests, cf. Woop et al. 2013 §3). Every
// quantity is a polynomial of degree <= 6 in differences of float32 values, so in double it can
// neither overflow (|x| <= 2^128 per factor) nor underflow (a nonzero difference of floats is a
// multiple of 2^-149, a nonzero degree-6 value at least 2^-894).
//
// Filter. Each double value carries a bound e with |exact - v| <= e, propagated by running error
// analysis (Higham 2002 §3.1): sums and products take the exact rounding error of their own step
// from TwoSum / TwoProduct (Knuth; fma), so values computed without rounding keep e = 0 and decide
// exactly, zero included (integer coordinates, axis-parallel rays). A sign is decided when
// e == 0 or |v| > e; otherwise the triangle (or the comparison) is recomputed in mpq_class.
#include "traversal/exact.h"

#include <gmpxx.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <vector>

#include "structures/structure_cache.h"

namespace tb {
namespace {

constexpr double kU = 0x1p-53;  // unit roundoff of double

// Rounds a nonnegative error bound up past the rounding of its own computation (at most five
// roundings of nonnegative terms: factor (1 + u)^5 < 1 + 8u) and past any underflow in it.
inline double up(double e) { return e == 0 ? 0.0 : e * (1 + 8 * kU) + 0x1p-1020; }

struct E {
  double v = 0, e = 0;  // |exact - v| <= e
};
inline E neg(E a) { return {-a.v, a.e}; }
inline E add(E a, E b) {
  const double s = a.v + b.v, bb = s - a.v, r = (a.v - (s - bb)) + (b.v - bb);  // TwoSum: r exact
  return {s, (a.e == 0 && b.e == 0) ? std::fabs(r) : up(a.e + b.e + std::fabs(r))};
}
inline E sub(E a, E b) { return add(a, neg(b)); }
inline E mul(E a, E b) {
  const double p = a.v * b.v, r = std::fma(a.v, b.v, -p);  // TwoProduct: r exact
  if (a.e == 0 && b.e == 0) return {p, std::fabs(r)};
  return {p, up(std::fabs(a.v) * b.e + std::fabs(b.v) * a.e + a.e * b.e + std::fabs(r))};
}
// -1, 0, +1, or kUnknown when the bound cannot decide (NaN from non-finite input included).
constexpr int kUnknown = 2;
inline int sign(E a) {
  if (a.e == 0) return (a.v > 0) - (a.v < 0);
  if (std::fabs(a.v) > a.e) return a.v > 0 ? 1 : -1;
  return kUnknown;
}

struct E3 {
  E x, y, z;
};
inline E3 cross(const E3& a, const E3& b) {
  return {sub(mul(a.y, b.z), mul(a.z, b.y)), sub(mul(a.z, b.x), mul(a.x, b.z)), sub(mul(a.x, b.y), mul(a.y, b.x))};
}
inline E dot(const E3& a, const E3& b) { return add(add(mul(a.x, b.x), mul(a.y, b.y)), mul(a.z, b.z)); }
inline E3 exact3(Vec3 v) { return {{v.x, 0}, {v.y, 0}, {v.z, 0}}; }
inline E3 minus(Vec3 p, Vec3 o) { return {sub({p.x, 0}, {o.x, 0}), sub({p.y, 0}, {o.y, 0}), sub({p.z, 0}, {o.z, 0})}; }

bool finite(Vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
bool ray_valid(const Ray& r) { return finite(r.org) && finite(r.dir) && !std::isnan(r.tmin) && !std::isnan(r.tmax); }

// ---- exact path ---------------------------------------------------------------------------------

struct Q3 {
  mpq_class x, y, z;
};
Q3 qminus(Vec3 p, Vec3 o) {
  return {mpq_class(double(p.x)) - double(o.x), mpq_class(double(p.y)) - double(o.y),
          mpq_class(double(p.z)) - double(o.z)};
}
Q3 qcross(const Q3& a, const Q3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
mpq_class qdot(const Q3& a, const Q3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

// The rule in rationals: true and (T, D) with D > 0 when the triangle is hit within [tmin, tmax).
bool exact_tri(const Ray& ray, Vec3 A, Vec3 B, Vec3 C, mpq_class& T, mpq_class& D) {
  if (!finite(A) || !finite(B) || !finite(C)) return false;
  const Q3 a = qminus(A, ray.org), b = qminus(B, ray.org), c = qminus(C, ray.org);
  const Q3 d{mpq_class(double(ray.dir.x)), mpq_class(double(ray.dir.y)), mpq_class(double(ray.dir.z))};
  const Q3 bc = qcross(b, c);
  const int su = sgn(qdot(d, bc)), sv = sgn(qdot(d, qcross(c, a))), sw = sgn(qdot(d, qcross(a, b)));
  if ((su < 0 || sv < 0 || sw < 0) && (su > 0 || sv > 0 || sw > 0)) return false;
  if (su == 0 && sv == 0 && sw == 0) return false;  // D = 0: parallel or degenerate
  const bool flip = su < 0 || sv < 0 || sw < 0;
  D = qdot(d, bc) + qdot(d, qcross(c, a)) + qdot(d, qcross(a, b));
  T = qdot(a, bc);
  if (flip) D = -D, T = -T;
  if (std::isfinite(ray.tmin) && T < D * mpq_class(double(ray.tmin))) return false;
  if (ray.tmin == std::numeric_limits<float>::infinity()) return false;
  if (std::isfinite(ray.tmax) && !(T < D * mpq_class(double(ray.tmax)))) return false;
  if (ray.tmax == -std::numeric_limits<float>::infinity()) return false;
  return true;
}

// Round to nearest float, ties to even: the nearest of float(q.get_d()) and its two neighbours.
float round_to_float(const mpq_class& q) {
  const double g = q.get_d();  // truncated: within one double ulp of q
  float best = float(g);
  if (!std::isfinite(best)) return best;  // beyond the float range (t > 3.4e38 with tmax = inf)
  mpq_class best_d = abs(q - mpq_class(double(best)));
  for (float c : {std::nextafter(best, -INFINITY), std::nextafter(best, INFINITY)}) {
    if (!std::isfinite(c)) continue;
    const mpq_class dist = abs(q - mpq_class(double(c)));
    uint32_t bits;
    std::memcpy(&bits, &c, 4);
    if (dist < best_d || (dist == best_d && (bits & 1) == 0)) best = c, best_d = dist;
  }
  return best;
}

// ---- filtered candidates ------------------------------------------------------------------------

// A candidate hit: T / D with D > 0 certified, as filtered values.
struct Cand {
  uint32_t prim = kNoHit;
  E T, D;
  double u = 0, v = 0;
};

E from_q(const mpq_class& q) {
  const double v = q.get_d();
  return {v, sgn(q) == 0 ? 0.0 : up(std::fabs(v) * 2 * kU)};
}

// Tests one triangle under the rule; fills cand (prim excepted) on a hit.
bool tri_candidate(const Ray& ray, Vec3 A, Vec3 B, Vec3 C, Cand& cand) {
  const E3 a = minus(A, ray.org), b = minus(B, ray.org), c = minus(C, ray.org), d = exact3(ray.dir);
  const E3 bc = cross(b, c);
  const E U = dot(d, bc), V = dot(d, cross(c, a)), W = dot(d, cross(a, b));
  const int su = sign(U), sv = sign(V), sw = sign(W);
  // Decided opposite signs reject without more work (the common case).
  if ((su == -1 || sv == -1 || sw == -1) && (su == 1 || sv == 1 || sw == 1)) return false;
  bool need_exact = su == kUnknown || sv == kUnknown || sw == kUnknown;
  E D, T;
  if (!need_exact) {
    if (su == 0 && sv == 0 && sw == 0) return false;  // D = 0: parallel ray or degenerate triangle
    if (ray.tmin == INFINITY || ray.tmax == -INFINITY) return false;
    D = add(add(U, V), W), T = dot(a, bc);
    if (su == -1 || sv == -1 || sw == -1) D = neg(D), T = neg(T);
    // tmin <= T / D  <=>  T - tmin D >= 0;  T / D < tmax  <=>  T - tmax D < 0 (D > 0).
    if (std::isfinite(ray.tmin)) {
      const int s = ray.tmin == 0 ? sign(T) : sign(sub(T, mul({ray.tmin, 0}, D)));
      if (s == kUnknown) need_exact = true;
      else if (s < 0) return false;
    }
    if (!need_exact && std::isfinite(ray.tmax)) {
      const int s = sign(sub(T, mul({ray.tmax, 0}, D)));
      if (s == kUnknown) need_exact = true;
      else if (s >= 0) return false;
    }
  }
  if (need_exact) {
    mpq_class Tq, Dq;
    if (!exact_tri(ray, A, B, C, Tq, Dq)) return false;
    T = from_q(Tq), D = from_q(Dq);
  }
  cand.T = T, cand.D = D;
  const double det = U.v + V.v + W.v;  // barycentrics are reported approximately
  cand.u = det != 0 ? V.v / det : 0, cand.v = det != 0 ? W.v / det : 0;
  return true;
}

// Exact T, D (D > 0) of a triangle known to be hit, for a comparison the filter left open: with
// N = (B - A) x (C - A), D = d . N and T = (A - o) . N (the same values as exact_tri's U + V + W and
// det(a, b, c); one cross product and two dot products instead of exact_tri's four and four, and
// no edge signs: the candidate's were decided already).
void exact_td(const Ray& ray, Vec3 A, Vec3 B, Vec3 C, mpq_class& T, mpq_class& D) {
  const Q3 n = qcross(qminus(B, A), qminus(C, A));
  const Q3 d{mpq_class(double(ray.dir.x)), mpq_class(double(ray.dir.y)), mpq_class(double(ray.dir.z))};
  D = qdot(d, n);
  T = qdot(qminus(A, ray.org), n);
  if (sgn(D) < 0) D = -D, T = -T;
}

// A candidate's exact T and D, formed the first time a comparison needs them and kept with the
// candidate: the closest so far meets every later tie (a stack of coplanar, overlapping triangles
// put ~150 ties on one ray, each of which formed both sides anew: 15 ms a ray).
// (In an optional: most candidates never need them, and a rational's constructor allocates.)
struct ExactTD {
  struct Values {
    mpq_class T, D;
  };
  std::optional<Values> v;
  const Values& need(const Ray& ray, Vec3 A, Vec3 B, Vec3 C) {
    if (!v) {
      v.emplace();
      exact_td(ray, A, B, C, v->T, v->D);
    }
    return *v;
  }
  const Values& need(const Ray& ray, const Scene& s, uint32_t prim) {
    return need(ray, s.vertex(prim, 0), s.vertex(prim, 1), s.vertex(prim, 2));
  }
};

// Whether candidate x is closer than y: smaller exact t, or equal t and lower prim id. xe and ye
// hold (or receive) their exact T, D where the filter cannot decide.
bool closer(const Ray& ray, const Scene& s, const Cand& x, const Cand& y, ExactTD& xe, ExactTD& ye) {
  if (y.prim == kNoHit) return true;
  int c = sign(sub(mul(x.T, y.D), mul(y.T, x.D)));  // sign of t_x - t_y (both D > 0)
  if (c == kUnknown) {
    const ExactTD::Values &a = xe.need(ray, s, x.prim), &b = ye.need(ray, s, y.prim);
    const int q = cmp(a.T * b.D, b.T * a.D);
    c = (q > 0) - (q < 0);
  }
  return c < 0 || (c == 0 && x.prim < y.prim);
}

// Certified interval [lo, hi] of t = T / D (D > 0).
void t_bounds(const Cand& c, double& lo, double& hi) {
  const double nlo = c.T.v - c.T.e, nhi = c.T.v + c.T.e, dlo = c.D.v - c.D.e, dhi = c.D.v + c.D.e;
  if (!(dlo > 0)) {
    lo = -INFINITY, hi = INFINITY;
    return;
  }
  lo = nlo / (nlo >= 0 ? dhi : dlo);
  hi = nhi / (nhi >= 0 ? dlo : dhi);
  lo -= std::fabs(lo) * 4 * kU;
  hi += std::fabs(hi) * 4 * kU;
}

// `known`: best's ExactTD (closest's), whose T and D a tie may already have formed, so that they
// are not formed twice.
Hit finish(const Ray& ray, const Cand& best, Vec3 A, Vec3 B, Vec3 C, ExactTD* known = nullptr) {
  if (best.prim == kNoHit) return Hit{};
  double lo, hi;
  t_bounds(best, lo, hi);
  float t;
  if (float(lo) == float(hi)) {
    t = float(lo);  // round to nearest is monotonic: every value in [lo, hi] rounds to it
  } else {
    ExactTD fresh;
    const ExactTD::Values& e = (known ? *known : fresh).need(ray, A, B, C);
    t = round_to_float(mpq_class(e.T / e.D));
  }
  t += 0.f;  // a rational zero has no sign: report +0 (-0 + 0 = +0)
  return Hit{t, best.prim, float(best.u), float(best.v)};
}

Hit finish_closest(const Ray& ray, const Scene& s, const Cand& best, ExactTD* known = nullptr) {
  if (best.prim == kNoHit) return Hit{};
  return finish(ray, best, s.vertex(best.prim, 0), s.vertex(best.prim, 1), s.vertex(best.prim, 2), known);
}

// Conservative slab test in double: a box the ray touches for some t in [tmin, tfar] in exact
// arithmetic is never culled. A zero direction component (either sign) keeps the slab when the
// origin lies in it, bounds inclusive (the old reference's rcp(0) = 1e300 made (plane - o) * 1e300
// = 0 for an origin on the plane and culled the box: issue 16).
struct DRay {
  double o[3], d[3], inv[3];
  explicit DRay(const Ray& r) {
    for (int a = 0; a < 3; ++a) o[a] = r.org[a], d[a] = r.dir[a], inv[a] = d[a] == 0 ? 0 : 1.0 / d[a];
  }
};
bool box_hit(const DRay& r, const BVHNode& n, double tmin, double tfar, double& tnear) {
  double tn = tmin, tf = tfar;
  for (int a = 0; a < 3; ++a) {
    const double lo = n.lo[a], hi = n.hi[a];
    if (r.d[a] == 0) {
      if (r.o[a] < lo || r.o[a] > hi) return false;
      continue;
    }
    // Three roundings (difference, reciprocal, product): relative error < 4u; pad by 1e-12.
    double t0 = (lo - r.o[a]) * r.inv[a], t1 = (hi - r.o[a]) * r.inv[a];
    if (t0 > t1) std::swap(t0, t1);
    t0 -= std::fabs(t0) * 1e-12;
    t1 += std::fabs(t1) * 1e-12;
    if (t0 > tn) tn = t0;
    if (t1 < tf) tf = t1;
  }
  tnear = tn;
  return tn <= tf;
}

}  // namespace

bool exact_triangle_hit(const Ray& ray, Vec3 a, Vec3 b, Vec3 c, float* t_out) {
  if (!ray_valid(ray)) return false;
  Cand cand;
  if (!tri_candidate(ray, a, b, c, cand)) return false;
  cand.prim = 0;
  if (t_out) *t_out = finish(ray, cand, a, b, c).t;
  return true;
}

ExactOracle::ExactOracle(const Scene& scene, StructureCache& cache)
    : scene_(&scene),
      bvh_(cache.get<BVH>(BVHBuildParams{}.key(), [&] { return BVH::build(scene, BVHBuildParams{}); })) {}

ExactOracle::ExactOracle(const Scene& scene, std::shared_ptr<const BVH> bvh) : scene_(&scene), bvh_(std::move(bvh)) {}

namespace {

// Depth-first over the BVH, nearer child first; `f(cand)` sees every triangle the rule accepts in
// [tmin, tfar] and may shrink tfar (boxes beyond it are culled, inclusive).
template <class F>
void traverse(const BVH& bvh, const Scene& scene, const Ray& ray, double& tfar, uint64_t* tri_tests, F&& f) {
  if (bvh.nodes.empty()) return;
  const DRay r(ray);
  const BVHNode* nodes = bvh.nodes.data();
  double tnear, t0 = 0, t1 = 0;  // set by box_hit where it returns true (read only then)
  std::vector<uint32_t> stack;
  stack.reserve(64);
  stack.push_back(0);
  while (!stack.empty()) {
    const BVHNode& n = nodes[stack.back()];
    stack.pop_back();
    if (!box_hit(r, n, ray.tmin, tfar, tnear)) continue;
    if (n.is_leaf()) {
      for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) {
        const uint32_t prim = bvh.prim_index[k];
        if (tri_tests) ++*tri_tests;
        Cand c;
        if (!tri_candidate(ray, scene.vertex(prim, 0), scene.vertex(prim, 1), scene.vertex(prim, 2), c)) continue;
        c.prim = prim;
        f(c);
      }
      continue;
    }
    const bool h0 = box_hit(r, nodes[n.left_first], ray.tmin, tfar, t0);
    const bool h1 = box_hit(r, nodes[n.left_first + 1], ray.tmin, tfar, t1);
    if (h0 && h1) {  // nearer child on top
      stack.push_back(t0 <= t1 ? n.left_first + 1 : n.left_first);
      stack.push_back(t0 <= t1 ? n.left_first : n.left_first + 1);
    } else if (h0 || h1) {
      stack.push_back(h0 ? n.left_first : n.left_first + 1);
    }
  }
}

}  // namespace

Hit ExactOracle::closest(const Ray& ray, uint64_t* tri_tests) const {
  if (!ray_valid(ray) || !(ray.tmin < ray.tmax)) return Hit{};
  Cand best;
  ExactTD best_exact;
  double tfar = ray.tmax, lo;
  traverse(*bvh_, *scene_, ray, tfar, tri_tests, [&](const Cand& c) {
    ExactTD c_exact;
    if (!closer(ray, *scene_, c, best, c_exact, best_exact)) return;
    best = c;
    best_exact = std::move(c_exact);
    t_bounds(best, lo, tfar);  // an equal exact t of a lower id must still be found: inclusive
    if (tfar > ray.tmax) tfar = ray.tmax;
  });
  return finish_closest(ray, *scene_, best, &best_exact);
}

std::vector<Hit> ExactOracle::all_hits(const Ray& ray) const {
  std::vector<Hit> out;
  if (!ray_valid(ray) || !(ray.tmin < ray.tmax)) return out;
  double tfar = ray.tmax;
  traverse(*bvh_, *scene_, ray, tfar, nullptr, [&](const Cand& c) { out.push_back(finish_closest(ray, *scene_, c)); });
  std::sort(out.begin(), out.end(), [](const Hit& a, const Hit& b) { return a.t < b.t || (a.t == b.t && a.prim < b.prim); });
  return out;
}

Hit ExactOracle::closest_brute_force(const Ray& ray) const {
  if (!ray_valid(ray) || !(ray.tmin < ray.tmax)) return Hit{};
  Cand best;
  ExactTD best_exact;
  for (uint32_t prim = 0; prim < scene_->num_triangles(); ++prim) {
    Cand c;
    if (!tri_candidate(ray, scene_->vertex(prim, 0), scene_->vertex(prim, 1), scene_->vertex(prim, 2), c)) continue;
    c.prim = prim;
    ExactTD c_exact;
    if (closer(ray, *scene_, c, best, c_exact, best_exact)) best = c, best_exact = std::move(c_exact);
  }
  return finish_closest(ray, *scene_, best, &best_exact);
}

namespace {
float step_ulps(float x, int k) {
  const float to = k > 0 ? INFINITY : -INFINITY;
  for (int i = 0; i < std::abs(k); ++i) x = std::nextafter(x, to);
  return x;
}

std::vector<Ray> moved_rays(const Ray& ray, int k) {
  std::vector<Ray> out;
  auto comp = [](Ray& r, int i) -> float& { return i < 3 ? r.org[i] : r.dir[i - 3]; };
  for (int i = 0; i < 6; ++i)  // each of the six components alone by +-1 and +-k ulps
    for (int s : {1, -1, k, -k}) {
      Ray m = ray;
      comp(m, i) = step_ulps(comp(m, i), s);
      out.push_back(m);
    }
  for (int mask = 0; mask < 64; ++mask) {  // all six together by +-k ulps in every sign pattern
    Ray m = ray;
    for (int i = 0; i < 6; ++i) comp(m, i) = step_ulps(comp(m, i), (mask >> i) & 1 ? k : -k);
    out.push_back(m);
  }
  return out;
}

// Whether the ray passes inside the triangle up to k float roundings of each edge function: for
// one orientation every edge value U, V, W is >= -k 2^-24 M, M its magnitude (the sum of the
// absolute values of its products), i.e. a float evaluation a few ulps off accepts it. This is
// how a ray nearly in the plane of a triangle (edge-on: every edge value tiny) is recognised,
// where moving the ray by ulps sweeps the plane crossing far along the plane. Approximate (double)
// on purpose: it classifies, it never decides a hit.
bool inside_within_roundings(const Ray& ray, Vec3 A, Vec3 B, Vec3 C, int k) {
  double a[3], b[3], c[3], d[3];
  for (int i = 0; i < 3; ++i)
    a[i] = double(A[i]) - ray.org[i], b[i] = double(B[i]) - ray.org[i], c[i] = double(C[i]) - ray.org[i],
    d[i] = ray.dir[i];
  auto edge = [&](const double* p, const double* q, double& mag) {
    double v = 0;
    mag = 0;
    for (int i = 0; i < 3; ++i) {
      const int j = (i + 1) % 3, l = (i + 2) % 3;
      v += d[i] * (p[j] * q[l] - p[l] * q[j]);
      mag += std::fabs(d[i]) * (std::fabs(p[j] * q[l]) + std::fabs(p[l] * q[j]));
    }
    return v;
  };
  double mu, mv, mw;
  const double u = edge(b, c, mu), v = edge(c, a, mv), w = edge(a, b, mw);
  const double tol = k * 0x1p-24;
  bool inside = false;
  for (double s : {1.0, -1.0}) inside |= s * u >= -tol * mu && s * v >= -tol * mv && s * w >= -tol * mw;
  if (!inside) return false;
  // And the plane crossing in [tmin, tmax) up to roundings, unless the ray is edge-on.
  const double D = u + v + w;
  if (std::fabs(D) <= tol * (mu + mv + mw)) return true;
  const double T = a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) + a[2] * (b[0] * c[1] - b[1] * c[0]);
  const double t = T / D, slack = tol * (std::fabs(t) + 1);
  return t >= ray.tmin - slack && t < double(ray.tmax) + slack;
}

using P3 = std::array<double, 3>;

// Triangles whose bounding boxes overlap the box [lo, hi] (inclusive), over the BVH.
std::vector<uint32_t> prims_overlapping(const BVH& bvh, const Scene& scene, const double lo[3], const double hi[3]) {
  std::vector<uint32_t> out, stack;
  if (bvh.nodes.empty()) return out;
  auto overlaps = [&](const double* blo, const double* bhi) {
    for (int a = 0; a < 3; ++a)
      if (bhi[a] < lo[a] || blo[a] > hi[a]) return false;
    return true;
  };
  stack.push_back(0);
  while (!stack.empty()) {
    const BVHNode& n = bvh.nodes[stack.back()];
    stack.pop_back();
    const double nlo[3] = {n.lo.x, n.lo.y, n.lo.z}, nhi[3] = {n.hi.x, n.hi.y, n.hi.z};
    if (!overlaps(nlo, nhi)) continue;
    if (!n.is_leaf()) {
      stack.push_back(n.left_first), stack.push_back(n.left_first + 1);
      continue;
    }
    for (uint32_t k = n.left_first; k < n.left_first + n.count; ++k) {
      const uint32_t prim = bvh.prim_index[k];
      double tlo[3], thi[3];
      for (int a = 0; a < 3; ++a) {
        tlo[a] = thi[a] = scene.vertex(prim, 0)[a];
        for (int v = 1; v < 3; ++v) tlo[a] = std::min(tlo[a], double(scene.vertex(prim, v)[a])),
                                    thi[a] = std::max(thi[a], double(scene.vertex(prim, v)[a]));
      }
      if (overlaps(tlo, thi)) out.push_back(prim);
    }
  }
  return out;
}

// Whether some triangle of `landed` is not tied to the surface `group`: tied means connected to a
// triangle of the group by a chain of triangles that share a vertex (identical float
// coordinates) and all overlap the box of the crossing points `pts`, padded by 2^-20 of their
// magnitude (8 float ulps; a larger box can only lengthen chains: the test errs towards "tied").
// A watertight float kernel evaluates an edge or vertex shared by two triangles identically for
// both (Woop, Benthin, Wald, "Watertight Ray/Triangle Intersection", JCGT 2(1), 2013, claim
// closure for edges shared with identical vertices), so it cannot pass between tied triangles;
// between triangles that share no vertex (a T-junction: a vertex inside another triangle's edge;
// meshes meeting without common vertices) each decision is rounded on its own and a ray within
// ulps of the seam can be rejected by both (docs/ACCURACY.md "Error kinds", the seam rule).
bool lands_untied(const BVH& bvh, const Scene& scene, const std::vector<uint32_t>& group,
                  const std::vector<uint32_t>& landed, const std::vector<P3>& pts) {
  if (landed.empty()) return false;
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = INFINITY, hi[a] = -INFINITY;
    for (const P3& p : pts) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
    const double pad = 0x1p-20 * std::max({1.0, std::fabs(lo[a]), std::fabs(hi[a])});
    lo[a] -= pad, hi[a] += pad;
  }
  std::vector<uint32_t> nodes = prims_overlapping(bvh, scene, lo, hi);
  nodes.insert(nodes.end(), group.begin(), group.end());
  nodes.insert(nodes.end(), landed.begin(), landed.end());
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  // Flood fill from the group over shared vertices, by identical float coordinates (+0 and -0
  // are one key): linear in the triangles of the box, which a grazing ray can make large.
  auto key = [](Vec3 v) {
    uint32_t b[3];
    for (int a = 0; a < 3; ++a) {
      const float x = v[a] + 0.f;  // -0 + 0 = +0
      std::memcpy(&b[a], &x, 4);
    }
    return std::array<uint32_t, 3>{b[0], b[1], b[2]};
  };
  std::map<std::array<uint32_t, 3>, std::vector<size_t>> at_vertex;
  for (size_t i = 0; i < nodes.size(); ++i)
    for (int v = 0; v < 3; ++v) at_vertex[key(scene.vertex(nodes[i], v))].push_back(i);
  // Closure around a shared vertex holds only for rays that pass near it: two triangles are tied
  // through a vertex they share only when that vertex lies in the box of the crossings, and
  // anywhere through an edge they share (both vertices). Two edges on one line with one common
  // end — a T-junction along a corner, Sponza's wall 63985 and ceiling 13878 — are independent
  // edge functions away from that end.
  auto in_box = [&](Vec3 v) {
    for (int a = 0; a < 3; ++a)
      if (double(v[a]) < lo[a] || double(v[a]) > hi[a]) return false;
    return true;
  };
  auto has_vertex = [&](size_t j, const std::array<uint32_t, 3>& k) {
    for (int w = 0; w < 3; ++w)
      if (key(scene.vertex(nodes[j], w)) == k) return true;
    return false;
  };
  std::vector<char> tied(nodes.size(), 0);
  std::vector<size_t> todo;
  for (size_t i = 0; i < nodes.size(); ++i)
    if (std::find(group.begin(), group.end(), nodes[i]) != group.end()) tied[i] = 1, todo.push_back(i);
  while (!todo.empty()) {
    const size_t i = todo.back();
    todo.pop_back();
    for (int v = 0; v < 3; ++v) {
      const Vec3 p = scene.vertex(nodes[i], v);
      const bool near = in_box(p);
      const auto k1 = key(scene.vertex(nodes[i], (v + 1) % 3));
      for (size_t j : at_vertex[key(p)])
        if (!tied[j] && (near || has_vertex(j, k1))) tied[j] = 1, todo.push_back(j);
    }
  }
  for (uint32_t p : landed)
    if (!tied[size_t(std::lower_bound(nodes.begin(), nodes.end(), p) - nodes.begin())]) return true;
  return false;
}

}  // namespace

bool ExactOracle::ambiguous(const Ray& ray, const Hit& scheme, float rel_bar, int k) const {
  auto bar = [&](float t) { return rel_bar * std::max(1.f, t); };
  const std::vector<Ray> moves = moved_rays(ray, k);
  auto hit_flips = [&](Vec3 a, Vec3 b, Vec3 c) {
    if (inside_within_roundings(ray, a, b, c, k)) return true;
    // Moved rays: the same triangle, or another at the same distance (the fan around a vertex).
    for (const Ray& m : moves) {
      if (exact_triangle_hit(m, a, b, c)) return true;
      Ray w = m;
      w.tmin = std::max(ray.tmin, scheme.t - bar(scheme.t));
      w.tmax = std::min(ray.tmax, std::nextafter(scheme.t + bar(scheme.t), INFINITY));
      if (closest(w).hit()) return true;
    }
    return false;
  };
  // (2), first as it is cheap: the scheme's own hit is made by the exact ray at that distance, or
  // lies within k float roundings of the triangle's edge functions, or is made by some moved ray
  // (on that triangle, or on any at that distance).
  if (scheme.hit() && scheme.prim < scene_->num_triangles()) {
    const Vec3 a = scene_->vertex(scheme.prim, 0), b = scene_->vertex(scheme.prim, 1), c = scene_->vertex(scheme.prim, 2);
    float t;
    if (exact_triangle_hit(ray, a, b, c, &t)) {
      if (std::fabs(scheme.t - t) > bar(t)) return false;  // the right triangle at a wrong t
    } else if (!hit_flips(a, b, c)) {
      return false;
    }
  }
  // (1) Every surface the exact ray hits before the scheme's answer (all of them for a scheme
  // miss) must be escaped by some moved ray. A surface is the group of hits within the bar of each
  // other (both triangles at a shared edge or vertex). Escaping means no hit from the window's
  // start on, or a first hit beyond the window on a primitive outside the group: the neighbour
  // across an edge at the same distance does not count (a leak through a shared edge is a leak)
  // unless it is not tied to the group by shared vertices (lands_untied: a T-junction, where a
  // float kernel's decisions on the two triangles are independent roundings).
  const auto point = [](const Ray& r, float t) {
    return P3{double(r.org.x) + double(t) * r.dir.x, double(r.org.y) + double(t) * r.dir.y,
                 double(r.org.z) + double(t) * r.dir.z};
  };
  Ray before = ray;
  if (scheme.hit()) before.tmax = std::min(ray.tmax, scheme.t - bar(scheme.t));
  const std::vector<Hit> hs = all_hits(before);
  for (size_t i = 0; i < hs.size();) {
    size_t j = i + 1;
    while (j < hs.size() && hs[j].t - hs[j - 1].t <= bar(hs[j - 1].t)) ++j;
    const float lo = hs[i].t - bar(hs[i].t), hi = hs[j - 1].t + bar(hs[j - 1].t);
    auto in_group = [&](uint32_t p) {
      for (size_t g = i; g < j; ++g)
        if (hs[g].prim == p) return true;
      return false;
    };
    bool escapes = false;
    std::vector<uint32_t> group, landed;  // landed: other triangles moved rays hit in the window
    std::vector<P3> pts;               // the crossing points of the exact and the moved rays
    for (size_t g = i; g < j; ++g) group.push_back(hs[g].prim), pts.push_back(point(ray, hs[g].t));
    for (const Ray& m : moves) {
      Ray w = m;
      w.tmin = std::max(ray.tmin, lo);
      const Hit x = closest(w);
      if (!x.hit() || (!in_group(x.prim) && x.t > hi)) {
        escapes = true;
        break;
      }
      pts.push_back(point(m, x.t));
      if (!in_group(x.prim)) landed.push_back(x.prim);
    }
    if (!escapes && !lands_untied(*bvh_, *scene_, group, landed, pts)) return false;
    i = j;
  }
  return true;
}

}  // namespace tb
