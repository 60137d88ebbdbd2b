// The check of the scene-loader fuzz targets (fuzz_mesh, fuzz_gltf): whatever the format, a file
// must load a valid scene or raise a one-line tb::InputError.
#pragma once
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "structures/scene_loader.h"

namespace tb::fuzz {

// Loads `path` through load_scene_file and aborts (a finding) unless the result keeps the contract.
inline void check_scene_load(const std::string& path) {
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
}

}  // namespace tb::fuzz
