"""Writes spec_gloss.gltf (+ spec_gloss.bin): three spheres whose materials are only
KHR_materials_pbrSpecularGlossiness (required, no metallic-roughness fallback), for comparing
Flowlight's conversion with Blender's importer and Cycles
(crates/flowlight-bench/peers/cycles_gltf.py).

    python3 scenes/spec-gloss/make_spec_gloss.py        # stdlib only; outputs are committed

Left to right (x = -2.2, 0, 2.2, radius 1, glTF +Y up):
- a red plastic: diffuse (0.8, 0.1, 0.1), specular 0.04, glossiness 0.6;
- a gold-like metal: diffuse black, specular (1.0, 0.77, 0.34), glossiness 0.75;
- a grey semi-gloss: diffuse 0.5, specular 0.25, glossiness 0.3.
"""
import json
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))
STEPS = 48
MATERIALS = [
    ("red-plastic", [0.8, 0.1, 0.1, 1.0], [0.04, 0.04, 0.04], 0.6),
    ("gold-like", [0.0, 0.0, 0.0, 1.0], [1.0, 0.77, 0.34], 0.75),
    ("grey-semigloss", [0.5, 0.5, 0.5, 1.0], [0.25, 0.25, 0.25], 0.3),
]


def sphere():
    pos, idx = [], []
    rings, segs = STEPS // 2, STEPS
    for a in range(rings + 1):
        theta = math.pi * a / rings
        for b in range(segs + 1):
            phi = 2.0 * math.pi * b / segs
            pos.append((math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi)))
    for a in range(rings):
        for b in range(segs):
            i0 = a * (segs + 1) + b
            i1, i2, i3 = i0 + 1, i0 + segs + 1, i0 + segs + 2
            # Counter-clockwise seen from outside.
            idx += [i0, i1, i2, i1, i3, i2]
    return pos, idx


def main():
    pos, idx = sphere()
    data = bytearray()
    for p in pos:
        data += struct.pack("<3f", *p)
    normals_at = len(data)
    for p in pos:
        data += struct.pack("<3f", *p)
    index_at = len(data)
    for i in idx:
        data += struct.pack("<I", i)
    views = [
        {"buffer": 0, "byteOffset": 0, "byteLength": normals_at, "target": 34962},
        {"buffer": 0, "byteOffset": normals_at, "byteLength": index_at - normals_at, "target": 34962},
        {"buffer": 0, "byteOffset": index_at, "byteLength": len(data) - index_at, "target": 34963},
    ]
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3", "min": [-1, -1, -1], "max": [1, 1, 1]},
        {"bufferView": 1, "componentType": 5126, "count": len(pos), "type": "VEC3"},
        {"bufferView": 2, "componentType": 5125, "count": len(idx), "type": "SCALAR"},
    ]
    ext = "KHR_materials_pbrSpecularGlossiness"
    materials, meshes, nodes = [], [], []
    for k, (name, diffuse, specular, gloss) in enumerate(MATERIALS):
        materials.append(
            {"name": name, "extensions": {ext: {"diffuseFactor": diffuse, "specularFactor": specular, "glossinessFactor": gloss}}}
        )
        meshes.append({"name": name, "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": k}]})
        nodes.append({"name": name, "mesh": k, "translation": [2.2 * (k - 1), 0.0, 0.0]})
    with open(os.path.join(HERE, "spec_gloss.bin"), "wb") as f:
        f.write(data)
    doc = {
        "asset": {"version": "2.0", "generator": "scenes/spec-gloss/make_spec_gloss.py"},
        "extensionsUsed": [ext],
        "extensionsRequired": [ext],
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "buffers": [{"uri": "spec_gloss.bin", "byteLength": len(data)}],
        "bufferViews": views,
        "accessors": accessors,
    }
    with open(os.path.join(HERE, "spec_gloss.gltf"), "w") as f:
        json.dump(doc, f, indent=1)


if __name__ == "__main__":
    main()
