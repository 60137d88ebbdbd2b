#!/usr/bin/env bash
# The main job: set-up + build + the default suite on a scene, CSV and plots under results/<scene>/.
#   scripts/run.sh [--quick] [SCENE ...]     SCENE: built-in name (default: room) or scene file path
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0
scenes=()
for a in "$@"; do
  case "$a" in
    --quick) quick=1 ;;
    -h|--help) sed -n 2,3p "$0"; exit 0 ;;
    *) scenes+=("$a") ;;
  esac
done
[ ${#scenes[@]} -eq 0 ] && scenes=(room)
scripts/setup.sh
scripts/build.sh >/dev/null
TB=build/travbench
if [ $quick -eq 1 ]; then
  size=(--width 256 --height 256); reps=3
else
  size=(--width 512 --height 512); reps=5
fi
for scene in "${scenes[@]}"; do
  name=$(basename "$scene"); name=${name%.*}
  out=results/$name
  mkdir -p "$out"
  echo "== $scene -> $out" >&2
  "$TB" run --scene "$scene" --schemes all --workloads primary,divergence:8,rnd,rnd2,bounce:1,bounce:2,shadow \
    --reps $reps "${size[@]}" --stats --csv "$out/run.csv"
  if /usr/bin/python3 -c "import matplotlib" 2>/dev/null; then
    /usr/bin/python3 scripts/plot.py "$out" || echo "plotting failed (results are in $out)" >&2
  fi
done
