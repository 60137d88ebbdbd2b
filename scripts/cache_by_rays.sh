#!/usr/bin/env bash
# Table 11's counting unit, by measurement: the simulated reads and writes per ray of one scheme as a
# function of the image size (ray count) and of the path depth, so results/THESIS.md can say whether
# the thesis' per-ray figure can differ from ours by its ray count.
#
#   scripts/cache_by_rays.sh [SCENE] [OUT.csv]
#     SCENE   default ../shared/scenes/conference.obj;  OUT default results/<scene>/cache_by_rays.csv
#   SCHEME=mbvh_rs  PARAMS="--param width=4" (the thesis' 4-wide layout, as table cache runs it)
#   SIZES=64,128,256,512  WORKLOADS=primary,bounce:1,bounce:2,bounce:3,bounce:4  TB=build/travbench
#
# Each size is one `travbench run --cache` (the simulated l1=32K:8, l2=256K:8, l3=2M:16, tree-PLRU
# hierarchy of table cache, fed one access per 64-byte line by the traversal's probes; 1 rep, 1
# thread). The simulated counts do not depend on the build (the probes name the data-structure
# accesses, not instructions), so any travbench binary gives the same numbers.
set -euo pipefail
cd "$(dirname "$0")/.."
SCENE=${1:-../shared/scenes/conference.obj}
name=$(basename "$SCENE"); name=${name%.*}
OUT=${2:-results/$name/cache_by_rays.csv}
SCHEME=${SCHEME:-mbvh_rs}
PARAMS=${PARAMS:---param width=4}
SIZES=${SIZES:-64,128,256,512}
WORKLOADS=${WORKLOADS:-primary,bounce:1,bounce:2,bounce:3,bounce:4}
TB=${TB:-build/travbench}
[ -x "$TB" ] || { echo "cache_by_rays: no $TB (scripts/build.sh, or TB=...)" >&2; exit 2; }
read -r -a params <<<"$PARAMS"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
IFS=, read -r -a size_list <<<"$SIZES"
for n in "${size_list[@]}"; do
  echo "cache_by_rays: $SCHEME $WORKLOADS on $name (${n}x$n)" >&2
  $TB run --scene "$SCENE" --schemes "$SCHEME" "${params[@]}" --workloads "$WORKLOADS" --width "$n" --height "$n" \
    --reps 1 --threads 1 --cache --csv "$work/$n.csv" >/dev/null 2>"$work/$n.log" || { cat "$work/$n.log" >&2; exit 1; }
done
mkdir -p "$(dirname "$OUT")"
/usr/bin/python3 - "$work" "$OUT" "$SIZES" <<'EOF'
import csv, os, sys
work, out, sizes = sys.argv[1], sys.argv[2], sys.argv[3].split(",")
rows = []
for n in sizes:
    for r in csv.DictReader(l for l in open(os.path.join(work, f"{n}.csv")) if not l.startswith("#")):
        rays, pixels = int(r["rays"]), int(n) * int(n)
        reads = sum(float(r[k]) for k in ("l1_read_hit_m", "l2_read_hit_m", "l3_read_hit_m", "mem_read_m")) * 1e6
        writes = sum(float(r[k]) for k in ("l1_write_hit_m", "l2_write_hit_m", "l3_write_hit_m", "mem_write_m")) * 1e6
        rows.append({"scene": r["scene"], "scheme": r["scheme"], "params": r["params"], "workload": r["workload"],
                     "image": f"{n}x{n}", "pixels": pixels, "rays": rays, "rays_per_pixel": f"{rays / pixels:.4f}",
                     "read_lines_per_ray": f"{reads / rays:.2f}", "write_lines_per_ray": f"{writes / rays:.2f}",
                     "read_lines_per_pixel": f"{reads / pixels:.2f}", "l1_read_hit_m": r["l1_read_hit_m"],
                     "l1_write_hit_m": r["l1_write_hit_m"], "mem_read_m": r["mem_read_m"]})
with open(out, "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0])); w.writeheader(); w.writerows(rows)
print("\n".join(f"{r['image']:>8} {r['workload']:<10} rays {r['rays']:>8} reads/ray {r['read_lines_per_ray']:>8} "
                f"writes/ray {r['write_lines_per_ray']:>7} reads/pixel {r['read_lines_per_pixel']:>8}" for r in rows))
print(f"-> {out}", file=sys.stderr)
EOF
