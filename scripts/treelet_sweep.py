#!/usr/bin/python3
"""treelet_queue's simulated memory reads per ray over its pool size x treelet budget (issue 19).

Usage:
  /usr/bin/python3 scripts/treelet_sweep.py --scene ../shared/scenes/crytek_sponza_partial.obj \
      --width 512 --height 512 --out results/crytek_sponza_partial/treelet_sweep.csv \
      [--flights 1024,4096,...] [--budgets 32768,262144,...] [--tree cwbvh|mbvh8] [--bin build/travbench]

Each point is one `travbench table bandwidth --schemes treelet_queue --reps 1 --param
rays_in_flight=F --param treelet_bytes=B --param tree=T` (the default --cache hierarchy
l1=32K:8,l2=256K:8,l3=2M:16); one more run of mbvh8_single gives the ratio. Per (point, workload)
the CSV keeps the memory reads per ray, their ratio to mbvh8_single's, where they go
(treelet_mem_slots, _stacks: the suspended rays' state; _nodes, _tris: the scene; _other: ray
batch, queues, treelet map) and the queue statistics, and the cold reads of the single-ray scheme
whose visits treelet_queue reorders on the same arrays (lines first touched by a load: the floor
under any reordering; mbvh8_single's for tree=mbvh8, cwbvh_single's for tree=cwbvh, the default;
`floor_ratio` is that floor over mbvh8_single's reads, the least ratio any point can reach). Rows
without a `tree` column (files written before it) are tree=mbvh8. The question it answers: is there a pool size at which the waiting rays' state
stays cached while the queues are still long enough to amortise the treelets (the goal: <= 0.5x
mbvh8_single on bounce:2 beyond L3)? Points already in --out are kept (an interrupted sweep resumes).
A PNG beside --out plots bounce:2's reads per ray against the pool size, one line per budget.
"""
import argparse
import csv
import os
import subprocess
import sys
import tempfile

KEEP = ["mem_reads_per_ray", "cold_reads_per_ray", "treelet_mem_slots", "treelet_mem_stacks", "treelet_mem_nodes", "treelet_mem_tris",
        "treelet_mem_other", "treelet_switches_per_ray", "treelet_rays_per_visit", "treelet_queue_rays", "treelets",
        "rays", "mismatch_rate", "false_miss", "false_hit"]
FIELDS = ["scene", "width", "height", "workload", "tree", "rays_in_flight", "treelet_bytes", "ratio_to_mbvh8_single",
          "mbvh8_single_mem_reads_per_ray", "mbvh8_single_cold_reads_per_ray", "floor_cold_reads_per_ray", "floor_ratio"] + KEEP + ["state_reads_per_ray", "other_reads_per_ray",
                                                       "reads_if_state_48B_per_switch", "ratio_if_state_48B_per_switch",
                                                       "ratio_if_state_free"]
# The smallest state a suspended ray can be resumed from: origin and direction (24 bytes), closest
# t and primitive (8), the reference it resumes at (4), its ray index (4) and one stack entry
# (reference and entry distance, 8) = 48 bytes, 0.75 of a 64-byte line. "if_state_48B": the
# measured scene and other reads plus that much per treelet switch, streamed from memory (a pool
# that amortises the treelets is far larger than the L3: 65536 x 48 bytes = 3 MiB), or the measured
# state reads where those are fewer (small pools whose state stays cached); "if_state_free":
# the state costs nothing (Aila and Karras' on-chip queues).
STATE_LINES_PER_SWITCH = 48 / 64


def derive(row):
    f = {k: float(row[k]) for k in ("mem_reads_per_ray", "treelet_mem_slots", "treelet_mem_stacks",
                                     "treelet_switches_per_ray", "mbvh8_single_mem_reads_per_ray")}
    state = f["treelet_mem_slots"] + f["treelet_mem_stacks"]
    other = f["mem_reads_per_ray"] - state
    # A smaller state never costs more lines than the measured one: the lesser of the two.
    bound = other + min(state, STATE_LINES_PER_SWITCH * f["treelet_switches_per_ray"])
    base = f["mbvh8_single_mem_reads_per_ray"]
    row.update({"state_reads_per_ray": state, "other_reads_per_ray": other, "reads_if_state_48B_per_switch": bound,
                "ratio_if_state_48B_per_switch": bound / base, "ratio_if_state_free": other / base})
    return row


def bandwidth(args, scheme, params):
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "b.csv")
        cmd = [args.bin, "table", "bandwidth", "--scene", args.scene, "--schemes", scheme, "--width", str(args.width),
               "--height", str(args.height), "--reps", "1", "--csv", path]
        for p in params:
            cmd += ["--param", p]
        print(" ".join(cmd), file=sys.stderr, flush=True)
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        with open(path, newline="") as f:
            return {r["workload"]: r for r in csv.DictReader(f)}


def plot(rows, out_png, scene, tree):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    b2 = [r for r in rows if r["workload"] == "bounce:2"]
    base = float(b2[0]["mbvh8_single_mem_reads_per_ray"])
    for budget in sorted({int(r["treelet_bytes"]) for r in b2}):
        pts = sorted((int(r["rays_in_flight"]), r) for r in b2 if int(r["treelet_bytes"]) == budget)
        xs = [p[0] for p in pts]
        line, = axes[0].plot(xs, [float(p[1]["mem_reads_per_ray"]) for p in pts], marker="o", label=f"{budget // 1024} KiB")
        axes[0].plot(xs, [float(derive(dict(p[1]))["reads_if_state_48B_per_switch"]) for p in pts], ls="--", lw=1,
                     color=line.get_color(), label=f"{budget // 1024} KiB, state of 48 B")
        state = [float(p[1]["treelet_mem_slots"]) + float(p[1]["treelet_mem_stacks"]) for p in pts]
        scene_reads = [float(p[1]["mem_reads_per_ray"]) - s for p, s in zip(pts, state)]
        line, = axes[1].plot(xs, state, marker="o", label=f"state, {budget // 1024} KiB")
        axes[1].plot(xs, scene_reads, marker="x", ls="--", color=line.get_color(), label=f"rest, {budget // 1024} KiB")
    for ax in axes:
        ax.set_xscale("log", base=2)
        ax.set_xlabel("rays in flight")
        ax.grid(alpha=0.3)
    axes[0].axhline(base, color="k", lw=1, label="mbvh8_single")
    axes[0].axhline(0.5 * base, color="k", lw=1, ls=":", label="goal: 0.5x mbvh8_single")
    floor = b2[0].get("floor_cold_reads_per_ray") or b2[0].get("mbvh8_single_cold_reads_per_ray")
    if floor:
        single = "cwbvh_single" if tree == "cwbvh" else "mbvh8_single"
        axes[0].axhline(float(floor), color="tab:red", lw=1, ls="-.", label=f"floor: {single}'s cold reads")
    axes[0].set_ylabel("simulated memory reads per ray")
    axes[0].set_title(f"treelet_queue (tree={tree}), {scene} bounce:2")
    axes[0].legend(fontsize=6, ncol=2)
    axes[1].set_title("split: waiting rays' state (slots + stacks) vs the rest")
    axes[1].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)


def write(path, rows):
    with open(path, "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=FIELDS, restval="")
        wr.writeheader()
        wr.writerows(derive(r) for r in rows)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", required=True)
    ap.add_argument("--width", type=int, default=512)
    ap.add_argument("--height", type=int, default=512)
    ap.add_argument("--flights", default="1024,4096,8192,16384,32768,65536,131072,262144")
    ap.add_argument("--budgets", default="262144,32768,2097152,1048576,131072")
    ap.add_argument("--tree", default="cwbvh", choices=["cwbvh", "mbvh8"])
    ap.add_argument("--bin", default="build/travbench")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    rows = []
    if os.path.exists(args.out):
        with open(args.out, newline="") as f:
            rows = [r for r in csv.DictReader(f) if r["width"] == str(args.width) and r["height"] == str(args.height)]
    for r in rows:
        r["tree"] = r.get("tree") or "mbvh8"
    done = {(r["tree"], r["rays_in_flight"], r["treelet_bytes"]) for r in rows}
    base = {r["workload"]: r["mbvh8_single_mem_reads_per_ray"] for r in rows}
    cold = {r["workload"]: r.get("mbvh8_single_cold_reads_per_ray", "") for r in rows}
    if not base:
        got = bandwidth(args, "mbvh8_single", [])
        base = {w: r["mem_reads_per_ray"] for w, r in got.items()}
        cold = {w: r.get("cold_reads_per_ray", "") for w, r in got.items()}
    # The floor: the cold reads of the single-ray scheme whose visits the treelets reorder.
    floor = dict(cold)
    if args.tree == "cwbvh":
        floor = {w: r.get("cold_reads_per_ray", "") for w, r in bandwidth(args, "cwbvh_single", []).items()}
    scene = os.path.splitext(os.path.basename(args.scene))[0]
    for budget in args.budgets.split(","):
        for flight in args.flights.split(","):
            if (args.tree, flight, budget) in done:
                continue
            got = bandwidth(args, "treelet_queue", [f"rays_in_flight={flight}", f"treelet_bytes={budget}", f"tree={args.tree}"])
            for w, r in got.items():
                row = {"scene": scene, "width": args.width, "height": args.height, "workload": w, "tree": args.tree,
                       "rays_in_flight": flight, "treelet_bytes": budget,
                       "ratio_to_mbvh8_single": float(r["mem_reads_per_ray"]) / float(base[w]),
                       "mbvh8_single_mem_reads_per_ray": base[w], "mbvh8_single_cold_reads_per_ray": cold.get(w, ""),
                       "floor_cold_reads_per_ray": floor.get(w, ""),
                       "floor_ratio": float(floor[w]) / float(base[w]) if floor.get(w) else ""}
                row.update({k: r.get(k, "") for k in KEEP})
                rows.append(row)
            write(args.out, rows)  # after every point: an interrupted sweep resumes
    write(args.out, rows)
    mine = [r for r in rows if r["tree"] == args.tree]
    plot(mine, os.path.splitext(args.out)[0] + ".png", scene, args.tree)
    best = min((r for r in mine if r["workload"] == "bounce:2"), key=lambda r: float(r["mem_reads_per_ray"]))
    for key in ("ratio_if_state_48B_per_switch", "ratio_if_state_free"):
        b = min((derive(dict(r)) for r in mine if r["workload"] == "bounce:2"), key=lambda r: float(r[key]))
        print(f"best bounce:2 {key}: rays_in_flight={b['rays_in_flight']} treelet_bytes={b['treelet_bytes']}: "
              f"{float(b[key]):.3f}x mbvh8_single")
    print(f"best bounce:2 point: rays_in_flight={best['rays_in_flight']} treelet_bytes={best['treelet_bytes']}: "
          f"{float(best['mem_reads_per_ray']):.2f} reads/ray = {float(best['ratio_to_mbvh8_single']):.3f}x mbvh8_single")
    if best.get("floor_ratio") not in (None, ""):
        floor = best.get("floor_cold_reads_per_ray") or best["mbvh8_single_cold_reads_per_ray"]
        single = "cwbvh_single" if args.tree == "cwbvh" else "mbvh8_single"
        print(f"floor ({single}'s cold reads): {float(floor):.2f} reads/ray = "
              f"{float(best['floor_ratio']):.3f}x mbvh8_single: no point can go below it")


if __name__ == "__main__":
    main()
