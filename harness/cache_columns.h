// The Table 11 columns of `travbench run --cache`: one instrumented trace through the simulated
// cache hierarchy (thesis §5.4), hits per level in millions, memory accesses and estimated cost.
#pragma once
#include <span>
#include <string>

#include "harness/records.h"
#include "traversal/traverser.h"

namespace tb {

void add_cache_columns(Record& r, const Traverser& scheme, const RayBatch& batch, std::span<Hit> hits,
                       const std::string& config, const std::string& policy);

}  // namespace tb
