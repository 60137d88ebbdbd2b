// `travbench table build`: thesis Table 1 (§3.2: BVH rebuild and refit "for a group of 4 objects,
// with a combined triangle count of 44k, 88k and 388k triangles, using 1 thread and 4 threads")
// as the thesis ran it — four objects with their own BVHs under a top-level BVH
// (structures/two_level.h, Alg. 3.1) — plus the build time and memory of every scheme's structure
// and of Embree's three build qualities, on the --scene.
#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <ctime>
#include <cstdio>
#include <memory>
#include <thread>
#include <malloc.h>
#include <sys/resource.h>
#include <vector>

#include "harness/tables.h"
#include "harness/thesis_reference.h"
#include "structures/builtin_scenes.h"
#include "structures/bvh.h"
#include "structures/two_level.h"
#include "traversal/embree_common.h"
#include "traversal/registry.h"

namespace tb {
namespace {

double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

// The 1-minute load average (/proc/loadavg; -1 where unreadable): how many runnable threads shared
// the cores while a Table 1 row was timed, so its thread speed-ups can be read against it.
double load_average() {
  double l = -1;
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf", &l) != 1) l = -1;
    std::fclose(f);
  }
  return l;
}

// The process's page faults so far (minor and major; getrusage).
long process_page_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt + u.ru_majflt;
}

struct Timing {
  double wall_ms, cpu_ms;  // medians over the reps
  long page_faults;        // ... and of the pages each rep faulted in
};

// Wall clock and process CPU time: on a shared machine a single-threaded build's CPU time is
// stable to ~0.5% while its wall time moves by ~30% with the load (measured on the 2-core VM).
// The CPU time includes the kernel's time for the build's page faults (every rep builds into
// fresh memory: the structures of earlier reps are kept), which on a virtual machine can cost
// microseconds each and move with the host: `build_page_faults` says how much of a build is
// exposed to that (docs/PERFORMANCE.md, session 28).
// warm (table build's `warm` parameter): one untimed build first, and before each timed build
// `release` frees the previous one, outside the timer, so every timed build reuses memory the
// allocator already holds, as a per-frame rebuild does. Otherwise (cold) the builds are kept until
// all are timed and the allocator's free memory is returned to the system before each, so each
// writes memory it has not touched before (the faults of `build_page_faults`), ours and Embree's.
// Table 1's frames (the two-level rows) take neither: a frame's rebuild frees the previous frame's
// structures inside its timed step, so the frames after the first run in memory the process holds,
// as a renderer's frames do.
enum class BuildMemory { frames, cold, warm };
template <class F, class R>
Timing median_ms(int reps, F&& f, R&& release, BuildMemory mem) {
  const bool warm = mem == BuildMemory::warm;
  std::vector<double> wall, cpu;
  std::vector<long> faults;
  if (warm) f(), release();
  for (int r = 0; r < std::max(1, reps); ++r) {
    if (warm && r > 0) release();
#if defined(__GLIBC__)
    // Cold: the allocator's free memory goes back to the system first, so this build faults in
    // every page it uses, whichever rows ran before it (without this, Embree's rows, which run
    // last, built into memory our rows had freed: 0-15 faults against our 200-5000, a bias of up
    // to 0.8x in the spatial-split ratio on small scenes; docs/PERFORMANCE.md, session 29).
    if (mem == BuildMemory::cold) malloc_trim(0);
#endif
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = process_cpu_ms();
    const long f0 = process_page_faults();
    f();
    cpu.push_back(process_cpu_ms() - c0);
    faults.push_back(process_page_faults() - f0);
    wall.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(wall.begin(), wall.end());
  std::sort(cpu.begin(), cpu.end());
  std::sort(faults.begin(), faults.end());
  return {wall[wall.size() / 2], cpu[cpu.size() / 2], faults[faults.size() / 2]};
}
template <class F>
Timing median_ms(int reps, F&& f) {
  return median_ms(reps, f, [] {}, BuildMemory::frames);
}

// The first n triangles of a mesh, its vertices compacted: a piece of the model of the size a
// Table 1 row needs (the Stanford models are decimated to ~100k triangles).
Scene triangle_prefix(const Scene& s, size_t n, const std::string& name) {
  Scene out;
  out.name = name;
  std::map<uint32_t, uint32_t> remap;
  for (size_t t = 0; t < std::min(n, s.num_triangles()); ++t) {
    std::array<uint32_t, 3> tri{};
    for (int c = 0; c < 3; ++c) {
      auto [it, fresh] = remap.emplace(s.triangles[t][size_t(c)], uint32_t(out.positions.size()));
      if (fresh) out.positions.push_back(s.positions[s.triangles[t][size_t(c)]]);
      tri[size_t(c)] = it->second;
    }
    out.triangles.push_back(tri);
  }
  return out;
}

// Table 1's group: four objects of total/4 triangles each, pieces of the Stanford models found
// beside the --scene file (or in ../shared/scenes, or beside TRAVBENCH_REFERENCE_DIR): the first
// four of lucy, dragon, buddha, bunny, lucy, dragon, ... that have that many triangles (bunny's
// 69k are too few for the 388k row, where a second Lucy takes its place). Without the models,
// spheres:total/4 meshes, labelled. Each object is scaled to unit size, turned by 45 degrees more than the last and set in a row.
struct Group {
  TwoLevelBVH tl;
  std::string objects;  // what the four objects are, for the CSV
};
Group make_group(size_t total, const std::string& scene_arg) {
  namespace fs = std::filesystem;
  std::vector<fs::path> dirs;
  if (fs::is_regular_file(scene_arg)) dirs.push_back(fs::path(scene_arg).parent_path());
  dirs.push_back("../shared/scenes");
  // The scenes lie beside the thesis tables (../shared/{reference,scenes}): a checkout elsewhere
  // that points TRAVBENCH_REFERENCE_DIR at them finds the models too.
  if (const char* ref = std::getenv("TRAVBENCH_REFERENCE_DIR")) dirs.push_back(fs::path(ref).parent_path() / "scenes");
  const size_t each = total / 4;
  std::vector<Scene> meshes;
  std::string names;
  for (const fs::path& d : dirs) {
    if (!fs::is_regular_file(d / "lucy_100k.obj")) continue;
    std::map<std::string, Scene> loaded;
    const char* order[] = {"lucy_100k", "dragon_100k", "buddha_100k", "bunny"};
    for (int k = 0; meshes.size() < 4 && k < 16; ++k) {
      const std::string m = order[k % 4];
      if (!fs::is_regular_file(d / (m + ".obj"))) continue;
      if (!loaded.count(m)) loaded[m] = load_scene((d / (m + ".obj")).string());
      if (loaded[m].num_triangles() < each) continue;
      meshes.push_back(triangle_prefix(loaded[m], each, m));
      names += (names.empty() ? "" : "+") + m;
    }
    break;
  }
  if (meshes.size() < 4) {
    meshes.clear();
    names = "spheres:" + std::to_string(each) + " x4 (Stanford models not found)";
    for (int k = 0; k < 4; ++k) meshes.push_back(make_builtin_scene("spheres:" + std::to_string(each)));
  }
  Group g;
  g.objects = names + " (first " + std::to_string(each) + " triangles each)";
  for (size_t k = 0; k < meshes.size(); ++k) {
    const AABB b = meshes[k].bounds();
    const float s = 1.f / std::max(length(b.extent()), 1e-20f);
    const uint32_t o = g.tl.add_object(std::move(meshes[k]));
    // rotate_y_scale_translate maps p to R(s p) + d: d = (1.5 k, 0, 0) - R(c) keeps the object's
    // centre at (1.5 k, 0, 0).
    Affine a = Affine::rotate_y_scale_translate(45.f * float(k), s, {0, 0, 0});
    a.t = Vec3{1.5f * float(k), 0, 0} - a.vector(b.centre());
    g.tl.add_instance(o, a);
  }
  return g;
}

}  // namespace

int build_table(const TableOptions& opt) {
  // Everything the table is asked for is checked, and the scene loaded, before the two-level
  // builds below take their minutes.
  // Each repetition rebuilds every structure of the table (minutes on the big scenes): at most 5,
  // refused above rather than capped without a word.
  if (opt.run.reps > 5)
    throw InputError("table build takes --reps 1..5 (each repetition rebuilds every structure), not " +
                     std::to_string(opt.run.reps));
  const ParamSpecs table_params = {
      bool_param("warm", false,
                 "time the structure builds in a warm process: one untimed build of each first, and each timed build's "
                 "predecessor freed before its timer starts, so every build reuses memory the allocator holds (as a "
                 "per-frame rebuild does); 0: a structure's timed builds are kept until all are timed and the "
                 "allocator's free memory is returned to the system before each, so every build, ours and Embree's, "
                 "faults in the memory it uses"),
      bool_param("two_level", true,
                 "the thesis' Table 1 rows (two-level BVHs of 4 objects, rebuild and refit, 44k-388k triangles; most "
                 "of the table's time); 0: only the scheme and Embree rows (scripts/build_goal.py's rounds)")};
  const std::vector<std::string> names = default_schemes(opt, {}, table_params);
  const bool warm = param_to_bool(table_param(opt, table_params, "warm"));
  const BuildMemory mem = warm ? BuildMemory::warm : BuildMemory::cold;
  const bool two_level = param_to_bool(table_param(opt, table_params, "two_level"));
  for (const auto& name : names)
    if (!opt.run.schemes.empty() && find_scheme(name).baseline)
      throw InputError("table build does not take --schemes " + name + ": it times our schemes' structure builds; "
                       "Embree's builds are its own rows (embree low, medium, high, high fast)");
  const Scene scene = load_scene(opt.scene.empty() ? "room" : opt.scene);
  const ThesisTable thesis = load_thesis_table("table01_build_refit.csv");
  const int hw = int(std::thread::hardware_concurrency());
  const int reps = std::max(1, opt.run.reps);
  std::vector<Record> records;
  // Table 1, per frame (Alg. 3.1): "rebuild" rebuilds the four objects' BVHs and then the top
  // level; "refit" refits the four objects' BVHs (deforming objects: same topology, moved
  // vertices) and then builds the top level, as the thesis builds a new top level every frame.
  // Both with spatial splits in the object builds (the thesis' builder considers a spatial split
  // at each bin plane, §3.2) and with plain binned SAH (its fast builder for dynamic objects).
  // top_build_ms / top_refit_ms: the top level alone (rigid motion: CS348K's two-level BVH, the
  // objects' BVHs built once). 4 threads are measured on this machine's `hardware_threads`
  // (2 here): the sidecar and the threads_note column say so. The vertices are not moved between
  // repetitions (a refit's work does not depend on where they are), and a rebuild frees the
  // previous frame's BVHs inside the timed step, as a per-frame rebuild does.
  for (const char* tris : {"44000", "88000", "388000"}) {
    if (!two_level) break;
    Group g = make_group(size_t(std::stoul(tris)), opt.scene);
    TwoLevelBVH& tl = g.tl;
    for (bool spatial : {true, false}) {
      for (int threads : {1, 4}) {
        BVHBuildParams p;
        p.spatial = spatial;
        const Timing build = median_ms(reps, [&] {
          tl.build_objects(p, threads);
          tl.build_top();
        });
        const Timing refit = median_ms(reps, [&] {
          tl.refit_objects(threads);
          tl.build_top();
        });
        const Timing top_build = median_ms(reps, [&] { tl.build_top(); });
        const Timing top_refit = median_ms(reps, [&] { tl.refit_top(); });
        const std::string tcol = threads == 1 ? "1t" : "4t";
        Record r;
        r.set("structure", std::string("two-level, 4 objects, ") + (spatial ? "spatial splits" : "binned SAH"));
        r.set("scene", std::string("group:") + tris).set("objects", g.objects).set("triangles", uint64_t(tl.num_triangles()));
        r.set("threads", threads).set("build_ms", build.wall_ms).set("refit_ms", refit.wall_ms);
        r.set("top_build_ms", top_build.wall_ms).set("top_refit_ms", top_refit.wall_ms).set("bytes", uint64_t(tl.bytes()));
        r.set("build_cpu_ms", build.cpu_ms).set("refit_cpu_ms", refit.cpu_ms).set("loadavg", load_average());
        if (threads > hw)
          r.set("threads_note", std::to_string(threads) + " threads on " + std::to_string(hw) + " hardware threads");
        if (auto v = thesis.lookup({"triangles"}, {tris}, "rebuild_" + tcol + "_ms")) r.set("thesis_ms", *v);
        if (auto v = thesis.lookup({"triangles"}, {tris}, "refit_" + tcol + "_ms")) r.set("thesis_refit_ms", *v);
        r.set("thesis_threads", tcol);
        std::fprintf(stderr, "two-level %s tris %s, %d thread(s): rebuild %.1f ms, refit %.1f ms, top %.3f / %.3f ms\n",
                     tris, spatial ? "spatial" : "binned", threads, build.wall_ms, refit.wall_ms, top_build.wall_ms,
                     top_refit.wall_ms);
        records.push_back(std::move(r));
      }
    }
  }
  // Every scheme's structure (prepare() on a fresh cache) and Embree's build qualities.
  for (const auto& name : names) {
    if (find_scheme(name).baseline) continue;
    // Structures are kept alive until after the timing: only construction is timed, for ours and
    // Embree's alike (freeing a structure is not part of a build).
    std::vector<std::unique_ptr<StructureCache>> caches;
    std::vector<std::unique_ptr<Traverser>> built;
    const Timing ms = median_ms(
        reps,
        [&] {
          caches.push_back(std::make_unique<StructureCache>(scene));
          built.push_back(make_scheme(name, config_for(name, opt.run.scheme_config)));
          built.back()->prepare(scene, *caches.back());
        },
        [&] { built.clear(), caches.clear(); }, mem);
    const Traverser* t = built.back().get();
    Record r;
    r.set("structure", name).set("scene", scene.name).set("triangles", uint64_t(scene.num_triangles()));
    r.set("threads", 1).set("build_ms", ms.wall_ms).set("build_cpu_ms", ms.cpu_ms).set("build_page_faults", uint64_t(std::max(0L, ms.page_faults)));
    r.set("warm", warm ? 1 : 0);
    r.set("bytes", uint64_t(t->structure_bytes()));
    r.set("info", t->structure_info());
    std::fprintf(stderr, "%-14s %s: %.1f ms  %s\n", name.c_str(), scene.name.c_str(), ms.wall_ms, t->structure_info().c_str());
    records.push_back(std::move(r));
  }
  // Embree's qualities in robust mode (the embree_* schemes' default), and HIGH in its fast mode:
  // the only mode in which Debian's Embree 3.13.5 builds spatial splits (issue 17's build goal).
  struct EmbreeBuild {
    EmbreeQuality q;
    bool robust;
    const char* name;
  };
  for (const EmbreeBuild& eb : {EmbreeBuild{EmbreeQuality::low, true, "embree low"},
                                EmbreeBuild{EmbreeQuality::medium, true, "embree medium"},
                                EmbreeBuild{EmbreeQuality::high, true, "embree high"},
                                EmbreeBuild{EmbreeQuality::high, false, "embree high fast"}}) {
    const char* qn = eb.name;
    std::vector<std::unique_ptr<EmbreeScene>> built;
    const Timing ms = median_ms(
        reps, [&] { built.push_back(std::make_unique<EmbreeScene>(scene, eb.q, eb.robust)); }, [&] { built.clear(); }, mem);
    Record r;
    r.set("structure", qn).set("scene", scene.name).set("triangles", uint64_t(scene.num_triangles()));
    r.set("threads", 1).set("build_ms", ms.wall_ms).set("build_cpu_ms", ms.cpu_ms).set("build_page_faults", uint64_t(std::max(0L, ms.page_faults)));
    r.set("warm", warm ? 1 : 0);
    r.set("bytes", uint64_t(built.back()->bytes().total()));
    std::fprintf(stderr, "%-14s %s: %.1f ms\n", qn, scene.name.c_str(), ms.wall_ms);
    records.push_back(std::move(r));
  }
  write_csv(opt.csv, records,
            {{"command", "table build"}, {"scene", scene.name}, {"table1", "two-level BVH, 4 objects (structures/two_level.h)"},
             {"table1_threads", "1 and 4; " + std::to_string(hw) + " hardware threads"}});
  print_table(records, {"structure", "scene", "triangles", "threads", "build_ms", "build_cpu_ms", "refit_ms", "thesis_ms",
                        "thesis_refit_ms", "top_build_ms", "top_refit_ms", "bytes"},
              stdout);
  return 0;
}

}  // namespace tb
