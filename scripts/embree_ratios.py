#!/usr/bin/python3
"""Each scheme's speed as a ratio to a baseline of the same run, over repeated runs.

Usage:
  for i in 1 2 3 4 5; do
    build/travbench run --scene S --schemes mbvh8_single,mbvh4_single,embree_single \
        --workloads primary,bounce:2 --reps 7 --csv /tmp/r_$i.csv
  done
  /usr/bin/python3 scripts/embree_ratios.py [--baseline embree_single] /tmp/r_*.csv

Every CSV is one `travbench run` (one process: its cells are comparable); per CSV and
(scene, workload) each scheme's mrays_median is divided by the baseline's of the same CSV, and the
script prints, per (scene, workload, scheme), the median and the min..max of those ratios over the
CSVs, and the baseline's own Mrays/s (median, min..max: how much the machine moved between runs).
On a shared machine interleave the runs of the scenes (and of two binaries) rather than running
one scene's repetitions back to back.
"""
import argparse
import csv
import statistics
from collections import defaultdict


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csvs", nargs="+")
    ap.add_argument("--baseline", default="embree_single")
    args = ap.parse_args()
    ratios, base = defaultdict(list), defaultdict(list)
    for path in args.csvs:
        with open(path) as f:
            rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
        ref = {(r["scene"], r["workload"]): float(r["mrays_median"]) for r in rows if r["scheme"] == args.baseline}
        for r in rows:
            key = (r["scene"], r["workload"])
            if key not in ref:
                continue
            if r["scheme"] == args.baseline:
                base[key].append(ref[key])
            else:
                ratios[key + (r["scheme"],)].append(float(r["mrays_median"]) / ref[key])
    if not ratios:
        raise SystemExit(f"embree_ratios: no cell has a {args.baseline} row to divide by")
    print(f"{'scene':<24}{'workload':<12}{'scheme':<16}{'median':>8}  min..max     runs   {args.baseline} Mrays/s")
    for (scene, workload, scheme), v in sorted(ratios.items()):
        b = base[(scene, workload)]
        print(f"{scene:<24}{workload:<12}{scheme:<16}{statistics.median(v):8.3f}  {min(v):.3f}..{max(v):.3f}  {len(v):4d}"
              f"   {statistics.median(b):.2f} ({min(b):.2f}..{max(b):.2f})")


if __name__ == "__main__":
    main()
