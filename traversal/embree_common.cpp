#include "traversal/embree_common.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <map>
#include <mutex>
#include <vector>
#include <stdexcept>

namespace tb {

namespace {
void on_error(void*, RTCError code, const char* msg) {
  std::fprintf(stderr, "travbench: embree error %d: %s\n", int(code), msg ? msg : "");
}

// Net bytes Embree's device holds. Embree 3 has no per-scene memory query; its memory monitor
// callback sees every allocation and free of the device, so a scene's footprint is the growth of
// this counter across its construction (vertex/index buffers + BVH). Builds run one at a time.
std::atomic<int64_t> g_device_bytes{0};
bool on_memory(void*, ssize_t bytes, bool) {
  g_device_bytes.fetch_add(bytes, std::memory_order_relaxed);
  return true;
}
}  // namespace

namespace {
// The `isa` values and what the CPU needs for each (Embree 3.13's ISA groups: its AVX2 kernels
// also use FMA3 and BMI1/2, its AVX-512 ones F, DQ, CD, BW and VL).
bool cpu_has_isa(const std::string& isa) {
  if (isa == "sse2") return true;  // x86-64
  if (isa == "sse4.2") return __builtin_cpu_supports("sse4.2");
  if (isa == "avx") return __builtin_cpu_supports("avx");
  if (isa == "avx2")
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi") &&
           __builtin_cpu_supports("bmi2");
  if (isa == "avx512")
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
           __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512bw") &&
           __builtin_cpu_supports("avx512vl");
  return false;
}
const std::vector<std::string> kIsaNames = {"default", "sse2", "sse4.2", "avx", "avx2", "avx512"};
}  // namespace

RTCDevice embree_device(const std::string& isa) {
  static std::mutex mu;
  static std::map<std::string, RTCDevice> devices;
  const std::lock_guard<std::mutex> lock(mu);
  if (auto it = devices.find(isa); it != devices.end()) return it->second;
  std::string config = "threads=1,set_affinity=0";
  if (isa != "default") {
    if (std::find(kIsaNames.begin(), kIsaNames.end(), isa) == kIsaNames.end()) {
      std::string names;
      for (const std::string& n : kIsaNames) names += (names.empty() ? "" : ", ") + n;
      throw InputError("embree isa '" + isa + "': not one of " + names);
    }
    if (!cpu_has_isa(isa)) throw InputError("embree isa '" + isa + "': this CPU does not support it");
    config += ",isa=" + isa;
  }
  RTCDevice d = rtcNewDevice(config.c_str());
  if (!d) throw std::runtime_error("embree: rtcNewDevice(\"" + config + "\") failed");
  rtcSetDeviceErrorFunction(d, on_error, nullptr);
  rtcSetDeviceMemoryMonitorFunction(d, on_memory, nullptr);
  devices.emplace(isa, d);
  return d;
}

EmbreeScene::EmbreeScene(const Scene& scene, EmbreeQuality quality, bool robust, const std::string& isa) {
  RTCDevice dev = embree_device(isa);
  const int64_t before = g_device_bytes.load();
  scene_ = rtcNewScene(dev);
  rtcSetSceneFlags(scene_, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  const RTCBuildQuality q = quality == EmbreeQuality::high     ? RTC_BUILD_QUALITY_HIGH
                            : quality == EmbreeQuality::medium ? RTC_BUILD_QUALITY_MEDIUM
                                                               : RTC_BUILD_QUALITY_LOW;
  rtcSetSceneBuildQuality(scene_, q);
  RTCGeometry geom = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geom, q);
  // Embree may read 16 bytes at the last vertex: allocate through Embree, which pads.
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                        3 * sizeof(float), scene.positions.size()));
  for (size_t i = 0; i < scene.positions.size(); ++i) {
    v[3 * i] = scene.positions[i].x;
    v[3 * i + 1] = scene.positions[i].y;
    v[3 * i + 2] = scene.positions[i].z;
  }
  auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                             3 * sizeof(uint32_t), scene.triangles.size()));
  for (size_t i = 0; i < scene.triangles.size(); ++i)
    for (int c = 0; c < 3; ++c) idx[3 * i + c] = scene.triangles[i][c];
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene_, geom);
  rtcReleaseGeometry(geom);
  const int64_t buffers = g_device_bytes.load();
  rtcCommitScene(scene_);
  bytes_.prims = size_t(std::max<int64_t>(0, buffers - before));
  bytes_.nodes = size_t(std::max<int64_t>(0, g_device_bytes.load() - buffers));
}

EmbreeScene::~EmbreeScene() {
  if (scene_) rtcReleaseScene(scene_);
}

std::shared_ptr<const EmbreeScene> fetch_embree_scene(const Scene& scene, StructureCache& cache,
                                                      EmbreeQuality quality, bool robust, const std::string& isa) {
  const std::string key =
      "embree:q" + std::to_string(int(quality)) + (robust ? ":robust" : ":fast") + (isa == "default" ? "" : ":" + isa);
  return cache.get<EmbreeScene>(key, [&] { return EmbreeScene(scene, quality, robust, isa); });
}

ParamSpecs embree_param_specs() {
  return {bool_param("robust", true, "RTC_SCENE_FLAG_ROBUST: Embree's watertight mode (0: its fast default)"),
          choice_param("quality", "high", {"low", "medium", "high"},
                       "rtcSetSceneBuildQuality: low (Morton), medium (binned SAH), high (SAH; spatial splits when robust=0; "
                       "with robust=1 Embree builds high as medium)"),
          choice_param("isa", "default", kIsaNames,
                       "Embree's kernel ISA: default (its run-time choice, the CPU's best) or the device config "
                       "isa=NAME, for like-for-like comparisons across machines (refused where the CPU lacks it)")};
}

bool embree_robust(const SchemeConfig& cfg) { return cfg.get_bool("robust"); }

const std::string& embree_isa(const SchemeConfig& cfg) { return cfg.get_choice("isa"); }

EmbreeQuality embree_quality(const SchemeConfig& cfg) {
  const std::string& q = cfg.get_choice("quality");
  return q == "low" ? EmbreeQuality::low : q == "medium" ? EmbreeQuality::medium : EmbreeQuality::high;
}

}  // namespace tb
