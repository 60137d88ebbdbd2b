// libFuzzer target: the ray-file and hit-file readers (workloads/ray_file.cpp). Inputs that start
// with the hit-file magic go to read_hits, all others to read_rays. A ray file that loads must be
// valid (RayBatch::validate ran) and must survive a write/read round trip unchanged.
#include <cstdlib>
#include <cstring>

#include "fuzz_util.h"
#include "workloads/ray_file.h"
#include "structures/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = tb::fuzz::write_input("in.bin", data, size);
  const bool hits = size >= 8 && std::memcmp(data, "TBHITS1\0", 8) == 0;
  try {
    if (hits) {
      auto h = tb::read_hits(path);
      (void)h;
    } else {
      tb::RayBatch b = tb::read_rays(path);
      const std::string again = tb::fuzz::work_dir() + "/again.bin";
      tb::write_rays(again, b);
      tb::RayBatch c = tb::read_rays(again);
      if (c.rays.size() != b.rays.size() || c.packet_begin != b.packet_begin) std::abort();
      if (!b.rays.empty() && std::memcmp(c.rays.data(), b.rays.data(), b.rays.size() * sizeof(tb::Ray)) != 0)
        std::abort();
    }
  } catch (const tb::InputError& e) {
    if (std::strchr(e.what(), '\n')) std::abort();
  }
  return 0;
}
