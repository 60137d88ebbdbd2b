// A pool of per-call scratch records for the batch schemes (mbvh_rs, raygrid). A call takes one
// record for its duration and returns it, so repeated calls reuse arrays that are already sized
// and faulted in, and concurrent calls on disjoint ranges never share one. Allocating the scratch
// per call instead meant zeroing it per call: for mbvh_rs's 8192-ray streams ~4 MB of stacks
// per 8192 rays, 5% of its instructions on conference bounce:3, and a sweep through the L2 that
// evicted the tree the streams were about to read.
#pragma once
#include <memory>
#include <mutex>
#include <vector>

namespace tb {

template <class T>
class ScratchPool {
 public:
  // A record for one call; give it back with release().
  std::unique_ptr<T> acquire() const {
    std::lock_guard lock(mutex_);
    if (pool_.empty()) return std::make_unique<T>();
    std::unique_ptr<T> s = std::move(pool_.back());
    pool_.pop_back();
    return s;
  }
  void release(std::unique_ptr<T> s) const {
    std::lock_guard lock(mutex_);
    pool_.push_back(std::move(s));
  }
  // Drops every record (a new structure may need other sizes; stale records only cost memory).
  void clear() const {
    std::lock_guard lock(mutex_);
    pool_.clear();
  }

 private:
  mutable std::mutex mutex_;
  mutable std::vector<std::unique_ptr<T>> pool_;
};

}  // namespace tb
