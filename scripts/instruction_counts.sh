#!/usr/bin/env bash
# Instructions per ray of every scheme, counted by valgrind's callgrind (hardware counters are not
# available on the development VM; instruction counts are exact and reproducible, unlike its timings).
#
#   scripts/instruction_counts.sh [SCENE] [WORKLOADS] [OUT.csv]
#     SCENE      built-in name or scene file (default: ../shared/scenes/sponza.obj, else room)
#     WORKLOADS  comma-separated (default: primary,bounce:2,bounce:3)
#     OUT.csv    default: results/<scene>/instructions.csv
#   SIZE=128 (image side), SCHEMES=all (or a comma-separated list) in the environment.
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
OUT=${3:-results/$name/instructions.csv}
SIZE=${SIZE:-128}
REPS=1

command -v valgrind >/dev/null || { echo "instruction_counts: valgrind is not installed (scripts/setup.sh)" >&2; exit 2; }
cmake -S . -B build-valgrind -DCMAKE_BUILD_TYPE=Release -DTRAVBENCH_NATIVE=OFF >/dev/null
cmake --build build-valgrind -j "$(nproc)" --target travbench >build-valgrind/build.log 2>&1 ||
  { tail -40 build-valgrind/build.log >&2; exit 1; }
TB=build-valgrind/travbench

if [ -z "${SCHEMES:-}" ] || [ "$SCHEMES" = all ]; then
  SCHEMES=$($TB list schemes | grep -v '^reference$' | paste -sd,)
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
IFS=, read -r -a scheme_list <<<"$SCHEMES"
IFS=, read -r -a workload_list <<<"$WORKLOADS"
for s in "${scheme_list[@]}"; do
  for w in "${workload_list[@]}"; do
    echo "instruction_counts: $s $w on $name (${SIZE}x${SIZE})" >&2
    f="$work/$s@$w"
    valgrind --tool=callgrind --collect-atstart=no --toggle-collect='tb::measure(*' --callgrind-out-file="$f.cg" -q \
      $TB run --scene "$SCENE" --schemes "$s" --workloads "$w" --width "$SIZE" --height "$SIZE" \
      --reps $REPS --threads 1 --csv "$f.csv" >/dev/null 2>"$f.log" || { cat "$f.log" >&2; exit 1; }
  done
done

mkdir -p "$(dirname "$OUT")"
/usr/bin/python3 - "$work" "$OUT" "$REPS" "$SCHEMES" "$WORKLOADS" <<'EOF'
import csv, os, re, sys
work, out, reps, schemes = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4].split(",")
rows = []
for s in schemes:
    for wl in sys.argv[5].split(","):
        csv_path = os.path.join(work, f"{s}@{wl}.csv")
        c = next(csv.DictReader(open(csv_path)))
        ir = int(re.search(r"^totals: (\d+)", open(csv_path[:-4] + ".cg").read(), re.M).group(1))
        rays = int(c["rays"]) * (reps + 1)  # warm-up + timed reps
        rows.append({"scene": c["scene"], "triangles": c["triangles"], "workload": c["workload"],
                     "scheme": s, "rays": c["rays"], "instructions_per_ray": f"{ir / rays:.1f}",
                     "mismatch_rate": c["mismatch_rate"]})
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
