#!/usr/bin/python3
"""Writes a scene shaped like issue 17's held-out scene: scanned models on a large ground plane
with a wall (a few huge triangles among many small ones), as an OBJ plus a scenes.json with its
camera views beside it. The output is derived from ../shared data: write it outside the repository
(default /tmp/heldout/heldout.obj) and never commit it.

Usage:
  /usr/bin/python3 scripts/heldout_scene.py [--out /tmp/heldout/heldout.obj] \
      [--dragon ../shared/scenes/dragon_100k.obj] [--bunny ../shared/scenes/bunny.obj]
  build/travbench run --scene /tmp/heldout/heldout.obj --schemes mbvh8_single,embree_single \
      --workloads primary,bounce:2

Layout (Y up, the models' units): dragon_100k as it is (14 x 10 x 6.3, standing on y = 0) at
x = -6; the bunny scaled 3x and dropped onto y = 0 at x = +8; a 120 x 120 ground quad at y = 0
and a 120 x 40 wall quad at z = -15: four huge triangles, appended after the models' triangles
(so primitive ids 0 .. n-5 are the models', in file order: dragon, then bunny). The issue's
held-out scene has 65% of its bounce rays starting on its four huge triangles; the views below
(eye 17-24 units from the models, looking down at them) give this scene a similar share, which
`--check RAYS.bin` reports for a ray file of `travbench rays`: view 1, bounce:2, 256x256: 68.8%
(`travbench rays --scene /tmp/heldout/heldout.obj --workload bounce:2 --width 256 --height 256
--out /tmp/heldout/b2.bin`).
"""
import argparse
import json
import os
import struct
import sys

GROUND_Y = 0.0
WALL_Z = -15.0
HALF = 60.0  # the ground is 120 x 120
WALL_H = 40.0


def read_obj(path):
    """v and f lines (the ../shared OBJs hold nothing else); polygons fanned like the loader."""
    verts, faces = [], []
    with open(path) as f:
        for ln, line in enumerate(f, 1):
            p = line.split()
            if not p or p[0].startswith("#"):
                continue
            if p[0] == "v":
                verts.append(tuple(float(x) for x in p[1:4]))
            elif p[0] == "f":
                idx = [int(x.split("/")[0]) for x in p[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                for k in range(2, len(idx)):
                    faces.append((idx[0], idx[k - 1], idx[k]))
            else:
                sys.exit(f"heldout_scene: {path}:{ln}: unexpected '{p[0]}' line (v and f only)")
    if not faces:
        sys.exit(f"heldout_scene: {path}: no faces")
    return verts, faces


def place(verts, scale, dx, dz):
    """Scaled by `scale`, moved by (dx, dz) and dropped so that its lowest vertex is on the ground."""
    lo_y = min(v[1] for v in verts) * scale
    return [(v[0] * scale + dx, v[1] * scale - lo_y + GROUND_Y, v[2] * scale + dz) for v in verts]


def views():
    look = [-1.0, 4.0, -2.0]
    return [{"eye": [9.0, 7.0, 15.0], "target": look, "up": [0, 1, 0], "vfov_deg": 60},
            {"eye": [-16.0, 7.0, 16.0], "target": look, "up": [0, 1, 0], "vfov_deg": 60},
            {"eye": [2.0, 18.0, 16.0], "target": [0.0, 2.0, -4.0], "up": [0, 1, 0], "vfov_deg": 60}]


def write(args):
    dv, df = read_obj(args.dragon)
    bv, bf = read_obj(args.bunny)
    dv = place(dv, 1.0, -6.0, 0.0)
    bv = place(bv, 3.0, 8.0, 1.0)
    quads = [[(-HALF, GROUND_Y, -HALF), (-HALF, GROUND_Y, HALF), (HALF, GROUND_Y, HALF), (HALF, GROUND_Y, -HALF)],
             [(-HALF, GROUND_Y, WALL_Z), (HALF, GROUND_Y, WALL_Z), (HALF, WALL_H, WALL_Z), (-HALF, WALL_H, WALL_Z)]]
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    name = os.path.splitext(os.path.basename(args.out))[0]
    with open(args.out, "w") as f:
        f.write(f"# {name}: written by travbench scripts/heldout_scene.py from {args.dragon} and {args.bunny}\n")
        base = 0
        for verts, faces in ((dv, df), (bv, bf)):
            f.writelines(f"v {x:.6g} {y:.6g} {z:.6g}\n" for x, y, z in verts)
            f.writelines(f"f {a + 1 + base} {b + 1 + base} {c + 1 + base}\n" for a, b, c in faces)
            base += len(verts)
        for q in quads:
            f.writelines(f"v {x:.6g} {y:.6g} {z:.6g}\n" for x, y, z in q)
            f.write(f"f {base + 1} {base + 2} {base + 3}\nf {base + 1} {base + 3} {base + 4}\n")
            base += 4
    with open(os.path.join(os.path.dirname(os.path.abspath(args.out)), "scenes.json"), "w") as f:
        json.dump({name: {"file": os.path.basename(args.out), "triangles": len(df) + len(bf) + 4,
                          "source": "scripts/heldout_scene.py (dragon_100k, bunny x3, ground and wall quads)",
                          "views": views()}}, f, indent=1)
    print(f"heldout_scene: {len(df) + len(bf) + 4} triangles -> {args.out} (+ scenes.json)")


def check(path):
    """Share of a ray file's rays whose origin lies on the ground or the wall (a bounce ray
    leaving one of the four huge triangles). The workloads lift a bounce origin off its surface
    by 1e-4 of the triangle's longest edge (workloads/workload.cpp, surface_point): 0.013-0.017
    here, so an origin within 0.02 of a quad's plane left that quad."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"TBRAYS1\0":
        sys.exit(f"heldout_scene: {path}: not a travbench ray file")
    (count,) = struct.unpack_from("<Q", data, 8)
    on = 0
    for i in range(count):
        ox, oy, oz = struct.unpack_from("<3f", data, 24 + 32 * i)
        in_ground = abs(ox) <= HALF and abs(oz) <= HALF
        if (abs(oy - GROUND_Y) < 0.02 and in_ground) or (abs(oz - WALL_Z) < 0.02 and abs(ox) <= HALF):
            on += 1
    print(f"{path}: {on} of {count} rays ({100.0 * on / max(count, 1):.1f}%) start on the ground or the wall")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="/tmp/heldout/heldout.obj")
    ap.add_argument("--dragon", default="../shared/scenes/dragon_100k.obj")
    ap.add_argument("--bunny", default="../shared/scenes/bunny.obj")
    ap.add_argument("--check", metavar="RAYS.bin", help="report the share of rays starting on the quads")
    args = ap.parse_args()
    if args.check:
        check(args.check)
    else:
        write(args)


if __name__ == "__main__":
    main()
