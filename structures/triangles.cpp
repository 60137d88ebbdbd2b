#include "structures/triangles.h"

#include "structures/scene.h"

namespace tb {

std::string_view kernel_name(TriKernel k) {
  switch (k) {
    case TriKernel::watertight: return "watertight";
    case TriKernel::moller: return "moller";
    case TriKernel::plane: return "plane";
    case TriKernel::plane_rcp: return "plane_rcp";
  }
  return "?";
}

TriKernel parse_kernel(std::string_view name) {
  for (TriKernel k : kAllTriKernels)
    if (kernel_name(k) == name) return k;
  throw InputError("unknown kernel '" + std::string(name) + "' (expected watertight, moller, plane or plane_rcp)");
}

PlaneTri make_plane_tri(const TriVerts& t) {
  const Vec3 e1 = t.v1 - t.v0, e2 = t.v2 - t.v0;
  const Vec3 n = cross(e1, e2);
  const float n2 = dot(n, n);
  PlaneTri p{};
  p.n = n;
  p.nd = dot(n, t.v0);
  if (n2 == 0.f) {  // degenerate: an empty plane that no ray can satisfy (dn == 0)
    p.n = {0, 0, 0};
    p.nd = 0;
    return p;
  }
  // u-plane: zero on edge v0-v2, one at v1; v-plane: zero on edge v0-v1, one at v2.
  p.u = cross(e2, n) / n2;
  p.ud = -dot(p.u, t.v0);
  p.v = cross(n, e1) / n2;
  p.vd = -dot(p.v, t.v0);
  return p;
}

}  // namespace tb
