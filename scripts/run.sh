#!/usr/bin/env bash
# The main job: set-up + build + the default suite on a scene, CSV + PNG under results/<scene>/.
#   scripts/run.sh [--quick] [--scaling] [--steps LIST] [SCENE|FOLDER ...]
# SCENE: a built-in name (default: room) or a scene file path (e.g. ../shared/scenes/sponza.obj);
# FOLDER: every scene file in it (e.g. ../shared/scenes).
# The default suite takes 4-8 minutes per scene on 2 cores (measured: room 4; Sponza and Conference
# 11 together); --quick ~1 minute (small images, 1 rep). --steps picks a subset of
# run,divergence,bounce,raygrid,cache,accuracy,hard,build,simt,image (default: all; hard: every scheme's
# default kernel on the hard:* workloads, hard_cases.csv; simt is the SIMT warp model of thesis
# Tables 12-13, docs/SIMT.md, ~2 minutes per real scene; image: one heat map per scheme family,
# heat_<scheme>_<metric>.png, `travbench image`). --scaling adds the scaling
# table (spheres:100k..10M, bounce:2; ~4 minutes, 6 GB of memory) under results/spheres/.
# Ends with the performance-goal ratios of each scene (scripts/goals.py) and results/THESIS.md
# (scripts/thesis_report.py). Every thesis table for every scene: scripts/run.sh ../shared/scenes
# (Tables 2-4 at 1280x800, Table 11 at 512x512 as the thesis ran them; Table 1 in each build.csv).
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0
scaling=0
want=run,divergence,bounce,raygrid,cache,accuracy,hard,build,simt,image
scenes=()
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --scaling) scaling=1 ;;
    --steps) want=${2:?--steps needs a list}; shift ;;
    -h|--help) sed -n 2,13p "$0"; exit 0 ;;
    -*) echo "run.sh: unknown option '$1' (see --help)" >&2; exit 2 ;;
    *)
      if [ -d "$1" ]; then
        found=$(find "$1" -maxdepth 1 -type f \( -iname '*.obj' -o -iname '*.ply' -o -iname '*.off' -o -iname '*.stl' \
                -o -iname '*.gltf' -o -iname '*.glb' \) | sort)
        [ -n "$found" ] || { echo "run.sh: no scene files in folder '$1'" >&2; exit 2; }
        while IFS= read -r f; do scenes+=("$f"); done <<<"$found"
      elif [[ "$1" == */* ]] && [ ! -f "${1%@*}" ]; then
        echo "run.sh: scene file '$1' not found" >&2; exit 2
      else
        scenes+=("$1")
      fi ;;
  esac
  shift
done
[ ${#scenes[@]} -eq 0 ] && [ $scaling -eq 0 ] && scenes=(room)
scripts/setup.sh
buildlog=$(mktemp)
scripts/build.sh >"$buildlog" 2>&1 || { tail -30 "$buildlog" >&2; rm -f "$buildlog"; exit 1; }
rm -f "$buildlog"
TB=build/travbench
if [ $quick -eq 1 ]; then
  big=(--width 128 --height 128 --reps 1); small=(--width 64 --height 64 --reps 1); hard=("${small[@]}")
  img=(--width 128 --height 128)
else
  big=(--width 512 --height 512 --reps 5); small=(--width 256 --height 256 --reps 3)
  hard=(--width 256 --height 256 --reps 1)  # an accuracy check: one timed repetition is enough
  img=(--width 320 --height 240)
fi
hard_workloads=$($TB list workloads | grep '^hard:' | paste -sd, -)
tables=$($TB list tables)
has() { grep -qx "$1" <<<"$tables" && grep -qw "$1" <<<"${want//,/ }"; }

steps=()
for scene in "${scenes[@]}"; do
  name=$(basename "$scene"); name=${name%.*}; out=results/$name
  if grep -qw run <<<"${want//,/ }"; then
    steps+=("$TB run --scene $scene --schemes all --workloads primary,divergence:8,rnd,rnd2,bounce:1,bounce:2,bounce:3,shadow --stats ${big[*]} --csv $out/run.csv")
  fi
  # Tables 2-4 at the thesis' own parameters: without --width/--height the divergence table runs
  # 1280x800 with the thesis camera (0.034 deg * D between adjacent rays, §3.4); --quick keeps its
  # small image (a smoke test, not a thesis table: its CSV says so in deg_per_ray and the sidecar).
  # The four schemes of the thesis' comparison (ranged packets, partition, the single-ray control,
  # Embree's packets): every scheme at 1280x800 would take about an hour per scene on 2 cores.
  if [ $quick -eq 1 ]; then div=("${small[@]}"); else div=(--schemes bvh_ranged,bvh_partition,mbvh4_single,embree_packet8 --reps 3); fi
  has divergence && steps+=("$TB table divergence --scene $scene ${div[*]} --csv $out/divergence.csv")
  has bounce && steps+=("$TB table bounce --scene $scene ${big[*]} --csv $out/bounce.csv")
  has raygrid && steps+=("$TB table raygrid --scene $scene ${big[*]} --csv $out/raygrid.csv")
  has cache && steps+=("$TB table cache --scene $scene --reps 1 --csv $out/cache.csv")
  has accuracy && steps+=("$TB table accuracy --scene $scene ${small[*]} --csv $out/accuracy.csv")
  grep -qw hard <<<"${want//,/ }" && steps+=("$TB run --scene $scene --schemes all --workloads $hard_workloads ${hard[*]} --csv $out/hard_cases.csv")
  has build && steps+=("$TB table build --scene $scene --reps 3 --csv $out/build.csv")
  # simt runs the warp model: the image size only (it refuses --reps, nothing is timed).
  has simt && steps+=("$TB table simt --scene $scene ${big[*]:0:4} --csv $out/simt.csv")
  if grep -qw image <<<"${want//,/ }"; then
    # One per scheme family: the single-ray ones per ray (--packet 1), the stream scheme per packet
    # (what it does is per packet), Embree by time (it has no counters), and |n.d| to see the camera.
    for heat in "bvh_single nodes 1" "mbvh8_single nodes 1" "kd_single nodes 1" "raygrid nodes 0" \
                "embree_single time 1" "bvh_single shade 0"; do
      read -r hs hm hp <<<"$heat"
      steps+=("$TB image --scene $scene --scheme $hs --metric $hm --packet $hp ${img[*]} --out $out/heat_${hs}_${hm}.png")
    done
  fi
done
if [ $scaling -eq 1 ]; then
  steps+=("$TB table scaling ${small[*]} --csv results/spheres/scaling.csv")
fi

# One line of progress per step on stderr; each step's own output goes to its log beside the CSV.
# A step writes into a fresh staging folder and its outputs (the files named like its last
# argument: X.csv, X.json, X.log, X.png) move into results/ only when it finished, so an
# interrupted re-run never leaves committed results half overwritten.
total=${#steps[@]}
i=0
start=$(date +%s)
stage=$(mktemp -d results/.staging.XXXXXX)
trap 'rm -rf "$stage"' EXIT
for step in "${steps[@]}"; do
  i=$((i + 1))
  dest=${step##* }
  tmp=$stage/$i/$(basename "$dest")
  bar=$(printf '%*s' $((i * 30 / total)) '' | tr ' ' '#')
  printf '[%-30s] %d/%d %s (%ds)\n' "$bar" "$i" "$total" "${dest}" $(( $(date +%s) - start )) >&2
  mkdir -p "$(dirname "$tmp")" "$(dirname "$dest")"
  if ! ${step% *} "$tmp" >"${tmp%.*}.log" 2>&1; then
    echo "step failed: $step" >&2
    tail -3 "${tmp%.*}.log" >&2
    exit 1
  fi
  mv -f "$(dirname "$tmp")"/* "$(dirname "$dest")"/
done
folders=()
for scene in "${scenes[@]}"; do name=$(basename "$scene"); folders+=("results/${name%.*}"); done
[ $scaling -eq 1 ] && folders+=(results/spheres)
if /usr/bin/python3 -c "import matplotlib" 2>/dev/null; then
  /usr/bin/python3 scripts/plot.py "${folders[@]}" >&2
else
  echo "matplotlib (python3-matplotlib) missing: CSVs are in ${folders[*]}, no plots" >&2
fi
for f in "${folders[@]}"; do
  csvs=()
  for c in "$f/run.csv" "$f/build.csv"; do if [ -f "$c" ]; then csvs+=("$c"); fi; done
  if [ ${#csvs[@]} -gt 0 ]; then /usr/bin/python3 scripts/goals.py "${csvs[@]}"; fi
done
# results/THESIS.md: the thesis' tables beside ours and its claims as checks, from the CSVs above.
/usr/bin/python3 scripts/thesis_report.py >&2
echo "done in $(( $(date +%s) - start )) s: ${folders[*]}" >&2
