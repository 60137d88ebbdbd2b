#include "workloads/hard_cases.h"

#include <cmath>
#include <numbers>

#include "workloads/workload.h"

namespace tb {

std::vector<std::string> hard_case_names() {
  return {"hard:inside", "hard:vertices", "hard:edges", "hard:axis", "hard:grazing", "hard:surface", "hard:tmin_tmax"};
}

bool hard_case_must_hit(const std::string& name) {
  return name == "hard:inside" || name == "hard:vertices" || name == "hard:edges" || name == "hard:axis";
}

Vec3 interior_point(const Scene& scene) { return scene.bounds().centre(); }

namespace {

Vec3 random_dir(Rng& rng) {
  const float z = 1.f - 2.f * rng.uniform(), phi = 2.f * std::numbers::pi_v<float> * rng.uniform();
  const float r = std::sqrt(std::max(0.f, 1.f - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

void push_towards(RayBatch& b, Vec3 org, Vec3 target) {
  const Vec3 d = target - org;
  if (!(length(d) > 0.f)) return;
  b.rays.push_back({org, 0.f, normalize(d), INFINITY});
}

// Picks up to n indices of [0, count) spread evenly (deterministic).
template <class F>
void spread(size_t count, size_t n, F&& f) {
  if (count == 0) return;
  const double step = std::max(1.0, double(count) / double(n));
  for (double x = 0; x < double(count) && size_t(x) < count; x += step) f(size_t(x));
}

}  // namespace

RayBatch hard_case_rays(const Scene& scene, const WorkloadSpec& spec) {
  RayBatch b;
  const size_t n = size_t(spec.width) * spec.height;
  const Vec3 c = interior_point(scene);
  const std::string& k = spec.kind;
  if (k == "hard:inside") {
    // Random rays from points jittered by 1e-3 of the extent around the interior point.
    const Vec3 e = scene.bounds().extent() * 1e-3f;
    for (size_t i = 0; i < n; ++i) {
      Rng rng(spec.seed, i);
      const Vec3 o = c + Vec3{(rng.uniform() - .5f) * e.x, (rng.uniform() - .5f) * e.y, (rng.uniform() - .5f) * e.z};
      b.rays.push_back({o, 0.f, random_dir(rng), INFINITY});
    }
  } else if (k == "hard:vertices") {
    spread(scene.positions.size(), n, [&](size_t v) { push_towards(b, c, scene.positions[v]); });
  } else if (k == "hard:edges") {
    spread(scene.num_triangles(), n / 3 + 1, [&](size_t t) {
      for (int e = 0; e < 3; ++e) push_towards(b, c, (scene.vertex(t, e) + scene.vertex(t, (e + 1) % 3)) * 0.5f);
    });
  } else if (k == "hard:axis") {
    // Axis-parallel rays through stored vertices and edge midpoints: the origin shares two
    // coordinates with the target, so two direction components are exactly +0 or -0.
    // Targets on the scene's bounding box would put the origin on an outer wall, and targets
    // level with the interior point leave no room to start inside: both are skipped.
    const AABB box = scene.bounds();
    const Vec3 ext = box.extent();
    auto axis_rays = [&](Vec3 target, size_t salt) {
      for (int a = 0; a < 3; ++a) {
        Vec3 o = target;
        o[a] = c[a];
        const float s = target[a] - c[a];
        const int b1 = (a + 1) % 3, b2 = (a + 2) % 3;
        if (std::fabs(s) < 1e-3f * ext[a] || o[b1] == box.lo[b1] || o[b1] == box.hi[b1] || o[b2] == box.lo[b2] ||
            o[b2] == box.hi[b2])
          continue;
        Vec3 d{0, 0, 0};
        d[a] = s > 0 ? 1.f : -1.f;
        // Alternate +0 and -0 in the zero components.
        if ((salt + a) & 1) d[(a + 1) % 3] = -0.f;
        if ((salt + a) & 2) d[(a + 2) % 3] = -0.f;
        b.rays.push_back({o, 0.f, d, INFINITY});
      }
    };
    spread(scene.positions.size(), n / 6 + 1, [&](size_t v) { axis_rays(scene.positions[v], v); });
    spread(scene.num_triangles(), n / 6 + 1, [&](size_t t) {
      axis_rays((scene.vertex(t, 0) + scene.vertex(t, 1)) * 0.5f, t);
    });
  } else if (k == "hard:grazing" || k == "hard:surface") {
    // grazing: rays nearly parallel to a triangle, passing just above or below a point of it
    // (normal component 1e-2 .. 1e-6). surface: origins exactly on a triangle, any direction.
    spread(scene.num_triangles(), n, [&](size_t t) {
      Rng rng(spec.seed, t);
      const Vec3 a = scene.vertex(uint32_t(t), 0), e1 = scene.vertex(uint32_t(t), 1) - a,
                 e2 = scene.vertex(uint32_t(t), 2) - a;
      const Vec3 nrm = cross(e1, e2);
      if (!(length(nrm) > 0.f)) return;
      float u = rng.uniform(), v = rng.uniform();
      if (u + v > 1.f) u = 1.f - u, v = 1.f - v;
      const Vec3 p = a + e1 * u + e2 * v;
      if (k == "hard:surface") {
        b.rays.push_back({p, 0.f, random_dir(rng), INFINITY});
        return;
      }
      const Vec3 nn = normalize(nrm), tangent = normalize(e1);
      const float tilt = std::pow(10.f, -2.f - 4.f * rng.uniform()) * (rng.uniform() < .5f ? -1.f : 1.f);
      const Vec3 d = normalize(tangent + nn * tilt);
      const float back = length(e1) + length(e2);
      b.rays.push_back({p - d * back, 0.f, d, INFINITY});
    });
  } else if (k == "hard:tmin_tmax") {
    // Empty intervals [t, t): nothing may be reported, whatever lies at distance t.
    for (size_t i = 0; i < n; ++i) {
      Rng rng(spec.seed, i);
      const float t = scene.bounds().extent().x * rng.uniform();
      b.rays.push_back({c, t, random_dir(rng), t});
    }
  } else {
    throw InputError("unknown hard-case workload '" + k + "'");
  }
  b.common_origin = k == "hard:vertices" || k == "hard:edges" || k == "hard:tmin_tmax";
  b.group_uniform(256);
  return b;
}

}  // namespace tb
