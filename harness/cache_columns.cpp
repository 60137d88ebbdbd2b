#include "harness/cache_columns.h"

#include <cctype>

#include "cachesim/hierarchy.h"
#include "harness/trace_runner.h"

namespace tb {

void add_cache_columns(Record& r, const Traverser& scheme, const RayBatch& batch, std::span<Hit> hits,
                       const std::string& config, const std::string& policy) {
  cachesim::HierarchyConfig cfg = cachesim::parse_config(config);
  cfg.policy = cachesim::parse_policy(policy);
  cachesim::Hierarchy h(cfg);
  Probe probe;
  probe.cache = &h;
  enable_ftz_daz();
  scheme.trace(batch, PacketRange::all(batch), hits, probe);
  auto level_key = [&](size_t i) {
    std::string lv = h.level_config(i).name;
    for (char& c : lv) c = char(std::tolower(static_cast<unsigned char>(c)));
    return lv;
  };
  for (size_t i = 0; i < h.num_levels(); ++i) {
    const std::string lv = level_key(i);
    const auto& c = h.counters(i);
    r.set(lv + "_read_hit_m", double(c.read_hits) * 1e-6).set(lv + "_write_hit_m", double(c.write_hits) * 1e-6);
  }
  r.set("mem_read_m", double(h.memory_reads()) * 1e-6)
      .set("mem_write_m", double(h.memory_writes()) * 1e-6)
      .set("mem_read_cold_m", double(h.cold_reads()) * 1e-6)
      .set("cost_mcycles", double(h.cost_cycles()) * 1e-6)
      .set("read_cost_mcycles", double(h.read_cost_cycles()) * 1e-6);
  const double total = double(h.read_cost_cycles());
  for (size_t i = 0; i < h.num_levels() && total > 0; ++i) {
    r.set(level_key(i) + "_pct", 100.0 * double(h.counters(i).read_hits * h.level_config(i).latency_cycles) / total);
  }
  if (total > 0)
    r.set("mem_pct", 100.0 * double(h.memory_reads() * h.config().memory_latency_cycles) / total);
}

}  // namespace tb
