// Workload generation: Fig. 16 layout, determinism, packet bookkeeping, ray/hit file round trip.
#include <cstring>
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
    if (i < 64) EXPECT_TRUE(x < 8 && y < 8) << "first 64 rays are the first quadrant";
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

TEST(Workloads, DivergenceSpreadsRaysAroundTileCentre) {
  Bench bench(make_builtin_scene("room"));
  const RayBatch d1 = primary_rays(bench.scene(), test::small_spec("primary", 512), 1.f);
  const RayBatch d8 = primary_rays(bench.scene(), test::small_spec("primary", 512), 8.f);
  const uint32_t centre_packet = 15 * 32 + 15;  // a tile next to the image centre
  auto spread = [&](const RayBatch& b) {  // angle between two horizontally adjacent rays
    const Vec3 a = b.rays[b.packet_begin[centre_packet]].dir, c = b.rays[b.packet_begin[centre_packet] + 1].dir;
    return std::atan2(length(cross(a, c)), dot(a, c));
  };
  EXPECT_NEAR(spread(d8) / spread(d1), 8.f, 0.3f);
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
