#!/usr/bin/env python3
"""Writes the seed corpus of the fuzz targets into tests/fuzz/corpus/<target>/ (committed; rerun
only to regenerate). Standard library only. The ray seeds use a built travbench when one is given:
    tests/fuzz/make_seeds.py [path/to/travbench]
"""
import base64
import json
import os
import struct
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "corpus")


def put(target, name, data):
    d = os.path.join(CORPUS, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


# ---- mesh: first byte selects the format ('0' obj, '1' off, '2' ply, '3' stl) -----------------
OBJ = "# quad, triangle, negative and forward indices\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n" \
      "g grp\nusemtl m\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -1 -2 -3\nf 1 2 5\nv 2 0 0\nf 1 1 2\n"
OFF = "COFF\n# comment\n5 3 0 # counts\n0 0 0 1 1 1 1\n1 0 0 1 1 1 1\n1 1 0 1 1 1 1\n0 1 0 1 1 1 1\n" \
      "2 2 2 1 1 1 1\n4 0 1 2 3 255 0 0\n3 2 3 4\n3 0 0 0\n"
PLY_HEAD = "ply\nformat {fmt} 1.0\ncomment hand made\nelement vertex 4\nproperty float x\nproperty float y\n" \
           "property float z\nproperty double quality\nelement face 2\nproperty list uchar {it} vertex_indices\n" \
           "element edge 1\nproperty int a\nproperty int b\nend_header\n"


def ply_binary(big):
    e = ">" if big else "<"
    b = PLY_HEAD.format(fmt="binary_big_endian" if big else "binary_little_endian", it="uint").encode()
    for k in range(4):
        b += struct.pack(e + "fffd", k, k % 2, 0, 0.5)
    b += struct.pack(e + "B4I", 4, 0, 1, 2, 3) + struct.pack(e + "B3I", 3, 3, 2, 1)
    b += struct.pack(e + "ii", 0, 1)
    return b


PLY_ASCII = PLY_HEAD.format(fmt="ascii", it="int") + "0 0 0 1\n1 1 0 1\n2 0 0 1\n3 1 0 1\n4 0 1 2 3\n3 3 2 1\n0 1\n"


def stl_ascii():
    s = "solid t\n"
    for tri in [((0, 0, 0), (1, 0, 0), (0, 1, 0)), ((1, 0, 0), (1, 1, 0), (0, 1, 0)), ((0, 0, 0), (0, 0, 0), (1, 1, 1))]:
        s += "  facet normal 0 0 1\n    outer loop\n"
        for v in tri:
            s += "      vertex %g %g %g\n" % v
        s += "    endloop\n  endfacet\n"
    return s + "endsolid t\nsolid second\nendsolid second\n"


def stl_binary(header=b"binary stl"):
    b = header.ljust(80, b"\0") + struct.pack("<I", 2)
    for tri in [((0, 0, 0), (1, 0, 0), (0, 1, 0)), ((1, 0, 0), (1, 1, 0), (0, 1, 0))]:
        b += struct.pack("<3f", 0, 0, 1)
        for v in tri:
            b += struct.pack("<3f", *v)
        b += b"\0\0"
    return b


put("mesh", "obj_basic", "0" + OBJ)
put("mesh", "off_colours", "1" + OFF)
put("mesh", "off_nokeyword", "1" + "3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
put("mesh", "ply_ascii", "2" + PLY_ASCII)
put("mesh", "ply_le", b"2" + ply_binary(False))
put("mesh", "ply_be", b"2" + ply_binary(True))
put("mesh", "stl_ascii", "3" + stl_ascii())
put("mesh", "stl_binary", b"3" + stl_binary())
put("mesh", "stl_binary_solid", b"3" + stl_binary(b"solid but binary"))

# ---- gltf --------------------------------------------------------------------------------------


class Gltf:
    def __init__(self):
        self.bin = b""
        self.j = {"asset": {"version": "2.0"}, "bufferViews": [], "accessors": [], "meshes": [], "nodes": []}

    def view(self, data, stride=0):
        self.bin += b"\0" * (-len(self.bin) % 4)
        v = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        self.bin += data
        self.j["bufferViews"].append(v)
        return len(self.j["bufferViews"]) - 1

    def accessor(self, view, comp, typ, count, **kw):
        a = {"componentType": comp, "type": typ, "count": count}
        if view is not None:
            a["bufferView"] = view
        a.update(kw)
        self.j["accessors"].append(a)
        return len(self.j["accessors"]) - 1

    def positions(self, pts):
        return self.accessor(self.view(b"".join(struct.pack("<3f", *p) for p in pts)), 5126, "VEC3", len(pts))

    def indices(self, idx, fmt="H", comp=5123):
        return self.accessor(self.view(b"".join(struct.pack("<" + fmt, i) for i in idx)), comp, "SCALAR", len(idx))

    def mesh(self, prims):
        self.j["meshes"].append({"primitives": prims})
        return len(self.j["meshes"]) - 1

    def node(self, n):
        self.j["nodes"].append(n)
        return len(self.j["nodes"]) - 1

    def gltf(self):
        self.bin += b"\0" * (-len(self.bin) % 4)
        d = dict(self.j)
        d["buffers"] = [{"byteLength": len(self.bin),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(self.bin).decode()}]
        return json.dumps(d)

    def glb(self):
        self.bin += b"\0" * (-len(self.bin) % 4)
        d = dict(self.j)
        d["buffers"] = [{"byteLength": len(self.bin)}]
        js = json.dumps(d).encode()
        js += b" " * (-len(js) % 4)
        out = b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js) + 8 + len(self.bin))
        out += struct.pack("<II", len(js), 0x4E4F534A) + js
        out += struct.pack("<II", len(self.bin), 0x004E4942) + self.bin
        return out


def transformed():
    g = Gltf()
    pa = g.positions([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    ia = g.indices([0, 1, 2])
    pb = g.positions([(0, 0, 0), (0, 0, 1), (1, 0, 0)])
    m0 = g.mesh([{"attributes": {"POSITION": pa}, "indices": ia}])
    m1 = g.mesh([{"attributes": {"POSITION": pb}}])
    h = 0.5 ** 0.5
    g.node({"translation": [10, 0, 0], "mesh": m0, "children": [1]})
    g.node({"scale": [2, 2, 2], "rotation": [0, 0, h, h], "mesh": m1})
    g.node({"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 5, 0, 1], "mesh": m0})
    g.j["scenes"] = [{"nodes": [0, 2]}]
    g.j["scene"] = 0
    return g


def modes():
    g = Gltf()
    p = g.positions([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (2, 0, 0)])
    i8 = g.indices([0, 1, 2, 3, 4], "B", 5121)
    i32 = g.indices([4, 3, 2, 1, 0], "I", 5125)
    prims = [{"attributes": {"POSITION": p}, "indices": i8, "mode": 5},
             {"attributes": {"POSITION": p}, "indices": i32, "mode": 6},
             {"attributes": {"POSITION": p}, "mode": 0},
             {"attributes": {"POSITION": p}, "indices": i8, "mode": 1}]
    g.node({"mesh": g.mesh(prims)})
    return g


def quantized():
    g = Gltf()
    us = g.accessor(g.view(struct.pack("<12H", 0, 0, 0, 0, 2, 0, 0, 0, 0, 3, 0, 0), 8), 5123, "VEC3", 3)
    sb = g.accessor(g.view(struct.pack("<12b", 0, 0, 0, 0, 127, 0, 0, 0, 0, -128, 0, 0), 4), 5120, "VEC3", 3,
                    normalized=True)
    zero = g.accessor(None, 5126, "VEC3", 3)
    g.mesh([{"attributes": {"POSITION": a}} for a in (us, sb, zero)])  # nodeless: meshes taken as they are
    del g.j["nodes"]
    g.j["extensionsUsed"] = g.j["extensionsRequired"] = ["KHR_mesh_quantization"]
    return g


put("gltf", "transformed.gltf", transformed().gltf())
put("gltf", "transformed.glb", transformed().glb())
put("gltf", "modes.gltf", modes().gltf())
put("gltf", "modes.glb", modes().glb())
put("gltf", "quantized.gltf", quantized().gltf())
put("gltf", "quantized.glb", quantized().glb())

# ---- din ---------------------------------------------------------------------------------------
put("din", "basic", "0 1000\n1 0x1004 ignored\n2 ffffffffffffffff\n\n# comment\n0 0X0000000000000000000abc\n")
put("din", "config_lru", "#config l1=1K:2:32,l2=8K:4:32:9,mem=50 lru\n0 0\n1 20\n0 40\n0 7fe\n1 0\n")
put("din", "config_bitplru", "#config l1=512:8,l3=4K:16:64:30 bitplru\n" + "".join("%d %x\n" % (i % 2, i * 52) for i in range(40)))
put("din", "config_plru", "#config l1=2KB:4 plru\n" + "".join("0 %x\n" % (i * 64) for i in range(20)))

# ---- rays: generated by a built travbench when available, plus hand-made edge cases -------------


def rays_file(rays, packet_size=4, table=None):
    b = b"TBRAYS1\0" + struct.pack("<QII", len(rays), packet_size, 0 if table is None else len(table) - 1)
    for r in rays:
        b += struct.pack("<8f", *r)
    if table is not None:
        b += struct.pack("<%dI" % len(table), *table)
    return b


R = [(0, 0, -5, 0, 0, 1, 0, 1e30), (0.5, 0.5, -5, 0, -0.0, 1, 0, 100), (1, 2, 3, 1, 0, 0, 1, 1),
     (0, 0, 0, 0.577, 0.577, 0.577, 0, float("inf"))]
put("rays", "uniform.bin", rays_file(R, 2))
put("rays", "table.bin", rays_file(R, 4, [0, 1, 4]))
put("rays", "empty.bin", rays_file([], 16))
put("rays", "hits.bin", b"TBHITS1\0" + struct.pack("<Q", 2) + struct.pack("<fIff", 1.5, 7, 0.25, 0.5) +
    struct.pack("<fIff", float("inf"), 0xFFFFFFFF, 0, 0))
if len(sys.argv) > 1:
    with tempfile.TemporaryDirectory() as tmp:
        for wl in ("primary", "bounce:1"):
            out = os.path.join(tmp, "r.bin")
            subprocess.run([sys.argv[1], "rays", "--scene", "sphere", "--workload", wl, "--width", "16", "--height",
                            "16", "--out", out], check=True, stderr=subprocess.DEVNULL)
            with open(out, "rb") as f:
                put("rays", wl.replace(":", "") + "_16x16.bin", f.read())
