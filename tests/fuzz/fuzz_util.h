// Shared helpers of the libFuzzer targets (tests/fuzz/README in tests/README.md).
//
// The loaders take file paths, so each input is written to a file in a private directory that the
// process creates once (under /dev/shm when it exists: no disk traffic per execution). The
// directory holds nothing else, so a glTF buffer URI can only name the input itself or fail; it is
// removed when the process exits normally.
#pragma once
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

namespace tb::fuzz {

inline const std::string& work_dir() {
  // Never destroyed: the exit handler below still needs it after static destructors have run.
  static const std::string& dir = *new std::string([] {
    const char* base = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    std::string tmpl = std::string(base) + "/travbench_fuzz_XXXXXX";
    if (!mkdtemp(tmpl.data())) std::abort();
    return tmpl;
  }());
  static const bool cleanup = [] {
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(work_dir(), ec);  // removed on a normal exit; kept after a crash
    });
    return true;
  }();
  (void)cleanup;
  return dir;
}

// Writes the bytes to <work_dir>/<name> (replacing the previous input) and returns the path.
inline std::string write_input(const std::string& name, const uint8_t* data, size_t size) {
  const std::string path = work_dir() + "/" + name;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  return path;
}

}  // namespace tb::fuzz
