#include "structures/clip.h"

#include "structures/box_simd.h"

#include <algorithm>
#include <bit>
#include <limits>
#include <cmath>
#include <utility>

#include <immintrin.h>
#include <cstdint>

namespace tb {

namespace {

struct ClipVert {
  double p[3];
  uint8_t exact;  // bit a: p[a] is exactly a float input (a vertex coordinate or a box plane)
};

// Vertices a clipped triangle can have. A convex polygon gains at most one vertex per plane (3 + 6
// = 9), but interpolated vertices carry rounding, so a nearly degenerate polygon (a sliver, or a
// triangle whose vertices are collinear) need not stay convex in double and may cross a plane more
// than twice. Clipping n vertices outputs the inside ones plus one per in/out transition, at most
// in + 2 min(in, out) <= 4n/3: 3 -> 4 -> 5 -> 6 -> 8 -> 10 -> 13 after six planes.
constexpr int kMaxClipVerts = 16;

// Sutherland-Hodgman against the six planes of the closed box; inside tests are inclusive, so a
// triangle lying in a face of the box survives whole. Returns the vertex count (0: no overlap).
int clip_polygon(Vec3 a, Vec3 b, Vec3 c, const AABB& box, ClipVert* out /* kMaxClipVerts */) {
  ClipVert buf[2][kMaxClipVerts];
  const Vec3 v[3] = {a, b, c};
  for (int i = 0; i < 3; ++i) buf[0][i] = {{v[i].x, v[i].y, v[i].z}, 7};
  int n = 3, cur = 0;
  for (int axis = 0; axis < 3 && n > 0; ++axis) {
    for (int side = 0; side < 2 && n > 0; ++side) {
      const double w = side == 0 ? double(box.lo[axis]) : double(box.hi[axis]);
      const ClipVert* in = buf[cur];
      ClipVert* o = buf[cur ^ 1];
      int m = 0;
      auto inside = [&](const ClipVert& q) { return side == 0 ? q.p[axis] >= w : q.p[axis] <= w; };
      for (int i = 0; i < n; ++i) {
        const ClipVert& s = in[i];
        const ClipVert& e = in[(i + 1) % n];
        const bool si = inside(s), ei = inside(e);
        if (si) o[m++] = s;
        // An endpoint on the plane counts as inside, and is where the edge meets the plane: it is
        // output as it is (exact coordinates and all), not recomputed as a crossing. So a
        // triangle touching the box only at a vertex or along an edge clips to exactly that.
        if (si != ei && s.p[axis] != w && e.p[axis] != w) {
          // The edge crosses the plane strictly.
          const double t = (w - s.p[axis]) / (e.p[axis] - s.p[axis]);
          ClipVert x;
          x.exact = 0;
          for (int k = 0; k < 3; ++k) {
            if (s.p[k] == e.p[k]) {
              x.p[k] = s.p[k];
              x.exact |= uint8_t(s.exact & e.exact & (1u << k));
            } else {
              x.p[k] = s.p[k] + t * (e.p[k] - s.p[k]);
            }
          }
          x.p[axis] = w;
          x.exact |= uint8_t(1u << axis);
          o[m++] = x;
        }
      }
      n = m;
      cur ^= 1;
    }
  }
  for (int i = 0; i < n; ++i) out[i] = buf[cur][i];
  return n;
}

// One float step down/up for finite values (std::nextafter is a libm call, and the spatial-split
// builder calls these millions of times).
inline float step_down(float f) {
  if (f == 0.f) return -std::numeric_limits<float>::denorm_min();
  const uint32_t u = std::bit_cast<uint32_t>(f);
  return std::bit_cast<float>(f > 0.f ? u - 1 : u + 1);
}
inline float step_up(float f) { return -step_down(-f); }
inline float round_down(double x) {
  const float f = float(x);
  return double(f) > x ? step_down(f) : f;
}
inline float round_up(double x) {
  const float f = float(x);
  return double(f) < x ? step_up(f) : f;
}

}  // namespace

AABB clip_triangle_bounds(Vec3 a, Vec3 b, Vec3 c, const AABB& box) {
  ClipVert poly[kMaxClipVerts];
  const int n = clip_polygon(a, b, c, box, poly);
  AABB out;
  if (n == 0) return out;
  for (int k = 0; k < 3; ++k) {
    // Interpolated coordinates carry a double rounding error of a few ulps of the largest
    // magnitude involved; widen by far more than that, then round outward to float.
    const double scale = std::max({std::fabs(double(a[k])), std::fabs(double(b[k])), std::fabs(double(c[k])),
                                   std::fabs(double(box.lo[k])), std::fabs(double(box.hi[k]))});
    const double margin = scale * 1e-13;
    float lo = INFINITY, hi = -INFINITY;
    for (int i = 0; i < n; ++i) {
      const double x = poly[i].p[k];
      const bool exact = poly[i].exact & (1u << k);
      lo = std::min(lo, exact ? float(x) : round_down(x - margin));
      hi = std::max(hi, exact ? float(x) : round_up(x + margin));
    }
    // Never beyond the box (the cell) or the triangle's own bounds.
    lo = std::max(lo, std::max(box.lo[k], std::min({a[k], b[k], c[k]})));
    hi = std::min(hi, std::min(box.hi[k], std::max({a[k], b[k], c[k]})));
    out.lo[k] = lo;
    out.hi[k] = hi;
  }
  return out;
}

double clipped_triangle_area(Vec3 a, Vec3 b, Vec3 c, const AABB& box) {
  ClipVert poly[kMaxClipVerts];
  const int n = clip_polygon(a, b, c, box, poly);
  if (n < 3) return 0.0;
  // Newell's vector area of the planar polygon.
  double nx = 0, ny = 0, nz = 0;
  for (int i = 0; i < n; ++i) {
    const double* p = poly[i].p;
    const double* q = poly[(i + 1) % n].p;
    nx += (p[1] - q[1]) * (p[2] + q[2]);
    ny += (p[2] - q[2]) * (p[0] + q[0]);
    nz += (p[0] - q[0]) * (p[1] + q[1]);
  }
  return 0.5 * std::sqrt(nx * nx + ny * ny + nz * nz);
}

void split_triangle_bounds(const Vec3 v[3], int axis, float pos, AABB& left, AABB& right) {
  left = right = AABB{};
  for (int i = 0; i < 3; ++i) {
    const Vec3 &p = v[i], &q = v[(i + 1) % 3];
    if (p[axis] <= pos) left.grow(p);
    if (p[axis] >= pos) right.grow(p);
    if ((p[axis] < pos && q[axis] > pos) || (p[axis] > pos && q[axis] < pos)) {
      // The crossing in double, widened by far more than its rounding error, rounded outward
      // (the rule of clip_triangle_bounds), clamped to the edge's own bounds.
      const double t = (double(pos) - p[axis]) / (double(q[axis]) - p[axis]);
      AABB x;
      for (int k = 0; k < 3; ++k) {
        if (k == axis) {
          x.lo[k] = x.hi[k] = pos;
          continue;
        }
        const double c = double(p[k]) + t * (double(q[k]) - p[k]);
        const double margin = std::max(std::fabs(double(p[k])), std::fabs(double(q[k]))) * 1e-13;
        x.lo[k] = std::max(round_down(c - margin), std::min(p[k], q[k]));
        x.hi[k] = std::min(round_up(c + margin), std::max(p[k], q[k]));
      }
      left.grow(x);
      right.grow(x);
    }
  }
}

// The float crossing of edge (p, q) with the plane x[axis] = w, p[axis] < w < q[axis]: t = (w -
// p_a) * inv with inv = fl(1 / fl(q_a - p_a)), then c_k = fl(p_k + fl(t * fl(q_k - p_k))) on each
// other axis k. Error bound (u = 2^-24, standard model |fl(x op y) - x op y| <= u |x op y|, no
// underflow): t carries four roundings (the two differences, the reciprocal, the product), so
// t' = t (1 + d), |d| <= 4u + O(u^2); with d_k = q_k - p_k, |d_k| <= 2M where M = max(|p_k|,
// |q_k|), the product fl(t' fl(d_k)) is t d_k (1 + e), |e| <= 6u + O(u^2), and the final sum adds
// u |c| <= u M (the exact crossing lies on the segment, |c| <= M): |c' - c| <= 12uM + uM + O(u^2)
// = 13.001uM. Padding by 32uM = M * 2^-19 (exact: a power of two), the padded subtraction and
// addition rounding by at most u (M + pad), gives fl(c' - pad) <= c - 17uM < c and
// fl(c' + pad) > c. Underflow adds at most 2^-149 per operation (and |q_a - p_a| >= 2^-100 is
// required, so 1 / (q_a - p_a) cannot overflow and an underflowed w - p_a moves t by at most
// 2^-50, i.e. c by 2^-49 M): FLT_MIN more covers it. Below 2^-100 the crossing is bounded by the
// edge's own box (it lies on the edge), which is also the clamp for every crossing.
namespace {

// The sweep for one axis A, in SSE (a box is a (lo, hi) pair of 4-float registers). With the
// vertices sorted along A (a0 <= a1 <= a2), a plane a0 < w < a2 is crossed strictly by the long
// edge v0-v2 and by v0-v1 (w < a1) or v1-v2 (w > a1); at w = a1 the short edges meet it at v1, a
// vertex. The part in slab i is bounded by the crossings of its two planes and the vertices in
// the closed slab, so one pass over the planes, carrying the lower plane's crossings, gives every
// slab's box without a per-slab array.
template <int A>
void chop_axis(const Vec3 v[3], const float* pl, int n, const AABB& clamp, AABB* out) {
  constexpr float kTiny = 0x1p-100f, kPad = 0x1p-19f, kAbs = std::numeric_limits<float>::min();
  constexpr int kAxisLane = 1 << A;
  int o[3] = {0, 1, 2};
  if (v[o[0]][A] > v[o[1]][A]) std::swap(o[0], o[1]);
  if (v[o[1]][A] > v[o[2]][A]) std::swap(o[1], o[2]);
  if (v[o[0]][A] > v[o[1]][A]) std::swap(o[0], o[1]);
  const float a[3] = {v[o[0]][A], v[o[1]][A], v[o[2]][A]};
  const __m128 P[3] = {load_vec3(v[o[0]]), load_vec3(v[o[1]]), load_vec3(v[o[2]])};
  const __m128 inf = _mm_set1_ps(INFINITY), ninf = _mm_set1_ps(-INFINITY), sign = _mm_set1_ps(-0.f);
  int slab[3];
  bool on[3];
  for (int j = 0; j < 3; ++j) {
    // Slab of the vertex: the last i with pl[i] <= x (i >= 1), else 0; on a plane it is in both.
    const int i = n > 1 ? int(std::upper_bound(pl + 1, pl + n, a[j]) - pl) - 1 : 0;
    slab[j] = i;
    on[j] = i > 0 && pl[i] == a[j];
  }
  struct Edge {
    __m128 p, d, lo, hi, pad;
    float pa, inv;
  };
  // The pad of the error bound above; an edge too short on the sweep axis gets an infinite one
  // (t = 0), which the clamp to the edge's own bounds turns into those bounds. Where d = 0 the
  // crossing is p exactly and the clamp to [p, p] returns it.
  auto edge = [&](int i, int j) {
    Edge e;
    e.p = P[i];
    e.d = _mm_sub_ps(P[j], P[i]);
    e.lo = _mm_min_ps(P[i], P[j]);
    e.hi = _mm_max_ps(P[i], P[j]);
    e.pa = a[i];
    const float den = a[j] - a[i];
    const bool tiny = !(den >= kTiny);
    e.inv = tiny ? 0.f : 1.f / den;
    const __m128 mag = _mm_max_ps(_mm_andnot_ps(sign, P[i]), _mm_andnot_ps(sign, P[j]));
    e.pad = tiny ? inf : _mm_add_ps(_mm_mul_ps(mag, _mm_set1_ps(kPad)), _mm_set1_ps(kAbs));
    return e;
  };
  const Edge L = edge(0, 2), S0 = edge(0, 1), S1 = edge(1, 2);
  auto cross = [&](const Edge& e, float w, __m128& xl, __m128& xh) {
    const __m128 c = _mm_add_ps(e.p, _mm_mul_ps(_mm_set1_ps((w - e.pa) * e.inv), e.d));
    const __m128 wv = _mm_set1_ps(w);
    xl = _mm_min_ps(xl, _mm_blend_ps(_mm_max_ps(_mm_sub_ps(c, e.pad), e.lo), wv, kAxisLane));
    xh = _mm_max_ps(xh, _mm_blend_ps(_mm_min_ps(_mm_add_ps(c, e.pad), e.hi), wv, kAxisLane));
  };
  const __m128 clo = load_vec3(clamp.lo), chi = load_vec3(clamp.hi);
  __m128 lo_l = inf, lo_h = ninf;  // crossings of slab i's lower plane (none for slab 0)
  for (int i = 0; i < n; ++i) {
    __m128 up_l = inf, up_h = ninf;  // crossings of its upper plane pl[i + 1] (none for the last)
    if (i + 1 < n) {
      const float w = pl[i + 1];
      if (w > a[0] && w < a[2]) {
        cross(L, w, up_l, up_h);
        if (w < a[1]) cross(S0, w, up_l, up_h);
        else if (w > a[1]) cross(S1, w, up_l, up_h);
      }
    }
    __m128 bl = _mm_min_ps(lo_l, up_l), bh = _mm_max_ps(lo_h, up_h);
    for (int j = 0; j < 3; ++j)
      if (slab[j] == i || (on[j] && slab[j] == i + 1)) bl = _mm_min_ps(bl, P[j]), bh = _mm_max_ps(bh, P[j]);
    lo_l = up_l, lo_h = up_h;
    // Cut to the clamp box; a part left empty (lo > hi on some axis) grows nothing.
    bl = _mm_max_ps(bl, clo), bh = _mm_min_ps(bh, chi);
    if ((_mm_movemask_ps(_mm_cmple_ps(bl, bh)) & 7) != 7) continue;
    out[i] = to_aabb(_mm_min_ps(bl, load_vec3(out[i].lo)), _mm_max_ps(bh, load_vec3(out[i].hi)));
  }
}

}  // namespace

void chop_triangle_bounds(const Vec3 v[3], int axis, const float* pl, int n, const AABB& clamp, AABB* out) {
  n = std::clamp(n, 1, kMaxChopSlabs);
  if (axis == 0) chop_axis<0>(v, pl, n, clamp, out);
  else if (axis == 1) chop_axis<1>(v, pl, n, clamp, out);
  else chop_axis<2>(v, pl, n, clamp, out);
}

}  // namespace tb
