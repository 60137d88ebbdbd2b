#!/usr/bin/python3
"""Before/after speed of two travbench binaries on the same rays, measured in interleaved runs.

Usage:
  /usr/bin/python3 scripts/ab_compare.py --old OLD_BIN --new NEW_BIN --rounds 3 \
      --scenes ../shared/scenes/sponza.obj,../shared/scenes/conference.obj \
      --workloads primary,bounce:2 [--schemes all] [--reps 5] [--out DIR] [--markdown]

Each round runs `OLD run` then `NEW run` (alternating which goes first) on every scene, so slow
drifts of a shared machine hit both binaries alike. Workload rays are deterministic (same seed), so
both binaries trace identical rays. Per (scene, workload, scheme) the script prints the median over
rounds of NEW/OLD Mrays/s (each run's cell is already the median of --reps) and the spread
(min..max of the per-round ratios), which is the noise floor to read the median against, and the
same median with each run's cell first divided by that run's --control scheme (default
embree_single, the same library in both binaries: what is left of its own ratio is the machine).

--callgrind counts instructions instead (valgrind's callgrind, collection toggled on inside
tb::measure: the timed traces only, one run per scheme and workload at --size x --size, 1 thread,
1 rep): exact and reproducible, but not time. Pass binaries valgrind can run (on an AVX-512 host,
builds with -DTRAVBENCH_NATIVE=OFF: scripts/valgrind_build.sh). It prints NEW/OLD instructions.
"""
import argparse
import csv
import os
import statistics
import subprocess
import sys
from collections import defaultdict


def run(binary, scene, args, csv_path):
    cmd = [binary, "run", "--scene", scene, "--schemes", args.schemes, "--workloads", args.workloads,
           "--reps", str(args.reps), "--csv", csv_path]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open(csv_path) as f:
        return {(r["scene"], r["workload"], r["scheme"]): float(r["mrays_median"]) for r in csv.DictReader(f)}


def count_instructions(binary, scene, scheme, workload, args, tag):
    """Instructions of the timed traces of one cell, counted by callgrind."""
    base = os.path.join(args.out, f"cg_{tag}_{os.path.basename(scene)}_{scheme}_{workload}".replace(":", "_"))
    cmd = ["valgrind", "--tool=callgrind", "--collect-atstart=no", "--toggle-collect=tb::measure(*",
           f"--callgrind-out-file={base}.cg", "-q", binary, "run", "--scene", scene, "--schemes", scheme,
           "--workloads", workload, "--width", str(args.size), "--height", str(args.size), "--reps", "1",
           "--threads", "1", "--csv", base + ".csv"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(base + ".cg") as f:
        for line in f:
            if line.startswith("totals:"):
                return int(line.split()[1])
    raise RuntimeError(f"no totals in {base}.cg")


def callgrind_main(args):
    schemes = args.schemes.split(",")
    if "all" in schemes:
        sys.exit("ab_compare: --callgrind needs an explicit --schemes list")
    print(f"{'scene':24s} {'workload':10s} {'scheme':16s} {'old':>12s} {'new':>12s}  new/old")
    for scene in args.scenes.split(","):
        for wl in args.workloads.split(","):
            for scheme in schemes:
                o = count_instructions(args.old, scene, scheme, wl, args, "old")
                n = count_instructions(args.new, scene, scheme, wl, args, "new")
                name = os.path.splitext(os.path.basename(scene))[0]
                print(f"{name:24s} {wl:10s} {scheme:16s} {o:12d} {n:12d}  {n / o:.3f}", flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", required=True)
    ap.add_argument("--new", required=True)
    ap.add_argument("--scenes", required=True)
    ap.add_argument("--workloads", default="primary,bounce:2")
    ap.add_argument("--schemes", default="all")
    # Options of one mode only default to None, so that giving one to the other mode is refused.
    ap.add_argument("--reps", type=int, help="timed: reps per run (default 5)")
    ap.add_argument("--rounds", type=int, help="timed: interleaved rounds (default 3)")
    ap.add_argument("--out", default="/tmp/ab_compare")
    ap.add_argument("--markdown", action="store_true", help="timed: markdown tables")
    ap.add_argument("--control", help="timed: the scheme each run is normalised by (default embree_single)")
    ap.add_argument("--callgrind", action="store_true")
    ap.add_argument("--size", type=int, help="--callgrind: image side (default 128)")
    args = ap.parse_args()
    timed_only = {"--reps": args.reps, "--rounds": args.rounds, "--control": args.control,
                  "--markdown": args.markdown or None}
    if args.callgrind:
        given = [k for k, v in timed_only.items() if v is not None]
        if given:
            ap.error(f"{', '.join(given)}: not used with --callgrind (one count per cell)")
        args.size = args.size or 128
    else:
        if args.size is not None:
            ap.error("--size: only with --callgrind (timed runs use travbench's default 512x512)")
        args.reps, args.rounds = args.reps or 5, args.rounds or 3
        args.control = args.control or "embree_single"
    os.makedirs(args.out, exist_ok=True)
    if args.callgrind:
        return callgrind_main(args)
    ratios = defaultdict(list)
    normed = defaultdict(list)
    for rnd in range(args.rounds):
        for si, scene in enumerate(args.scenes.split(",")):
            order = [("old", args.old), ("new", args.new)]
            if (rnd + si) % 2:
                order.reverse()
            got = {}
            for tag, binary in order:
                path = os.path.join(args.out, f"{tag}_{si}_{rnd}.csv")
                got[tag] = run(binary, scene, args, path)
                print(f"round {rnd + 1}/{args.rounds} {tag} {scene} done", file=sys.stderr)
            for key, new in got["new"].items():
                old = got["old"].get(key)
                if old:
                    ratios[key].append(new / old)
                    ctrl = (key[0], key[1], args.control)
                    if ctrl in got["new"] and ctrl in got["old"]:
                        normed[key].append((new / got["new"][ctrl]) / (old / got["old"][ctrl]))
    rows = sorted(ratios.items())

    def norm(key):
        n = normed.get(key)
        return f"{statistics.median(n):.3f}" if n else "-"
    if args.markdown:
        print(f"| scene | workload | scheme | new/old (median) | spread over rounds | median, each run / its {args.control} |")
        print("|---|---|---|---|---|---|")
        for key, r in rows:
            scene, wl, scheme = key
            print(f"| {scene} | {wl} | {scheme} | {statistics.median(r):.3f} | {min(r):.3f}–{max(r):.3f} | {norm(key)} |")
    else:
        for key, r in rows:
            scene, wl, scheme = key
            print(f"{scene:24s} {wl:10s} {scheme:16s} {statistics.median(r):.3f}  [{min(r):.3f}..{max(r):.3f}]  normalised {norm(key)}")
    # Per scheme: the geometric mean of its cells' medians and its lowest cell.
    by_scheme = defaultdict(list)
    for (scene, wl, scheme), r in rows:
        by_scheme[scheme].append(statistics.median(r))
    if args.markdown:
        print("\n| scheme | geometric mean of the cells' medians | lowest cell |")
        print("|---|---|---|")
    for scheme, meds in sorted(by_scheme.items()):
        gm = statistics.geometric_mean(meds)
        if args.markdown:
            print(f"| {scheme} | {gm:.3f} | {min(meds):.3f} |")
        else:
            print(f"{scheme:16s} geometric mean {gm:.3f}  lowest cell {min(meds):.3f}")
    worst = min(rows, key=lambda kv: statistics.median(kv[1])) if rows else None
    if worst:
        print(f"slowest cell: {worst[0]} median new/old {statistics.median(worst[1]):.3f}", file=sys.stderr)


if __name__ == "__main__":
    main()
