#!/usr/bin/env bash
# Work per ray of the divergence experiment as the thesis ran it (§3.4, Tables 2-4: 1280x800,
# adjacent rays 0.034 deg * D apart, 16x16 packets), counted by callgrind: the work x rate split of
# results/THESIS.md's "D = 8 keeps <= 31% of D = 1" checks.
#
#   scripts/divergence_counts.sh SCENE [OUT.csv [STATS.csv]]
#     SCENE a scene file or a built-in scene name (room, stadium)
#     OUT.csv default results/<scene>/divergence_counts.csv, STATS.csv results/<scene>/divergence_stats.csv
#   SCHEMES=bvh_ranged,mbvh4_single  DS=1,8  VIEWS=1,2,3  STRIDE=8  TIME_REPS=7  JOBS=1
#   STEPS=counts,stats (stats: `travbench trace --stats` on the same rays, the full 1280x800 image, one
#   process per view, D and scheme: nodes, leaves, triangles per ray, rays per visited node, range per node)
#   TB=<a non-native travbench> (default: builds build-valgrind/ as scripts/instruction_counts.sh does)
#
# The rays: `travbench rays --camera thesis` writes divergence:D of the scene's views at 1280x800 on
# the camera of thesis Tables 2-4 (hfov = thesis_hfov_deg() = 2 atan(1280 tan(0.017 deg)),
# docs/WORKLOADS.md), the rays `table divergence` traces by default. (Until session 41 the script
# replaced the views' vfov in a scenes.json beside a link to the scene file instead, which needed a
# scene file; the same rays bit for bit, checked on conference: results/README.md.)
# The subsample: every STRIDE-th 16x16 packet of the file (tile order), whole packets, so each
# packet keeps its rays, its spacing and its tile geometry; a packet's instruction count does not
# depend on the packets traced before it, so the subsample's instructions per ray estimate the full
# image's (500 of 4000 packets at STRIDE=8). Counted: tb::measure only (warm-up + 1 rep, 1 thread);
# --cache-sim/--branch-sim as PROFILE=1 of instruction_counts.sh (callgrind's models). Timed: the same
# binary natively on the same subsample (TIME_REPS reps, 1 thread) -> instructions_per_ns.
set -euo pipefail
cd "$(dirname "$0")/.."
SCENE=${1:?usage: scripts/divergence_counts.sh SCENE [OUT.csv [STATS.csv]]}
[[ "$SCENE" != */* || -f "$SCENE" ]] || { echo "divergence_counts: no scene file '$SCENE'" >&2; exit 2; }
name=$(basename "$SCENE"); name=${name%.*}
OUT=${2:-results/$name/divergence_counts.csv}
STATS_OUT=${3:-results/$name/divergence_stats.csv}
STEPS=${STEPS:-counts,stats}
SCHEMES=${SCHEMES:-bvh_ranged,mbvh4_single}
DS=${DS:-1,8}
VIEWS=${VIEWS:-1,2,3}
STRIDE=${STRIDE:-8}
TIME_REPS=${TIME_REPS:-7}
JOBS=${JOBS:-1}
if [ -z "${TB:-}" ]; then
  TB=$(scripts/valgrind_build.sh)
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
IFS=, read -r -a scheme_list <<<"$SCHEMES"
IFS=, read -r -a d_list <<<"$DS"
IFS=, read -r -a view_list <<<"$VIEWS"
for v in "${view_list[@]}"; do
  for d in "${d_list[@]}"; do
    f="$work/v${v}_d$d"
    $TB rays --scene "$SCENE" --workload "divergence:$d" --width 1280 --height 800 --view "$v" --camera thesis \
      --out "$f.full.rays" 2>"$f.log" ||
      { cat "$f.log" >&2; exit 1; }
    /usr/bin/python3 - "$f.full.rays" "$f.rays" "$STRIDE" "$d" <<'EOF'
import math, struct, sys
raw = open(sys.argv[1], "rb").read()
count, psize, pcount = struct.unpack("<QII", raw[8:24])
if raw[:8] != b"TBRAYS1\0" or pcount != 0 or psize != 256 or count != 1280 * 800:
    sys.exit(f"divergence_counts: {sys.argv[1]}: expected 1280x800 rays in uniform 256-ray packets")
# The camera check: the first two rays of the tile at the image centre (row 25, column 40 of 80 tiles; rays 0
# and 1 are horizontal neighbours, the 2x2 groups of the Fig. 16 order) are 0.034 deg * D apart (less the
# cos^2 fall-off one pixel off the centre, 0.3%).
first = lambda i: struct.unpack("<8f", raw[24 + 32 * i: 56 + 32 * i])[3:6]
a, b = first((25 * 80 + 40) * 256), first((25 * 80 + 40) * 256 + 1)
deg = math.degrees(math.acos(sum(x * y for x, y in zip(a, b)) / math.dist(a, (0, 0, 0)) / math.dist(b, (0, 0, 0))))
want = 0.034 * int(sys.argv[4])
if abs(deg / want - 1) > 0.01:
    sys.exit(f"divergence_counts: {sys.argv[1]}: centre rays {deg:.4f} deg apart, not {want:.4f} (thesis camera)")
print(f"divergence_counts: D={sys.argv[4]}: centre tile's first two rays {deg:.4f} deg apart ({want:.3f} wanted)", file=sys.stderr)
stride, rec = int(sys.argv[3]), 32 * psize
packets = [raw[24 + i * rec: 24 + (i + 1) * rec] for i in range(0, count // psize, stride)]
with open(sys.argv[2], "wb") as out:
    out.write(raw[:8] + struct.pack("<QII", len(packets) * psize, psize, 0) + b"".join(packets))
EOF
  done
done
if [[ ",$STEPS," == *,stats,* ]]; then
  mkdir -p "$(dirname "$STATS_OUT")"
  for v in "${view_list[@]}"; do
    for d in "${d_list[@]}"; do
      for s in "${scheme_list[@]}"; do
        echo "divergence_counts: --stats, $s view $v D=$d, full image" >&2
        $TB trace --scene "$SCENE" --scheme "$s" --rays "$work/v${v}_d$d.full.rays" --stats --reps 1 --threads 1 \
          --csv "$work/stats_v${v}_d$d@$s.csv" >/dev/null 2>"$work/stats.log" || { cat "$work/stats.log" >&2; exit 1; }
      done
    done
  done
  /usr/bin/python3 - "$work" "$STATS_OUT" "$VIEWS" "$DS" "$SCHEMES" "$name" <<'EOF'
import csv, os, sys
work, out = sys.argv[1], sys.argv[2]
views, ds, schemes = (a.split(",") for a in sys.argv[3:6])
keep = ("scene", "view", "workload", "scheme", "rays", "mrays_median", "mismatch_rate", "nodes_per_ray", "leaves_per_ray",
        "tris_per_ray", "rays_per_node", "rays_per_leaf", "range_per_node", "range_per_leaf")
rows = []
for v in views:
    for d in ds:
        for s in schemes:
            for r in csv.DictReader(l for l in open(os.path.join(work, f"stats_v{v}_d{d}@{s}.csv")) if not l.startswith("#")):
                # trace labels the cell by its ray file: name the view and workload the rays were made for
                r.update(scene=sys.argv[6], view=v, workload=f"divergence:{d}")
                rows.append({k: r[k] for k in keep})
with open(out, "w", newline="") as fh:
    w = csv.DictWriter(fh, fieldnames=list(keep))
    w.writeheader()
    w.writerows(rows)
print(f"-> {out}", file=sys.stderr)
EOF
fi
[[ ",$STEPS," == *,counts,* ]] || exit 0
count() {
  local s=$1 v=$2 d=$3 f="$work/v$2_d$3"
  echo "divergence_counts: $s view $v D=$d on $name" >&2
  valgrind --tool=callgrind --cache-sim=yes --branch-sim=yes "--LL=${LL:-33554432,16,64}" --collect-atstart=no \
    --toggle-collect='tb::measure(*' --callgrind-out-file="$f@$s.cg" -q \
    $TB trace --scene "$SCENE" --scheme "$s" --rays "$f.rays" --reps 1 --threads 1 --csv "$f@$s.csv" \
    >/dev/null 2>"$f@$s.log" || { cat "$f@$s.log" >&2; return 1; }
}
pids=()
for v in "${view_list[@]}"; do
  for d in "${d_list[@]}"; do
    for s in "${scheme_list[@]}"; do
      while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do sleep 1; done
      count "$s" "$v" "$d" & pids+=($!)
    done
  done
done
for p in "${pids[@]}"; do wait "$p" || { echo "divergence_counts: a cell failed" >&2; exit 1; }; done
echo "divergence_counts: timing the same binary natively ($TIME_REPS reps)" >&2
for v in "${view_list[@]}"; do
  for d in "${d_list[@]}"; do
    for s in "${scheme_list[@]}"; do
      f="$work/v${v}_d$d"
      $TB trace --scene "$SCENE" --scheme "$s" --rays "$f.rays" --reps "$TIME_REPS" --threads 1 --csv "$f@$s.time.csv" \
        >/dev/null 2>"$f@$s.log" || { cat "$f@$s.log" >&2; exit 1; }
    done
  done
done
mkdir -p "$(dirname "$OUT")"
/usr/bin/python3 - "$work" "$OUT" "$name" "$SCHEMES" "$DS" "$VIEWS" "$STRIDE" <<'EOF'
import csv, math, os, re, sys
work, out, scene = sys.argv[1:4]
schemes, ds, views = (a.split(",") for a in sys.argv[4:7])
stride = sys.argv[7]
hfov = 2 * math.atan(1280 * math.tan(0.5 * 0.034 * math.pi / 180))
rows = []
for v in views:
    for d in ds:
        for s in schemes:
            f = os.path.join(work, f"v{v}_d{d}@{s}")
            c = next(csv.DictReader(open(f + ".csv")))
            t = next(csv.DictReader(open(f + ".time.csv")))
            text = open(f + ".cg").read()
            events = re.search(r"^events: (.*)$", text, re.M).group(1).split()
            ev = dict(zip(events, map(int, re.search(r"^totals: (.*)$", text, re.M).group(1).split())))
            rays = int(c["rays"]) * 2  # warm-up + 1 rep
            ns = 1e3 / float(t["mrays_median"])
            ir = ev["Ir"] / rays
            rows.append({"scene": scene, "view": v, "divergence": d, "deg_per_ray": f"{0.034 * int(d):.3f}",
                         "scheme": s, "image": "1280x800", "hfov_deg": f"{math.degrees(hfov):.4f}",
                         "packet_stride": stride, "rays": c["rays"], "mismatch_rate": c["mismatch_rate"],
                         "instructions_per_ray": f"{ir:.1f}",
                         "d1_misses_per_ray": f"{(ev['D1mr'] + ev['D1mw']) / rays:.2f}",
                         "branch_mispredicts_per_ray": f"{(ev.get('Bcm', 0) + ev.get('Bim', 0)) / rays:.2f}",
                         "mrays_median": t["mrays_median"], "mrays_min": t["mrays_min"], "mrays_max": t["mrays_max"],
                         "time_reps": t["reps"], "ns_per_ray": f"{ns:.1f}", "instructions_per_ns": f"{ir / ns:.3f}"})
with open(out, "w", newline="") as fh:
    w = csv.DictWriter(fh, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
for r in rows:
    print(f"view {r['view']} D={r['divergence']:>2} {r['scheme']:<14} {r['instructions_per_ray']:>9} instr/ray "
          f"{r['ns_per_ray']:>7} ns/ray {r['instructions_per_ns']:>6} instr/ns")
print(f"-> {out}", file=sys.stderr)
EOF
