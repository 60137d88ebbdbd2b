// Triangle storage layouts: the triangles of a scene in the order an acceleration structure
// stores them, in the form each ray/triangle kernel reads (vertices, or the precomputed planes of
// thesis Appendix C), and the names of those kernels. Layouts, not kernels: the kernels that read
// them live in traversal/kernels.h (one definition each), and the structures' builders need only
// this header.
#pragma once
#include <cstdint>
#include <string_view>
#include <vector>

#include "structures/aligned.h"
#include "structures/vec3.h"

namespace tb {

enum class TriKernel : uint8_t { watertight, moller, plane, plane_rcp };
inline constexpr TriKernel kAllTriKernels[] = {TriKernel::watertight, TriKernel::moller, TriKernel::plane,
                                               TriKernel::plane_rcp};
std::string_view kernel_name(TriKernel k);
TriKernel parse_kernel(std::string_view name);  // throws InputError on unknown names
// The plane kernels read PlaneTri records, the others the vertices.
constexpr bool uses_planes(TriKernel k) { return k == TriKernel::plane || k == TriKernel::plane_rcp; }

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
  aligned_vector<TriVerts> verts;   // always present
  aligned_vector<PlaneTri> planes;  // only for the plane kernels
  std::vector<uint32_t> prim_id;    // stored position -> scene triangle index
  size_t size() const { return verts.size(); }
  // `order[i]` = scene triangle stored at position i.
  template <class SceneT>
  void build(const SceneT& scene, const std::vector<uint32_t>& order, TriKernel k);
  const void* data_at(uint32_t i, TriKernel k) const {
    return uses_planes(k) ? static_cast<const void*>(&planes[i]) : static_cast<const void*>(&verts[i]);
  }
  static constexpr uint32_t bytes(TriKernel k) { return uses_planes(k) ? sizeof(PlaneTri) : sizeof(TriVerts); }
};
PlaneTri make_plane_tri(const TriVerts& t);

template <class SceneT>
void TriangleSet::build(const SceneT& scene, const std::vector<uint32_t>& order, TriKernel k) {
  reserve_on_huge_pages(verts, order.size());  // the leaves' reads: structures/aligned.h
  verts.resize(order.size());
  prim_id = order;
  for (size_t i = 0; i < order.size(); ++i)
    verts[i] = {scene.vertex(order[i], 0), scene.vertex(order[i], 1), scene.vertex(order[i], 2)};
  planes.clear();
  if (uses_planes(k)) {
    reserve_on_huge_pages(planes, verts.size());
    planes.resize(verts.size());
    for (size_t i = 0; i < verts.size(); ++i) planes[i] = make_plane_tri(verts[i]);
  }
}

}  // namespace tb
