// libFuzzer target: the Dinero IV din-trace reader (cachesim/din_trace.cpp) replayed through a
// small hierarchy, and the --config / --policy parsers of `travbench cachesim`. When the first
// line is "#config CONFIG [POLICY]" those two are parsed and the hierarchy is built from them
// ('#' lines are comments to the din reader, so the rest of the input is still a trace).
#include <cstdlib>
#include <cstring>
#include <sstream>

#include "cachesim/din_trace.h"
#include "structures/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    tb::cachesim::HierarchyConfig cfg;
    bool have = false;
    if (text.rfind("#config ", 0) == 0) {
      const size_t eol = text.find('\n');
      std::istringstream first(text.substr(8, eol == std::string::npos ? std::string::npos : eol - 8));
      std::string config, policy;
      first >> config >> policy;
      // Bounded: a fuzzer-made config must not allocate gigabytes of simulated cache.
      if (config.size() > 64) return 0;
      cfg = tb::cachesim::parse_config(config);
      uint64_t bytes = 0;
      for (const auto& l : cfg.levels) bytes += l.size_bytes;
      if (bytes > (64u << 20)) return 0;
      if (!policy.empty()) cfg.policy = tb::cachesim::parse_policy(policy);
      have = true;
    }
    if (!have) cfg = tb::cachesim::parse_config("l1=1K:2,l2=4K:4");
    tb::cachesim::Hierarchy h(std::move(cfg));
    std::istringstream in(text);
    tb::cachesim::replay_din(in, h, "fuzz.din");
    std::ostringstream out;
    tb::cachesim::write_report(h, out);
  } catch (const tb::InputError& e) {
    if (std::strchr(e.what(), '\n')) std::abort();
  }
  return 0;
}
