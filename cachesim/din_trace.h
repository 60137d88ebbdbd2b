// Replay of Dinero IV "din" traces through the simulated hierarchy, so the simulator can be checked
// against other simulators (Dinero IV, cachegrind via scripts/cachegrind_check.sh) on identical
// address streams, independently of the ray-traversal instrumentation.
//
// din format, one access per line:   <label> <hex address> [anything]
//   label 0 = data read, 1 = data write, 2 = instruction fetch (simulated as a read; the hierarchy
//   is unified). Dinero's escape labels 3 (unknown type) and 4 (flush) are rejected.
//   The address is a hexadecimal byte address, with or without a 0x prefix, at most 64 bits.
//   din carries no access size: every access is 4 bytes (one 32-bit word), so an address within
//   the last 3 bytes of a line touches two lines. As in Dinero, text after the address is ignored;
//   in particular a third number is NOT read as a size.
//   Blank lines and lines whose first non-blank character is '#' are skipped (an extension: din
//   itself has no comments). Anything else raises tb::InputError "name:line: what is wrong".
#pragma once
#include <cstdint>
#include <iosfwd>
#include <string>

#include "cachesim/hierarchy.h"

namespace tb::cachesim {

constexpr uint32_t kDinAccessBytes = 4;

// Feeds every access of the trace into `h` and returns how many there were. `name_for_errors`
// prefixes error messages (usually the file path).
uint64_t replay_din(std::istream& in, Hierarchy& h, const std::string& name_for_errors);

// `travbench cachesim --config CONFIG --policy POLICY --trace PATH`: builds the hierarchy
// (parse_config / parse_policy; an empty string selects the §5.4 default), replays the trace
// (PATH "-" reads standard input) and writes the report (write_report) to `out`. Returns 0; every
// problem with the input raises tb::InputError with a one-line message.
int run_cachesim_command(const std::string& config, const std::string& policy,
                         const std::string& trace_path, std::ostream& out);

}  // namespace tb::cachesim
