#!/usr/bin/env python3
"""Scenes for measuring Embree's packets on whole renders (docs/performance.md, "Standing
decisions"; first used for `4d4fd96`, 2026-12-04): a lumpy
icosphere of 20·4^N triangles on the floor of a box (white, red and green walls, no front)
lit by a ceiling lamp, written as OUT/packets-N.gltf with a render config OUT/packets-N.toml
(256², depth 32, 16 spp, Embree). Standard library only.

    crates/flowlight-bench/scripts/packet_scenes.py 6 /tmp/packets      # 81,920 sphere triangles
    FLOWLIGHT_EMBREE_PACKETS=never  target/release/flowlight render /tmp/packets/packets-6.toml --threads 1
    FLOWLIGHT_EMBREE_PACKETS=always target/release/flowlight render /tmp/packets/packets-6.toml --threads 1

Alternate the two renders a few times and compare the summaries' `cpu time`.
"""
import base64
import json
import math
import os
import struct
import sys

GOLDEN = (1 + 5**0.5) / 2
ICOSAHEDRON_VERTICES = [
    (-1, GOLDEN, 0), (1, GOLDEN, 0), (-1, -GOLDEN, 0), (1, -GOLDEN, 0),
    (0, -1, GOLDEN), (0, 1, GOLDEN), (0, -1, -GOLDEN), (0, 1, -GOLDEN),
    (GOLDEN, 0, -1), (GOLDEN, 0, 1), (-GOLDEN, 0, -1), (-GOLDEN, 0, 1),
]
ICOSAHEDRON_FACES = [
    (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
    (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
    (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
]


def normalised(v):
    length = math.sqrt(sum(c * c for c in v))
    return tuple(c / length for c in v)


def icosphere(subdivisions):
    """Unit icosphere: each subdivision splits every face into four (shared midpoints)."""
    vertices = [normalised(v) for v in ICOSAHEDRON_VERTICES]
    faces = list(ICOSAHEDRON_FACES)
    for _ in range(subdivisions):
        midpoints = {}

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in midpoints:
                va, vb = vertices[a], vertices[b]
                vertices.append(normalised(tuple((x + y) / 2 for x, y in zip(va, vb))))
                midpoints[key] = len(vertices) - 1
            return midpoints[key]

        split = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            split += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = split
    return vertices, faces


def lumpy(vertices):
    """The sphere moved onto the floor, radius 0.3 with bumps of up to 12%."""
    out = []
    for x, y, z in vertices:
        r = 0.3 * (1 + 0.08 * math.sin(7 * x) * math.cos(5 * y) + 0.04 * math.sin(13 * z))
        out.append((x * r, 0.4 + y * r, z * r))
    return out


QUAD = [(0, 1, 2), (0, 2, 3)]
WHITE, RED, GREEN, LAMP = range(4)


def gltf(meshes):
    """A glTF document (buffer as a data URI) with one node per (name, positions, faces,
    material) mesh and the four Lambertian materials."""
    data, views, accessors, gltf_meshes = b"", [], [], []
    for name, positions, faces, material in meshes:
        for blob, accessor in (
            (b"".join(struct.pack("<3f", *p) for p in positions),
             {"componentType": 5126, "count": len(positions), "type": "VEC3",
              "min": [min(p[i] for p in positions) for i in range(3)],
              "max": [max(p[i] for p in positions) for i in range(3)]}),
            (b"".join(struct.pack("<3I", *f) for f in faces),
             {"componentType": 5125, "count": 3 * len(faces), "type": "SCALAR"}),
        ):
            views.append({"buffer": 0, "byteOffset": len(data), "byteLength": len(blob)})
            data += blob
            accessors.append({"bufferView": len(views) - 1, **accessor})
        gltf_meshes.append({"name": name, "primitives": [{
            "attributes": {"POSITION": len(accessors) - 2},
            "indices": len(accessors) - 1, "material": material}]})
    diffuse = {"KHR_materials_specular": {"specularFactor": 0.0}}

    def material(name, colour, **extra):
        m = {"name": name, "extensions": dict(diffuse),
             "pbrMetallicRoughness": {"baseColorFactor": colour + [1.0], "metallicFactor": 0.0}}
        m.update(extra)
        return m

    materials = [
        material("white", [0.7, 0.7, 0.7]),
        material("red", [0.7, 0.1, 0.1]),
        material("green", [0.1, 0.7, 0.1]),
        material("lamp", [0.0, 0.0, 0.0], emissiveFactor=[1.0, 1.0, 1.0]),
    ]
    materials[LAMP]["extensions"]["KHR_materials_emissive_strength"] = {"emissiveStrength": 15.0}
    return {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(meshes)))}],
        "nodes": [{"mesh": i} for i in range(len(meshes))],
        "meshes": gltf_meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
        "extensionsUsed": ["KHR_materials_specular", "KHR_materials_emissive_strength"],
    }


CONFIG = """scene = "packets-{n}.gltf"
[render]
width = 256
height = 256
spp = 16
seed = 1
tile_size = 32
intersector = "embree"
[camera]
position = [0.0, 1.0, -3.2]
look_at = [0.0, 0.9, 0.0]
fov_y = 40.0
[integrator]
plugin = "mcpt"
path_depth = 32
"""


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: packet_scenes.py SUBDIVISIONS OUT_DIR")
    n, out = int(sys.argv[1]), sys.argv[2]
    vertices, faces = icosphere(n)
    meshes = [
        ("sphere", lumpy(vertices), faces, WHITE),
        ("floor", [(-1, 0, -1), (-1, 0, 1), (1, 0, 1), (1, 0, -1)], QUAD, WHITE),
        ("back", [(-1, 0, 1), (-1, 2, 1), (1, 2, 1), (1, 0, 1)], QUAD, WHITE),
        ("left", [(-1, 0, -1), (-1, 2, -1), (-1, 2, 1), (-1, 0, 1)], QUAD, RED),
        ("right", [(1, 0, 1), (1, 2, 1), (1, 2, -1), (1, 0, -1)], QUAD, GREEN),
        ("ceiling", [(-1, 2, -1), (1, 2, -1), (1, 2, 1), (-1, 2, 1)], QUAD, WHITE),
        ("lamp", [(-0.25, 1.99, -0.25), (0.25, 1.99, -0.25), (0.25, 1.99, 0.25),
                  (-0.25, 1.99, 0.25)], QUAD, LAMP),
    ]
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, f"packets-{n}.gltf"), "w") as f:
        json.dump(gltf(meshes), f)
    with open(os.path.join(out, f"packets-{n}.toml"), "w") as f:
        f.write(CONFIG.format(n=n))
    print(f"{out}/packets-{n}.toml: {len(faces)} sphere triangles")


if __name__ == "__main__":
    main()
