#include "cachesim/din_trace.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string_view>

#include "structures/scene.h"  // tb::InputError

namespace tb::cachesim {

namespace {

bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// Next blank-separated token of `s` starting at `pos` (advanced past it); empty at end of line.
std::string_view next_token(std::string_view s, size_t& pos) {
  while (pos < s.size() && is_blank(s[pos])) ++pos;
  const size_t start = pos;
  while (pos < s.size() && !is_blank(s[pos])) ++pos;
  return s.substr(start, pos - start);
}

// A token as an error message shows it: at most 40 characters, control and non-ASCII bytes as
// \xNN (a raw NUL cut the message short, an ESC reached the terminal).
std::string shorten(std::string_view s) {
  std::string out;
  const std::string_view cut = s.size() <= 40 ? s : s.substr(0, 37);
  for (const char ch : cut) {
    const auto c = static_cast<unsigned char>(ch);
    if (c >= 0x20 && c < 0x7F) {
      out += ch;
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02X", c);
      out += buf;
    }
  }
  return s.size() <= 40 ? out : out + "...";
}

}  // namespace

uint64_t replay_din(std::istream& in, Hierarchy& h, const std::string& name_for_errors) {
  std::string line;
  uint64_t lineno = 0, count = 0;
  while (std::getline(in, line)) {
    ++lineno;
    auto fail = [&](const std::string& msg) {
      throw InputError(name_for_errors + ":" + std::to_string(lineno) + ": " + msg);
    };
    size_t pos = 0;
    const std::string_view label = next_token(line, pos);
    if (label.empty() || label[0] == '#') continue;

    bool write = false;
    if (label == "0" || label == "2") {
      write = false;  // data read; instruction fetch, simulated as a read of the unified hierarchy
    } else if (label == "1") {
      write = true;
    } else if (label == "3" || label == "4") {
      fail("din escape label " + std::string(label) + " (" +
           (label == "3" ? "unknown access type" : "cache flush") + ") is not supported");
    } else {
      fail("label '" + shorten(label) + "' is not a din access type (0 read, 1 write, 2 fetch)");
    }

    std::string_view addr = next_token(line, pos);
    if (addr.empty()) fail("missing hex address after label " + std::string(label));
    const std::string_view shown = addr;
    if (addr.size() > 2 && addr[0] == '0' && (addr[1] == 'x' || addr[1] == 'X')) addr.remove_prefix(2);
    while (addr.size() > 1 && addr[0] == '0') addr.remove_prefix(1);  // leading zeros are free
    if (addr.size() > 16) fail("address '" + shorten(shown) + "' does not fit in 64 bits");
    uint64_t a = 0;
    for (char c : addr) {
      const int d = hex_digit(c);
      if (d < 0) fail("address '" + shorten(shown) + "' is not hexadecimal");
      a = a << 4 | static_cast<uint64_t>(d);
    }
    h.access(a, kDinAccessBytes, write);
    ++count;
  }
  if (in.bad()) throw InputError(name_for_errors + ": read error after line " + std::to_string(lineno));
  return count;
}

int run_cachesim_command(const std::string& config, const std::string& policy,
                         const std::string& trace_path, std::ostream& out) {
  HierarchyConfig cfg = config.empty() ? default_config() : parse_config(config);
  if (!policy.empty()) cfg.policy = parse_policy(policy);
  Hierarchy h(std::move(cfg));

  if (trace_path.empty()) throw InputError("cachesim: no trace file given (--trace FILE, or - for stdin)");
  if (trace_path == "-") {
    replay_din(std::cin, h, "<stdin>");
  } else {
    std::error_code ec;
    if (std::filesystem::is_directory(trace_path, ec))
      throw InputError("cannot read trace '" + trace_path + "': it is a directory");
    std::ifstream f(trace_path);
    if (!f) throw InputError("cannot open trace '" + trace_path + "': " + std::strerror(errno));
    replay_din(f, h, trace_path);
  }
  write_report(h, out);
  return 0;
}

}  // namespace tb::cachesim
