// Workload generation: Fig. 16 layout, determinism, packet bookkeeping, ray/hit file round trip.
#include <cmath>
#include <cstring>
#include <numbers>
#include <fstream>
#include <set>

#include "test_util.h"
#include "workloads/ray_file.h"

namespace tb {
namespace {

TEST(Workloads, Fig16LayoutCoversTheTileOnce) {
  std::set<std::pair<uint32_t, uint32_t>> seen;
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t x, y;
    fig16_pixel(i, x, y);
    EXPECT_LT(x, 16u);
    EXPECT_LT(y, 16u);
    seen.insert({x, y});
    if (i < 64) {
      EXPECT_TRUE(x < 8 && y < 8) << "first 64 rays are the first quadrant";
    }
  }
  EXPECT_EQ(seen.size(), 256u);
  uint32_t x0, y0, x3, y3;
  fig16_pixel(0, x0, y0);
  fig16_pixel(3, x3, y3);
  EXPECT_EQ(x3 - x0, 1u);  // rays 0..3 form a 2x2 square
  EXPECT_EQ(y3 - y0, 1u);
}

TEST(Workloads, ParseErrorsNameTheProblem) {
  EXPECT_THROW(parse_workload("divergence:0"), InputError);
  EXPECT_THROW(parse_workload("divergence:x"), InputError);
  EXPECT_THROW(parse_workload("bounce"), InputError);
  EXPECT_THROW(parse_workload("primary:3"), InputError);
  EXPECT_THROW(parse_workload("hard:nope"), InputError);
  EXPECT_THROW(parse_workload("sideways"), InputError);
  EXPECT_EQ(parse_workload("divergence:8").name(), "divergence:8");
  EXPECT_EQ(parse_workload("bounce:3").param, 3);
}

TEST(Workloads, DeterministicAndPacketed) {
  Bench bench(make_builtin_scene("room"));
  for (const char* w : {"primary", "divergence:4", "rnd", "rnd2", "bounce:2", "shadow", "hard:inside"}) {
    const WorkloadSpec spec = test::small_spec(w, 80);
    const RayBatch a = generate_workload(bench.scene(), spec, closest_hits_of(bench.reference()));
    const RayBatch b = generate_workload(bench.scene(), spec, closest_hits_of(bench.reference()));
    ASSERT_EQ(a.size(), b.size()) << w;
    EXPECT_EQ(std::memcmp(a.rays.data(), b.rays.data(), a.size() * sizeof(Ray)), 0) << w;
    EXPECT_EQ(a.packet_begin, b.packet_begin) << w;
    EXPECT_GT(a.size(), 0u) << w;
    for (uint32_t p = 0; p < a.num_packets(); ++p) EXPECT_LE(a.packet_rays(p), 256u) << w;
    EXPECT_EQ(a.packet_begin.back(), a.size()) << w;
  }
  // 80x80 is not a multiple of 16: edge tiles are partial packets.
  const RayBatch p = generate_workload(bench.scene(), test::small_spec("primary", 80), closest_hits_of(bench.reference()));
  EXPECT_EQ(p.size(), 6400u);
  EXPECT_EQ(p.num_packets(), 25u);
  EXPECT_TRUE(p.common_origin);
}

TEST(Workloads, SeedChangesRandomRays) {
  Bench bench(make_builtin_scene("sphere"));
  WorkloadSpec s = test::small_spec("rnd2", 32);
  const RayBatch a = generate_workload(bench.scene(), s, closest_hits_of(bench.reference()));
  s.seed = 2;
  const RayBatch b = generate_workload(bench.scene(), s, closest_hits_of(bench.reference()));
  EXPECT_NE(std::memcmp(a.rays.data(), b.rays.data(), a.size() * sizeof(Ray)), 0);
}

// Thesis §3.4, Tables 2-4: "Divergence is in multiples of 0.034 degrees between adjacent rays" at
// 1280x800. On the thesis camera, the rays of the tile at the image centre are 0.034 D degrees apart
// from their right and lower neighbours (float rays; the pinhole's own distortion over D + 0.5
// pixels from the centre is below 1.3e-4 relative at D = 32).
TEST(Workloads, DivergenceIsInMultiplesOfTheThesisAngle) {
  Bench bench(make_builtin_scene("room"));
  WorkloadSpec spec = test::small_spec("primary", 16);
  spec.width = kThesisWidth, spec.height = kThesisHeight, spec.hfov_deg = thesis_hfov_deg();
  EXPECT_NEAR(centre_pixel_deg(bench.scene(), spec), kThesisRayDeg, 1e-9);
  const uint32_t centre_packet = (400 / 16) * (1280 / 16) + 640 / 16;  // its corner pixel is (640, 400)
  auto deg = [](Vec3 a, Vec3 b) {
    const double ax = a.x, ay = a.y, az = a.z, bx = b.x, by = b.y, bz = b.z;
    const double cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
    return std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz) * 180.0 / std::numbers::pi;
  };
  for (int d : {1, 2, 4, 8, 16, 32}) {
    const RayBatch b = primary_rays(bench.scene(), spec, float(d));
    ASSERT_EQ(b.size(), size_t(1280) * 800);
    const Ray* tile = &b.rays[b.packet_begin[centre_packet]];  // Fig. 16: rays 0, 1, 2 = (0,0), (1,0), (0,1)
    EXPECT_NEAR(deg(tile[0].dir, tile[1].dir), kThesisRayDeg * d, 5e-4 * kThesisRayDeg * d) << "D = " << d;
    EXPECT_NEAR(deg(tile[0].dir, tile[2].dir), kThesisRayDeg * d, 5e-4 * kThesisRayDeg * d) << "D = " << d;
  }
  // The views' own fields of view (55-70 degrees vertical) are not the thesis' camera.
  spec.hfov_deg = 0;
  EXPECT_GT(centre_pixel_deg(bench.scene(), spec), 2 * kThesisRayDeg);
}

// The tiles are scaled about their top-left corner (docs/WORKLOADS.md): the corner ray stays,
// the ray right of it moves to D pixels right of the corner, so tiles grow right and down only.
TEST(Workloads, DivergenceScalesAboutTheTileCorner) {
  Bench bench(make_builtin_scene("room"));
  for (uint32_t tile : {16u, 8u}) {
    WorkloadSpec spec = test::small_spec("primary", 64);
    spec.tile = tile;
    const RayBatch d1 = primary_rays(bench.scene(), spec, 1.f), d4 = primary_rays(bench.scene(), spec, 4.f);
    ASSERT_EQ(d1.size(), d4.size());
    for (uint32_t p = 0; p < d1.num_packets(); ++p) {
      const Ray* a = &d1.rays[d1.packet_begin[p]];
      const Ray* b = &d4.rays[d4.packet_begin[p]];
      // Fig. 16 order: ray 0 is pixel (0,0) of the packet, ray 1 (1,0), ray 8 (4,0).
      EXPECT_EQ(std::memcmp(&a[0].dir, &b[0].dir, sizeof(Vec3)), 0) << "packet " << p;
      EXPECT_EQ(std::memcmp(&a[8].dir, &b[1].dir, sizeof(Vec3)), 0) << "packet " << p << " tile " << tile;
    }
  }
}

// bounce:k/p: Russian roulette with survival p at each surface; p = 1 is plain bounce:k.
TEST(Workloads, RussianRouletteKeepsAFractionPOfThePathsPerBounce) {
  EXPECT_EQ(parse_workload("bounce:2/0.5").name(), "bounce:2/0.5");
  EXPECT_DOUBLE_EQ(parse_workload("bounce:2/0.5").survival, 0.5);
  EXPECT_EQ(parse_workload("bounce:2/1").name(), "bounce:2");
  for (const char* bad : {"bounce:2/0", "bounce:2/1.5", "bounce:2/x", "bounce:2/", "bounce:2/-0.5"})
    EXPECT_THROW(parse_workload(bad), InputError) << bad;
  Bench bench(make_builtin_scene("room"));  // closed: nearly every path bounces
  const RayBatch all = generate_workload(bench.scene(), test::small_spec("bounce:2", 64), closest_hits_of(bench.reference()));
  const RayBatch rr = generate_workload(bench.scene(), test::small_spec("bounce:2/0.5", 64), closest_hits_of(bench.reference()));
  // Expected 0.25 of the paths (about 1000 of 4096; 5 standard deviations either side).
  EXPECT_NEAR(double(rr.size()) / double(all.size()), 0.25, 0.04);
  EXPECT_EQ(rr.workload, "bounce:2/0.5");
}

TEST(Workloads, BounceRaysKeepTheirPixelsPacket) {
  Bench bench(make_builtin_scene("room"));
  const RayBatch b = generate_workload(bench.scene(), test::small_spec("bounce:1", 64), closest_hits_of(bench.reference()));
  EXPECT_EQ(b.depth, 1u);
  EXPECT_LE(b.num_packets(), 16u);  // 64x64 = 16 primary packets; paths only disappear
  EXPECT_GT(b.size(), 64u * 64u * 9 / 10);  // a closed room: nearly every path bounces
}

TEST(RayFile, RoundTripKeepsRaysAndPackets) {
  Bench bench(make_builtin_scene("room"));
  const auto dir = test::temp_dir("rayfile");
  for (const char* w : {"primary", "bounce:2"}) {
    const RayBatch& b = bench.rays(test::small_spec(w, 48));
    write_rays((dir / "r.bin").string(), b);
    const RayBatch c = read_rays((dir / "r.bin").string());
    ASSERT_EQ(b.size(), c.size());
    EXPECT_EQ(std::memcmp(b.rays.data(), c.rays.data(), b.size() * sizeof(Ray)), 0);
    EXPECT_EQ(b.packet_begin, c.packet_begin);
  }
  std::vector<Hit> hits = {{1.5f, 3, 0.25f, 0.5f}, {}};
  write_hits((dir / "h.bin").string(), hits);
  const auto back = read_hits((dir / "h.bin").string());
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].prim, 3u);
  EXPECT_EQ(back[1].prim, kNoHit);
  std::filesystem::remove_all(dir);
}

TEST(RayFile, BadFilesAreRejected) {
  const auto dir = test::temp_dir("badrays");
  auto write = [&](const std::string& name, const std::string& bytes) {
    std::ofstream((dir / name).string(), std::ios::binary) << bytes;
    return (dir / name).string();
  };
  RayBatch b;
  b.rays = {{{0, 0, 0}, 0, {0, 0, 1}, INFINITY}, {{0, 0, 0}, 0, {1, 0, 0}, INFINITY}};
  b.group_uniform(256);
  write_rays((dir / "good.bin").string(), b);
  std::ifstream in((dir / "good.bin").string(), std::ios::binary);
  std::string good((std::istreambuf_iterator<char>(in)), {});
  EXPECT_NO_THROW(read_rays((dir / "good.bin").string()));
  EXPECT_THROW(read_rays(write("trunc.bin", good.substr(0, good.size() - 5))), InputError);
  EXPECT_THROW(read_rays(write("short.bin", good.substr(0, 10))), InputError);
  std::string bad_magic = good;
  bad_magic[0] = 'X';
  EXPECT_THROW(read_rays(write("magic.bin", bad_magic)), InputError);
  std::string huge = good;
  const uint64_t big = ~uint64_t{0} / 2;
  std::memcpy(huge.data() + 8, &big, 8);
  EXPECT_THROW(read_rays(write("huge.bin", huge)), InputError);
  std::string nan_ray = good;
  const float nan = NAN;
  std::memcpy(nan_ray.data() + 24 + 12, &nan, 4);
  EXPECT_THROW(read_rays(write("nan.bin", nan_ray)), InputError);
  std::string zero_dir = good;
  const float zero[3] = {0, 0, 0};
  std::memcpy(zero_dir.data() + 24 + 12, zero, 12);
  EXPECT_THROW(read_rays(write("zero.bin", zero_dir)), InputError);
  EXPECT_THROW(read_rays(dir.string()), InputError);
  EXPECT_THROW(read_rays((dir / "missing.bin").string()), InputError);
  EXPECT_THROW(read_hits(write("hits.bin", "TBHITS1")), InputError);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tb
