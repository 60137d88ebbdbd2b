#include "harness/pathtrace.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <map>
#include <memory>
#include <numbers>

#include "harness/image.h"
#include "harness/records.h"
#include "workloads/camera.h"
#include "workloads/workload.h"

namespace tb {

namespace {

constexpr float kPi = std::numbers::pi_v<float>;
// A path that survives this many segments is cut (Russian roulette with survival <= 0.95 makes it
// a 0.95^256 event: no measurable bias; it only bounds the loop).
constexpr uint32_t kMaxSegments = 256;

float luminance(Vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }
float max_component(Vec3 c) { return std::max(c.x, std::max(c.y, c.z)); }

// A light described relative to the scene's bounds: its centre at lo + f * extent (f in [0, 1]^3
// over the two horizontal axes and the up axis), its sides as fractions of the horizontal
// extents, facing down (against the view's up axis), and its power as a multiple of the default.
struct LightDesc {
  float fx, fy, fz;  // centre: horizontal axis 1, up axis, horizontal axis 2
  float sx, sz;      // side lengths as fractions of the two horizontal extents
  float power;       // relative radiance
};
struct SceneDesc {
  Vec3 albedo, sky;
  std::vector<LightDesc> lights;
};

// Per-scene descriptions (Scene keeps no materials; the OBJ scenes here have no emitters). Sponza
// gets four lights of unequal power along its long axis, so RIS's location-invariant pdf (light
// power) differs from the contribution a surface point sees; they hang in the open atrium, more
// than 1.5 m from every vertex (points next to a light make fireflies: the 1/d^2 of the direct
// light estimate). Every other scene gets the default.
const std::map<std::string, SceneDesc>& descriptions() {
  static const std::map<std::string, SceneDesc> d = {
      {"sponza",
       {{0.62f, 0.58f, 0.52f},
        {0.25f, 0.30f, 0.40f},
        {{0.30f, 0.80f, 0.5f, 0.06f, 0.12f, 1.0f},
         {0.43f, 0.80f, 0.5f, 0.06f, 0.12f, 0.5f},
         {0.57f, 0.80f, 0.5f, 0.06f, 0.12f, 2.0f},
         {0.70f, 0.80f, 0.5f, 0.06f, 0.12f, 0.25f}}}},
      // The closed conference room: two ceiling panels over the table, the second weaker.
      {"conference",
       {{0.65f, 0.63f, 0.60f},
        {0.05f, 0.05f, 0.06f},
        {{0.35f, 0.90f, 0.5f, 0.12f, 0.15f, 3.0f}, {0.65f, 0.90f, 0.5f, 0.12f, 0.15f, 1.5f}}}},
  };
  return d;
}
const SceneDesc kDefault{{0.6f, 0.6f, 0.6f}, {0.2f, 0.25f, 0.3f}, {{0.5f, 0.9f, 0.5f, 0.2f, 0.2f, 1.0f}}};

int up_axis(const Scene& scene) {
  const Vec3 up = scene.views.empty() ? Vec3{0, 1, 0} : scene.views[0].up;
  const Vec3 a{std::fabs(up.x), std::fabs(up.y), std::fabs(up.z)};
  return a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
}

uint64_t fnv(uint64_t h, const void* p, size_t n) {
  const auto* b = static_cast<const unsigned char*>(p);
  for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 0x100000001b3ull;
  return h;
}

uint64_t salt_hash(const std::string& s) { return fnv(0xcbf29ce484222325ull, s.data(), s.size()); }

// floor(log2 v), with floor(log2 0) = -1 (31 - clz(v), clz(0) taken as 32).
int floor_log2(uint32_t v) { return v ? 31 - __builtin_clz(v) : -1; }

// DPT's segment count of sample idx of spp (§6.3.2): N/2 samples get one segment, N/4 two, and
// so on, the last two log2(N) and log2(N) + 1 — the list the thesis gives for spp = 16
// (1 x8, 2 x4, 3 x2, 4, 5). Its CUDA form clz((spp-1)-idx) - clz(spp) + 1 gives that list plus one
// (2 x8, ..., 6), and the printed formula floor(log2(spp - idx)) + 1 a different one (5, 4 x8,
// 3 x4, 2 x2, 1), which keeps too many deep paths and, with the x2 weights, brightens the image
// (we measured it). We follow the list: d_max = floor(log2 spp) - floor(log2(spp - 1 - idx)).
uint32_t dpt_max_depth(uint32_t spp, uint32_t idx) {
  return uint32_t(floor_log2(spp) - floor_log2(spp - 1 - idx));
}

// The per-path state of the wavefront (one lane).
struct Path {
  Ray ray;
  Vec3 thr{1, 1, 1};
  uint32_t pixel = 0, sample = 0;
  uint32_t depth = 0;      // segments shaded so far
  uint32_t max_depth = 0;  // DPT's d_max; 0: Russian roulette decides
  float bsdf_pdf = 0;      // solid-angle pdf of ray.dir at the last vertex (MIS)
  bool active = false, diffuse = false;
  Rng rng{0, 0};
};

class Wavefront {
 public:
  Wavefront(const Scene& scene, const Traverser& tracer, const Lighting& lighting, PtMethod method,
            const PtOptions& opt, PtStats& stats, bool by_depth)
      : scene_(scene), tracer_(tracer), light_(lighting), method_(method), opt_(opt), stats_(stats),
        cam_(scene.views[opt.view], opt.width, opt.height), salt_(salt_hash(opt.salt)),
        accum_(size_t(opt.width) * opt.height * 3, 0.0) {
    if (by_depth) depth_accum_.assign(kPtDepths, std::vector<double>(accum_.size(), 0.0));
    double total = 0;
    for (const AreaLight& l : light_.lights) {
      total += double(luminance(l.radiance)) * l.area;
      cdf_.push_back(total);
    }
    for (double& c : cdf_) c /= total;
  }

  // A new camera path for (pixel, sample): jittered inside the pixel; its generator is keyed by
  // (seed, salt, sample) and the pixel, so any order of work gives the same path.
  void start(Path& p, uint32_t pixel, uint32_t sample) const {
    p = Path{};
    p.pixel = pixel, p.sample = sample;
    p.rng = Rng(opt_.seed ^ (salt_ * 0x9E3779B97F4A7C15ull) ^ (uint64_t(sample) << 40), pixel);
    const float x = float(pixel % opt_.width) + p.rng.uniform(), y = float(pixel / opt_.width) + p.rng.uniform();
    p.ray.org = cam_.eye;
    p.ray.dir = cam_.direction(x, y);
    p.active = true;
    if (method_ == PtMethod::dpt) p.max_depth = dpt_max_depth(opt_.spp, sample);
  }

  // One iteration of every driver: the active lanes' extension rays, grouped in packets by
  // `group_begin` (lane ranges; one packet each), traced, shaded; then their shadow rays.
  void step(std::vector<Path>& lanes, const std::vector<uint32_t>& group_begin) {
    ++stats_.iterations;
    RayBatch ext;
    ext.packet_begin.assign(1, 0);
    std::vector<uint32_t> lane_of;
    for (size_t g = 0; g + 1 < group_begin.size(); ++g) {
      for (uint32_t w = group_begin[g]; w < group_begin[g + 1]; w += kPtWarp) {
        uint32_t active = 0;
        for (uint32_t l = w; l < std::min(w + kPtWarp, group_begin[g + 1]); ++l)
          if (lanes[l].active) {
            ++active;
            ext.rays.push_back(lanes[l].ray);
            lane_of.push_back(l);
          }
        if (active) stats_.warp_slots += kPtWarp, stats_.warp_active += active;
      }
      if (ext.rays.size() > ext.packet_begin.back()) ext.packet_begin.push_back(uint32_t(ext.rays.size()));
    }
    if (ext.rays.empty()) return;
    stats_.ext_rays += ext.size();
    stats_.ext_packets += ext.num_packets();
    std::vector<Hit> hits(ext.size());
    trace(ext, hits, "pathtrace:ext");

    // Shadow rays keep the packet of the extension ray that made them.
    shadow_.rays.clear();
    shadow_.packet_begin.assign(1, 0);
    shadow_contrib_.clear();
    shadow_pixel_.clear();
    shadow_depth_.clear();
    for (uint32_t p = 0; p < ext.num_packets(); ++p) {
      for (uint32_t i = ext.packet_begin[p]; i < ext.packet_begin[p + 1]; ++i) shade(lanes[lane_of[i]], hits[i]);
      if (shadow_.rays.size() > shadow_.packet_begin.back())
        shadow_.packet_begin.push_back(uint32_t(shadow_.rays.size()));
    }
    if (shadow_.rays.empty()) return;
    stats_.shadow_rays += shadow_.size();
    stats_.shadow_packets += shadow_.num_packets();
    std::vector<Hit> occ(shadow_.size());
    trace(shadow_, occ, "pathtrace:shadow");
    for (size_t i = 0; i < occ.size(); ++i)
      if (!occ[i].hit()) add(shadow_pixel_[i], shadow_contrib_[i], shadow_depth_[i]);
  }

  PtImage image(uint32_t spp) const { return to_image(accum_, spp); }
  std::vector<PtImage> depth_images(uint32_t spp) const {
    std::vector<PtImage> out;
    for (const auto& a : depth_accum_) out.push_back(to_image(a, spp));
    return out;
  }

 private:
  void trace(const RayBatch& b, std::span<Hit> hits, const char* kind) {
    if (opt_.traced) {
      opt_.traced->push_back(b);
      opt_.traced->back().workload = kind;
      opt_.traced->back().depth = uint32_t(stats_.iterations - 1);
    }
    const auto t0 = std::chrono::steady_clock::now();
    tracer_.trace(b, PacketRange::all(b), hits);
    stats_.trace_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  PtImage to_image(const std::vector<double>& a, uint32_t spp) const {
    PtImage img{opt_.width, opt_.height, std::vector<float>(a.size())};
    for (size_t i = 0; i < a.size(); ++i) img.rgb[i] = float(a[i] / spp);
    return img;
  }

  // A contribution of path vertex `depth` (by_depth above) to the pixel.
  void add(uint32_t pixel, Vec3 c, uint32_t depth) {
    for (std::vector<double>* a : {&accum_, depth_accum_.empty() ? nullptr : &depth_accum_[std::min(depth, kPtDepths - 1)]})
      if (a) {
        (*a)[size_t(pixel) * 3 + 0] += c.x;
        (*a)[size_t(pixel) * 3 + 1] += c.y;
        (*a)[size_t(pixel) * 3 + 2] += c.z;
      }
  }

  // The nearest light in front of the ray closer than t_max (-1: none); t and cos at the light.
  int light_hit(const Ray& r, float t_max, float& t_out, float& cos_out) const {
    int best = -1;
    for (size_t i = 0; i < light_.lights.size(); ++i) {
      const AreaLight& l = light_.lights[i];
      const float denom = dot(r.dir, l.n);
      if (!(denom < 0.f)) continue;  // one-sided: seen from behind, a light is not there
      const float t = dot(l.corner - r.org, l.n) / denom;
      if (!(t > r.tmin && t < t_max)) continue;
      const Vec3 q = r.org + r.dir * t - l.corner;
      const float a = dot(q, l.e1) / dot(l.e1, l.e1), b = dot(q, l.e2) / dot(l.e2, l.e2);
      if (a < 0.f || a > 1.f || b < 0.f || b > 1.f) continue;
      best = int(i), t_max = t, t_out = t, cos_out = -denom;
    }
    return best;
  }

  // The probability of picking light i by power (the location-invariant pdf of §6.4.2).
  double light_prob(size_t i) const { return cdf_[i] - (i ? cdf_[i - 1] : 0.0); }
  size_t pick_light(float u) const {
    return std::min<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), double(u)) - cdf_.begin(), cdf_.size() - 1);
  }

  // One candidate point on a light as seen from (org, n): unshadowed contribution f (RGB, per unit
  // area of the light), its area pdf, and the shadow ray's geometry.
  struct Candidate {
    Vec3 f, wi;
    float dist = 0, cos_s = 0, cos_l = 0;
    double pdf_area = 0;
    bool valid = false;
  };
  Candidate candidate(Vec3 org, Vec3 n, Rng& rng) const {
    Candidate c;
    const size_t li = pick_light(rng.uniform());
    const AreaLight& l = light_.lights[li];
    const Vec3 x = l.corner + l.e1 * rng.uniform() + l.e2 * rng.uniform();
    const Vec3 d = x - org;
    const float d2 = dot(d, d);
    if (!(d2 > 0.f)) return c;
    c.dist = std::sqrt(d2);
    c.wi = d / c.dist;
    c.cos_s = dot(n, c.wi), c.cos_l = -dot(l.n, c.wi);
    c.pdf_area = light_prob(li) / l.area;
    if (!(c.cos_s > 0.f && c.cos_l > 0.f)) return c;
    c.f = light_.albedo * (1.f / kPi) * l.radiance * (c.cos_s * c.cos_l / d2);
    c.valid = true;
    return c;
  }
  // MIS balance weight of the light strategy at a candidate (solid-angle pdfs, §6.4.3).
  static float light_weight(const Candidate& c) {
    const double pl = c.pdf_area * double(c.dist) * c.dist / c.cos_l, pb = c.cos_s / kPi;
    return float(pl / (pl + pb));
  }

  // The explicit light sample at a diffuse vertex (Alg. 6.1 sampleDirect; RIS: Alg. 6.3).
  void sample_direct(const Path& p, Vec3 org, Vec3 n, Rng& rng) {
    if (light_.lights.empty()) return;
    Candidate y;
    Vec3 estimate;
    if (method_ == PtMethod::ris || method_ == PtMethod::ris_mis) {
      // Resampled importance sampling (Talbot et al. 2005): X candidates from the power pdf p,
      // one chosen with probability proportional to w = p_hat / p, p_hat the luminance of the
      // unshadowed contribution; estimate f(y) / p_hat(y) * (sum w) / X.
      const uint32_t X = opt_.ris_per_light * uint32_t(light_.lights.size());
      std::vector<Candidate> cand(X);
      std::vector<double> w(X, 0.0);
      double sum = 0;
      for (uint32_t i = 0; i < X; ++i) {
        cand[i] = candidate(org, n, rng);
        if (cand[i].valid) w[i] = double(luminance(cand[i].f)) / cand[i].pdf_area;
        sum += w[i];
      }
      const double r = double(rng.uniform()) * sum;
      if (!(sum > 0)) return;
      double acc = 0;
      uint32_t k = 0;
      for (; k + 1 < X; ++k)
        if ((acc += w[k]) > r) break;
      while (!cand[k].valid) --k;  // r fell past the last positive weight only by rounding
      y = cand[k];
      estimate = y.f * float(sum / X / double(luminance(y.f)));
      if (method_ == PtMethod::ris_mis) estimate = estimate * light_weight(y);
    } else {
      y = candidate(org, n, rng);
      if (!y.valid) return;
      estimate = y.f * float(1.0 / y.pdf_area);
    }
    Ray s;
    s.org = org;
    s.dir = y.wi;
    s.tmax = y.dist * (1.f - 1e-4f);
    shadow_.rays.push_back(s);
    shadow_contrib_.push_back(p.thr * estimate);
    shadow_pixel_.push_back(p.pixel);
    shadow_depth_.push_back(p.depth);
  }

  void shade(Path& p, const Hit& h) {
    float tl = 0, cos_l = 0;
    const int li = light_hit(p.ray, h.t, tl, cos_l);
    if (li >= 0) {  // path reached a light (Alg. 6.1 lines 10-12)
      const AreaLight& l = light_.lights[size_t(li)];
      if (!p.diffuse) {
        add(p.pixel, p.thr * l.radiance, p.depth);
      } else if (method_ == PtMethod::ris_mis) {  // the extension ray as MIS's BRDF sample
        const double pl = light_prob(size_t(li)) / l.area * double(tl) * tl / cos_l;
        add(p.pixel, p.thr * l.radiance * float(p.bsdf_pdf / (p.bsdf_pdf + pl)), p.depth);
      }
      p.active = false;
      return;
    }
    if (!h.hit()) {  // path left the scene: the sky (never sampled explicitly, so always added)
      add(p.pixel, p.thr * light_.sky, p.depth);
      p.active = false;
      return;
    }
    const SurfacePoint sp = surface_point(scene_, h.prim, h.u, h.v);
    const Vec3 n = dot(sp.n, p.ray.dir) > 0.f ? -sp.n : sp.n;  // face the incoming ray
    const Vec3 org = sp.p + n * sp.eps;
    ++p.depth;
    p.diffuse = true;
    sample_direct(p, org, n, p.rng);
    if (method_ == PtMethod::dpt) {
      // Alg. 6.2: the path ends after d_max segments; otherwise it goes on with the fixed
      // survival of 50% applied deterministically (throughput / (1 - 0.5)).
      if (p.depth >= p.max_depth) return void(p.active = false);
      p.thr = p.thr * light_.albedo * 2.f;
    } else {
      // Russian roulette with survival q = the albedo (Arvo & Kirk 1990), capped to [0.05, 0.95].
      const float q = std::clamp(max_component(light_.albedo), 0.05f, 0.95f);
      if (!(p.rng.uniform() < q) || p.depth >= kMaxSegments) return void(p.active = false);
      p.thr = p.thr * light_.albedo * (1.f / q);
    }
    p.ray = Ray{};
    p.ray.org = org;
    p.ray.dir = cosine_hemisphere(n, p.rng);  // Lambert: cosine pdf, weight = albedo
    p.bsdf_pdf = std::max(0.f, dot(n, p.ray.dir)) / kPi;
  }

  const Scene& scene_;
  const Traverser& tracer_;
  const Lighting& light_;
  PtMethod method_;
  const PtOptions& opt_;
  PtStats& stats_;
  Camera cam_;
  uint64_t salt_;
  std::vector<double> accum_;
  std::vector<double> cdf_;
  RayBatch shadow_;
  std::vector<Vec3> shadow_contrib_;
  std::vector<uint32_t> shadow_pixel_, shadow_depth_;
  std::vector<std::vector<double>> depth_accum_;  // by_depth (render_pathtrace), empty when not asked
};

double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

bool any_active(const std::vector<Path>& lanes) {
  return std::any_of(lanes.begin(), lanes.end(), [](const Path& p) { return p.active; });
}

}  // namespace

uint64_t Lighting::hash() const {
  uint64_t h = salt_hash(source);
  h = fnv(h, &albedo, sizeof(albedo));
  h = fnv(h, &sky, sizeof(sky));
  for (const AreaLight& l : lights) h = fnv(h, &l, sizeof(l));
  return h;
}

Lighting scene_lighting(const Scene& scene) {
  const auto it = descriptions().find(scene.name);
  const SceneDesc& d = it == descriptions().end() ? kDefault : it->second;
  Lighting out;
  out.source = it == descriptions().end() ? "default" : "description:" + scene.name;
  out.albedo = d.albedo, out.sky = d.sky;
  const AABB b = scene.bounds();
  const int up = up_axis(scene), h1 = (up + 1) % 3, h2 = (up + 2) % 3;
  const Vec3 ext = b.extent();
  for (const LightDesc& ld : d.lights) {
    Vec3 c = b.lo, e1, e2;
    c[h1] += ld.fx * ext[h1], c[up] += ld.fy * ext[up], c[h2] += ld.fz * ext[h2];
    e1[h1] = ld.sx * ext[h1];
    e2[h2] = ld.sz * ext[h2];
    AreaLight l;
    l.corner = c - e1 * 0.5f - e2 * 0.5f;
    // Facing down: choose the side order so that e1 x e2 points against the up axis.
    l.e1 = e1, l.e2 = e2;
    if (cross(e1, e2)[up] > 0) std::swap(l.e1, l.e2);
    l.n = normalize(cross(l.e1, l.e2));
    l.area = length(cross(l.e1, l.e2));
    // Radiance such that a light of relative power 1 gives irradiance ~2 at the centre of the
    // bounds (exposure: a grey surface there shows ~0.4), whatever the scene's scale.
    const float d = std::max(1e-6f, length(b.centre() - c));
    const float le = ld.power * 2.f * d * d / std::max(1e-12f, l.area);
    l.radiance = {le, le, le};
    out.lights.push_back(l);
  }
  return out;
}

const std::vector<std::string>& pt_method_names() {
  static const std::vector<std::string> n = {"Ref", "PR", "DPT", "SPT", "RIS", "RIS/MIS"};
  return n;
}

PtMethod parse_pt_method(const std::string& name) {
  const auto& n = pt_method_names();
  for (size_t i = 0; i < n.size(); ++i)
    if (n[i] == name) return PtMethod(i);
  std::string known;
  for (const auto& s : n) known += " " + s;
  throw InputError("unknown path-tracing method '" + name + "' (known:" + known + ")");
}

std::string pt_method_name(PtMethod m) { return pt_method_names()[size_t(m)]; }

PtImage render_pathtrace(const Scene& scene, const Traverser& tracer, const Lighting& lighting, PtMethod method,
                         const PtOptions& opt, PtStats* stats_out, std::vector<PtImage>* by_depth) {
  if (opt.spp == 0) throw InputError("path tracing needs spp >= 1");
  if (opt.width == 0 || opt.height == 0) throw InputError("path tracing needs a non-empty image");
  if (opt.view >= scene.views.size())
    throw InputError("view " + std::to_string(opt.view + 1) + " does not exist in scene '" + scene.name + "'");
  if (opt.ris_per_light == 0) throw InputError("RIS needs at least one candidate per light");
  PtStats stats;
  const auto t0 = std::chrono::steady_clock::now();
  const double c0 = thread_cpu_seconds();
  Wavefront wf(scene, tracer, lighting, method, opt, stats, by_depth != nullptr);
  // Lanes are pixels in the 16x16 tiles of the thesis' packet layout (Fig. 16): one tile is one
  // packet (and 8 warps of 32 lanes); primary_rays gives that order.
  WorkloadSpec spec;
  spec.kind = "primary", spec.width = opt.width, spec.height = opt.height, spec.view = opt.view;
  const RayBatch layout = primary_rays(scene, spec, 1.f);
  const std::vector<uint32_t>& lane_pixel = layout.pixel;
  const uint32_t npix = uint32_t(lane_pixel.size());
  std::vector<Path> lanes(npix);

  if (method == PtMethod::spt) {
    // Streaming path tracing (§6.3.3): a stream of N = one sample per pixel; after each
    // extension the survivors are compacted to the front (keeping their order, so the stream
    // stays sorted by depth) and the rest is refilled with new primary rays, sample-major.
    std::vector<Path> stream;
    stream.reserve(npix);
    const uint64_t total = uint64_t(npix) * opt.spp;
    uint64_t next = 0;
    for (;;) {
      while (stream.size() < npix && next < total) {
        stream.emplace_back();
        wf.start(stream.back(), lane_pixel[next % npix], uint32_t(next / npix));
        ++next;
      }
      if (stream.empty()) break;
      std::vector<uint32_t> groups;
      for (uint32_t g = 0; g < stream.size(); g += kPtPacket) groups.push_back(g);
      groups.push_back(uint32_t(stream.size()));
      wf.step(stream, groups);
      stream.erase(std::remove_if(stream.begin(), stream.end(), [](const Path& p) { return !p.active; }),
                   stream.end());
    }
  } else if (method == PtMethod::pr) {
    // Path regeneration (Novák et al. 2010; §6.3.1): at the start of each iteration a lane whose
    // path ended starts its pixel's next sample, until the pixel has started spp; the closing
    // phase runs the remaining paths out.
    std::vector<uint32_t> started(npix, 0);
    for (;;) {
      for (uint32_t l = 0; l < npix; ++l)
        if (!lanes[l].active && started[l] < opt.spp) wf.start(lanes[l], lane_pixel[l], started[l]++);
      if (!any_active(lanes)) break;
      wf.step(lanes, layout.packet_begin);
    }
  } else {
    // Ref, RIS, RIS/MIS (Alg. 6.1) and DPT (Alg. 6.2): one pass per sample; a pass iterates until
    // every lane's path has ended.
    for (uint32_t s = 0; s < opt.spp; ++s) {
      for (uint32_t l = 0; l < npix; ++l) wf.start(lanes[l], lane_pixel[l], s);
      while (any_active(lanes)) wf.step(lanes, layout.packet_begin);
    }
  }
  stats.total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  stats.cpu_s = thread_cpu_seconds() - c0;
  if (stats_out) *stats_out = stats;
  if (by_depth) *by_depth = wf.depth_images(opt.spp);
  return wf.image(opt.spp);
}

double pt_rmse(const PtImage& a, const PtImage& b) {
  if (a.width != b.width || a.height != b.height || a.rgb.size() != b.rgb.size())
    throw InputError("rmse of images of different sizes (" + std::to_string(a.width) + "x" + std::to_string(a.height) +
                     " vs " + std::to_string(b.width) + "x" + std::to_string(b.height) + ")");
  double s = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    const double d = 255.0 * (double(a.rgb[i]) - double(b.rgb[i]));
    s += d * d;
  }
  return a.rgb.empty() ? 0 : std::sqrt(s / double(a.rgb.size()));
}

double pt_mean(const PtImage& img) {
  double s = 0;
  for (float v : img.rgb) s += v;
  return img.rgb.empty() ? 0 : s / double(img.rgb.size());
}

void write_pt_png(const std::string& path, const PtImage& img) {
  std::vector<uint8_t> rgb(img.rgb.size());
  for (size_t i = 0; i < rgb.size(); ++i)
    rgb[i] = uint8_t(std::lround(255.0 * std::pow(std::clamp(double(img.rgb[i]), 0.0, 1.0), 1.0 / 2.2)));
  write_rgb_png(path, img.width, img.height, rgb);
}

namespace {
constexpr char kMagic[8] = {'T', 'B', 'P', 'T', 'I', 'M', 'G', '1'};
}

void save_pt_image(const std::string& path, const PtImage& img) {
  std::string bytes(kMagic, sizeof(kMagic));
  const uint32_t wh[2] = {img.width, img.height};
  bytes.append(reinterpret_cast<const char*>(wh), sizeof(wh));
  bytes.append(reinterpret_cast<const char*>(img.rgb.data()), img.rgb.size() * sizeof(float));
  write_file_durably(path, bytes);
}

bool load_pt_image(const std::string& path, PtImage& img, std::string* why) {
  if (why) why->clear();
  std::error_code ec;
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec && !std::filesystem::exists(path)) return false;  // missing: no reason to give
  auto bad = [&](const std::string& w) {
    if (why) *why = w;
    return false;
  };
  if (ec) return bad("cannot read its size (" + ec.message() + ")");
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) return bad("cannot open it");
  char magic[8];
  uint32_t wh[2];
  if (std::fread(magic, 1, 8, f.get()) != 8 || std::memcmp(magic, kMagic, 8) != 0 || std::fread(wh, 4, 2, f.get()) != 2)
    return bad("not a converged-image cache (no TBPTIMG1 header)");
  // The declared size must be what the file holds before anything is allocated for it: a header
  // of 0xFFFFFFFF x 0xFFFFFFFF would otherwise ask for 2^66 bytes.
  const uint64_t header = sizeof kMagic + sizeof wh, pixels = uint64_t(wh[0]) * wh[1];  // < 2^64
  const uint64_t bytes_per_pixel = 3 * sizeof(float);
  if (pixels == 0) return bad("declares an empty image (" + std::to_string(wh[0]) + "x" + std::to_string(wh[1]) + ")");
  if (size < header || (size - header) % bytes_per_pixel != 0 || (size - header) / bytes_per_pixel != pixels)
    return bad("declares " + std::to_string(wh[0]) + "x" + std::to_string(wh[1]) + " pixels but holds " +
               std::to_string(size - std::min<uintmax_t>(size, header)) + " bytes of pixels (" +
               std::to_string(bytes_per_pixel) + " a pixel)");
  PtImage out{wh[0], wh[1], std::vector<float>(pixels * 3)};
  if (std::fread(out.rgb.data(), sizeof(float), out.rgb.size(), f.get()) != out.rgb.size())
    return bad("cut short while reading its pixels");
  // Radiance is finite and never negative: a NaN here would make every rmse against it NaN.
  for (size_t i = 0; i < out.rgb.size(); ++i)
    if (!std::isfinite(out.rgb[i]) || out.rgb[i] < 0)
      return bad("pixel " + std::to_string(i / 3) + " holds " + std::to_string(out.rgb[i]) +
                 ", not a radiance (finite, >= 0)");
  img = std::move(out);
  return true;
}

}  // namespace tb
