// libFuzzer target: the glTF 2.0 loader (.gltf JSON and .glb binary; the loader picks the
// container from the "glTF" magic, whatever the extension) through load_scene_file. Every input
// must load a valid scene or raise a one-line tb::InputError.
#include <cstdlib>
#include <cstring>

#include "fuzz_util.h"
#include "structures/scene_loader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = tb::fuzz::write_input("in.gltf", data, size);
  try {
    tb::Scene s = tb::load_scene_file(path);
    if (s.triangles.empty()) std::abort();
    for (const auto& t : s.triangles)
      for (uint32_t i : t)
        if (i >= s.positions.size()) std::abort();
  } catch (const tb::InputError& e) {
    if (std::strchr(e.what(), '\n')) std::abort();
  }
  return 0;
}
