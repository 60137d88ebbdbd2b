#!/usr/bin/python3
"""Writes a rotated copy of a ../shared scene, with its camera views rotated the same way, as an
OBJ plus a scenes.json beside it: the same geometry and the same images, but no longer aligned with
the axes, so every axis-aligned box (BVH nodes, the spatial-split rules of structures/bvh_spatial.h)
sees a scene nobody tuned for. The output is derived from ../shared data: write it outside the
repository (default /tmp/rotated/) and never commit it.

Usage:
  /usr/bin/python3 scripts/rotated_scene.py conference --axis 0,1,0 --degrees 45 [--out /tmp/rotated]
  build/travbench run --scene /tmp/rotated/conference_r45_0_1_0.obj --schemes mbvh8_single,embree_single \
      --workloads primary,bounce:2

The rotation is about `--axis` through the origin (Rodrigues' formula, in double, vertices written
with 9 significant digits); the eye, target and up of every view of the scene's entry in
../shared/scenes/scenes.json turn with it. Lines other than `v` are copied as they are. The output's
scenes.json gains one entry per call (the file name without .obj).
"""
import argparse
import json
import math
import os
import sys

SHARED = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "scenes"))


def rotation(axis, degrees):
    n = math.sqrt(sum(a * a for a in axis))
    if not n > 0:
        sys.exit("rotated_scene: --axis must not be zero")
    x, y, z = (a / n for a in axis)
    t = math.radians(degrees)
    c, s, k = math.cos(t), math.sin(t), 1 - math.cos(t)
    return [[c + x * x * k, x * y * k - z * s, x * z * k + y * s],
            [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
            [z * x * k - y * s, z * y * k + x * s, c + z * z * k]]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="a scene of ../shared/scenes/scenes.json, e.g. conference")
    ap.add_argument("--axis", default="0,1,0", help="rotation axis x,y,z")
    ap.add_argument("--degrees", type=float, default=45.0)
    ap.add_argument("--out", default="/tmp/rotated")
    ap.add_argument("--shared", default=SHARED, help="the directory of scenes.json and the OBJs")
    args = ap.parse_args()
    try:
        axis = [float(a) for a in args.axis.split(",")]
    except ValueError:
        axis = []
    if len(axis) != 3 or not all(math.isfinite(a) for a in axis):
        sys.exit(f"rotated_scene: --axis '{args.axis}' is not three numbers x,y,z")
    if not math.isfinite(args.degrees):
        sys.exit("rotated_scene: --degrees must be a number")
    with open(os.path.join(args.shared, "scenes.json")) as f:
        scenes = json.load(f)
    if args.scene not in scenes:
        sys.exit(f"rotated_scene: no scene '{args.scene}' in {args.shared}/scenes.json (have: {', '.join(sorted(scenes))})")
    meta = scenes[args.scene]
    R = rotation(axis, args.degrees)

    def rot(p):
        return [sum(R[i][j] * p[j] for j in range(3)) for i in range(3)]

    os.makedirs(args.out, exist_ok=True)
    name = f"{args.scene}_r{args.degrees:g}_{'_'.join(f'{a:g}' for a in axis)}".replace("-", "m").replace(".", "p")
    path = os.path.join(args.out, name + ".obj")
    with open(os.path.join(args.shared, meta["file"])) as src, open(path, "w") as out:
        for ln, line in enumerate(src, 1):
            if line.startswith("v "):
                p = line.split()
                try:
                    v = rot([float(p[1]), float(p[2]), float(p[3])])
                except (IndexError, ValueError):
                    sys.exit(f"rotated_scene: {meta['file']}:{ln}: a vertex needs three numbers")
                out.write(f"v {v[0]:.9g} {v[1]:.9g} {v[2]:.9g}\n")
            else:
                out.write(line)
    views = [{"eye": rot(v["eye"]), "target": rot(v["target"]), "up": rot(v["up"]), "vfov_deg": v["vfov_deg"]}
             for v in meta.get("views", [])]
    index = os.path.join(args.out, "scenes.json")
    entries = {}
    if os.path.exists(index):
        with open(index) as f:
            entries = json.load(f)
    entries[name] = {"file": name + ".obj", "source": f"scripts/rotated_scene.py: {args.scene} turned "
                     f"{args.degrees:g} degrees about ({args.axis})", "views": views}
    with open(index, "w") as f:
        json.dump(entries, f, indent=1)
    print(path)


if __name__ == "__main__":
    main()
