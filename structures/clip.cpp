#include "structures/clip.h"

#include <algorithm>
#include <bit>
#include <limits>
#include <cmath>
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

}  // namespace tb
