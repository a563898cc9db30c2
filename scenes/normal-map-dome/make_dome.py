"""Writes dome.gltf (+ dome.bin; the normal map embedded): a gold dome as real geometry next to the
same dome as a tangent-space normal map on a flat square, at two roughnesses. It stands in for
the Khronos NormalTangentTest / NormalTangentMirrorTest, whose gold cells compare normal-mapped
domes with a geometric one; the numbers decide the same question: does a normal-mapped glossy
metal reflect as much light as the geometry it stands for?

    python3 scenes/normal-map-dome/make_dome.py        # stdlib only; outputs are committed

Layout (glTF is Y-up; the cells lie in the X-Z plane, facing +Y, radius 1):

    z = -1.2 row: roughness 0.15     x = -1.2: normal-mapped square   x = +1.2: dome mesh
    z = +1.2 row: roughness 0.4

The geometric dome stands on the rest of its square cell, as in NormalTangentTest: a reflection
leaving its steep rim downwards meets the gold floor and reflects once more. Under a uniform
white sky every reflection that escapes sees radiance 1.
`measure_dome.py` renders it and prints each cell's mean luminance over the dome's disk.
"""
import base64
import json
import math
import os
import struct
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
MAP = 256
GOLD = [1.0, 0.766, 0.336, 1.0]
ROUGHNESS = [0.15, 0.4]
STEPS = 64


def png_rgb(width, height, rows):
    """An 8-bit RGB PNG from rows of (r, g, b) bytes."""
    raw = b"".join(b"\x00" + bytes(row) for row in rows)

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )


def dome_normal_map():
    """Tangent space (T = +X, B = N × T = -Z, N = +Y): the hemisphere's normal (x, h, z) at
    the texel's point is (x, -z, h) there; flat (0, 0, 1) outside the disk."""
    rows = []
    for j in range(MAP):
        v = (j + 0.5) / MAP
        z = 2.0 * v - 1.0
        row = []
        for i in range(MAP):
            x = 2.0 * (i + 0.5) / MAP - 1.0
            r2 = x * x + z * z
            n = (x, -z, math.sqrt(1.0 - r2)) if r2 < 1.0 else (0.0, 0.0, 1.0)
            row += [max(0, min(255, round((c + 1.0) * 0.5 * 255.0))) for c in n]
        rows.append(row)
    return png_rgb(MAP, MAP, rows)


class Buffer:
    def __init__(self):
        self.data = bytearray()
        self.views = []
        self.accessors = []

    def add(self, values, fmt, count, kind, component, target, minmax=None):
        while len(self.data) % 4:
            self.data.append(0)
        start = len(self.data)
        for v in values:
            self.data += struct.pack(fmt, *v) if isinstance(v, tuple) else struct.pack(fmt, v)
        self.views.append({"buffer": 0, "byteOffset": start, "byteLength": len(self.data) - start, "target": target})
        acc = {"bufferView": len(self.views) - 1, "componentType": component, "count": count, "type": kind}
        if minmax:
            acc["min"], acc["max"] = minmax
        self.accessors.append(acc)
        return len(self.accessors) - 1


def square(buf):
    """The flat normal-mapped cell: a 2 × 2 square facing +Y, uv = ((x+1)/2, (z+1)/2)."""
    p = [(-1.0, 0.0, -1.0), (1.0, 0.0, -1.0), (1.0, 0.0, 1.0), (-1.0, 0.0, 1.0)]
    attrs = {
        "POSITION": buf.add(p, "<3f", 4, "VEC3", 5126, 34962, ([-1, 0, -1], [1, 0, 1])),
        "NORMAL": buf.add([(0.0, 1.0, 0.0)] * 4, "<3f", 4, "VEC3", 5126, 34962),
        "TANGENT": buf.add([(1.0, 0.0, 0.0, 1.0)] * 4, "<4f", 4, "VEC4", 5126, 34962),
        "TEXCOORD_0": buf.add([((x + 1) / 2, (z + 1) / 2) for x, _, z in p], "<2f", 4, "VEC2", 5126, 34962),
    }
    # Counter-clockwise seen from +Y.
    idx = buf.add([0, 2, 1, 0, 3, 2], "<I", 6, "SCALAR", 5125, 34963)
    return attrs, idx


def hemisphere(buf):
    """The geometric dome: a unit hemisphere over y = 0 with its exact normals, standing on
    the rest of its 2 × 2 cell (a flat square with the dome's disk cut out), as the
    geometric cells of NormalTangentTest stand on theirs."""
    pos, nrm, idx = [], [], []
    rings, segs = STEPS // 2, STEPS
    for a in range(rings + 1):
        theta = 0.5 * math.pi * a / rings  # from the pole
        for b in range(segs + 1):
            phi = 2.0 * math.pi * b / segs
            n = (math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi))
            pos.append(n)
            nrm.append(n)
    for a in range(rings):
        for b in range(segs):
            i0 = a * (segs + 1) + b
            i1, i2, i3 = i0 + 1, i0 + segs + 1, i0 + segs + 2
            # Counter-clockwise seen from outside.
            idx += [i0, i1, i2, i1, i3, i2]
    # The floor: each rim segment joined to the square's edge along the same rays.
    base = len(pos)
    for b in range(segs + 1):
        phi = 2.0 * math.pi * b / segs
        c = (math.cos(phi), 0.0, math.sin(phi))
        edge = 1.0 / max(abs(c[0]), abs(c[2]))
        pos += [c, (c[0] * edge, 0.0, c[2] * edge)]
        nrm += [(0.0, 1.0, 0.0)] * 2
    for b in range(segs):
        r0, e0, r1, e1 = base + 2 * b, base + 2 * b + 1, base + 2 * b + 2, base + 2 * b + 3
        # Counter-clockwise seen from +Y.
        idx += [r0, r1, e0, r1, e1, e0]
    attrs = {
        "POSITION": buf.add([tuple(p) for p in pos], "<3f", len(pos), "VEC3", 5126, 34962, ([-1, 0, -1], [1, 1, 1])),
        "NORMAL": buf.add([tuple(n) for n in nrm], "<3f", len(nrm), "VEC3", 5126, 34962),
    }
    return attrs, buf.add(idx, "<I", len(idx), "SCALAR", 5125, 34963)


def main():
    buf = Buffer()
    sq_attrs, sq_idx = square(buf)
    hs_attrs, hs_idx = hemisphere(buf)
    materials, meshes, nodes = [], [], []
    for k, rough in enumerate(ROUGHNESS):
        base = {"baseColorFactor": GOLD, "metallicFactor": 1.0, "roughnessFactor": rough}
        materials.append({"name": f"gold-mapped-{rough}", "pbrMetallicRoughness": base, "normalTexture": {"index": 0}})
        materials.append({"name": f"gold-geometry-{rough}", "pbrMetallicRoughness": base})
        meshes.append({"name": f"mapped-{rough}", "primitives": [{"attributes": sq_attrs, "indices": sq_idx, "material": 2 * k}]})
        meshes.append({"name": f"dome-{rough}", "primitives": [{"attributes": hs_attrs, "indices": hs_idx, "material": 2 * k + 1}]})
        z = -1.2 if k == 0 else 1.2
        nodes.append({"name": f"mapped-{rough}", "mesh": 2 * k, "translation": [-1.2, 0.0, z]})
        nodes.append({"name": f"dome-{rough}", "mesh": 2 * k + 1, "translation": [1.2, 0.0, z]})
    with open(os.path.join(HERE, "dome.bin"), "wb") as f:
        f.write(buf.data)
    doc = {
        "asset": {"version": "2.0", "generator": "scenes/normal-map-dome/make_dome.py"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9729, "minFilter": 9729}],
        "images": [{"uri": "data:image/png;base64," + base64.b64encode(dome_normal_map()).decode()}],
        "buffers": [{"uri": "dome.bin", "byteLength": len(buf.data)}],
        "bufferViews": buf.views,
        "accessors": buf.accessors,
    }
    with open(os.path.join(HERE, "dome.gltf"), "w") as f:
        json.dump(doc, f, indent=1)


if __name__ == "__main__":
    main()
