#!/usr/bin/env bash
# The main job: set-up + build + the default suite on a scene, CSV + PNG under results/<scene>/.
#   scripts/run.sh [--quick] [SCENE ...]
# SCENE: a built-in name (default: room) or a scene file path (e.g. ../shared/scenes/sponza.obj).
# The default suite takes ~10 minutes on 2 cores; --quick takes ~1 minute (small images, 1 rep).
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0
scenes=()
for a in "$@"; do
  case "$a" in
    --quick) quick=1 ;;
    -h|--help) sed -n 2,5p "$0"; exit 0 ;;
    *) scenes+=("$a") ;;
  esac
done
[ ${#scenes[@]} -eq 0 ] && scenes=(room)
scripts/setup.sh
scripts/build.sh >/dev/null
TB=build/travbench
if [ $quick -eq 1 ]; then
  big=(--width 128 --height 128 --reps 1); small=(--width 64 --height 64 --reps 1)
else
  big=(--width 512 --height 512 --reps 5); small=(--width 256 --height 256 --reps 3)
fi
tables=$($TB list tables)
has() { grep -qx "$1" <<<"$tables"; }

steps=()
for scene in "${scenes[@]}"; do
  name=$(basename "$scene"); name=${name%.*}; out=results/$name
  steps+=("$TB run --scene $scene --schemes all --workloads primary,divergence:8,rnd,rnd2,bounce:1,bounce:2,shadow --stats ${big[*]} --csv $out/run.csv")
  has divergence && steps+=("$TB table divergence --scene $scene ${small[*]} --csv $out/divergence.csv")
  has bounce && steps+=("$TB table bounce --scene $scene ${big[*]} --csv $out/bounce.csv")
  has raygrid && steps+=("$TB table raygrid --scene $scene ${big[*]} --csv $out/raygrid.csv")
  has cache && steps+=("$TB table cache --scene $scene --reps 1 --csv $out/cache.csv")
  has accuracy && steps+=("$TB table accuracy --scene $scene ${small[*]} --csv $out/accuracy.csv")
  has build && steps+=("$TB table build --scene $scene --reps 3 --csv $out/build.csv")
  mkdir -p "$out"
done

# One line of progress per step on stderr; each step's own output goes to its log beside the CSV.
total=${#steps[@]}
i=0
start=$(date +%s)
for step in "${steps[@]}"; do
  i=$((i + 1))
  csv=${step##* }
  bar=$(printf '%*s' $((i * 30 / total)) '' | tr ' ' '#')
  printf '[%-30s] %d/%d %s (%ds)\n' "$bar" "$i" "$total" "${csv}" $(( $(date +%s) - start )) >&2
  $step >"${csv%.csv}.log" 2>&1 || { echo "step failed: $step (see ${csv%.csv}.log)" >&2; exit 1; }
done
for scene in "${scenes[@]}"; do
  name=$(basename "$scene"); name=${name%.*}
  if /usr/bin/python3 -c "import matplotlib" 2>/dev/null; then
    /usr/bin/python3 scripts/plot.py "results/$name" >&2
  else
    echo "matplotlib (python3-matplotlib) missing: CSVs are in results/$name, no plots" >&2
  fi
done
echo "done in $(( $(date +%s) - start )) s: ${scenes[*]} -> results/" >&2
