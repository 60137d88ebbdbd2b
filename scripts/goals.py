#!/usr/bin/python3
"""Prints the performance goals (issue "Performance") as ratios from travbench run CSVs.

Usage: /usr/bin/python3 scripts/goals.py run1.csv [run2.csv ...]
Each CSV should come from one `travbench run` (same run = comparable timings) with at least the
workloads primary, bounce:2 and bounce:3; a CSV with --threads 2 rows adds the scaling line.
"""
import csv
import sys
from collections import defaultdict

SINGLE = ["bvh_single", "mbvh4_single", "mbvh8_single", "kd_single"]
BATCH = ["mbvh_rs", "raygrid"]
PACKET = ["bvh_masked", "bvh_ranged", "bvh_partition", "kd_packet"]


def best(cells, names, workload):
    got = [(cells[(workload, n)], n) for n in names if (workload, n) in cells]
    return max(got) if got else (None, None)


def ratio(a, b):
    return f"{a / b:.2f}x" if a and b else "n/a"


def main(paths):
    for path in paths:
        rows = list(csv.DictReader(open(path)))
        by_threads = defaultdict(dict)
        for r in rows:
            by_threads[int(r["threads"])][(r["workload"], r["scheme"])] = float(r["mrays_median"])
        scene = rows[0]["scene"] if rows else path
        c = by_threads[min(by_threads)] if by_threads else {}
        print(f"== {scene} ({path})")
        s2, s2n = best(c, SINGLE, "bounce:2")
        print(f"  best single-ray on bounce:2 ({s2n}) / embree_single: {ratio(s2, c.get(('bounce:2', 'embree_single')))}"
              "   goal >= 1.10x")
        s3, s3n = best(c, SINGLE, "bounce:3")
        b3, b3n = best(c, BATCH, "bounce:3")
        print(f"  best batch on bounce:3 ({b3n}) / best single ({s3n}): {ratio(b3, s3)}   goal >= 1.3x")
        print(f"  best batch on bounce:3 ({b3n}) / embree_stream: {ratio(b3, c.get(('bounce:3', 'embree_stream')))}"
              "   goal >= 1.0x")
        sp, spn = best(c, SINGLE, "primary")
        pp, ppn = best(c, PACKET, "primary")
        print(f"  best packet on primary ({ppn}) / best single ({spn}): {ratio(pp, sp)}   goal >= 2x")
        print(f"  best packet on primary ({ppn}) / embree_packet8: {ratio(pp, c.get(('primary', 'embree_packet8')))}"
              "   goal >= 1.0x")
        if len(by_threads) > 1:
            lo, hi = min(by_threads), max(by_threads)
            for key in sorted(by_threads[lo]):
                if key in by_threads[hi]:
                    print(f"  scaling {key[1]:<16} {key[0]:<10} {hi} vs {lo} threads: "
                          f"{ratio(by_threads[hi][key], by_threads[lo][key])}   goal >= 1.8x")


if __name__ == "__main__":
    main(sys.argv[1:])
