// The path tracer and the schemes of thesis ch. 6 (harness/pathtrace, issue 22): reproducible
// images, the unbiased schemes agreeing in mean, rmse falling as 1/sqrt(spp), DPT's higher
// variance with (nearly) the same mean, utilisation ordering, and clear errors for bad input.
// Small images (32x32) on the built-in room with bvh_single keep every test at a few seconds.
#include <cmath>
#include <filesystem>
#include <fstream>

#include "harness/compare.h"
#include "harness/pathtrace.h"
#include "harness/tables.h"
#include "structures/builtin_scenes.h"
#include "test_pathtrace_util.h"
#include "test_util.h"
#include "traversal/registry.h"

namespace tb {
namespace {

struct Fixture {
  Scene scene;
  StructureCache cache;
  std::unique_ptr<Traverser> tracer;
  Lighting lighting;
  Fixture() : scene(make_builtin_scene("room")), cache(scene) {
    scene.ensure_views();
    tracer = make_scheme("bvh_single");
    tracer->prepare(scene, cache);
    lighting = scene_lighting(scene);
  }
  PtImage render(PtMethod m, uint32_t spp, const std::string& salt, PtStats* st = nullptr, uint32_t size = 32) const {
    PtOptions o;
    o.width = o.height = size, o.spp = spp, o.salt = salt;
    return render_pathtrace(scene, *tracer, lighting, m, o, st);
  }
};

const Fixture& fixture() {
  static const Fixture f;
  return f;
}
// A converged image of the test scene: Ref at 1024 spp with its own random numbers.
const PtImage& converged() {
  static const PtImage img = fixture().render(PtMethod::ref, 1024, "converged");
  return img;
}

TEST(PathTrace, SameSeedSameImageOtherSaltOtherImage) {
  const Fixture& f = fixture();
  for (PtMethod m : {PtMethod::ref, PtMethod::pr, PtMethod::dpt, PtMethod::spt, PtMethod::ris, PtMethod::ris_mis}) {
    const PtImage a = f.render(m, 2, "x"), b = f.render(m, 2, "x"), c = f.render(m, 2, "y");
    EXPECT_EQ(a.rgb, b.rgb) << pt_method_name(m);
    EXPECT_NE(a.rgb, c.rgb) << pt_method_name(m);
    EXPECT_GT(pt_mean(a), 0.0) << pt_method_name(m) << ": the default light reaches the camera";
  }
}

TEST(PathTrace, DefaultLightingIsDocumentedShape) {
  const Fixture& f = fixture();
  EXPECT_EQ(f.lighting.source, "default");
  ASSERT_EQ(f.lighting.lights.size(), 1u);
  const AreaLight& l = f.lighting.lights[0];
  EXPECT_LT(l.n.y, -0.99f) << "the default light faces down (room's up is +y)";
  EXPECT_GT(l.area, 0.f);
  EXPECT_NE(f.lighting.hash(), Lighting{}.hash());
}

// The unbiased schemes estimate the same image: the mean over the image of K independent
// renderings per method agrees with Ref's within 4 standard errors (from the K renderings).
TEST(PathTrace, UnbiasedMethodsAgreeInMean) {
  const Fixture& f = fixture();
  constexpr int K = 4;
  auto stats_of = [&](PtMethod m) {
    double s = 0, s2 = 0;
    for (int k = 0; k < K; ++k) {
      const double v = pt_mean(f.render(m, 16, pt_method_name(m) + std::to_string(k)));
      s += v, s2 += v * v;
    }
    const double mean = s / K, var = std::max(0.0, (s2 - K * mean * mean) / (K - 1));
    return std::pair{mean, std::sqrt(var / K)};
  };
  const auto [ref_mean, ref_se] = stats_of(PtMethod::ref);
  for (PtMethod m : {PtMethod::pr, PtMethod::spt, PtMethod::ris, PtMethod::ris_mis}) {
    const auto [mean, se] = stats_of(m);
    const double tol = 4.0 * std::sqrt(ref_se * ref_se + se * se) + 1e-4 * ref_mean;
    EXPECT_NEAR(mean, ref_mean, tol) << pt_method_name(m);
  }
  // And with the converged image (Ref, 1024 spp, independent numbers).
  EXPECT_NEAR(pt_mean(converged()), ref_mean, 4.0 * ref_se + 1e-4 * ref_mean);
}

// rmse against the converged image falls as spp^-1/2: the least-squares slope of log rmse over
// log spp (2 .. 64; rmse^2 averaged over 3 independent renderings, since a 32x32 image's rmse is
// itself noisy) is -0.5 within 0.1 (the converged image's own noise, 1/16 of the variance at
// 64 spp, flattens it by ~0.01).
TEST(PathTrace, RmseFallsAsOneOverSqrtSpp) {
  const Fixture& f = fixture();
  for (PtMethod m : {PtMethod::ref, PtMethod::ris_mis}) {  // PR, SPT: Ref's paths (next test)
    std::vector<double> x, y;
    for (uint32_t spp = 2; spp <= 64; spp *= 2) {
      double mse = 0;
      for (int k = 0; k < 3; ++k) {
        const double e = pt_rmse(f.render(m, spp, pt_method_name(m) + "slope" + std::to_string(k)), converged());
        mse += e * e / 3;
      }
      x.push_back(std::log(double(spp)));
      y.push_back(0.5 * std::log(mse));
    }
    double mx = 0, my = 0;
    for (size_t i = 0; i < x.size(); ++i) mx += x[i] / x.size(), my += y[i] / y.size();
    double sxy = 0, sxx = 0;
    for (size_t i = 0; i < x.size(); ++i) sxy += (x[i] - mx) * (y[i] - my), sxx += (x[i] - mx) * (x[i] - mx);
    EXPECT_NEAR(sxy / sxx, -0.5, 0.1) << pt_method_name(m);
  }
}

// With the same random numbers, SPT and PR compute exactly Ref's paths (a path's generator is
// keyed by pixel and sample, not by the order of work): only the schedule differs.
TEST(PathTrace, SchedulesDoNotChangeThePaths) {
  const Fixture& f = fixture();
  const PtImage ref = f.render(PtMethod::ref, 4, "same");
  for (PtMethod m : {PtMethod::pr, PtMethod::spt}) {
    const PtImage img = f.render(m, 4, "same");
    EXPECT_LT(pt_rmse(img, ref), 1e-3) << pt_method_name(m) << ": only the order of the sums differs";
  }
}

// DPT (§6.3.2): a fixed 50% termination applied deterministically. Its mean is Ref's up to the
// truncation after log2(spp) + 1 segments (albedo 0.5: below 2% darker at 32 spp); its
// per-pixel variance (half the mean squared difference of two independent renderings, which
// cancels the truncation bias) is higher than Ref's albedo-based roulette where the albedo is high
// (0.8: DPT's weights 2^k x 0.8^k grow along the path where Ref's stay 1).
TEST(PathTrace, DptKeepsTheMeanAndRaisesTheVariance) {
  const Fixture& f = fixture();
  PtOptions o;
  o.width = o.height = 32, o.spp = 32;
  auto render = [&](const Lighting& l, PtMethod m, const std::string& salt) {
    o.salt = salt;
    return render_pathtrace(f.scene, *f.tracer, l, m, o);
  };
  Lighting dark = f.lighting, bright = f.lighting;
  dark.albedo = {0.5f, 0.5f, 0.5f}, bright.albedo = {0.8f, 0.8f, 0.8f};
  const double ref_mean = pt_mean(render(dark, PtMethod::ref, "m1")), dpt_mean = pt_mean(render(dark, PtMethod::dpt, "m2"));
  EXPECT_NEAR(dpt_mean / ref_mean, 1.0, 0.02);
  auto variance = [&](PtMethod m) {
    const double e = pt_rmse(render(bright, m, "v1"), render(bright, m, "v2"));
    return e * e / 2;
  };
  const double vr = variance(PtMethod::ref), vd = variance(PtMethod::dpt);
  EXPECT_GT(vd, 1.2 * vr) << "DPT " << vd << " Ref " << vr;
}

// The split by path vertex sums to the image; DPT at 8 spp has no vertex past d_max = 4 (its
// truncation bias is exactly the energy Ref finds there), Ref's roulette reaches past it.
TEST(PathTrace, ByDepthSumsToTheImageAndShowsDptsTruncation) {
  const Fixture& f = fixture();
  PtOptions o;
  o.width = o.height = 32, o.spp = 8, o.salt = "depth";
  for (PtMethod m : {PtMethod::ref, PtMethod::dpt, PtMethod::ris_mis}) {
    std::vector<PtImage> parts;
    const PtImage img = render_pathtrace(f.scene, *f.tracer, f.lighting, m, o, nullptr, &parts);
    ASSERT_EQ(parts.size(), size_t(kPtDepths));
    PtImage sum = img;
    std::fill(sum.rgb.begin(), sum.rgb.end(), 0.f);
    for (const PtImage& p : parts)
      for (size_t i = 0; i < sum.rgb.size(); ++i) sum.rgb[i] += p.rgb[i];
    EXPECT_LT(pt_rmse(sum, img), 1e-3) << pt_method_name(m);
    EXPECT_EQ(render_pathtrace(f.scene, *f.tracer, f.lighting, m, o).rgb, img.rgb) << "the split changes nothing";
    const double deep = pt_mean(parts[5]) + pt_mean(parts[6]);
    if (m == PtMethod::dpt) EXPECT_EQ(deep, 0.0);
    else EXPECT_GT(deep, 0.0) << pt_method_name(m);
    EXPECT_GT(pt_mean(parts[1]), pt_mean(parts[2])) << "the first bounce carries the most";
  }
}

// Every sample index gets the segment count of the thesis' list (spp = 16: 1 x8, 2 x4, 3 x2, 4, 5):
// DPT traces sum(d_max) extension rays per pixel at most.
TEST(PathTrace, DptSegmentBudget) {
  const Fixture& f = fixture();
  PtStats st;
  f.render(PtMethod::dpt, 16, "budget", &st);
  const uint64_t per_pixel = 8 * 1 + 4 * 2 + 2 * 3 + 4 + 5;
  EXPECT_LE(st.ext_rays, per_pixel * 32 * 32);
  EXPECT_GT(st.ext_rays, per_pixel * 32 * 32 / 2) << "the room is closed: most segments hit";
}

// Utilisation (the thesis' motivation for PR and SPT, §6.3): both keep more lanes busy than Ref.
TEST(PathTrace, RegenerationAndStreamingKeepMoreLanesActive) {
  const Fixture& f = fixture();
  PtStats ref, pr, spt;
  f.render(PtMethod::ref, 8, "u", &ref);
  f.render(PtMethod::pr, 8, "u", &pr);
  f.render(PtMethod::spt, 8, "u", &spt);
  EXPECT_GT(pr.util(), ref.util());
  EXPECT_GT(spt.util(), pr.util());
  EXPECT_GT(pr.warp_util(), ref.warp_util());
  EXPECT_GT(spt.warp_util(), 0.9);
  EXPECT_GE(ref.warp_util(), ref.util()) << "a warp that finished stops counting; a packet counts to its last ray";
}

// The capture hook (`travbench rays --pathtrace`): every traced batch, in order, extension then
// shadow per iteration, their rays the stats' counts; replaying them gives the frame's hits.
TEST(PathTrace, TracedBatchesAreTheFramesRays) {
  const Fixture& f = fixture();
  PtOptions o;
  o.width = o.height = 32, o.spp = 1, o.salt = "traced";
  std::vector<RayBatch> traced;
  o.traced = &traced;
  PtStats st;
  const PtImage img = render_pathtrace(f.scene, *f.tracer, f.lighting, PtMethod::ref, o, &st);
  ASSERT_FALSE(traced.empty());
  EXPECT_EQ(traced.front().workload, "pathtrace:ext");
  EXPECT_EQ(traced.front().size(), 32u * 32u) << "iteration 0: one camera ray per pixel";
  uint64_t ext = 0, shadow = 0;
  for (size_t i = 0; i < traced.size(); ++i) {
    const RayBatch& b = traced[i];
    (b.workload == "pathtrace:ext" ? ext : shadow) += b.size();
    EXPECT_EQ(b.packet_begin.back(), b.size());
    if (b.workload == "pathtrace:shadow") {
      ASSERT_GT(i, 0u);
      EXPECT_EQ(traced[i - 1].workload, "pathtrace:ext") << "a shadow batch follows its iteration's extension rays";
      EXPECT_EQ(traced[i - 1].depth, b.depth);
    }
  }
  EXPECT_EQ(ext, st.ext_rays);
  EXPECT_EQ(shadow, st.shadow_rays);
  EXPECT_GT(shadow, 0u);
  o.traced = nullptr;
  EXPECT_EQ(render_pathtrace(f.scene, *f.tracer, f.lighting, PtMethod::ref, o).rgb, img.rgb) << "capturing changes nothing";
}

TEST(PathTrace, BadInputIsAnError) {
  const Fixture& f = fixture();
  EXPECT_THROW(f.render(PtMethod::ref, 0, "x"), InputError);
  EXPECT_THROW(parse_pt_method("Bidir"), InputError);
  EXPECT_EQ(parse_pt_method("RIS/MIS"), PtMethod::ris_mis);
  PtOptions o;
  o.width = o.height = 8, o.view = 99;
  EXPECT_THROW(render_pathtrace(f.scene, *f.tracer, f.lighting, PtMethod::ref, o), InputError);
  PtImage a{2, 2, std::vector<float>(12)}, b{2, 1, std::vector<float>(6)};
  EXPECT_THROW(pt_rmse(a, b), InputError);
}

// The table: CSV rows method x spp, the converged image cached and reused (its sidecar states spp),
// and invalidated when the converged spp changes.
TEST(PathTrace, TableWritesRowsImagesAndReusesTheConvergedCache) {
  const auto dir = test::temp_dir("pathtrace_table");
  TableOptions opt = test::small_pathtrace_table(
      (dir / "pt.csv").string(), {{"min_spp", "2"}, {"max_spp", "4"}, {"ref_spp", "8"}, {"seeds", "2"}});
  ASSERT_EQ(run_table("pathtrace", opt), 0);
  std::ifstream csv(opt.csv);
  std::string line;
  int rows = -1;
  while (std::getline(csv, line)) ++rows;
  EXPECT_EQ(rows, 6 * 2) << "six methods x spp 2, 4";
  const CsvTable table = read_csv(opt.csv);
  auto col = [&](size_t row, const char* name) { return std::stod(table.at(row, table.column(name))); };
  for (size_t i = 0; i < table.rows.size(); ++i) {
    EXPECT_EQ(col(i, "seeds"), 2);
    EXPECT_GT(col(i, "rmse_sd"), 0.0) << "two independent renderings differ";
    EXPECT_GT(col(i, "noise_rmse"), 0.0);
    EXPECT_LE(col(i, "rmse_min"), col(i, "rmse_max"));
    EXPECT_LT(col(i, "rmse_corr"), col(i, "rmse_max")) << "the converged image's residual removed";
  }
  std::ifstream depth(dir / "pt.depth.csv");
  rows = -1;
  while (std::getline(depth, line)) ++rows;
  EXPECT_EQ(rows, 6 * 2 * int(kPtDepths)) << "method x spp x vertex";
  for (const char* png : {"pt_converged.png", "pt_ref.png", "pt_ris_mis.png", "pt_spt.png"})
    EXPECT_TRUE(std::filesystem::exists(dir / png)) << png;
  nlohmann::json side;
  std::ifstream(dir / "pt_converged.json") >> side;
  EXPECT_EQ(side["key"]["spp"], 8);
  EXPECT_GT(side["residual_rmse"].get<double>(), 0.0) << "two halves of 4 spp differ";
  const auto t0 = std::filesystem::last_write_time(dir / "pt_converged.bin");
  ASSERT_EQ(run_table("pathtrace", opt), 0);
  EXPECT_EQ(std::filesystem::last_write_time(dir / "pt_converged.bin"), t0) << "reused";
  opt.run.scheme_config.params["ref_spp"] = "16";
  ASSERT_EQ(run_table("pathtrace", opt), 0);
  std::ifstream(dir / "pt_converged.json") >> side;
  EXPECT_EQ(side["key"]["spp"], 16) << "re-rendered for the new spp";
  opt.run.scheme_config.params["min_spp"] = "8";
  EXPECT_THROW(run_table("pathtrace", opt), InputError) << "min_spp > max_spp";
}

}  // namespace
}  // namespace tb
