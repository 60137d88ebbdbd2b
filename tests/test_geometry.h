// Geometry the structure tests check against, written independently of the structures' own code,
// and the random scenes they build over.
#pragma once
#include <algorithm>
#include <cmath>
#include <random>

#include "structures/scene.h"
#include "structures/vec3.h"

namespace tb::test {

// Where random_triangles puts its triangles: centres uniform in [-spread, spread]^3 plus offset,
// each corner within +-size of its centre per axis. With huge_every > 0, every huge_every-th
// triangle (from the first) is huge instead: its corners anywhere in [-huge_spread, huge_spread]^3
// plus offset, so that it crosses many cells of a structure.
struct RandomTriangles {
  float spread = 10.f;
  float size = 0.5f;
  Vec3 offset = {0, 0, 0};
  uint32_t huge_every = 0;
  float huge_spread = 8.f;
};

// n separate triangles (no shared vertices, ids in creation order), the same for a seed.
inline Scene random_triangles(uint32_t n, uint32_t seed, const RandomTriangles& shape = {}) {
  Scene s;
  s.name = "random";
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(-shape.spread, shape.spread), E(-shape.size, shape.size),
      B(-shape.huge_spread, shape.huge_spread);
  for (uint32_t i = 0; i < n; ++i) {
    const Vec3 c = Vec3{U(rng), U(rng), U(rng)} + shape.offset;
    const bool huge = shape.huge_every && i % shape.huge_every == 0;
    for (int k = 0; k < 3; ++k)
      s.positions.push_back(huge ? Vec3{B(rng), B(rng), B(rng)} + shape.offset : c + Vec3{E(rng), E(rng), E(rng)});
    s.triangles.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  s.ensure_views();
  return s;
}

// A ray that tests a conservative node test near box c (of size ~scale): the origin near the box,
// on one of its planes, inside it or far away; the direction at its inside, a face, edge or corner
// (grazing) or random, with components +-0, denormal (0 under DAZ) and 1e-30; tmin 0 or small,
// tfar infinite or short. CWBVH.FusedNodeTestIsConservative and MBVH.FusedNodeTestIsConservative.
struct HammerRay {
  Vec3 org, dir;
  float tmin, tfar;
};
inline HammerRay hammer_ray(std::mt19937& rng, const AABB& c, float scale) {
  std::uniform_real_distribution<float> U(-1.f, 1.f), U01(0.f, 1.f);
  auto inside = [&](const AABB& b) {
    return Vec3{b.lo.x + (b.hi.x - b.lo.x) * U01(rng), b.lo.y + (b.hi.y - b.lo.y) * U01(rng),
                b.lo.z + (b.hi.z - b.lo.z) * U01(rng)};
  };
  auto on_boundary = [&](const AABB& b) {  // a face, edge or corner
    Vec3 q = inside(b);
    for (int a = 0; a < 3; ++a)
      if (rng() % 2) q[a] = rng() % 2 ? b.lo[a] : b.hi[a];
    return q;
  };
  Vec3 o;
  switch (rng() % 4) {
    case 0: o = c.lo + Vec3{U(rng), U(rng), U(rng)} * (3 * scale); break;
    case 1: o = on_boundary(c) + Vec3{U(rng), U(rng), U(rng)} * scale; break;
    case 2: o = inside(c); break;
    default: o = c.lo + Vec3{U(rng), U(rng), U(rng)} * (1e3f * scale); break;
  }
  if (rng() % 3 == 0) {  // the origin on one of the box's planes
    const int a = int(rng() % 3);
    o[a] = rng() % 2 ? c.lo[a] : c.hi[a];
  }
  Vec3 d;
  switch (rng() % 3) {
    case 0: d = inside(c) - o; break;
    case 1: d = on_boundary(c) - o; break;
    default: d = {U(rng), U(rng), U(rng)}; break;
  }
  for (int a = 0; a < 3; ++a) {
    const uint32_t m = rng() % 16;
    if (m == 0) d[a] = 0.f;
    else if (m == 1) d[a] = -0.f;
    else if (m == 2) d[a] = 1e-40f;  // denormal: 0 under DAZ
    else if (m == 3) d[a] = std::copysign(1e-30f, U(rng));
  }
  if (d.x == 0 && d.y == 0 && d.z == 0) d.z = 1;
  const float tmin = rng() % 4 == 0 ? 1e-3f * U01(rng) : 0.f;
  const float tfar = rng() % 3 == 0 ? 2.f * U01(rng) : INFINITY;
  return {o, d, tmin, tfar};
}

// The exact parameter interval [t0, t1] of the ray o + t d, tmin <= t <= tfar, inside box b, in
// long double (a float's product and quotient are within its 64-bit mantissa's reach): what a
// conservative node test must never cull. Under DAZ (every tracing thread) |d| < 2^-126 reads as 0:
// the ray is parallel to that slab and inside it exactly when lo <= o <= hi.
inline bool exact_slab_interval(const AABB& b, Vec3 o, Vec3 d, float tmin, float tfar, long double& t0,
                                long double& t1) {
  t0 = tmin, t1 = tfar;
  for (int a = 0; a < 3; ++a) {
    if (std::fabs(d[a]) < 0x1p-126f) {
      if (o[a] < b.lo[a] || o[a] > b.hi[a]) return false;
      continue;
    }
    long double n = ((long double)b.lo[a] - o[a]) / d[a], f = ((long double)b.hi[a] - o[a]) / d[a];
    if (n > f) std::swap(n, f);
    t0 = std::max(t0, n), t1 = std::min(t1, f);
  }
  return t0 <= t1;
}

// Independent closed triangle / closed box overlap: the separating axis theorem (Akenine-Moller
// 2001) in double — the box's three axes, the triangle normal, and the nine edge x axis
// crosses. Touching counts as overlap (strict separation only).
inline bool sat_overlap(Vec3 a, Vec3 b, Vec3 c, const AABB& box) {
  const double v[3][3] = {{a.x, a.y, a.z}, {b.x, b.y, b.z}, {c.x, c.y, c.z}};
  const double lo[3] = {box.lo.x, box.lo.y, box.lo.z}, hi[3] = {box.hi.x, box.hi.y, box.hi.z};
  for (int k = 0; k < 3; ++k) {
    const double mn = std::min({v[0][k], v[1][k], v[2][k]}), mx = std::max({v[0][k], v[1][k], v[2][k]});
    if (mn > hi[k] || mx < lo[k]) return false;
  }
  auto separated = [&](const double L[3]) {
    if (L[0] == 0 && L[1] == 0 && L[2] == 0) return false;
    double tmin = INFINITY, tmax = -INFINITY, bmin = INFINITY, bmax = -INFINITY;
    for (int i = 0; i < 3; ++i) {
      const double p = v[i][0] * L[0] + v[i][1] * L[1] + v[i][2] * L[2];
      tmin = std::min(tmin, p), tmax = std::max(tmax, p);
    }
    for (int cr = 0; cr < 8; ++cr) {
      const double p = (cr & 1 ? hi[0] : lo[0]) * L[0] + (cr & 2 ? hi[1] : lo[1]) * L[1] + (cr & 4 ? hi[2] : lo[2]) * L[2];
      bmin = std::min(bmin, p), bmax = std::max(bmax, p);
    }
    return tmin > bmax || tmax < bmin;
  };
  double e[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) e[i][k] = v[(i + 1) % 3][k] - v[i][k];
  const double n[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1], e[0][2] * e[1][0] - e[0][0] * e[1][2],
                       e[0][0] * e[1][1] - e[0][1] * e[1][0]};
  if (separated(n)) return false;
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      double u[3] = {0, 0, 0};
      u[k] = 1;
      const double L[3] = {e[i][1] * u[2] - e[i][2] * u[1], e[i][2] * u[0] - e[i][0] * u[2],
                           e[i][0] * u[1] - e[i][1] * u[0]};
      if (separated(L)) return false;
    }
  return true;
}

}  // namespace tb::test
