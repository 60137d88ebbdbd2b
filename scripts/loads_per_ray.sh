#!/usr/bin/env bash
# Every load the traversal code executes per ray, beside what our cache simulator counts, for the
# thesis' Table 11 cell (Conference, bounce:2): the measurement behind results/THESIS.md's
# "t11.reads_per_ray". The thesis "uses code instrumentation to record reads and writes" (§5.4);
# our simulator is fed only the accesses the probes name, one per 64-byte line (docs/WORKLOADS.md).
#
#   scripts/loads_per_ray.sh [SCENE] [OUT.csv]
#     SCENE    default ../shared/scenes/conference.obj
#     OUT.csv  default results/<scene>/loads_per_ray.csv
#   SIZE=128 (image side) in the environment.
#
# loads_per_ray / stores_per_ray: callgrind's data reads / writes (Dr, Dw; --cache-sim=yes) inside
# the timed trace (collection toggled on in tb::measure: warm-up + 1 rep, 1 thread), over the rays
# traced; d1/ll_misses_per_ray: its simulated D1 and last-level data misses (its own cache model:
# 32 KB D1 and the host's LL by default); branch_mispredicts_per_ray: --branch-sim's conditional +
# indirect mispredictions (a simple predictor model, not the host's). sim_read_lines_per_ray: `travbench run --cache` on the same cell (native build), all
# demand reads (L1 hits + misses) per ray. Uses build-valgrind/ (-DTRAVBENCH_NATIVE=OFF: valgrind
# 3.19 cannot run AVX-512), as scripts/instruction_counts.sh does.
set -euo pipefail
cd "$(dirname "$0")/.."
SCENE=${1:-../shared/scenes/conference.obj}
name=$(basename "$SCENE"); name=${name%.*}
OUT=${2:-results/$name/loads_per_ray.csv}
SIZE=${SIZE:-128}
TB_VG=$(scripts/valgrind_build.sh)
cmake --build build -j "$(nproc)" --target travbench >/dev/null
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# scheme|parameters: mbvh_rs and raygrid in the thesis' 4-wide layout, as `table cache` runs them.
# One valgrind process per cell (callgrind's totals are per process), the three side by side.
cells=("mbvh_rs|--param width=4 --param sort=none" "raygrid|--param width=4 --param queue=256" "mbvh4_single|")
measure() {
  local s=${1%%|*} p=${1#*|}
  echo "loads_per_ray: $s bounce:2 on $name (${SIZE}x${SIZE}) under callgrind" >&2
  # shellcheck disable=SC2086
  valgrind --tool=callgrind --cache-sim=yes --branch-sim=yes --collect-atstart=no --toggle-collect='tb::measure(*' \
    --callgrind-out-file="$work/$s.cg" -q "$TB_VG" run --scene "$SCENE" --schemes "$s" $p \
    --workloads bounce:2 --width "$SIZE" --height "$SIZE" --reps 1 --threads 1 --csv "$work/$s.csv" >/dev/null 2>"$work/$s.log" ||
    { cat "$work/$s.log" >&2; exit 1; }
  # shellcheck disable=SC2086
  build/travbench run --scene "$SCENE" --schemes "$s" $p --workloads bounce:2 --width "$SIZE" --height "$SIZE" \
    --reps 1 --threads 1 --cache --csv "$work/$s.sim.csv" >/dev/null 2>>"$work/$s.log" || { cat "$work/$s.log" >&2; exit 1; }
}
pids=()
for cell in "${cells[@]}"; do measure "$cell" & pids+=($!); done
for p in "${pids[@]}"; do wait "$p" || { echo "loads_per_ray: a cell failed" >&2; exit 1; }; done
mkdir -p "$(dirname "$OUT")"
/usr/bin/python3 - "$work" "$OUT" "$SIZE" "${cells[@]}" <<'PY'
import csv, re, sys
work, out, size, cells = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
rows = []
for cell in cells:
    s = cell.split("|")[0]
    text = open(f"{work}/{s}.cg").read()
    events = re.search(r"^events: (.*)$", text, re.M).group(1).split()
    m = re.search(r"^totals: (.*)$", text, re.M) or re.search(r"^summary: (.*)$", text, re.M)
    ev = dict(zip(events, [int(x) for x in m.group(1).split()]))
    c = next(csv.DictReader(l for l in open(f"{work}/{s}.csv") if not l.startswith("#")))
    sim = next(csv.DictReader(l for l in open(f"{work}/{s}.sim.csv") if not l.startswith("#")))
    rays = int(c["rays"]) * 2  # warm-up + 1 timed rep
    sim_reads = sum(float(sim[k]) for k in ("l1_read_hit_m", "l2_read_hit_m", "l3_read_hit_m", "mem_read_m")) * 1e6
    rows.append({"scene": c["scene"], "workload": c["workload"], "scheme": s, "params": cell.split("|")[1].replace("--param ", ""),
                 "image": f"{size}x{size}", "rays": c["rays"], "instructions_per_ray": f"{ev['Ir'] / rays:.1f}",
                 "loads_per_ray": f"{ev['Dr'] / rays:.1f}", "stores_per_ray": f"{ev['Dw'] / rays:.1f}",
                 "d1_misses_per_ray": f"{(ev['D1mr'] + ev['D1mw']) / rays:.1f}",
                 "ll_misses_per_ray": f"{(ev['DLmr'] + ev['DLmw']) / rays:.1f}",
                 "branch_mispredicts_per_ray": f"{(ev.get('Bcm', 0) + ev.get('Bim', 0)) / rays:.1f}",
                 "sim_read_lines_per_ray": f"{sim_reads / int(sim['rays']):.1f}"})
with open(out, "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
for r in rows:
    print(f"{r['scheme']:<14} loads/ray {r['loads_per_ray']:>9}  simulated reads (lines)/ray {r['sim_read_lines_per_ray']:>8}")
print(f"-> {out}", file=sys.stderr)
PY
