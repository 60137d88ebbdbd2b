// Structures are built once per scene and parameter set and shared by every scheme that uses
// them (bvh_single and the packet schemes trace the same BVH; the MBVHs collapse that BVH).
//
// A key is the stored type plus the canonical key() string of the structure's build parameters
// (BVHBuildParams::key(), KDBuildParams::key(), ...), so one string can never be read back as
// another type. The global lock only guards the map: each key has its own slot built under
// std::call_once, so two different structures build concurrently, a second fetch of the same key
// waits for the first build instead of repeating it, and a builder may fetch another structure
// (the MBVH collapse fetching its binary BVH) without deadlocking. A builder that throws leaves the
// slot unbuilt; the next fetch tries again.
#pragma once
#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <typeindex>
#include <utility>

namespace tb {

struct Scene;

class StructureCache {
 public:
  explicit StructureCache(const Scene& scene) : scene_(scene) {}
  const Scene& scene() const { return scene_; }

  // Returns the T stored under `key`, building it with `build()` (which returns a T) on first use.
  template <class T, class Build>
  std::shared_ptr<const T> get(const std::string& key, Build&& build) {
    Slot& s = slot(typeid(T), key);
    std::call_once(s.once, [&] {
      const auto t0 = std::chrono::steady_clock::now();
      std::shared_ptr<const T> p = std::make_shared<const T>(build());
      s.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      s.ptr = std::move(p);
      s.ready.store(true, std::memory_order_release);
    });
    return std::static_pointer_cast<const T>(s.ptr);  // the slot of typeid(T) only ever holds a T
  }
  // Build time in ms of the T cached under `key` (0 when absent or still building); the time of a
  // builder that fetched other structures includes theirs when it built them.
  template <class T>
  double build_ms(const std::string& key) const {
    std::lock_guard lock(mutex_);
    auto it = slots_.find({std::type_index(typeid(T)), key});
    if (it == slots_.end() || !it->second->ready.load(std::memory_order_acquire)) return 0.0;
    return it->second->ms;
  }
  // Number of structures built so far.
  size_t size() const {
    std::lock_guard lock(mutex_);
    size_t n = 0;
    for (const auto& [k, s] : slots_) n += s->ready.load(std::memory_order_acquire);
    return n;
  }

 private:
  struct Slot {
    std::once_flag once;
    std::shared_ptr<const void> ptr;
    double ms = 0;
    std::atomic<bool> ready{false};
  };
  Slot& slot(std::type_index type, const std::string& key) {
    std::lock_guard lock(mutex_);
    auto& s = slots_[{type, key}];
    if (!s) s = std::make_unique<Slot>();
    return *s;  // slots are never erased, so the reference outlives the lock
  }
  const Scene& scene_;
  mutable std::mutex mutex_;
  std::map<std::pair<std::type_index, std::string>, std::unique_ptr<Slot>> slots_;
};

}  // namespace tb
