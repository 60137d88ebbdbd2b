// `travbench table scaling`: Mrays/s of every scheme on bounce:2 of spheres:N from ~100k to ~10M
// triangles (log-log curves), with the memory of each scheme's structure.
#include <cstdio>

#include "harness/tables.h"
#include "structures/builtin_scenes.h"
#include "traversal/registry.h"

namespace tb {

int scaling_table(const TableOptions& opt) {
  // --scene may give a comma-free list of sizes as "spheres:N"; by default the full ladder.
  std::vector<std::string> scenes = {"spheres:100000", "spheres:300000", "spheres:1000000", "spheres:3000000",
                                     "spheres:10000000"};
  if (!opt.scene.empty()) scenes = {opt.scene};
  const std::vector<std::string> names = default_schemes(opt);  // checked before the first scene
  std::vector<Record> records;
  for (const auto& scene_name : scenes) {
    Bench bench(load_scene(scene_name));
    const WorkloadSpec spec = table_spec(opt, "bounce:2");
    for (const auto& name : names) {
      auto t = make_scheme(name, config_for(name, opt.run.scheme_config));
      t->prepare(bench.scene(), bench.cache());
      Record r = measure_cell(bench, spec, *t, opt.run, name);
      r.set("structure_mb", double(t->structure_bytes()) / (1024.0 * 1024.0));
      std::fprintf(stderr, "%-18s %-16s %8s Mrays/s\n", bench.scene().name.c_str(), name.c_str(),
                   r.get("mrays_median")->c_str());
      records.push_back(std::move(r));
    }
  }
  write_csv(opt.csv, records, {{"command", "table scaling"}, {"workload", "bounce:2"}});
  print_table(records, {"scene", "triangles", "scheme", "mrays_median", "mismatch_rate", "structure_mb"}, stdout);
  return 0;
}

}  // namespace tb
