"""The Khronos normal-map test assets, NormalTangentTest and NormalTangentMirrorTest, cell by
cell against Blender Cycles under a uniform white sky: each cell's mean luminance in both
renderers, and each normal-mapped cell against the real-geometry cell of its row.

    /path/to/bpy-venv/bin/python crates/flowlight-bench/peers/normal_map_cells.py \\
        --flowlight target/release/flowlight --out /tmp/normal-maps \\
        --asset /path/to/NormalTangentMirrorTest.glb [--asset /path/to/NormalTangentTest.glb]

The assets (CC-BY 4.0, Analytical Graphics, mesh and textures by Ed Mackey) are the
glTF-Binary files of the Khronos sample models; they are not in this repository. Each is a
plate of cells, five rows (top to bottom) of hemispherical bumps: per material a cell whose
bump is geometry and cells whose bump is a tangent-space normal map (NormalTangentMirrorTest:
also with the UVs mirrored in V and in U). Seen face-on through an orthographic camera; a
cell's mean is taken over a disk of radius 0.13 about its centre (the cells are 0.3 wide; the
disk leaves out the tangent arrows drawn in their corners). Both renderers as in
`cycles_gltf.py`: single-scattering GGX, path depth 8, a box pixel filter.

`--lambertian` renders the assets with their specular layer off (a copy of each with
`KHR_materials_specular` factor 0; Cycles' Specular IOR Level 0), leaving the Lambertian base.
"""
import json
import os
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cycles_gltf as cg  # noqa: E402

ROWS = [0.8, 0.4, 0.0, -0.4, -0.8]
RADIUS = 0.13
# Asset file name -> its groups: (material, [(cell name, x of the cell centre)]), the
# geometry cell first. Centres measured on a Flowlight render of each asset.
LAYOUTS = {
    "NormalTangentMirrorTest.glb": [
        ("dielectric", [("geometry", -1.275), ("normal", -0.955), ("V mirror", -0.629), ("U mirror", -0.291)]),
        ("gold", [("geometry", 0.300), ("normal", 0.620), ("V mirror", 0.941), ("U mirror", 1.264)]),
    ],
    "NormalTangentTest.glb": [
        ("pink dielectric", [("geometry", -0.96), ("normal", -0.64)]),
        ("blue dielectric", [("geometry", -0.16), ("normal", 0.16)]),
        ("gold", [("geometry", 0.64), ("normal", 0.96)]),
    ],
}
VIEW = ((0.0, -0.08, 10.0), (0.0, -0.08, 0.0), 2.4, 375, 300)


def without_specular(asset, out):
    """A copy of the GLB `asset` in `out` whose materials have `KHR_materials_specular`
    factor 0."""
    data = open(asset, "rb").read()
    length = struct.unpack("<I", data[12:16])[0]
    doc, rest = json.loads(data[20 : 20 + length]), data[20 + length :]
    for m in doc["materials"]:
        m.setdefault("extensions", {})["KHR_materials_specular"] = {"specularFactor": 0.0}
    used = doc.setdefault("extensionsUsed", [])
    if "KHR_materials_specular" not in used:  # the spec's entries are unique
        used.append("KHR_materials_specular")
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I", len(text)) + b"JSON" + text + rest
    copy = os.path.join(out, "lambertian-" + os.path.basename(asset))
    with open(copy, "wb") as f:
        f.write(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return copy


def no_specular(mat, node):
    node.inputs["Specular IOR Level"].default_value = 0.0


def compare(flowlight, asset, spp, out, lambertian):
    name = os.path.splitext(os.path.basename(asset))[0]
    groups = LAYOUTS[os.path.basename(asset)]
    pos, target, ortho, w, h = VIEW
    path = without_specular(asset, out) if lambertian else os.path.abspath(asset)
    spec = (name, path, pos, target, ortho, w, h, spp, out)
    cycles = cg.render_cycles(*spec, adjust=no_specular if lambertian else None)
    images = [cg.luminance(cg.render_flowlight(flowlight, *spec)), cg.luminance(cycles)]
    what = " (specular layer off)" if lambertian else ""
    print(f"\n{name}{what}: mean luminance per cell (Flowlight / Cycles); normal-mapped cells also over "
          "their row's geometry cell in each renderer\n")
    print("| material | row | cell | Flowlight | Cycles | Flowlight / Cycles | ÷ geometry: Flowlight | Cycles |")
    print("|---|---:|---|---:|---:|---:|---:|---:|")
    for material, cells in groups:
        for r, y in enumerate(ROWS):
            # Disks about the cells' centres, in the image plane (centred on the camera).
            masks = cg.disk_masks(ortho, w, h, [(x, y - target[1], RADIUS) for _, x in cells])
            (f0, *fs), (c0, *cs) = [[img[m].mean() for m in masks] for img in images]
            print(f"| {material} | {r + 1} | geometry | {f0:.4f} | {c0:.4f} | {f0 / c0:.4f} | | |")
            for (cell, _), f, c in zip(cells[1:], fs, cs):
                print(f"| {material} | {r + 1} | {cell} | {f:.4f} | {c:.4f} | {f / c:.4f} | "
                      f"{f / f0:.4f} | {c / c0:.4f} |")


def main():
    def extend(ap):
        ap.add_argument("--asset", action="append", required=True)
        ap.add_argument("--lambertian", action="store_true")

    args = cg.arguments(256, extend=extend)
    for asset in args.asset:
        if os.path.basename(asset) not in LAYOUTS:
            sys.exit(f"normal_map_cells.py: {asset}: not one of {', '.join(LAYOUTS)}")
        compare(os.path.abspath(args.flowlight), asset, args.spp, args.out, args.lambertian)


if __name__ == "__main__":
    main()
