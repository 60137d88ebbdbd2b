// libFuzzer target: the glTF 2.0 loader (.gltf JSON and .glb binary; the loader picks the
// container from the "glTF" magic, whatever the extension) through load_scene_file. Every input
// must load a valid scene or raise a one-line tb::InputError.
#include "fuzz_scene.h"
#include "fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tb::fuzz::check_scene_load(tb::fuzz::write_input("in.gltf", data, size));
  return 0;
}
