// libFuzzer target: the OBJ / OFF / PLY / STL loaders through load_scene_file (dispatch on the
// extension, then Scene::validate). The first input byte picks the format (byte % 4: obj, off,
// ply, stl); the rest is the file. Every input must load a valid scene or raise a one-line
// tb::InputError; anything else (another exception, a signal, a sanitizer report, a hang, a huge
// allocation) is a finding.
#include "fuzz_scene.h"
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const char* const kExt[4] = {".obj", ".off", ".ply", ".stl"};
  tb::fuzz::check_scene_load(tb::fuzz::write_input(std::string("in") + kExt[data[0] % 4], data + 1, size - 1));
  return 0;
}
