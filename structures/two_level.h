// Two-level BVH: a top-level BVH over instances of objects, each object a mesh in its own space
// with its own BVH (thesis §3.2, Alg. 3.1 and Fig. 14: "a top-level BVH is constructed over
// per-object BVHs, which are either static, rebuilt or refitted"; Stanford CS348K lecture 18,
// "Two-level BVHs": per-object BVHs built once, only the top level rebuilt as objects move).
//
// The per-object BVHs and the top level come from the project's one binary builder
// (structures/bvh.h): an object's BVH is BVH::build over its mesh (spatial splits when
// BVHBuildParams::spatial, structures/bvh_spatial.h), the top level BVH::build over one PrimRef
// per instance (its world box, id = instance index), so top leaves index instances. An instance
// is an object and an affine transform; rays descend into it transformed to object space
// (traversal/two_level.h). The thesis' Table 1 times the per-frame work of a group of four such
// objects: rebuilding or refitting their BVHs, then the top level (harness/table_build.cpp).
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "structures/bvh.h"
#include "structures/scene.h"
#include "structures/vec3.h"

namespace tb {

// x' = L x + t, row-major 3x3 L.
struct Affine {
  std::array<float, 9> l{1, 0, 0, 0, 1, 0, 0, 0, 1};
  Vec3 t{0, 0, 0};

  Vec3 point(Vec3 p) const { return vector(p) + t; }
  Vec3 vector(Vec3 v) const {
    return {l[0] * v.x + l[1] * v.y + l[2] * v.z, l[3] * v.x + l[4] * v.y + l[5] * v.z,
            l[6] * v.x + l[7] * v.y + l[8] * v.z};
  }
  // Computed in double, rounded once per entry. Throws InputError for a singular L.
  Affine inverse() const;
  // The world box of a box: the 8 corners transformed, each bound rounded outward by a relative
  // 2^-20 so that float rounding of the transform never leaves geometry outside its box.
  AABB box(const AABB& b) const;

  static Affine translate(Vec3 d);
  // Rotation by `deg` about the y axis (up in every scene), then uniform scale `s`, then `d`.
  static Affine rotate_y_scale_translate(float deg, float s, Vec3 d);
};

struct Instance {
  uint32_t object = 0;
  Affine to_world, to_object;  // to_object = to_world.inverse()
  AABB world_box;              // of the object's current BVH root, transformed
};

class TwoLevelBVH {
 public:
  // An object in its own space; returns its index. Its BVH is made by build_objects.
  uint32_t add_object(Scene mesh);
  // An instance of `object` placed by `to_world`; returns its index (the top level's prim id).
  uint32_t add_instance(uint32_t object, const Affine& to_world);
  // Moves an instance (rigid motion: its object's BVH stays; refit_top or build_top follows).
  void set_transform(uint32_t instance, const Affine& to_world);

  // Per-frame steps (Alg. 3.1). build_objects rebuilds every object's BVH with `params`
  // (dynamic objects; the first build of static ones), refit_objects refits them to moved
  // vertices (deforming objects), keeping their topology. Objects are shared out over `threads`
  // workers; a worker with spare threads passes them to its builds (params.threads).
  void build_objects(const BVHBuildParams& params, int threads = 1);
  void refit_objects(int threads = 1);
  // The top level over the instances' current world boxes: a new binned SAH tree, or the old
  // topology refitted.
  void build_top(const BVHBuildParams& params = {});
  void refit_top();

  const std::vector<Scene>& objects() const { return objects_; }
  Scene& object_mesh(uint32_t object) { return objects_[object]; }  // e.g. to deform it
  const std::vector<BVH>& object_bvhs() const { return bvhs_; }
  const std::vector<Instance>& instances() const { return instances_; }
  const BVH& top() const { return top_; }
  size_t num_triangles() const;  // over instances (an object instanced twice counts twice)
  size_t bytes() const;          // every BVH's nodes and indices
  // Instance i's triangles are global prims prim_offset(i) .. + its object's triangle count.
  uint32_t prim_offset(uint32_t instance) const { return offsets_[instance]; }
  // The world-space scene: every instance's triangles transformed, in prim_offset order, so
  // global prim ids index it (the reference for the two-level traversal's tests).
  Scene flatten(const std::string& name = "two_level") const;

 private:
  void update_world_box(Instance& in) const;
  std::vector<Scene> objects_;
  std::vector<BVH> bvhs_;
  std::vector<Instance> instances_;
  std::vector<uint32_t> offsets_;
  BVH top_;
};

}  // namespace tb
