// Geometry the structure tests check against, written independently of the structures' own code.
#pragma once
#include <algorithm>
#include <cmath>

#include "structures/vec3.h"

namespace tb::test {

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
