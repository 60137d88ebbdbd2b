#!/usr/bin/python3
"""Per-round speed ratios of an interleaved `travbench table bandwidth` CSV (issue 19).

Usage: /usr/bin/python3 scripts/speed_ratios.py results/<scene>/bandwidth_512.csv [more CSVs...]

`table bandwidth` times its schemes round by round in one process (harness/table_bandwidth.cpp);
mrays_samples holds each round's Mrays/s in round order, so sample k of a scheme over sample k of
the table's first scheme (speed_base) is the ratio of two traces of one round. Prints per cell the
median ratio, its interquartile range and min..max, the cell's median Mrays/s and memory reads per ray.
"""
import csv
import statistics
import sys


def main(paths):
    for path in paths:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        base = {r["workload"]: [float(x) for x in r["mrays_samples"].split(";")]
                for r in rows if r["scheme"] == r["speed_base"]}
        for r in rows:
            s = [float(x) for x in r["mrays_samples"].split(";")]
            rat = sorted(a / b for a, b in zip(s, base[r["workload"]]))
            q = statistics.quantiles(rat, n=4) if len(rat) > 1 else [rat[0]] * 3
            print(f"{path} {r['scheme']:14s} {r['workload']:9s} rounds={len(rat)} ratio median {statistics.median(rat):.3f} "
                  f"IQR {q[0]:.2f}-{q[2]:.2f} min-max {rat[0]:.2f}-{rat[-1]:.2f}  {float(r['mrays_median']):.3f} Mrays/s  "
                  f"{float(r['mem_reads_per_ray']):.2f} memory reads/ray")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
