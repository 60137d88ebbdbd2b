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
(min..max of the per-round ratios), which is the noise floor to read the median against.
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


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--old", required=True)
    ap.add_argument("--new", required=True)
    ap.add_argument("--scenes", required=True)
    ap.add_argument("--workloads", default="primary,bounce:2")
    ap.add_argument("--schemes", default="all")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default="/tmp/ab_compare")
    ap.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    ratios = defaultdict(list)
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
    rows = sorted(ratios.items())
    if args.markdown:
        print("| scene | workload | scheme | new/old (median) | spread over rounds |")
        print("|---|---|---|---|---|")
        for (scene, wl, scheme), r in rows:
            print(f"| {scene} | {wl} | {scheme} | {statistics.median(r):.3f} | {min(r):.3f}–{max(r):.3f} |")
    else:
        for (scene, wl, scheme), r in rows:
            print(f"{scene:24s} {wl:10s} {scheme:16s} {statistics.median(r):.3f}  [{min(r):.3f}..{max(r):.3f}]")
    worst = min(rows, key=lambda kv: statistics.median(kv[1])) if rows else None
    if worst:
        print(f"slowest cell: {worst[0]} median new/old {statistics.median(worst[1]):.3f}", file=sys.stderr)


if __name__ == "__main__":
    main()
