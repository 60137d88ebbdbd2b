// Pinhole camera: pixel coordinates to ray directions for a CameraView.
#pragma once
#include <cmath>
#include <numbers>

#include "structures/scene.h"

namespace tb {

struct Camera {
  Vec3 eye, forward, right, up;
  float focal;  // distance of the image plane, in pixels
  uint32_t width, height;
  Camera(const CameraView& v, uint32_t w, uint32_t h) : eye(v.eye), width(w), height(h) {
    forward = normalize(v.target - v.eye);
    // `up` scaled by its largest component first (exact for a unit axis), so that the test below
    // is relative: with a short but valid `up` (1e-10) the absolute test took the fallback and
    // turned the camera by 90 degrees. Only an `up` parallel to the view direction within ~1e-6
    // (refused in scenes.json's views, structures/scene_loader.cpp) takes the fixed axis: the
    // corner views of a scene thin across x and z (Scene::ensure_views).
    const float m = max_abs(v.up);
    right = cross(forward, m > 0.f ? Vec3{v.up.x / m, v.up.y / m, v.up.z / m} : v.up);
    if (!(length(right) >= 1e-6f)) right = cross(forward, std::fabs(forward.x) < 0.9f ? Vec3{1, 0, 0} : Vec3{0, 0, 1});
    right = normalize(right);
    up = cross(right, forward);
    focal = 0.5f * h / std::tan(0.5f * v.vfov_deg * std::numbers::pi_v<float> / 180.f);
  }
  // Direction through image position (sx, sy) in pixels, (0,0) the top-left corner.
  Vec3 direction(float sx, float sy) const {
    return normalize(forward * focal + right * (sx - 0.5f * width) + up * (0.5f * height - sy));
  }
};

}  // namespace tb
