#include "traversal/probe.h"

#include "cachesim/hierarchy.h"

namespace tb {

void Probe::read(const void* p, uint32_t bytes) {
  if (cache) cache->access(reinterpret_cast<uintptr_t>(p), bytes, false);
}
void Probe::write(const void* p, uint32_t bytes) {
  if (cache) cache->access(reinterpret_cast<uintptr_t>(p), bytes, true);
}

}  // namespace tb
