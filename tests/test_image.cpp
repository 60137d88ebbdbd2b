// travbench image (issue 20): per-pixel costs from the probe, bounce rays on their pixel, the PNG
// read back with libpng, clear errors for a bad metric or a scheme without counters.
#include <png.h>

#include <cmath>

#include "harness/image.h"
#include "workloads/hard_cases.h"
#include "test_util.h"

namespace tb {
namespace {

ImageOptions options(const std::string& scheme, const std::string& workload, const std::string& metric) {
  ImageOptions o;
  o.scheme = scheme, o.workload = workload, o.metric = metric, o.width = 48, o.height = 32;
  return o;
}

TEST(Image, CostsComeFromTheProbeAndBounceRaysLandOnTheirPixel) {
  Bench& bench = test::bench_for("sphere");
  ImageOptions o = options("bvh_single", "primary", "nodes");
  o.packet = 1;  // per ray
  const CostImage prim = cost_image(bench, o);
  ASSERT_EQ(prim.value.size(), 48u * 32u);
  double sum = 0;
  for (double v : prim.value) {
    ASSERT_TRUE(std::isfinite(v)) << "every pixel has a primary ray";
    sum += v;
  }
  // The per-ray counts average to what --stats reports for the batch: the same probe, ray by ray.
  WorkloadSpec spec = parse_workload("primary");
  spec.width = 48, spec.height = 32;
  auto t = make_scheme("bvh_single");
  t->prepare(bench.scene(), bench.cache());
  RunOptions run;
  run.reps = 1, run.stats = true;
  const Record r = measure_cell(bench, spec, *t, run);
  EXPECT_NEAR(sum / double(prim.value.size()), std::stod(*r.get("nodes_per_ray")), 1e-5 * sum / prim.value.size());

  // Bounce paths that left the scene leave their pixel empty; the others keep a finite cost.
  const CostImage shade = cost_image(bench, options("bvh_single", "primary", "shade"));
  const CostImage bounce = cost_image(bench, options("bvh_single", "bounce:1", "tris"));
  size_t misses = 0;
  for (size_t i = 0; i < shade.value.size(); ++i) {
    if (std::isnan(shade.value[i])) {
      ++misses;
      EXPECT_TRUE(std::isnan(bounce.value[i])) << "a pixel whose primary ray missed has no bounce";
    } else {
      EXPECT_GE(shade.value[i], 0.0);
      EXPECT_LE(shade.value[i], 1.0);
    }
  }
  EXPECT_GT(misses, 0u) << "the sphere does not fill the view";
  EXPECT_LT(misses, shade.value.size());
}

TEST(Image, WritesAPngOfTheRequestedSize) {
  Bench& bench = test::bench_for("sphere");
  const std::string path = (test::temp_dir("image") / "heat.png").string();
  for (const char* metric : {"leaves", "time", "shade"}) {
    ImageOptions o = options(std::string(metric) == "time" ? "embree_single" : "mbvh8_single", "primary", metric);
    o.out = path;
    run_image(bench, o, "sphere");
    png_image img{};
    img.version = PNG_IMAGE_VERSION;
    ASSERT_TRUE(png_image_begin_read_from_file(&img, path.c_str())) << img.message;
    img.format = PNG_FORMAT_RGB;
    std::vector<uint8_t> px(PNG_IMAGE_SIZE(img));
    ASSERT_TRUE(png_image_finish_read(&img, nullptr, px.data(), 0, nullptr)) << img.message;
    EXPECT_EQ(img.width, 48u) << metric;
    EXPECT_GT(img.height, 32u) << "the legend strip is below the map";
    size_t distinct = 0;  // a heat map, not a blank page
    for (size_t i = 3; i < size_t(48 * 32 * 3); i += 3) distinct += px[i] != px[0] || px[i + 1] != px[1];
    EXPECT_GT(distinct, 0u) << metric;
  }
  std::filesystem::remove_all(std::filesystem::path(path).parent_path());
}

TEST(Image, BadMetricSchemeOrWorkloadIsAClearError) {
  auto message = [](const ImageOptions& o) {
    try {
      check_image_options(o);
      cost_image(test::bench_for("sphere"), o);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(options("bvh_single", "primary", "cycles")).find("one of nodes"), std::string::npos);
  EXPECT_NE(message(options("warp_drive", "primary", "nodes")).find("warp_drive"), std::string::npos);
  EXPECT_NE(message(options("embree_single", "primary", "nodes")).find("use --metric time or shade"), std::string::npos);
  EXPECT_NE(message(options("bvh_single", "rnd2", "nodes")).find("camera pixels"), std::string::npos);
  // By the workload's kind, also where it makes no rays (as many pixels as rays: none): a hard
  // case wrote a blank image and exited 0.
  for (const auto& h : hard_case_names())
    EXPECT_NE(message(options("bvh_single", h, "nodes")).find("camera pixels"), std::string::npos) << h;
}

}  // namespace
}  // namespace tb
