// libFuzzer target: the OBJ / OFF / PLY / STL loaders through load_scene_file (dispatch on the
// extension, then Scene::validate). The first input byte picks the format (byte % 4: obj, off,
// ply, stl); the rest is the file. Every input must load a valid scene or raise a one-line
// tb::InputError; anything else (another exception, a signal, a sanitizer report, a hang, a huge
// allocation) is a finding.
#include <cstdlib>
#include <cstring>

#include "fuzz_util.h"
#include "structures/scene_loader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const char* const kExt[4] = {".obj", ".off", ".ply", ".stl"};
  const std::string path = tb::fuzz::write_input(std::string("in") + kExt[data[0] % 4], data + 1, size - 1);
  try {
    tb::Scene s = tb::load_scene_file(path);
    // A loaded scene is valid: at least one triangle, every index in range, finite vertices.
    if (s.triangles.empty()) std::abort();
    for (const auto& t : s.triangles)
      for (uint32_t i : t)
        if (i >= s.positions.size()) std::abort();
  } catch (const tb::InputError& e) {
    if (std::strchr(e.what(), '\n')) std::abort();  // the CLI contract: one line per error
  }
  return 0;
}
