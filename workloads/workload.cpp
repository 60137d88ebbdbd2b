#include "workloads/workload.h"

#include <cmath>
#include <cstdio>
#include <numbers>

#include "workloads/camera.h"
#include "workloads/hard_cases.h"

namespace tb {

std::string WorkloadSpec::name() const {
  if (kind == "divergence" && tile != 16) return kind + ":" + std::to_string(param) + "/" + std::to_string(tile);
  if (kind == "bounce" && survival < 1.0) {
    char p[32];
    std::snprintf(p, sizeof p, "%g", survival);
    return kind + ":" + std::to_string(param) + "/" + p;
  }
  if (kind == "divergence" || kind == "bounce") return kind + ":" + std::to_string(param);
  return kind;
}

std::vector<std::string> workload_names() {
  std::vector<std::string> names = {"primary", "divergence:D", "rnd", "rnd2", "bounce:k", "shadow"};
  for (const auto& h : hard_case_names()) names.push_back(h);
  return names;
}

WorkloadSpec parse_workload(const std::string& text) {
  WorkloadSpec s;
  const auto colon = text.find(':');
  s.kind = text.substr(0, colon);
  std::string arg = colon == std::string::npos ? "" : text.substr(colon + 1);
  if (s.kind == "divergence" && arg.find('/') != std::string::npos) {  // divergence:D/T
    const std::string t = arg.substr(arg.find('/') + 1);
    arg = arg.substr(0, arg.find('/'));
    if (t != "1" && t != "2" && t != "4" && t != "8" && t != "16")
      throw InputError("workload '" + text + "': the tile of divergence:D/T must be 1, 2, 4, 8 or 16 (it divides the 16x16 packet)");
    s.tile = uint32_t(std::stoul(t));
  }
  if (s.kind == "bounce" && arg.find('/') != std::string::npos) {  // bounce:k/p
    const std::string p = arg.substr(arg.find('/') + 1);
    arg = arg.substr(0, arg.find('/'));
    char* end = nullptr;
    const double v = std::strtod(p.c_str(), &end);
    if (p.empty() || *end != '\0' || !(v > 0.0 && v <= 1.0))
      throw InputError("workload '" + text + "': the Russian-roulette survival p of bounce:k/p must be in (0, 1]");
    s.survival = v;
  }
  auto int_arg = [&](int lo, int hi) {
    char* end = nullptr;
    const long v = std::strtol(arg.c_str(), &end, 10);
    if (arg.empty() || *end != '\0' || v < lo || v > hi)
      throw InputError("workload '" + text + "': expected " + s.kind + ":N with N in [" + std::to_string(lo) + ", " +
                       std::to_string(hi) + "]");
    return int(v);
  };
  if (s.kind == "divergence") s.param = int_arg(1, 1024);
  else if (s.kind == "bounce") s.param = int_arg(1, 16);
  else if (s.kind == "hard") {
    for (const auto& h : hard_case_names())
      if (h == text) return s.kind = text, s;
    std::string known;
    for (const auto& h : hard_case_names()) known += " " + h;
    throw InputError("unknown hard-case workload '" + text + "' (known:" + known + ")");
  } else if ((s.kind == "primary" || s.kind == "rnd" || s.kind == "rnd2" || s.kind == "shadow") && arg.empty()) {
  } else {
    throw InputError("unknown workload '" + text + "' (known: primary, divergence:D, rnd, rnd2, bounce:k, shadow, hard:*)");
  }
  return s;
}

namespace {

const CameraView& view_of(const Scene& scene, const WorkloadSpec& spec) {
  if (scene.views.empty()) throw InputError("scene '" + scene.name + "' has no camera view");
  if (spec.view >= scene.views.size())
    throw InputError("view " + std::to_string(spec.view + 1) + " does not exist in scene '" + scene.name + "'");
  return scene.views[spec.view];
}

constexpr double kDeg = std::numbers::pi / 180.0;

// The view with spec.hfov_deg (when set) in place of its vfov, for the spec's aspect ratio.
CameraView camera_view(const Scene& scene, const WorkloadSpec& spec) {
  CameraView v = view_of(scene, spec);
  if (spec.hfov_deg > 0)
    v.vfov_deg = float(2.0 * std::atan(std::tan(0.5 * spec.hfov_deg * kDeg) * spec.height / spec.width) / kDeg);
  return v;
}

}  // namespace

// Orthonormal basis around n (Duff et al. 2017).
void basis(Vec3 n, Vec3& t, Vec3& b) {
  const float s = std::copysign(1.f, n.z);
  const float a = -1.f / (s + n.z), c = n.x * n.y * a;
  t = {1.f + s * n.x * n.x * a, s * c, -s * n.x};
  b = {c, s + n.y * n.y * a, -n.y};
}

// Cosine-weighted direction around n (Malley's method).
Vec3 cosine_hemisphere(Vec3 n, Rng& rng) {
  const float r = std::sqrt(rng.uniform()), phi = 2.f * std::numbers::pi_v<float> * rng.uniform();
  const float x = r * std::cos(phi), y = r * std::sin(phi), z = std::sqrt(std::max(0.f, 1.f - x * x - y * y));
  Vec3 t, b;
  basis(n, t, b);
  return normalize(t * x + b * y + n * z);
}

SurfacePoint surface_point(const Scene& s, uint32_t tri, float u, float v) {
  const Vec3 a = s.vertex(tri, 0), b = s.vertex(tri, 1), c = s.vertex(tri, 2);
  SurfacePoint sp;
  sp.p = a * (1.f - u - v) + b * u + c * v;
  const Vec3 n = cross(b - a, c - a);
  const float len = length(n);
  sp.n = len > 0.f ? n / len : Vec3{0, 1, 0};
  const float size = std::max(std::max(length(b - a), length(c - a)), length(c - b));
  const float mag = std::max(std::max(std::fabs(sp.p.x), std::fabs(sp.p.y)), std::fabs(sp.p.z));
  sp.eps = std::max(1e-4f * size, 4e-6f * mag);
  return sp;
}

namespace {

Vec3 uniform_sphere(Rng& rng) {
  const float z = 1.f - 2.f * rng.uniform(), phi = 2.f * std::numbers::pi_v<float> * rng.uniform();
  const float r = std::sqrt(std::max(0.f, 1.f - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

RayBatch trace_reference(const ClosestHitFn& reference, const RayBatch& batch, std::vector<Hit>& hits) {
  hits.assign(batch.size(), Hit{});
  reference(batch, hits);
  return batch;
}

// Each surviving path keeps the packet of its pixel: `packet_of[i]` is the primary packet.
void regroup(RayBatch& b, const std::vector<uint32_t>& packet_of) {
  b.packet_begin.assign(1, 0);
  for (uint32_t i = 1; i <= packet_of.size(); ++i)
    if (i == packet_of.size() || packet_of[i] != packet_of[i - 1]) b.packet_begin.push_back(i);
  if (packet_of.empty()) b.packet_begin.assign(1, 0);
}

RayBatch random_rays(const Scene& scene, const WorkloadSpec& spec, bool random_origins) {
  RayBatch b;
  const uint32_t n = spec.width * spec.height;
  b.rays.resize(n);
  b.common_origin = !random_origins;
  const CameraView& view = view_of(scene, spec);
  const Vec3 fwd = normalize(view.target - view.eye);
  // Area-weighted triangle sampling for rnd2 (random origins on scene surfaces).
  std::vector<double> cdf;
  if (random_origins) {
    cdf.resize(scene.num_triangles());
    double acc = 0;
    for (uint32_t t = 0; t < scene.num_triangles(); ++t) {
      acc += length(cross(scene.vertex(t, 1) - scene.vertex(t, 0), scene.vertex(t, 2) - scene.vertex(t, 0)));
      cdf[t] = acc;
    }
    if (!(acc > 0)) throw InputError("scene '" + scene.name + "' has no surface area to start rnd2 rays on");
  }
  for (uint32_t i = 0; i < n; ++i) {
    Rng rng(spec.seed, i);
    Ray& r = b.rays[i];
    Vec3 d = uniform_sphere(rng);
    if (random_origins) {
      const double x = double(rng.uniform()) * cdf.back();
      const uint32_t t = uint32_t(std::min<size_t>(std::lower_bound(cdf.begin(), cdf.end(), x) - cdf.begin(),
                                                   cdf.size() - 1));
      float u = rng.uniform(), v = rng.uniform();
      if (u + v > 1.f) u = 1.f - u, v = 1.f - v;
      const SurfacePoint sp = surface_point(scene, t, u, v);
      const Vec3 n = dot(sp.n, d) < 0.f ? -sp.n : sp.n;
      r.org = sp.p + n * sp.eps;
    } else {
      if (dot(d, fwd) < 0.f) d = -d;  // the camera's hemisphere
      r.org = view.eye;
    }
    r.dir = d;
  }
  b.group_uniform(256);
  return b;
}

// k-th diffuse bounce of camera paths (§5.2.3): primary rays, then k cosine-weighted bounces
// traced with the reference; paths that leave the scene stop. With shadow = true, returns rays
// from the primary hit points to a point light instead.
RayBatch path_rays(const Scene& scene, const WorkloadSpec& spec, const ClosestHitFn& reference, int k, bool shadow) {
  RayBatch cur = primary_rays(scene, spec, 1.f);
  std::vector<uint32_t> packet_of(cur.size());
  for (uint32_t p = 0; p < cur.num_packets(); ++p)
    for (uint32_t i = cur.packet_begin[p]; i < cur.packet_begin[p + 1]; ++i) packet_of[i] = p;
  const AABB bounds = scene.bounds();
  const Vec3 light = bounds.centre() + Vec3{0, 0.45f * bounds.extent().y, 0};
  std::vector<Hit> hits;
  for (int depth = 1; depth <= k; ++depth) {
    trace_reference(reference, cur, hits);
    RayBatch next;
    std::vector<uint32_t> next_packet;
    for (uint32_t i = 0; i < cur.size(); ++i) {
      if (!hits[i].hit()) continue;
      const SurfacePoint sp = surface_point(scene, hits[i].prim, hits[i].u, hits[i].v);
      const Vec3 n = dot(sp.n, cur.rays[i].dir) > 0.f ? -sp.n : sp.n;  // face the incoming ray
      Ray r;
      r.org = sp.p + n * sp.eps;
      if (shadow) {
        const Vec3 to = light - r.org;
        const float dist = length(to);
        if (!(dist > 0.f)) continue;
        r.dir = to / dist;
        r.tmax = dist * (1.f - 1e-4f);
      } else {
        Rng rng(spec.seed ^ (uint64_t(depth) << 56), i);
        // Russian roulette (thesis §2.1.6, Alg. 6.1): the path goes on with probability p. The
        // draw comes first and only when p < 1, so bounce:k without roulette keeps its rays.
        if (spec.survival < 1.0 && !(rng.uniform() < spec.survival)) continue;
        r.dir = cosine_hemisphere(n, rng);
      }
      next.rays.push_back(r);
      next.pixel.push_back(cur.pixel[i]);
      next_packet.push_back(packet_of[i]);
    }
    regroup(next, next_packet);
    next.packet_size = cur.packet_size;
    next.depth = depth;
    cur = std::move(next);
    packet_of = std::move(next_packet);
  }
  return cur;
}

}  // namespace

double thesis_hfov_deg() { return 2.0 * std::atan(kThesisWidth * std::tan(0.5 * kThesisRayDeg * kDeg)) / kDeg; }

double centre_pixel_deg(const Scene& scene, const WorkloadSpec& spec) {
  const double focal = 0.5 * spec.height / std::tan(0.5 * double(camera_view(scene, spec).vfov_deg) * kDeg);
  return 2.0 * std::atan(0.5 / focal) / kDeg;  // pixel centres 0.5 px either side of the image centre
}

RayBatch primary_rays(const Scene& scene, const WorkloadSpec& spec, float divergence) {
  const Camera cam(camera_view(scene, spec), spec.width, spec.height);
  RayBatch b;
  b.common_origin = true;
  b.packet_size = 256;
  b.packet_begin.assign(1, 0);
  b.rays.reserve(size_t(spec.width) * spec.height);
  for (uint32_t ty = 0; ty < spec.height; ty += 16)
    for (uint32_t tx = 0; tx < spec.width; tx += 16) {
      for (uint32_t i = 0; i < 256; ++i) {
        uint32_t x, y;
        fig16_pixel(i, x, y);
        // The anchor: the centre of the tile's top-left pixel, whose ray is the same at every D;
        // the tile's other rays move right and down, D pixels apart (§3.4, docs/WORKLOADS.md).
        const float ax = float(tx + x / spec.tile * spec.tile) + 0.5f, ay = float(ty + y / spec.tile * spec.tile) + 0.5f;
        x += tx, y += ty;
        if (x >= spec.width || y >= spec.height) continue;
        Ray r;
        r.org = cam.eye;
        r.dir = cam.direction(ax + divergence * (x + 0.5f - ax), ay + divergence * (y + 0.5f - ay));
        b.rays.push_back(r);
        b.pixel.push_back(y * spec.width + x);
      }
      b.packet_begin.push_back(uint32_t(b.rays.size()));
    }
  return b;
}

bool uses_view(const WorkloadSpec& spec) { return spec.kind != "rnd2" && spec.kind.rfind("hard:", 0) != 0; }
bool from_camera_pixels(const WorkloadSpec& spec) {
  return spec.kind == "primary" || spec.kind == "divergence" || spec.kind == "bounce" || spec.kind == "shadow";
}

RayBatch generate_workload(const Scene& scene, const WorkloadSpec& spec, const ClosestHitFn& reference) {
  RayBatch b;
  if (spec.kind == "primary") b = primary_rays(scene, spec, 1.f);
  else if (spec.kind == "divergence") b = primary_rays(scene, spec, float(spec.param));
  else if (spec.kind == "rnd") b = random_rays(scene, spec, false);
  else if (spec.kind == "rnd2") b = random_rays(scene, spec, true);
  else if (spec.kind == "bounce") b = path_rays(scene, spec, reference, spec.param, false);
  else if (spec.kind == "shadow") {
    b = path_rays(scene, spec, reference, 1, true);
    b.depth = 1;
  } else if (spec.kind.rfind("hard:", 0) == 0) b = hard_case_rays(scene, spec);
  else throw InputError("unknown workload kind '" + spec.kind + "'");
  b.workload = spec.name();
  // A generated component can be a denormal (a hit point within 1e-38 of a coordinate plane):
  // read as 0, as every tracing thread would (DAZ), rather than refused by validate below.
  for (Ray& r : b.rays)
    for (float* x : {&r.org.x, &r.org.y, &r.org.z, &r.dir.x, &r.dir.y, &r.dir.z, &r.tmin, &r.tmax})
      if (is_denormal(*x)) *x = 0.f;
  try {
    b.validate();
  } catch (const InputError& e) {  // a generated ray out of range: say which scene and workload made it
    throw InputError("workload '" + spec.name() + "' of scene '" + scene.name + "': " + e.what() +
                     " (check the scene's extent and its views)");
  }
  return b;
}

}  // namespace tb
