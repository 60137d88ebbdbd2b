#!/usr/bin/env bash
# The ray count behind thesis Table 11, by measurement: what one path-traced frame of a scene costs
# in traversal reads, beside what 512 x 512 single rays cost. Table 11 gives totals "for a 512x512
# image" in a chapter about "efficient ray tracing in the context of a path tracer" (§5.4-§5.5)
# without saying how many rays that image traced; results/THESIS.md's check "t11.reads_per_ray"
# divides its totals by 512 x 512. This script measures the per-pixel cost of two readings of
# "an image", each replayed from a ray file through the traverser:
#   pathtrace  every ray one frame of our Ref path tracer traces (harness/pathtrace.h, Alg. 6.1:
#              Russian roulette, one shadow ray per surface hit; `travbench rays --pathtrace Ref`),
#              extension and shadow rays in trace order, packets as the path tracer forms them
#   bounce0-4  primary + bounce:1..4 (Table 9's columns, each bounce:k a full image of k-th
#              bounce rays; concatenated in depth order)
#
#   scripts/pathtrace_reads.sh [SCENE] [OUT.csv]
#     SCENE    default ../shared/scenes/conference.obj
#     OUT.csv  default results/<scene>/pathtrace_reads.csv
#   SIZE=512 (image side), SPP=1, METHOD=Ref in the environment; TB=build/travbench (native, for the
#   ray files and the cache simulator), TB_VG=<a non-native travbench> (default: builds build-valgrind/),
#   STREAMS=512,1024 (extra mbvh_rs rows on the pathtrace set at these stream sizes, simulator only).
#
# Per (ray set, scheme) row: rays and rays_per_pixel; loads/stores_per_ray: callgrind's Dr / Dw
# (--cache-sim=yes) inside one trace of the whole file (`travbench trace` without --csv: one
# trace_batch call, collection toggled on there, 1 thread; build-valgrind/, -DTRAVBENCH_NATIVE=OFF
# as in scripts/loads_per_ray.sh: valgrind 3.19 cannot run AVX-512); read/write_lines_per_ray: the
# cache simulator of `table cache` (l1=32K:8, l2=256K:8, l3=2M:16, plru, 64-byte lines: L1 hits +
# misses) over the same file (`travbench trace --cache`, native build); read_words_per_ray: the same
# with 4-byte lines; *_per_pixel: per ray x rays_per_pixel, the unit of the thesis' totals / 512^2;
# d1_misses_per_ray: callgrind's own D1 model; l1_read_misses_per_pixel: the simulator's L2 + L3 + memory reads.
# The whole file is one Traverser::trace call: for mbvh_rs (packet by packet) that is what the path
# tracer does; RayGrid's queues then fill from the whole frame rather than from one iteration.
set -euo pipefail
cd "$(dirname "$0")/.."
SCENE=${1:-../shared/scenes/conference.obj}
name=$(basename "$SCENE"); name=${name%.*}
OUT=${2:-results/$name/pathtrace_reads.csv}
: "${SIZE:=512}" "${SPP:=1}" "${METHOD:=Ref}" "${TB:=build/travbench}"  # the environment's, else these
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
if [ -z "${TB_VG:-}" ]; then  # a non-native travbench for valgrind, built as scripts/instruction_counts.sh does
  TB_VG=$(scripts/valgrind_build.sh)
fi
[ -x "$TB" ] || { echo "pathtrace_reads: no $TB (scripts/build.sh, or TB=...)" >&2; exit 2; }
img=(--width "$SIZE" --height "$SIZE")

echo "pathtrace_reads: one $METHOD frame ($SPP spp, ${SIZE}x$SIZE) of $name -> ray file" >&2
$TB rays --scene "$SCENE" "${img[@]}" --pathtrace "$METHOD" --spp "$SPP" --out "$work/pathtrace.rays" \
  >"$work/pathtrace.segments.csv" 2>"$work/rays.log" || { cat "$work/rays.log" >&2; exit 1; }
parts=()
for k in 0 1 2 3 4; do
  w=$([ "$k" = 0 ] && echo primary || echo "bounce:$k")
  $TB rays --scene "$SCENE" "${img[@]}" --workload "$w" --out "$work/b$k.rays" 2>>"$work/rays.log" ||
    { cat "$work/rays.log" >&2; exit 1; }
  parts+=("$work/b$k.rays")
done
# Concatenates ray files (docs/FILE_FORMATS.md), keeping every file's packets.
/usr/bin/python3 - "$work/bounce0-4.rays" "${parts[@]}" <<'PY'
import struct, sys
out, parts = sys.argv[1], sys.argv[2:]
rays, begins = bytearray(), [0]
for p in parts:
    b = open(p, "rb").read()
    assert b[:8] == b"TBRAYS1\0", p
    count, psize, pcount = struct.unpack_from("<QII", b, 8)
    body = b[24:24 + 32 * count]
    offs = (list(struct.unpack_from(f"<{pcount + 1}I", b, 24 + 32 * count)) if pcount
            else [min(i * psize, count) for i in range((count + psize - 1) // psize + 1)])
    begins += [begins[-1] + o for o in offs[1:]]
    rays += body
n = len(rays) // 32
with open(out, "wb") as f:
    f.write(b"TBRAYS1\0" + struct.pack("<QII", n, 256, len(begins) - 1) + rays + struct.pack(f"<{len(begins)}I", *begins))
PY
rm -f "${parts[@]}"

# scheme|parameters: as `table cache` and scripts/loads_per_ray.sh run them (the thesis' 4-wide layout).
cells=("mbvh_rs|--param width=4 --param sort=none" "raygrid|--param width=4 --param queue=256")
simulate() {  # SET TAG SCHEME PARAMS...: the cache simulator in 64-byte lines and in 4-byte words
  local set=$1 tag=$2 s=$3
  shift 3
  $TB trace --scene "$SCENE" --scheme "$s" "$@" --rays "$work/$set.rays" --threads 1 --reps 1 --cache \
    --csv "$work/$tag.lines.csv" >/dev/null 2>>"$work/$tag.log" || { cat "$work/$tag.log" >&2; return 1; }
  $TB trace --scene "$SCENE" --scheme "$s" "$@" --rays "$work/$set.rays" --threads 1 --reps 1 --cache \
    --cache-config l1=32K:8:4,l2=256K:8:4,l3=2M:16:4 --csv "$work/$tag.words.csv" >/dev/null 2>>"$work/$tag.log" ||
    { cat "$work/$tag.log" >&2; return 1; }
}
measure() {  # SET CELL: callgrind, then the simulator
  local set=$1 s=${2%%|*} p=${2#*|} tag="$1.${2%%|*}"
  echo "pathtrace_reads: $s on $set under callgrind" >&2
  # shellcheck disable=SC2086
  valgrind --tool=callgrind --cache-sim=yes --collect-atstart=no --toggle-collect='tb::trace_batch(*' \
    --callgrind-out-file="$work/$tag.cg" -q "$TB_VG" trace --scene "$SCENE" --scheme "$s" $p \
    --rays "$work/$set.rays" --threads 1 --hits "$work/$tag.hits" >/dev/null 2>"$work/$tag.log" ||
    { cat "$work/$tag.log" >&2; return 1; }
  rm -f "$work/$tag.hits"
  # shellcheck disable=SC2086
  simulate "$set" "$tag" "$s" $p
}
# Two at a time (the machine has 2 cores; each valgrind process is single-threaded).
jobs=()
for set in pathtrace bounce0-4; do
  pids=()
  for cell in "${cells[@]}"; do measure "$set" "$cell" & pids+=($!); jobs+=("$set|$cell"); done
  for pid in "${pids[@]}"; do wait "$pid" || { echo "pathtrace_reads: a cell failed" >&2; exit 1; }; done
done
# MBVH/RS's stream size (most rays traced together), over the thesis' "optimal stream size for the
# MBVH/RS algorithm (256-1024)" (§5.3): the simulator only (no callgrind columns). It moves the reads
# that miss L1, not the reads.
IFS=, read -r -a streams <<<"${STREAMS:-512,1024}"
for n in "${streams[@]}"; do
  echo "pathtrace_reads: mbvh_rs stream=$n on pathtrace (simulator)" >&2
  simulate pathtrace "pathtrace.mbvh_rs.stream$n" mbvh_rs --param width=4 --param sort=none --param stream="$n"
  jobs+=("pathtrace|mbvh_rs|--param width=4 --param sort=none --param stream=$n")
done
mkdir -p "$(dirname "$OUT")"
/usr/bin/python3 - "$work" "$OUT" "$SIZE" "$METHOD" "$SPP" "${jobs[@]}" <<'PY'
import csv, os, re, sys
work, out, size, method, spp, jobs = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5], sys.argv[6:]
pixels = size * size
seg = list(csv.DictReader(open(f"{work}/pathtrace.segments.csv")))
ext = sum(int(r["rays"]) for r in seg if r["kind"] == "pathtrace:ext")
shadow = sum(int(r["rays"]) for r in seg if r["kind"] == "pathtrace:shadow")
# Extension rays per path segment (iteration k of a 1-spp Ref frame = segment k): the survivors.
survivors = ";".join(r["rays"] for r in seg if r["kind"] == "pathtrace:ext")
def row(path):
    return next(csv.DictReader(l for l in open(path) if not l.startswith("#")))
def reads(r):
    return sum(float(r[k]) for k in ("l1_read_hit_m", "l2_read_hit_m", "l3_read_hit_m", "mem_read_m")) * 1e6
def cg(event, n, extra=0, digits=1):  # a callgrind count per ray or pixel; empty without a callgrind run
    return f"{(ev[event] + extra) / n:.{digits}f}" if event in ev else ""
def writes(r):
    return sum(float(r[k]) for k in ("l1_write_hit_m", "l2_write_hit_m", "l3_write_hit_m", "mem_write_m")) * 1e6
rows = []
for job in jobs:
    st, s, params = job.split("|")
    stream = re.search(r"stream=(\d+)", params)
    tag = f"{st}.{s}" + (f".stream{stream.group(1)}" if stream else "")
    ev = {}
    if os.path.exists(f"{work}/{tag}.cg"):
        text = open(f"{work}/{tag}.cg").read()
        events = re.search(r"^events: (.*)$", text, re.M).group(1).split()
        m = re.search(r"^totals: (.*)$", text, re.M) or re.search(r"^summary: (.*)$", text, re.M)
        ev = dict(zip(events, [int(x) for x in m.group(1).split()]))
    lines, words = row(f"{work}/{tag}.lines.csv"), row(f"{work}/{tag}.words.csv")
    rays = int(lines["rays"])
    rpp = rays / pixels
    d = {"scene": lines["scene"], "ray_set": st,
         "description": (f"{method} path tracer, {spp} spp: extension + shadow rays" if st == "pathtrace"
                         else "primary + bounce:1..4, one image each"),
         "scheme": s, "params": params.replace("--param ", ""), "image": f"{size}x{size}",
         "rays": rays, "rays_per_pixel": f"{rpp:.4f}",
         "ext_rays": ext if st == "pathtrace" else "", "shadow_rays": shadow if st == "pathtrace" else "",
         "ext_rays_by_segment": survivors if st == "pathtrace" else "",
         "instructions_per_ray": cg("Ir", rays), "loads_per_ray": cg("Dr", rays), "stores_per_ray": cg("Dw", rays),
         "read_lines_per_ray": f"{reads(lines) / rays:.2f}", "write_lines_per_ray": f"{writes(lines) / rays:.2f}",
         "read_words_per_ray": f"{reads(words) / rays:.2f}",
         "l1_read_hit_m": lines["l1_read_hit_m"], "l1_write_hit_m": lines["l1_write_hit_m"],
         "l2_read_hit_m": lines["l2_read_hit_m"], "l3_read_hit_m": lines["l3_read_hit_m"],
         "mem_read_m": lines["mem_read_m"],
         "d1_misses_per_ray": cg("D1mr", rays, ev.get("D1mw", 0), 2),
         "loads_per_pixel": cg("Dr", pixels), "stores_per_pixel": cg("Dw", pixels),
         "read_lines_per_pixel": f"{reads(lines) / pixels:.1f}", "read_words_per_pixel": f"{reads(words) / pixels:.1f}",
         # Reads that miss the simulated L1 (its L2 + L3 hits + memory reads), per pixel: a line-level
         # count, whatever unit the accesses are counted in.
         "l1_read_misses_per_pixel": f"{sum(float(lines[k]) for k in ('l2_read_hit_m', 'l3_read_hit_m', 'mem_read_m')) * 1e6 / pixels:.1f}"}
    rows.append(d)
with open(out, "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=list(rows[0])); w.writeheader(); w.writerows(rows)
print("\n".join(f"{r['ray_set']:<10} {r['scheme']:<8} rays/pixel {r['rays_per_pixel']:>7}  per pixel: loads "
                f"{r['loads_per_pixel']:>8} stores {r['stores_per_pixel']:>7} lines {r['read_lines_per_pixel']:>7} "
                f"words {r['read_words_per_pixel']:>7}" for r in rows))
print(f"-> {out}", file=sys.stderr)
PY
