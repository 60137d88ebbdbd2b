#!/usr/bin/env bash
# Instructions per ray of every scheme, counted by valgrind's callgrind (hardware counters are not
# available on the development VM; instruction counts are exact and reproducible, unlike its timings).
#
#   scripts/instruction_counts.sh [SCENE] [WORKLOADS] [OUT.csv]
#     SCENE      built-in name or scene file (default: ../shared/scenes/sponza.obj, else room)
#     WORKLOADS  comma-separated (default: primary,bounce:2,bounce:3)
#     OUT.csv    default: results/<scene>/instructions.csv
#   SIZE=128 (image side), SCHEMES=all (or a comma-separated list), PARAMS (extra travbench options
#   for every cell, e.g. "--param width=4": the thesis' 4-wide MBVH/RS and RayGrid, as the tables run
#   them), JOBS=1 (valgrind processes side by side) in the environment.
#
#   PROFILE=1 adds where the time goes (the measurement behind results/THESIS.md's bounce-depth and
#   RayGrid explanations; default OUT results/<scene>/cost_per_ray.csv): callgrind's simulated D1 and
#   last-level data misses and mispredicted branches per ray (--cache-sim, --branch-sim: its own models,
#   the host's 32 KB D1, LL=33554432,16,64 the VM's 32 MiB L3; a simple predictor, not the host's),
#   and the SAME binary timed natively
#   on the same cells in one process after the counts (TIME_REPS=7 reps after a warm-up, 1 thread):
#   mrays_median/min/max, ns_per_ray and instructions_per_ns (instructions per ray / ns per ray, the
#   rate this core retires that scheme's instructions; hardware counters are unavailable on the VM).
#
# Builds build-valgrind/ with -DTRAVBENCH_NATIVE=OFF (AVX2+FMA only: valgrind 3.19 cannot run the
# AVX-512 code that -march=native may emit on this VM). Only the timed traces are counted:
# collection is toggled on inside tb::measure (warm-up + reps, 1 thread; scene loading, builds and
# the reference trace are excluded), one valgrind process per scheme and workload. Embree's own
# code is counted too (it runs inside measure), dispatched to its AVX2 kernels.
set -euo pipefail
cd "$(dirname "$0")/.."

SCENE=${1:-}
if [ -z "$SCENE" ]; then
  if [ -f ../shared/scenes/sponza.obj ]; then SCENE=../shared/scenes/sponza.obj; else SCENE=room; fi
fi
WORKLOADS=${2:-primary,bounce:2,bounce:3}
name=$(basename "$SCENE"); name=${name%.*}; name=${name%%@*}
PROFILE=${PROFILE:-0}
if [ "$PROFILE" = 1 ]; then OUT=${3:-results/$name/cost_per_ray.csv}; else OUT=${3:-results/$name/instructions.csv}; fi
SIZE=${SIZE:-128}
REPS=1
JOBS=${JOBS:-1}
TIME_REPS=${TIME_REPS:-7}
read -r -a params <<<"${PARAMS:-}"
sim=()
# LL: this VM's L3 as lscpu reports it (32 MiB, 16-way); valgrind's own detection reads the VM's cpuid
# as a 320 MB direct-mapped cache.
[ "$PROFILE" = 1 ] && sim=(--cache-sim=yes --branch-sim=yes "--LL=${LL:-33554432,16,64}")

TB=$(scripts/valgrind_build.sh)

if [ -z "${SCHEMES:-}" ] || [ "$SCHEMES" = all ]; then
  SCHEMES=$($TB list schemes | grep -v '^reference$' | paste -sd,)
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
IFS=, read -r -a scheme_list <<<"$SCHEMES"
IFS=, read -r -a workload_list <<<"$WORKLOADS"
# The PARAMS a scheme takes (a one-scheme run rejects the others' keys; a run of several takes a key
# that any of its schemes knows, as the timing run below does).
own_params() {
  local known i
  known=$($TB list params "$1")
  for ((i = 0; i + 1 < ${#params[@]}; i += 2)); do
    grep -q "^${params[i + 1]%%=*} " <<<"$known" && printf '%s\n%s\n' "${params[i]}" "${params[i + 1]}"
  done
  return 0
}
count() {
  local s=$1 w=$2 f="$work/$1@$2" p
  mapfile -t p < <(own_params "$s")
  echo "instruction_counts: $s $w on $name (${SIZE}x${SIZE})" >&2
  valgrind --tool=callgrind "${sim[@]}" --collect-atstart=no --toggle-collect='tb::measure(*' --callgrind-out-file="$f.cg" -q \
    $TB run --scene "$SCENE" --schemes "$s" --workloads "$w" --width "$SIZE" --height "$SIZE" "${p[@]}" \
    --reps $REPS --threads 1 --csv "$f.csv" >/dev/null 2>"$f.log" || { cat "$f.log" >&2; return 1; }
}
pids=()
for s in "${scheme_list[@]}"; do
  for w in "${workload_list[@]}"; do
    while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do sleep 1; done
    count "$s" "$w" & pids+=($!)
  done
done
for p in "${pids[@]}"; do wait "$p" || { echo "instruction_counts: a cell failed" >&2; exit 1; }; done
if [ "$PROFILE" = 1 ]; then
  echo "instruction_counts: timing the same binary natively ($TIME_REPS reps)" >&2
  $TB run --scene "$SCENE" --schemes "$SCHEMES" --workloads "$WORKLOADS" --width "$SIZE" --height "$SIZE" "${params[@]}" \
    --reps "$TIME_REPS" --threads 1 --csv "$work/time.csv" >/dev/null 2>"$work/time.log" || { cat "$work/time.log" >&2; exit 1; }
fi

mkdir -p "$(dirname "$OUT")"
/usr/bin/python3 - "$work" "$OUT" "$REPS" "$SCHEMES" "$WORKLOADS" "$PROFILE" "$SIZE" <<'EOF'
import csv, os, re, sys
work, out, reps, schemes = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4].split(",")
profile, size = sys.argv[6] == "1", sys.argv[7]
timed = {}
if profile:
    for r in csv.DictReader(l for l in open(os.path.join(work, "time.csv")) if not l.startswith("#")):
        timed[(r["scheme"], r["workload"])] = r
rows = []
for s in schemes:
    for wl in sys.argv[5].split(","):
        csv_path = os.path.join(work, f"{s}@{wl}.csv")
        c = next(csv.DictReader(open(csv_path)))
        text = open(csv_path[:-4] + ".cg").read()
        events = re.search(r"^events: (.*)$", text, re.M).group(1).split()
        ev = dict(zip(events, [int(x) for x in re.search(r"^totals: (.*)$", text, re.M).group(1).split()]))
        rays = int(c["rays"]) * (reps + 1)  # warm-up + timed reps
        row = {"scene": c["scene"], "triangles": c["triangles"], "workload": c["workload"],
               "scheme": s, "rays": c["rays"], "instructions_per_ray": f"{ev['Ir'] / rays:.1f}",
               "mismatch_rate": c["mismatch_rate"]}
        if profile:
            t = timed[(s, wl)]
            ns = 1e3 / float(t["mrays_median"])
            row.update({"image": f"{size}x{size}", "params": t["params"],
                        "d1_misses_per_ray": f"{(ev['D1mr'] + ev['D1mw']) / rays:.2f}",
                        "ll_misses_per_ray": f"{(ev['DLmr'] + ev['DLmw']) / rays:.2f}",
                        "branch_mispredicts_per_ray": f"{(ev.get('Bcm', 0) + ev.get('Bim', 0)) / rays:.2f}",
                        "mrays_median": t["mrays_median"], "mrays_min": t["mrays_min"], "mrays_max": t["mrays_max"],
                        "time_reps": t["reps"], "ns_per_ray": f"{ns:.1f}",
                        "instructions_per_ns": f"{ev['Ir'] / rays / ns:.3f}"})
        rows.append(row)
with open(out, "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
workloads = sys.argv[5].split(",")
print(f"{'scheme':<16}" + "".join(f"{w:>14}" for w in workloads))
for s in schemes:
    vals = {r["workload"]: r["instructions_per_ray"] for r in rows if r["scheme"] == s}
    print(f"{s:<16}" + "".join(f"{vals.get(w, ''):>14}" for w in workloads))
print(f"instructions per ray -> {out}", file=sys.stderr)
EOF
