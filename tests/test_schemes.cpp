// Every registered scheme against the reference on the built-in scenes and every workload
// (iterates the registry, so a new scheme is covered without touching this file).
#include <set>
#include <tuple>

#include "structures/bvh.h"
#include "traversal/embree_common.h"
#include "test_util.h"
#include "workloads/hard_cases.h"

namespace tb {
namespace {

class SchemeAccuracy : public ::testing::TestWithParam<std::string> {};
class SchemeRobustness : public ::testing::TestWithParam<std::string> {};

// One bench per scene for the whole suite: workloads and reference hits are generated once.
using test::bench_for;

const std::vector<std::string> kScenes = {"room", "stadium", "sphere", "spheres:20000"};
const std::vector<std::string> kWorkloads = {"primary", "divergence:8", "rnd", "rnd2", "bounce:1", "bounce:2", "shadow"};

TEST_P(SchemeAccuracy, MatchesReferenceOnOrdinaryWorkloads) {
  for (const auto& scene : kScenes) {
    Bench& bench = bench_for(scene);
    for (const auto& w : kWorkloads) {
      const Accuracy a = test::accuracy_of(bench, GetParam(), test::small_spec(w, 96));
      // The accuracy bar: mismatch <= 1e-5. On ~9k rays a single grazing silhouette ray is
      // already 1e-4, so allow at most one mismatch and never a leak.
      EXPECT_LE(a.mismatches, 1u) << GetParam() << " on " << scene << " / " << w << ": rate " << a.mismatch_rate();
      EXPECT_EQ(a.false_miss, 0u) << GetParam() << " on " << scene << " / " << w;
    }
  }
}

// The scaling and build tables report each scheme's memory: every scheme (baselines included,
// through Embree's memory monitor) must report at least its triangle references and no absurd
// amount; schemes sharing one structure report the same bytes.
TEST_P(SchemeAccuracy, ReportsItsStructureMemory) {
  Bench& bench = bench_for("room");
  auto t = make_scheme(GetParam());
  t->prepare(bench.scene(), bench.cache());
  const size_t tris = bench.scene().num_triangles();
  EXPECT_GE(t->structure_bytes(), tris * 12) << GetParam();
  EXPECT_LE(t->structure_bytes(), tris * 1024) << GetParam();
  if (GetParam() == "bvh_masked" || GetParam() == "bvh_ranged" || GetParam() == "bvh_partition") {
    auto single = make_scheme("bvh_single");
    single->prepare(bench.scene(), bench.cache());
    EXPECT_EQ(t->structure_bytes(), single->structure_bytes()) << GetParam();
  }
}

// `run --stats` reports node_bytes and prim_bytes from memory(): every scheme has nonzero node
// bytes, the split adds up to structure_bytes(), and the compressed BVH's nodes take at most 0.35x
// of mbvh8_single's (issue 19).
TEST(StructureBytes, SplitIntoNodesAndPrimsInRunStats) {
  Bench& bench = bench_for("room");
  RunOptions opt;
  opt.reps = 1, opt.stats = true, opt.progress = false, opt.width = opt.height = 16;
  opt.workloads = {"primary"};
  for (const auto& s : schemes()) opt.schemes.push_back(s.name);
  std::map<std::string, uint64_t> nodes;
  for (const Record& r : run_experiment(bench, opt)) {
    const std::string scheme = *r.get("scheme");
    ASSERT_TRUE(r.get("node_bytes") && r.get("prim_bytes")) << scheme;
    nodes[scheme] = std::stoull(*r.get("node_bytes"));
    EXPECT_GT(nodes[scheme], 0u) << scheme;
    auto t = make_scheme(scheme);
    t->prepare(bench.scene(), bench.cache());
    EXPECT_EQ(nodes[scheme] + std::stoull(*r.get("prim_bytes")), t->structure_bytes()) << scheme;
  }
  EXPECT_LE(double(nodes.at("cwbvh_single")), 0.35 * double(nodes.at("mbvh8_single")));
}

// Our schemes with their default kernels: not one leak on the must-hit workloads, also with the
// geometry translated to ~1e5 and ~1e6. (Embree is a baseline: its leak rate is reported by
// `travbench table accuracy`; Embree 3.13 in robust mode still leaks at exact vertex hits.)
TEST_P(SchemeRobustness, NoLeaksOnMustHitHardCases) {
  for (const std::string scene : {"sphere", "room", "sphere@148376,1234,-223423", "sphere@1483760,12340,-2234230",
                                   "room@-250000,100000,730000"}) {
    Bench& bench = bench_for(scene);
    for (const auto& w : hard_case_names()) {
      const WorkloadSpec spec = test::small_spec(w, 96);
      const Accuracy a = test::accuracy_of(bench, GetParam(), spec);
      if (hard_case_must_hit(w)) {
        EXPECT_EQ(a.false_miss, 0u) << GetParam() << " leaks on " << scene << " / " << w;
        // Without an offset every ray starts strictly inside a closed mesh; with one, float
        // quantisation can put origins on surfaces, so there only the comparison counts.
        const auto& ref = bench.reference_hits(spec);
        if (scene.find('@') == std::string::npos) {
          EXPECT_TRUE(std::all_of(ref.begin(), ref.end(), [](const Hit& h) { return h.hit(); }))
              << "reference misses on must-hit " << scene << " / " << w;
        }
      } else if (w == "hard:tmin_tmax") {
        EXPECT_EQ(a.false_hit, 0u) << GetParam() << " reports a hit in an empty interval";
      }
    }
  }
}

// ---- Registry-level checks: a scheme's name is written in schemes.def, in make_<name> and in its
// name(); its parameters in params_<name>() and where the constructor reads them. These tie them.

TEST(Registry, NamesAgreeAndEverySchemeIsMadeFromItsDeclaredDefaults) {
  for (const auto& s : schemes()) {
    // make_scheme resolves the declared defaults; a constructor that reads an undeclared key (or a
    // key without a default through get_*) throws std::logic_error here.
    std::unique_ptr<Traverser> t;
    ASSERT_NO_THROW(t = make_scheme(s.name)) << s.name;
    EXPECT_EQ(std::string(t->name()), s.name) << "schemes.def and name() disagree";
    std::set<std::string> seen;
    for (const auto& p : s.params) {
      EXPECT_TRUE(seen.insert(p.name).second) << s.name << " declares " << p.name << " twice";
      EXPECT_FALSE(p.doc.empty()) << s.name << " " << p.name;
      if (p.fallback.empty()) continue;  // default depends on another parameter
      EXPECT_NO_THROW(p.check(p.fallback)) << s.name << " " << p.name << "'s default is outside its range";
      // Given explicitly at its default, every parameter is accepted.
      SchemeConfig c;
      c.params[p.name] = p.fallback;
      EXPECT_NO_THROW(make_scheme(s.name, c)) << s.name << " " << p.name << "=" << p.fallback;
    }
  }
}

// The InputError message make_scheme refuses `c` with (a test failure if it accepts it).
std::string refusal(const char* scheme, const SchemeConfig& c) {
  try {
    make_scheme(scheme, c);
  } catch (const InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << scheme << " accepted the config";
  return {};
}

TEST(Registry, UnknownParameterIsAnErrorNamingTheClosestKey) {
  SchemeConfig c;
  c.params["leafsize"] = "8";
  const std::string m = refusal("bvh_single", c);
  EXPECT_NE(m.find("did you mean leaf_size"), std::string::npos) << m;
  EXPECT_NE(m.find("bins"), std::string::npos) << "names the valid keys: " << m;
  c.params = {{"zzzzzz", "1"}};
  const std::string far = refusal("reference", c);
  EXPECT_FALSE(far.empty());
  EXPECT_EQ(far.find("did you mean"), std::string::npos) << "nothing is close: " << far;
  EXPECT_EQ(closest_name("Leaf-Size", {"bins", "leaf_size"}), "leaf_size");
  EXPECT_EQ(closest_name("tricul", {"split", "tricull", "last"}), "tricull");
}

TEST(Registry, ValuesAreCheckedAgainstTheirDeclaredTypeAndRange) {
  const std::vector<std::tuple<std::string, std::string, std::string>> bad = {
      {"bvh_single", "leaf_size", "0"},  {"bvh_single", "leaf_size", "65"},   {"bvh_single", "leaf_size", "4.5"},
      {"bvh_single", "bins", "x"},       {"bvh_masked", "split", "2"},        {"mbvh8_single", "collapse", "best"},
      {"mbvh8_single", "tri_width", "6"}, {"mbvh_rs", "width", "16"},         {"raygrid", "queue", "0"},
      {"kd_single", "kd_ct", "nan"},     {"kd_packet", "kd_packet", "12"},     {"embree_single", "robust", "yes"},
      {"mbvh4_single", "small", "2"},    {"bvh_ranged", "tricull", "-1"},
      // 4-wide leaf blocks: `small` (which leaves of 8-wide blocks take a 4-wide one) only takes 0.
      {"mbvh4_single", "small", "4"},    {"mbvh_rs", "small", "4"},
      // Leaves a compressed BVH cannot hold (more than 16 triangles), also treelet_queue's default tree.
      {"cwbvh_single", "merge", "17"},   {"cwbvh_single", "leaf_size", "17"}, {"treelet_queue", "merge", "17"}};
  for (const auto& [scheme, key, value] : bad) {
    SchemeConfig c;
    c.params[key] = value;
    EXPECT_THROW(make_scheme(scheme, c), InputError) << scheme << " " << key << "=" << value;
  }
  const std::vector<std::tuple<std::string, std::string, std::string>> good = {
      {"bvh_single", "leaf_size", "1"}, {"bvh_single", "leaf_size", "64"}, {"bvh_masked", "split", "true"},
      {"mbvh_rs", "merge", "16"},       {"mbvh_rs", "collapse", "sah"},     {"kd_single", "kd_ct", "3.5"},
      {"mbvh8_single", "small", "4"},   {"mbvh_rs", "small", "0"}};
  for (const auto& [scheme, key, value] : good) {
    SchemeConfig c;
    c.params[key] = value;
    EXPECT_NO_THROW(make_scheme(scheme, c)) << scheme << " " << key << "=" << value;
  }
  {  // treelet_queue's MBVH8 tree takes the leaves its compressed tree refuses
    SchemeConfig c;
    c.params = {{"tree", "mbvh8"}, {"merge", "17"}};
    EXPECT_NO_THROW(make_scheme("treelet_queue", c));
  }
  // The refusal names the range in full (not 1.04858e+06 for 2^20).
  SchemeConfig c;
  c.params["rays_in_flight"] = "0";
  const std::string m = refusal("treelet_queue", c);
  EXPECT_NE(m.find("integer in [1, 1048576]"), std::string::npos) << m;
}

// The split_* parameters steer spatial splits only: without them (spatial=0, the binary BVH
// schemes' default) a value other than the default is refused rather than ignored; with
// spatial=1 it is taken. (Every split_* default is non-zero except split_overlap's.)
TEST(Registry, SpatialSplitParametersAreRefusedWithoutSpatialSplits) {
  for (const char* key : {"split_alpha", "split_overlap", "split_budget", "split_wall", "split_walls"}) {
    SchemeConfig off;
    off.params[key] = std::string(key) == "split_overlap" ? "0.5" : "0";
    try {
      make_scheme("bvh_single", off);
      ADD_FAILURE() << key << " accepted with spatial=0";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("bvh_single"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("spatial=1"), std::string::npos) << e.what();
    }
    off.params["spatial"] = "0";
    EXPECT_THROW(make_scheme("mbvh8_single", off), InputError) << key;
    SchemeConfig on = off;
    on.params["spatial"] = "1";
    EXPECT_NO_THROW(make_scheme("bvh_single", on)) << key;
    SchemeConfig dflt;  // mbvh8_single builds spatial splits by default
    dflt.params[key] = "0";
    EXPECT_NO_THROW(make_scheme("mbvh8_single", dflt)) << key;
  }
}

// mbvh_rs's `spatial` default follows its width: the 8-wide streams trace the spatial-split tree,
// the thesis' 4-wide layout the plain one. The tree built is the one the explicit value builds
// (same structure bytes, which spatial splits change on the room), and split_* is taken or refused
// by the resolved value.
TEST(Registry, MbvhRsSpatialDefaultFollowsItsWidth) {
  Bench& bench = bench_for("room");
  const auto bytes = [&](const std::string& entry) {
    auto t = make_scheme(entry);
    t->prepare(bench.scene(), bench.cache());
    return t->structure_bytes();
  };
  EXPECT_EQ(resolve_config("mbvh_rs", {}).find_bool("spatial"), std::nullopt);  // depends on width
  EXPECT_EQ(bytes("mbvh_rs"), bytes("mbvh_rs:spatial=1"));
  EXPECT_NE(bytes("mbvh_rs"), bytes("mbvh_rs:spatial=0"));
  EXPECT_EQ(bytes("mbvh_rs:width=4"), bytes("mbvh_rs:width=4:spatial=0"));
  EXPECT_NE(bytes("mbvh_rs:width=4"), bytes("mbvh_rs:width=4:spatial=1"));
  EXPECT_NO_THROW(make_scheme("mbvh_rs:split_budget=2"));
  EXPECT_THROW(make_scheme("mbvh_rs:width=4:split_budget=2"), InputError);
}

// builder=embree (structures/embree_bvh.h) takes spatial, split_budget, leaf_size and the costs;
// travbench's own builder knobs (bins, split_alpha, split_overlap, split_wall, split_walls) would
// change nothing there and are refused, as is a leaf size Embree cannot build.
TEST(Registry, EmbreeBuilderRefusesTravbenchBuilderParameters) {
  for (const char* key : {"bins", "split_alpha", "split_overlap", "split_wall", "split_walls"}) {
    SchemeConfig c;
    c.params["builder"] = "embree";
    c.params[key] = std::string(key) == "bins" ? "8" : std::string(key) == "split_overlap" ? "0.5" : "0";
    try {
      make_scheme("mbvh8_single", c);
      ADD_FAILURE() << key << " accepted with builder=embree";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("builder=embree"), std::string::npos) << e.what();
    }
    c.params["builder"] = "travbench";
    EXPECT_NO_THROW(make_scheme("mbvh8_single", c)) << key;
  }
  SchemeConfig ok;
  ok.params["builder"] = "embree";
  ok.params["spatial"] = "1";
  ok.params["split_budget"] = "0.5";
  ok.params["leaf_size"] = "32";
  EXPECT_NO_THROW(make_scheme("bvh_single", ok));
  ok.params["leaf_size"] = "33";
  EXPECT_THROW(make_scheme("bvh_single", ok), InputError);
}

// `--param isa=NAME` (issue 17: like-for-like Embree comparisons across machines) runs Embree's
// kernels for that ISA: sse2 exists on every x86-64 CPU and selects Embree's 4-wide BVH, a
// different kernel from the default's, which must still match the reference; a name Embree does
// not know is refused (Embree itself would fall back to SSE2 silently).
TEST(EmbreeIsa, ExplicitIsaMatchesTheReferenceAndUnknownNamesAreRefused) {
  Bench& bench = bench_for("stadium");
  for (const std::string isa : {"sse2", "default"}) {
    SchemeConfig c;
    c.params["isa"] = isa;
    for (const auto& w : {"primary", "bounce:2"}) {
      const Accuracy a = test::accuracy_of(bench, "embree_single", test::small_spec(w, 64), c);
      EXPECT_LE(a.mismatches, 1u) << isa << " " << w;
      EXPECT_EQ(a.false_miss, 0u) << isa << " " << w;
    }
  }
  // The ISA took effect: SSE2's BVH4 takes other node bytes than the BVH8 that an AVX2 CPU (the
  // suite's minimum) gets by default.
  StructureBytes bytes[2];
  for (int i = 0; i < 2; ++i) {
    SchemeConfig c;
    c.params["isa"] = i ? "sse2" : "default";
    auto t = make_scheme("embree_single", c);
    t->prepare(bench.scene(), bench.cache());
    bytes[i] = t->memory();
  }
  EXPECT_NE(bytes[0].nodes, bytes[1].nodes);
  SchemeConfig bad;
  bad.params["isa"] = "avx512skx";
  EXPECT_THROW(make_scheme("embree_single", bad), InputError);
  EXPECT_THROW(embree_device("avx3"), InputError);
}

TEST(Registry, RunParametersNeedOneSchemeOfTheRunThatDeclaresThem) {
  SchemeConfig c;
  c.params = {{"leaf_size", "8"}, {"robust", "0"}};
  EXPECT_NO_THROW(check_run_params({"bvh_single", "embree_single"}, c));
  EXPECT_THROW(check_run_params({"bvh_single"}, c), InputError);  // robust: only Embree's
  const SchemeConfig e = config_for("embree_single", c);
  EXPECT_EQ(e.params, (std::map<std::string, std::string>{{"robust", "0"}}));
  const SchemeConfig b = config_for("bvh_single", c);
  EXPECT_EQ(b.params, (std::map<std::string, std::string>{{"leaf_size", "8"}}));
  // A caller's own parameters (a table's) count too, and are checked against their spec.
  const ParamSpecs sweep = {bool_param("sweep", false, "table switch")};
  c.params = {{"sweep", "1"}};
  EXPECT_NO_THROW(check_run_params({"raygrid"}, c, sweep));
  c.params = {{"sweep", "3"}};
  EXPECT_THROW(check_run_params({"raygrid"}, c, sweep), InputError);
}

// A scheme entry NAME:KEY=VALUE[:KEY=VALUE...] carries parameters of its own: they override the
// run's for that entry alone, are checked against what the scheme declares, and the entry makes
// the registered scheme (so one run can hold embree_single and embree_single:robust=0).
TEST(Registry, SchemeEntriesCarryTheirOwnParameters) {
  SchemeConfig run;
  run.params = {{"leaf_size", "8"}, {"robust", "1"}};
  const SchemeConfig e = config_for("embree_single:robust=0", run);
  EXPECT_EQ(e.params, (std::map<std::string, std::string>{{"robust", "0"}}));
  const SchemeConfig b = config_for("bvh_single:leaf_size=2:bins=8", run);
  EXPECT_EQ(b.params, (std::map<std::string, std::string>{{"bins", "8"}, {"leaf_size", "2"}}));
  EXPECT_EQ(scheme_name_of("bvh_single:leaf_size=2"), "bvh_single");
  EXPECT_EQ(make_scheme("bvh_single:leaf_size=2")->name(), "bvh_single");
  EXPECT_EQ(resolve_config("bvh_single:leaf_size=2", {}).params.at("leaf_size"), "2");
  EXPECT_EQ(expand_scheme_list("embree_single,embree_single:robust=0"),
            (std::vector<std::string>{"embree_single", "embree_single:robust=0"}));
  EXPECT_THROW(check_run_params({"bvh_single:leaf_size=2"}, run), InputError);  // robust: only Embree's
  EXPECT_NO_THROW(check_run_params({"bvh_single:leaf_size=2", "embree_single:robust=0"}, run));
  for (const char* bad : {"bvh_single:robust=0", "embree_single:robust=2", "embree_single:robust", "embree_single:=1",
                          "embree_single:", "embree_singl:robust=0"})
    EXPECT_THROW(expand_scheme_list(bad), InputError) << bad;
}

TEST(Registry, ResolvedConfigHoldsDefaultsAndRefusesUndeclaredReads) {
  const SchemeConfig c = resolve_config("bvh_single", {});
  EXPECT_EQ(c.get_int("leaf_size"), BVHBuildParams{}.max_leaf);
  EXPECT_EQ(c.get_int("bins"), BVHBuildParams{}.bins);
  EXPECT_THROW(c.get_int("queue"), std::logic_error);
  SchemeConfig given;
  given.params["merge"] = "12";
  const SchemeConfig rs = resolve_config("mbvh_rs", given);
  EXPECT_EQ(rs.find_int("merge"), 12);
  EXPECT_EQ(resolve_config("mbvh_rs", {}).find_int("merge"), std::nullopt);  // depends on width
}

INSTANTIATE_TEST_SUITE_P(Registry, SchemeAccuracy, ::testing::ValuesIn(test::schemes_under_test()),
                         [](const auto& info) { return info.param; });
INSTANTIATE_TEST_SUITE_P(Registry, SchemeRobustness, ::testing::ValuesIn(test::schemes_under_test(true)),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace tb
