#include "structures/two_level.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <thread>

namespace tb {

Affine Affine::inverse() const {
  const double a = l[0], b = l[1], c = l[2], d = l[3], e = l[4], f = l[5], g = l[6], h = l[7], i = l[8];
  const double det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g);
  if (!(std::fabs(det) > 1e-30) || !std::isfinite(det)) throw InputError("two-level BVH: singular instance transform");
  const double inv[9] = {(e * i - f * h) / det, (c * h - b * i) / det, (b * f - c * e) / det,
                         (f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det,
                         (d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det};
  Affine r;
  for (int k = 0; k < 9; ++k) r.l[size_t(k)] = float(inv[k]);
  // t' = -L^-1 t, in double.
  const double tx = t.x, ty = t.y, tz = t.z;
  r.t = {float(-(inv[0] * tx + inv[1] * ty + inv[2] * tz)), float(-(inv[3] * tx + inv[4] * ty + inv[5] * tz)),
         float(-(inv[6] * tx + inv[7] * ty + inv[8] * tz))};
  return r;
}

AABB Affine::box(const AABB& b) const {
  AABB out;
  if (b.empty()) return out;
  for (int k = 0; k < 8; ++k)
    out.grow(point({k & 1 ? b.hi.x : b.lo.x, k & 2 ? b.hi.y : b.lo.y, k & 4 ? b.hi.z : b.lo.z}));
  // Outward by 2^-20 of each bound's magnitude and of the extent: the corners above and the ray
  // transform of traversal/two_level.h round, and a ray that hits in object space must enter the
  // world box. 2^-20 is ~8 float ulps, more than the few roundings of either.
  const Vec3 e = out.extent();
  auto pad = [](float lo, float hi, float ext) { return std::ldexp(std::max({std::fabs(lo), std::fabs(hi), ext}), -20); };
  const Vec3 p{pad(out.lo.x, out.hi.x, e.x), pad(out.lo.y, out.hi.y, e.y), pad(out.lo.z, out.hi.z, e.z)};
  out.lo = out.lo - p;
  out.hi = out.hi + p;
  return out;
}

Affine Affine::translate(Vec3 d) {
  Affine a;
  a.t = d;
  return a;
}

Affine Affine::rotate_y_scale_translate(float deg, float s, Vec3 d) {
  const double r = double(deg) * 3.14159265358979323846 / 180.0;
  const float c = float(std::cos(r) * s), sn = float(std::sin(r) * s);
  Affine a;
  a.l = {c, 0, sn, 0, s, 0, -sn, 0, c};
  a.t = d;
  return a;
}

uint32_t TwoLevelBVH::add_object(Scene mesh) {
  mesh.validate();
  objects_.push_back(std::move(mesh));
  bvhs_.emplace_back();
  return uint32_t(objects_.size() - 1);
}

uint32_t TwoLevelBVH::add_instance(uint32_t object, const Affine& to_world) {
  if (object >= objects_.size())
    throw InputError("two-level BVH: instance of object " + std::to_string(object) + ", but there are " +
                     std::to_string(objects_.size()) + " objects");
  const uint32_t off = offsets_.empty() ? 0 : offsets_.back() + uint32_t(objects_[instances_.back().object].num_triangles());
  Instance in;
  in.object = object;
  in.to_world = to_world;
  in.to_object = to_world.inverse();
  instances_.push_back(in);
  offsets_.push_back(off);
  return uint32_t(instances_.size() - 1);
}

void TwoLevelBVH::set_transform(uint32_t instance, const Affine& to_world) {
  Instance& in = instances_.at(instance);
  in.to_world = to_world;
  in.to_object = to_world.inverse();
}

// Objects shared out over min(threads, objects) workers, round robin; each build gets the
// threads left over per worker (binned SAH forks its top levels; the spatial builder runs on one).
template <class F>
static void for_objects(size_t n, int threads, F&& f) {
  const int workers = int(std::min<size_t>(size_t(std::max(1, threads)), std::max<size_t>(n, 1)));
  const int per = std::max(1, threads / workers);
  if (workers <= 1) {
    for (size_t i = 0; i < n; ++i) f(i, per);
    return;
  }
  std::vector<std::thread> pool;
  for (int w = 1; w < workers; ++w)
    pool.emplace_back([&, w] {
      for (size_t i = size_t(w); i < n; i += size_t(workers)) f(i, per);
    });
  for (size_t i = 0; i < n; i += size_t(workers)) f(i, per);
  for (auto& t : pool) t.join();
}

void TwoLevelBVH::build_objects(const BVHBuildParams& params, int threads) {
  for_objects(objects_.size(), threads, [&](size_t i, int per) {
    BVHBuildParams p = params;
    p.threads = per;
    bvhs_[i] = BVH::build(objects_[i], p);
  });
}

void TwoLevelBVH::refit_objects(int threads) {
  for_objects(objects_.size(), threads, [&](size_t i, int per) { bvhs_[i].refit(objects_[i], per); });
}

void TwoLevelBVH::update_world_box(Instance& in) const {
  const BVH& b = bvhs_[in.object];
  if (b.nodes.empty()) throw InputError("two-level BVH: build_objects must run before the top level");
  in.world_box = in.to_world.box(AABB{b.nodes[0].lo, b.nodes[0].hi});
}

void TwoLevelBVH::build_top(const BVHBuildParams& params) {
  if (instances_.empty()) throw InputError("two-level BVH: no instances");
  std::vector<PrimRef> refs;
  refs.reserve(instances_.size());
  for (uint32_t i = 0; i < instances_.size(); ++i) {
    update_world_box(instances_[i]);
    refs.emplace_back(instances_[i].world_box, i);
  }
  BVHBuildParams p = params;
  p.spatial = false;  // an instance cannot be clipped
  p.max_leaf = 1;     // a top leaf is one instance: its ray transform is done once per visit
  p.threads = 1;
  top_ = BVH::build(std::span<PrimRef>(refs), p);
}

void TwoLevelBVH::refit_top() {
  if (top_.nodes.empty()) throw InputError("two-level BVH: refit_top before build_top");
  for (Instance& in : instances_) update_world_box(in);
  top_.refit_boxes([&](uint32_t id) { return instances_[id].world_box; });
}

size_t TwoLevelBVH::num_triangles() const {
  size_t n = 0;
  for (const Instance& in : instances_) n += objects_[in.object].num_triangles();
  return n;
}

size_t TwoLevelBVH::bytes() const {
  size_t n = top_.stats.bytes + instances_.size() * sizeof(Instance);
  for (const BVH& b : bvhs_) n += b.stats.bytes;
  return n;
}

Scene TwoLevelBVH::flatten(const std::string& name) const {
  Scene s;
  s.name = name;
  for (const Instance& in : instances_) {
    const Scene& o = objects_[in.object];
    const uint32_t base = uint32_t(s.positions.size());
    for (const Vec3& p : o.positions) s.positions.push_back(in.to_world.point(p));
    for (const auto& t : o.triangles) s.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  s.ensure_views();
  return s;
}

}  // namespace tb
