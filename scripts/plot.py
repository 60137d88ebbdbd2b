#!/usr/bin/python3
"""Plots every travbench CSV in a results folder: one PNG per table.

Usage: /usr/bin/python3 scripts/plot.py results/<scene> [more folders...]
Run with Debian's /usr/bin/python3 (python3-matplotlib). Scheme colours are the same in every
plot; the thesis' values are drawn as hollow markers.
"""
import csv
import math
import zlib
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SCHEME_ORDER = [
    "bvh_single", "mbvh4_single", "mbvh8_single", "kd_single", "kd_packet", "bvh_masked", "bvh_ranged",
    "bvh_partition", "mbvh_rs", "raygrid", "cwbvh_single", "treelet_queue", "embree_single", "embree_packet8", "embree_stream", "reference",
    "mbvh8_packet", "simt_bvh", "mbvh8_interleave",
]
_palette = plt.get_cmap("tab20").colors


def colour(scheme):
    base = scheme.split("@")[0]
    # An entry with parameters of its own (`treelet_queue:tree=mbvh8`) takes its scheme's colour,
    # darkened: beside the default entry, never another scheme's colour.
    name, _, params = base.partition(":")
    i = SCHEME_ORDER.index(name) if name in SCHEME_ORDER else len(SCHEME_ORDER) + zlib.crc32(name.encode()) % 6  # stable across runs (str hash is salted)
    c = _palette[i % len(_palette)]
    return tuple(0.55 * x for x in c) if params else c


def read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def num(row, key):
    try:
        return float(row.get(key, "") or "nan")
    except ValueError:
        return math.nan


def points(rows, col):
    """(index, value) of the rows whose column `col` holds a number (thesis values, refit times)."""
    return [(i, num(r, col)) for i, r in enumerate(rows) if not math.isnan(num(r, col))]


def scatter(ax, pts, **style):
    """Marks the (index, value) points on ax; nothing when there are none."""
    if pts:
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], **style)


def finish_rows(fig, ax, path, labels, rotation, fontsize, title, ylabel, thesis=False):
    """finish() for a plot of one bar per CSV row, labelled under the bars."""
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels, rotation=rotation, fontsize=fontsize)
    finish(fig, ax, path.with_suffix(".png"), title, ylabel, thesis=thesis)


def ordered(names):
    return sorted(set(names), key=lambda s: (SCHEME_ORDER.index(s) if s in SCHEME_ORDER else 99, s))


def grouped_bars(ax, rows, group_key, groups, schemes, value_key, thesis_key=None, floor_key=None, floor_label=None):
    """Bars per group and scheme; thesis_key: hollow circles at the thesis' values; floor_key: a black
    tick at a lower bound of each bar (labelled once as floor_label)."""
    width = 0.8 / max(1, len(schemes))
    floors = []
    for j, s in enumerate(schemes):
        xs, ys, ts = [], [], []
        for i, g in enumerate(groups):
            match = [r for r in rows if r[group_key] == g and r["scheme"] == s]
            if not match:
                continue
            xs.append(i + (j - (len(schemes) - 1) / 2) * width)
            ys.append(num(match[0], value_key))
            ts.append(num(match[0], thesis_key) if thesis_key else math.nan)
            if floor_key and match[0].get(floor_key):
                floors.append((xs[-1], num(match[0], floor_key)))
        layout = next((r.get("layout") for r in rows if r["scheme"] == s and r.get("layout")), "")
        ax.bar(xs, ys, width, label=f"{s} ({layout})" if layout else s, color=colour(s))
        pts = [(x, t) for x, t in zip(xs, ts) if not math.isnan(t)]
        if pts:
            ax.scatter([p[0] for p in pts], [p[1] for p in pts], facecolors="none", edgecolors="black",
                       zorder=3, s=28, label=None)
    if floors:
        ax.scatter([p[0] for p in floors], [p[1] for p in floors], marker="_", s=width * 900, color="black",
                   linewidths=2, zorder=4, label=floor_label)
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels(groups, rotation=20)


def finish(fig, ax, out, title, ylabel, thesis=False):
    ax.set_title(title)
    ax.set_ylabel(ylabel)
    handles, labels = ax.get_legend_handles_labels()
    if thesis:
        handles.append(plt.Line2D([], [], marker="o", markerfacecolor="none", markeredgecolor="black",
                                  linestyle=""))
        labels.append("thesis (Bikker 2012)")
    ax.legend(handles, labels, fontsize=7, ncol=2)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    print(f"wrote {out}")


def plot_run(path):
    rows = read(path)
    workloads = list(dict.fromkeys(r["workload"] for r in rows))
    schemes = ordered(r["scheme"] for r in rows if r["scheme"] != "reference")
    fig, ax = plt.subplots(figsize=(10, 4.8))
    grouped_bars(ax, rows, "workload", workloads, schemes, "mrays_median")
    scene = rows[0]["scene"] if rows else ""
    finish(fig, ax, path.with_suffix(".png"), f"{scene}: throughput per workload (1 thread, median)", "Mrays/s")


ERROR_KINDS = [("false_miss", "tab:red"), ("false_hit", "tab:orange"), ("wrong_t", "tab:purple"),
               ("ambiguous", "tab:gray")]


def error_kind_panel(ax, rows, title, key="kernel"):
    """Side-by-side bars per `key` (kernel, or scheme): the count of each error kind
    (docs/ACCURACY.md) summed over the rows, on a symlog axis (linear up to 1, log above), since a
    handful of leaks sits next to thousands of ambiguous rays; every nonzero count is written on
    its bar, so a single leak is as legible as a thousand."""
    groups = list(dict.fromkeys(r[key] for r in rows))
    width = 0.8 / len(ERROR_KINDS)
    top = 1.0
    for j, (kind, c) in enumerate(ERROR_KINDS):
        vals = [sum(0.0 if math.isnan(num(r, kind)) else num(r, kind) for r in rows if r[key] == g) for g in groups]
        xs = [i + (j - (len(ERROR_KINDS) - 1) / 2) * width for i in range(len(groups))]
        ax.bar(xs, vals, width, color=c, label=kind)
        for x, v in zip(xs, vals):
            if v > 0:
                ax.text(x, v, f"{v:.0f}", ha="center", va="bottom", fontsize=5, rotation=90)
        top = max([top] + vals)
    ax.set_yscale("symlog", linthresh=1)
    ax.set_ylim(0, top * 30)
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels(groups, rotation=30 if key == "kernel" else 60, fontsize=7)
    ax.set_title(title, fontsize=9)
    ax.set_ylabel("rays (symlog; all rows summed)", fontsize=8)
    ax.grid(alpha=0.3, axis="y")


def plot_hard(path):
    """hard_cases.csv: one panel per hard:* workload, the error kinds of each scheme's default kernel."""
    rows = [r for r in read(path) if r["scheme"] != "reference"]
    workloads = list(dict.fromkeys(r["workload"] for r in rows))
    cols = 2
    nrows = (len(workloads) + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(14, 3.4 * nrows), squeeze=False)
    for ax, w in zip(axes.flat, workloads):
        wr = [r for r in rows if r["workload"] == w]
        error_kind_panel(ax, wr, f"{w} ({wr[0]['rays']} rays)", key="scheme")
    for ax in list(axes.flat)[len(workloads):]:
        ax.axis("off")
    if workloads:
        axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{rows[0]['scene'] if rows else ''}: error kinds of every scheme (default kernel) on the hard cases, "
                 "vs the exact reference (embree_*: baselines)")
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"), dpi=100)
    plt.close(fig)
    print(f"wrote {path.with_suffix('.png')}")


def plot_accuracy(path):
    """One panel per workload: Mrays/s against mismatch rate, colour = scheme, marker = kernel;
    a last row splits the disagreements into error kinds per kernel and offset."""
    all_rows = read(path)
    rows = [r for r in all_rows if r.get("offset", "0") == "0"]
    workloads = list(dict.fromkeys(r["workload"] for r in rows))
    offsets = list(dict.fromkeys(r.get("offset", "0") for r in all_rows))
    markers = {"watertight": "o", "moller": "s", "plane": "^", "plane_rcp": "v", "embree_robust": "D",
               "embree_default": "P"}
    cols = 4
    nrows = (len(workloads) + cols - 1) // cols
    fig, axes = plt.subplots(nrows + 1, cols, figsize=(16, 3.2 * (nrows + 1)), squeeze=False)
    for ax, w in zip(axes.flat, workloads):
        for r in (r for r in rows if r["workload"] == w):
            ax.scatter(num(r, "mrays_median"), max(num(r, "mismatch_rate"), 1e-6), color=colour(r["scheme"]),
                       marker=markers.get(r["kernel"], "x"), s=22, alpha=0.8)
        ax.set_yscale("log")
        ax.set_ylim(5e-7, 2)
        ax.axhline(1e-5, color="red", lw=0.8, ls="--")
        ax.set_title(w, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(workloads):]:
        ax.axis("off")
    for ax in axes[:nrows, 0]:
        ax.set_ylabel("mismatch rate (floor = 0)")
    for ax in axes[nrows - 1]:
        ax.set_xlabel("Mrays/s")
    for ax, off in zip(axes[nrows], offsets):
        ax.axis("on")
        error_kind_panel(ax, [r for r in all_rows if r.get("offset", "0") == off], f"error kinds, offset {off}")
    if offsets:
        axes[nrows][0].legend(fontsize=7)
    handles = [plt.Line2D([], [], marker="o", color=colour(s), linestyle="") for s in ordered(r["scheme"] for r in rows)]
    labels = ordered(r["scheme"] for r in rows)
    handles += [plt.Line2D([], [], marker=m, color="gray", linestyle="") for m in markers.values()]
    labels += list(markers)
    fig.suptitle(f"{rows[0]['scene'] if rows else ''}: speed vs error per workload (red: 1e-5 accuracy bar); "
                 "error kinds vs the exact reference")
    fig.tight_layout(rect=(0, 0, 0.87, 1))
    fig.legend(handles, labels, loc="center right", fontsize=7, ncol=1)
    fig.savefig(path.with_suffix(".png"), dpi=100)
    plt.close(fig)
    print(f"wrote {path.with_suffix('.png')}")


def plot_divergence(path):
    rows = read(path)
    views = sorted({r["view"] for r in rows})
    fig, axes = plt.subplots(2, len(views), figsize=(5 * len(views), 7.5), squeeze=False)
    for c, v in enumerate(views):
        vr = [r for r in rows if r["view"] == v]
        workloads = list(dict.fromkeys(r["workload"] for r in vr))
        for s in ordered(r["scheme"] for r in vr):
            sr = {r["workload"]: r for r in vr if r["scheme"] == s}
            xs = [i for i, w in enumerate(workloads) if w in sr]
            axes[0][c].plot(xs, [num(sr[workloads[i]], "mrays_median") for i in xs], "-o", ms=3, color=colour(s),
                            label=s)
            axes[1][c].plot(xs, [num(sr[workloads[i]], "pct_of_d1") for i in xs], "-o", ms=3, color=colour(s))
            th = [(i, num(sr[workloads[i]], "thesis_mrays")) for i in xs]
            th = [p for p in th if not math.isnan(p[1])]
            if th:
                axes[0][c].scatter([p[0] for p in th], [p[1] for p in th], facecolors="none", edgecolors="black")
        for ax in axes[:, c]:
            ax.set_xticks(range(len(workloads)))
            ax.set_xticklabels([w.replace("divergence:", "D=") for w in workloads], rotation=30, fontsize=8)
            ax.grid(alpha=0.3)
        axes[0][c].set_title(f"view {v}")
        axes[0][c].set_ylabel("Mrays/s")
        axes[1][c].set_ylabel("% of D=1")
    axes[0][0].legend(fontsize=7)
    fig.suptitle("divergence (thesis §3.4, Tables 2-4; hollow = thesis, ranged packets)")
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"), dpi=110)
    plt.close(fig)
    print(f"wrote {path.with_suffix('.png')}")


def plot_by_workload_with_thesis(path, title):
    rows = read(path)
    workloads = list(dict.fromkeys(r["workload"] for r in rows))
    schemes = ordered(r["scheme"] for r in rows)
    fig, ax = plt.subplots(figsize=(10, 4.8))
    grouped_bars(ax, rows, "workload", workloads, schemes, "mrays_median", "thesis_mrays")
    finish(fig, ax, path.with_suffix(".png"), title, "Mrays/s", thesis=True)
    if rows and "rays_per_node" in rows[0]:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        for ax, key in zip(axes, ["rays_per_node", "rays_per_leaf"]):
            grouped_bars(ax, rows, "workload", workloads, schemes, key, "thesis_" + key)
            ax.set_yscale("log")
            ax.set_ylabel(key.replace("_", " "))
            ax.grid(axis="y", alpha=0.3)
        axes[0].legend(fontsize=7)
        fig.suptitle("average rays per visited node (thesis Tables 8/10; hollow = thesis)")
        fig.tight_layout()
        out = path.with_name(path.stem + "_rays_per_node.png")
        fig.savefig(out, dpi=110)
        plt.close(fig)
        print(f"wrote {out}")


def plot_cache(path):
    rows = read(path)
    labels = [r.get("label") or r["scheme"] for r in rows]
    levels = [("l1", "L1"), ("l2", "L2"), ("l3", "L3"), ("mem", "memory")]
    lat = {"l1": 4, "l2": 11, "l3": 39, "mem": 107}
    fig, ax = plt.subplots(figsize=(max(7, len(rows) * 0.8), 4.8))
    bottom = [0.0] * len(rows)
    for (key, name), shade in zip(levels, ["#9ecae1", "#4292c6", "#08519c", "#08306b"]):
        col = f"{key}_read_hit_m" if key != "mem" else "mem_read_m"
        vals = [num(r, col) * lat[key] for r in rows]  # 1e6 hits x cycles = 1e6 cycles
        vals = [0 if math.isnan(v) else v for v in vals]
        ax.bar(range(len(rows)), vals, bottom=bottom, color=shade, label=name)
        bottom = [b + v for b, v in zip(bottom, vals)]
    th = points(rows, "thesis_read_cost_mcycles")
    if th:
        ax2 = ax.twinx()
        scatter(ax2, th, facecolors="none", edgecolors="black")
        ax2.set_ylabel("thesis estimate (1e6 cycles, Conference 512x512)")
    finish_rows(fig, ax, path, labels, 30, 8, "estimated read cost per level (thesis §5.4, Table 11)",
                "1e6 cycles (read hits x latency)", thesis=bool(th))


def plot_scaling(path):
    rows = read(path)
    fig, (ax, axm) = plt.subplots(1, 2, figsize=(12, 5))
    for s in ordered(r["scheme"] for r in rows):
        sr = sorted((r for r in rows if r["scheme"] == s), key=lambda r: num(r, "triangles"))
        tris = [num(r, "triangles") for r in sr]
        ax.plot(tris, [num(r, "mrays_median") for r in sr], "-o", ms=3, color=colour(s), label=s)
        # Schemes sharing one structure (the BVH packet schemes, the three Embree APIs) overlap here.
        axm.plot(tris, [num(r, "structure_mb") for r in sr], "-o", ms=3, color=colour(s), label=s)
    for a in (ax, axm):
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("triangles")
    axm.set_title("structure memory")
    axm.set_ylabel("MiB (nodes + triangle data)")
    axm.grid(axis="y", alpha=0.3)
    finish(fig, ax, path.with_suffix(".png"), "scaling: bounce:2 on spheres:N (1 thread)", "Mrays/s")


def plot_bandwidth(path):
    """table bandwidth (issue 19): bytes per node fetch, memory reads per ray, speed; per workload."""
    rows = read(path)
    workloads = list(dict.fromkeys(r["workload"] for r in rows))
    schemes = ordered(r["scheme"] for r in rows)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    panels = [("bytes_per_node", "bytes per node fetch"), ("mem_reads_per_ray", "simulated memory reads per ray (64 B lines)"),
              ("mrays_median", "Mrays/s (1 thread, median)")]
    for ax, (key, label) in zip(axes, panels):
        # The memory reads' compulsory part (cold reads, cachesim/hierarchy.h) as a tick on each bar.
        floor = ("cold_reads_per_ray", "cold reads (compulsory)") if key == "mem_reads_per_ray" else (None, None)
        grouped_bars(ax, rows, "workload", workloads, schemes, key, floor_key=floor[0], floor_label=floor[1])
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
        if floor[0] and any(r.get(floor[0]) for r in rows):
            ax.legend(handles=[h for h in ax.get_legend_handles_labels()[0] if h.get_label() == floor[1]], fontsize=8)
    scene = rows[0]["scene"] if rows else ""
    finish(fig, axes[0], path.with_suffix(".png"), f"{scene}: node bytes, memory reads, speed", "bytes per node fetch")


def plot_build(path):
    rows = read(path)
    labels = [f'{r["structure"]} {r.get("triangles", "")} tris, {r.get("threads", "1")} thr' for r in rows]
    fig, ax = plt.subplots(figsize=(max(7, len(rows) * 0.5), 5.2))
    ax.bar(range(len(rows)), [num(r, "build_ms") for r in rows], color="#4292c6", label="build (travbench / Embree)")
    scatter(ax, points(rows, "refit_ms"), marker="_", s=200, color="#d94801", zorder=3, label="refit")
    th = points(rows, "thesis_ms")
    scatter(ax, th, facecolors="none", edgecolors="black")
    scatter(ax, points(rows, "thesis_refit_ms"), marker="D", facecolors="none", edgecolors="#d94801",
            label="thesis refit")
    ax.set_yscale("log")
    finish_rows(fig, ax, path, labels, 60, 7, "build and refit times, 1 thread unless marked (thesis Table 1)",
                "ms (log)", thesis=bool(th))


def plot_simt(path):
    """Tables 12-13 on the SIMT warp model (docs/SIMT.md): efficiency, % of D=1, Table 13 growth."""
    rows = read(path)
    loops = list(dict.fromkeys(r["loop"] for r in rows))
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    styles = {"while_while": "tab:blue", "if_if": "tab:orange"}
    t12 = list(dict.fromkeys(r["row"] for r in rows if r["table"] == "12"))
    t13 = list(dict.fromkeys(r["row"] for r in rows if r["table"] == "13"))
    for loop in loops:
        lr = {(r["table"], r["row"]): r for r in rows if r["loop"] == loop}
        c = styles.get(loop, "tab:green")
        axes[0].plot(range(len(t12)), [num(lr[("12", k)], "simt_efficiency") for k in t12], "-o", ms=3, color=c,
                     label=loop)
        axes[1].plot(range(len(t12)), [num(lr[("12", k)], "model_pct_of_base") for k in t12], "-o", ms=3, color=c,
                     label=f"model, {loop}")
        axes[2].plot(range(len(t13)), [num(lr[("13", k)], "model_mrays") for k in t13], "-o", ms=3, color=c,
                     label=f"model, {loop}")
    first = {(r["table"], r["row"]): r for r in rows if r["loop"] == loops[0]}
    th12 = [(i, num(first[("12", k)], "thesis_pct_of_base")) for i, k in enumerate(t12)]
    th13 = [(i, num(first[("13", k)], "thesis_mrays")) for i, k in enumerate(t13)]
    for ax, th in ((axes[1], th12), (axes[2], th13)):
        th = [p for p in th if not math.isnan(p[1])]
        if th:
            ax.scatter([p[0] for p in th], [p[1] for p in th], facecolors="none", edgecolors="black", zorder=3,
                       label="thesis (GTX470)")
    for ax, labels, title, ylabel in ((axes[0], t12, "SIMT efficiency (Table 12 rows)", "active lanes / 32"),
                                      (axes[1], t12, "Table 12: % of D=1", "% of D=1"),
                                      (axes[2], t13, "Table 13: O active lanes per warp (rnd2)", "Mrays/s (log)")):
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=30, fontsize=8)
        ax.set_title(title)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[2].set_yscale("log")
    scene = rows[0]["scene"] if rows else ""
    fig.suptitle(f"{scene}: SIMT warp model of GPU traversal (thesis §6.2; a model, not a GPU measurement)")
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"), dpi=110)
    plt.close(fig)
    print(f"wrote {path.with_suffix('.png')}")


def plot_pathtrace(path):
    """Tables 14-15 (thesis §6.3-6.4, Fig. 38/40): rmse against time per path-tracing method, ours
    (one CPU core) beside the thesis' (two GTX470s), and each method's lane utilisation."""
    rows = read(path)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    scheme = rows[0]["scheme"] if rows else ""
    mine = [r for r in rows if r["scheme"] == scheme]
    cols = {m: plt.get_cmap("tab10").colors[i % 10] for i, m in enumerate(methods)}
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    for m in methods:
        mr = sorted((r for r in mine if r["method"] == m), key=lambda r: num(r, "spp"))
        t = "cpu_ms" if "cpu_ms" in mr[0] else "ms"
        axes[0].plot([num(r, t) for r in mr], [num(r, "rmse") for r in mr], "-o", ms=4, color=cols[m], label=m)
        for r in mr:
            axes[0].annotate(r["spp"], (num(r, t), num(r, "rmse")), fontsize=6, xytext=(2, 2),
                             textcoords="offset points")
        th = [(num(r, "thesis_ms"), num(r, "thesis_rmse")) for r in mr if not math.isnan(num(r, "thesis_ms"))]
        if th:
            axes[1].plot([p[0] for p in th], [p[1] for p in th], "--o", ms=5, color=cols[m], mfc="none", label=m)
    xs = range(len(methods))
    w = 0.38
    u = [num(next(r for r in mine if r["method"] == m), "util") for m in methods]
    wu = [num(next(r for r in mine if r["method"] == m), "warp_util") for m in methods]
    axes[2].bar([x - w / 2 for x in xs], u, w, color="tab:blue", label="util (256-ray packets)")
    axes[2].bar([x + w / 2 for x in xs], wu, w, color="tab:orange", label="warp_util (32 lanes, modelled)")
    axes[2].set_xticks(list(xs))
    axes[2].set_xticklabels(methods, fontsize=8)
    spp0 = mine[0]["spp"] if mine else ""
    for ax, title, xl, yl in ((axes[0], f"ours: {scheme}, 1 thread, {mine[0]['width']}x{mine[0]['height']}" if mine else "",
                               "CPU ms per frame (log)", "rmse vs converged (log)"),
                              (axes[1], "thesis Tables 14-15 (two GTX470, 512x512)", "ms per frame (log)",
                               "rmse (log)"),
                              (axes[2], f"active lanes, extension rays ({spp0} spp)", "", "fraction of lanes")):
        ax.set_title(title, fontsize=10)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes[:2]:
        ax.set_xscale("log")
        ax.set_yscale("log")
    if not axes[1].lines:
        axes[1].text(0.5, 0.5, "no thesis values for this scene", ha="center", transform=axes[1].transAxes)
    fig.suptitle(f"{rows[0]['scene'] if rows else ''}: path-tracing schemes, error against time (thesis §6.3-6.4)")
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"), dpi=110)
    plt.close(fig)
    print(f"wrote {path.with_suffix('.png')}")


PLOTTERS = {
    "pathtrace": plot_pathtrace,
    "simt": plot_simt,
    "run": plot_run,
    "accuracy": plot_accuracy,
    "hard": plot_hard,
    "divergence": plot_divergence,
    "bounce": lambda p: plot_by_workload_with_thesis(p, "bounce depth (thesis §5.2.3, Table 7)"),
    "raygrid": lambda p: plot_by_workload_with_thesis(p, "RayGrid vs MBVH (thesis §5.3, Table 9)"),
    "cache": plot_cache,
    "scaling": plot_scaling,
    "build": plot_build,
    "bandwidth": plot_bandwidth,
}


def main(folders):
    for folder in folders:
        for path in sorted(Path(folder).glob("*.csv")):
            kind = path.stem.split("_")[0]
            if kind in PLOTTERS:
                try:
                    PLOTTERS[kind](path)
                except (KeyError, ValueError, IndexError) as e:
                    print(f"could not plot {path}: {e}", file=sys.stderr)


if __name__ == "__main__":
    main(sys.argv[1:] or ["results"])
