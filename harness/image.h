// `travbench image`: where do the rays spend their time? A per-pixel heat map of one scheme's
// traversal cost on one workload (issue 20), with a colour bar and a legend, written as PNG by
// libpng. Costs come from the instrumented path (traversal/probe.h: the same counters as --stats)
// or, for `time`, from the timed path; `shade` is a plain |n.d| view to check the camera.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "harness/experiment.h"

namespace tb {

struct ImageOptions {
  std::string scheme = "bvh_single";
  std::string workload = "primary";
  std::string metric = "nodes";  // nodes | leaves | tris | time | shade
  uint32_t width = 256, height = 256, view = 0;
  uint64_t seed = 1;
  // 0: trace the workload's own packets, each alone, and give each pixel its packet's cost per
  // ray (what a packet or stream scheme does is per packet). N: regroup into packets of N rays
  // first; 1 is per-ray resolution, exact for the single-ray schemes.
  uint32_t packet = 0;
  SchemeConfig scheme_config;
  std::string out;
};

const std::vector<std::string>& image_metrics();
// Checks the metric and that the scheme can be counted (Embree baselines cannot: time or shade);
// throws InputError saying why. Runs before any scene is loaded.
void check_image_options(const ImageOptions& opt);

// The per-pixel values (NaN where no ray of the workload lands: a path that left the scene) and
// what they mean, e.g. "nodes/ray" (interior node visits per ray).
struct CostImage {
  uint32_t width = 0, height = 0;
  std::vector<double> value;
  std::string unit;
};
CostImage cost_image(Bench& bench, const ImageOptions& opt);

// Renders `img` as an RGB PNG of width x (height + legend strip): the heat map (viridis; grey for
// shade), a colour bar from 0 to the largest value (for time the 99th percentile, so one timer
// outlier does not flatten the map) with its labels, and the legend line `title`.
void write_cost_png(const std::string& path, const CostImage& img, const std::string& title, bool grey);

// An 8-bit RGB image (row-major, 3 bytes a pixel) as PNG through libpng; InputError when the file
// cannot be written. write_cost_png and the path tracer's images (harness/pathtrace) use it.
void write_rgb_png(const std::string& path, uint32_t width, uint32_t height, const std::vector<uint8_t>& rgb);

// The whole command: cost_image + write_cost_png.
void run_image(Bench& bench, const ImageOptions& opt, const std::string& scene_label);

}  // namespace tb
