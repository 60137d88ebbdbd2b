// Structures are built once per scene and parameter set and shared by every scheme that uses
// them (bvh_single and the packet schemes trace the same BVH; the MBVHs collapse that BVH).
#pragma once
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>

namespace tb {

struct Scene;

class StructureCache {
 public:
  explicit StructureCache(const Scene& scene) : scene_(scene) {}
  const Scene& scene() const { return scene_; }

  // Returns the structure stored under `key`, building it with `build()` on first use.
  template <class T, class Build>
  std::shared_ptr<const T> get(const std::string& key, Build&& build) {
    std::lock_guard lock(mutex_);
    auto it = items_.find(key);
    if (it != items_.end()) return std::static_pointer_cast<const T>(it->second.ptr);
    auto t0 = std::chrono::steady_clock::now();
    std::shared_ptr<const T> p = std::make_shared<const T>(build());
    double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    items_[key] = {p, ms};
    return p;
  }
  // Build time of a cached structure in ms (0 when absent).
  double build_ms(const std::string& key) const {
    std::lock_guard lock(mutex_);
    auto it = items_.find(key);
    return it == items_.end() ? 0.0 : it->second.ms;
  }

 private:
  struct Item {
    std::shared_ptr<const void> ptr;
    double ms = 0;
  };
  const Scene& scene_;
  mutable std::mutex mutex_;
  std::map<std::string, Item> items_;
};

}  // namespace tb
