// Triangle / axis-aligned box clipping, the one clipper of the project: the kD-tree's perfect
// splits (Wald & Havran 2006 §4.3; Havran's thesis "split clipping") and the RayGrid octree
// (thesis §5.3.2: which leaves reference a triangle, and the clipped boxes its mini-BVHs are
// built over) both call it.
//
// Robustness: Sutherland-Hodgman against the closed box in double, inclusive inside tests (a
// triangle lying in a face, or touching the box only along an edge or at a vertex, overlaps it);
// a vertex on a box plane is kept as it is, not recomputed as an edge crossing, so a triangle that
// touches the box only at a vertex or along an edge clips to exactly that vertex or edge; every
// coordinate that is exactly a float input (a vertex coordinate, a box plane, a coordinate kept by
// an axis-parallel edge) stays exact, every interpolated one is widened by far more than
// its double rounding error and rounded outward to float. The bounds can therefore only grow
// beyond the exact clipped polygon's, never shrink, and never reach beyond the box or the
// triangle's own bounds.
#pragma once
#include "structures/vec3.h"

namespace tb {

// Bounds of triangle (a, b, c) clipped to the closed box `box`, as above; an empty box
// (AABB::empty) when the triangle does not touch the box.
AABB clip_triangle_bounds(Vec3 a, Vec3 b, Vec3 c, const AABB& box);
// Bounds of the parts of triangle v on either side of the plane x[axis] = pos (its vertices on
// each side and the points where its edges cross the plane, rounded outward as above): the
// spatial-split BVH builder's reference split (Stich et al. 2009, structures/bvh_spatial.h).
// A side the triangle does not reach gets an empty box.
void split_triangle_bounds(const Vec3 v[3], int axis, float pos, AABB& left, AABB& right);
// Bounds of the parts of triangle v in consecutive slabs along `axis`, for the spatial-split
// builder's chopped binning (Stich et al. 2009 §4.1): out[i], i = 0..n-1, is grown by the bounds
// of the triangle's part in the closed slab pl[i] <= x[axis] <= pl[i + 1], except that slab 0 reaches
// down to -inf and slab n-1 up to +inf (pl[0] and pl[n] are not read), intersected with `clamp`
// (the box of the reference being chopped, which lies inside [pl[0], pl[n]]). pl ascending,
// 1 <= n <= kMaxChopSlabs. One sweep of the three edges through the planes, O(n + 3) (an exact
// clip per plane would be O(3n)), in float, every edge crossing padded outward by a proven bound
// (clip.cpp), so each out[i] contains the exact part: conservative, never tighter than the truth.
// A slab the triangle misses, or whose part misses `clamp`, leaves out[i] as it was.
constexpr int kMaxChopSlabs = 256;
void chop_triangle_bounds(const Vec3 v[3], int axis, const float* pl, int n, const AABB& clamp, AABB* out);
// Area of the triangle clipped to the closed box, in double (for tests and statistics).
double clipped_triangle_area(Vec3 a, Vec3 b, Vec3 c, const AABB& box);

}  // namespace tb
