"""Flowlight against Blender Cycles on the glTF layer extensions, under a white sky.

    /work/venvs/bpy/bin/python scenes/material-layers/compare_cycles.py OUT_DIR [--spp N]

Writes one test asset per material (a smooth UV sphere of radius 1 in front of a glTF camera,
the material's extension JSON written here by hand: Blender 4.5's exporter writes sheen but
neither iridescence nor diffuse transmission), renders it

- with Flowlight (`target/debug/flowlight render`, MCPT, `[environment]` white, 1.0), and
- with Cycles (bpy 4.5.4): the file imported by Blender's own glTF importer, which maps
  `KHR_materials_sheen` to the Principled BSDF's sheen and `KHR_materials_anisotropy` to its
  anisotropy (strength as Cycles' "Anisotropic", tangents along the sphere's parallels; the
  `_matched` materials then set Cycles' roughness and "Anisotropic" to glTF's α_t, α_b, since
  the importer's mapping gives other roughnesses); iridescence is set by hand as the
  Principled BSDF's thin film (thickness, IOR), and diffuse transmission as a Translucent BSDF
  (colour t_d C_t) added to a Principled BSDF of base colour (1 − t_d) ρ, since the importer
  reads neither extension. Every Principled BSDF uses single-scattering GGX ("GGX"), as glTF
  and Flowlight do; world colour white, strength 1; film transparent for the object mask;

and compares the mean luminance (Rec. 709, linear) over the pixels the object covers in
Cycles' alpha. Writes `OUT_DIR/<name>/{<name>.gltf, flowlight.exr, cycles.exr}`,
`OUT_DIR/summary.csv` and a side-by-side PNG per material.
"""
import argparse
import base64
import csv
import json
import math
import os
import struct
import subprocess
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RES = 160

# name: (pbrMetallicRoughness, extensions, cycles setup tag)
MATERIALS = {
    "plain": (
        {"baseColorFactor": [0.8, 0.3, 0.2, 1], "metallicFactor": 0, "roughnessFactor": 0.5},
        {},
    ),
    "sheen": (
        {"baseColorFactor": [0.05, 0.05, 0.2, 1], "metallicFactor": 0, "roughnessFactor": 0.7},
        {"KHR_materials_sheen": {"sheenColorFactor": [0.9, 0.9, 0.9], "sheenRoughnessFactor": 0.5}},
    ),
    "sheen_sharp": (
        {"baseColorFactor": [0.2, 0.05, 0.05, 1], "metallicFactor": 0, "roughnessFactor": 0.8},
        {"KHR_materials_sheen": {"sheenColorFactor": [1.0, 0.8, 0.8], "sheenRoughnessFactor": 0.3}},
    ),
    "diffuse_transmission": (
        {"baseColorFactor": [0.8, 0.2, 0.2, 1], "metallicFactor": 0, "roughnessFactor": 0.5},
        {
            "KHR_materials_diffuse_transmission": {
                "diffuseTransmissionFactor": 0.5,
                "diffuseTransmissionColorFactor": [0.2, 0.8, 0.2],
            }
        },
    ),
    "iridescence": (
        {"baseColorFactor": [0.05, 0.05, 0.05, 1], "metallicFactor": 0, "roughnessFactor": 0.2},
        {
            "KHR_materials_iridescence": {
                "iridescenceFactor": 1.0,
                "iridescenceIor": 1.3,
                "iridescenceThicknessMaximum": 400,
            }
        },
    ),
    "anisotropy_metal": (
        {"baseColorFactor": [0.9, 0.6, 0.3, 1], "metallicFactor": 1, "roughnessFactor": 0.3},
        {"KHR_materials_anisotropy": {"anisotropyStrength": 0.8}},
    ),
    "anisotropy": (
        {"baseColorFactor": [0.1, 0.3, 0.6, 1], "metallicFactor": 0, "roughnessFactor": 0.2},
        {"KHR_materials_anisotropy": {"anisotropyStrength": 1.0, "anisotropyRotation": 0.5}},
    ),
    # The same anisotropic GGX on both sides: Cycles' roughness and "Anisotropic" set so that
    # its α_x = α/aspect, α_y = α·aspect (aspect = √(1 − 0.9 A)) are glTF's α_t, α_b.
    "anisotropy_metal_matched": (
        {"baseColorFactor": [0.9, 0.6, 0.3, 1], "metallicFactor": 1, "roughnessFactor": 0.3},
        {"KHR_materials_anisotropy": {"anisotropyStrength": 0.8}},
    ),
    "anisotropy_matched": (
        {"baseColorFactor": [0.1, 0.3, 0.6, 1], "metallicFactor": 0, "roughnessFactor": 0.2},
        {"KHR_materials_anisotropy": {"anisotropyStrength": 0.6, "anisotropyRotation": 0.5}},
    ),
    "iridescence_metal": (
        {"baseColorFactor": [0.9, 0.6, 0.3, 1], "metallicFactor": 1, "roughnessFactor": 0.3},
        {
            "KHR_materials_iridescence": {
                "iridescenceFactor": 1.0,
                "iridescenceIor": 1.5,
                "iridescenceThicknessMaximum": 300,
            }
        },
    ),
}


def sphere(n_lon=96, n_lat=48):
    """Positions (= normals), texture coordinates, tangents (along the parallels, the
    anisotropy direction) and triangle indices of a unit UV sphere."""
    pos, uv, tan = [], [], []
    for i in range(n_lat + 1):
        th = math.pi * i / n_lat
        for j in range(n_lon + 1):
            ph = 2 * math.pi * j / n_lon
            pos.append((math.sin(th) * math.cos(ph), math.cos(th), -math.sin(th) * math.sin(ph)))
            uv.append((j / n_lon, i / n_lat))
            tan.append((-math.sin(ph), 0.0, -math.cos(ph), 1.0))
    idx = []
    w = n_lon + 1
    for i in range(n_lat):
        for j in range(n_lon):
            a, b, c, d = i * w + j, i * w + j + 1, (i + 1) * w + j, (i + 1) * w + j + 1
            if i > 0:
                idx += [a, c, b]
            if i < n_lat - 1:
                idx += [b, c, d]
    return (
        np.array(pos, np.float32),
        np.array(uv, np.float32),
        np.array(tan, np.float32),
        np.array(idx, np.uint32),
    )


def write_gltf(path, name, pbr, exts):
    p, uv, tan, idx = sphere()
    views = [p.tobytes(), p.tobytes(), uv.tobytes(), tan.tobytes(), idx.tobytes()]
    buf = b"".join(views)
    offsets = np.cumsum([0] + [len(v) for v in views])
    used = sorted(exts)
    doc = {
        "asset": {"version": "2.0", "generator": "scenes/material-layers/compare_cycles.py"},
        "extensionsUsed": used,
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"name": "sphere", "mesh": 0},
            {"name": "camera", "camera": 0, "translation": [0, 0, 4.2]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.55, "aspectRatio": 1.0, "znear": 0.1}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "TANGENT": 3},
                                    "indices": 4, "material": 0}]}],
        "materials": [{"name": name, "pbrMetallicRoughness": pbr, "extensions": exts}],
        "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": int(offsets[k]), "byteLength": len(v), "target": 34963 if k == 4 else 34962}
            for k, v in enumerate(views)
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(p), "type": "VEC3",
             "min": p.min(0).tolist(), "max": p.max(0).tolist()},
            {"bufferView": 1, "componentType": 5126, "count": len(p), "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": len(p), "type": "VEC2"},
            {"bufferView": 3, "componentType": 5126, "count": len(p), "type": "VEC4"},
            {"bufferView": 4, "componentType": 5125, "count": len(idx), "type": "SCALAR"},
        ],
    }
    if not used:
        del doc["extensionsUsed"]
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)


def read_exr(path):
    """RGBA of an EXR file as float rows top-down, through Blender's image loader."""
    import bpy

    img = bpy.data.images.load(path, check_existing=False)
    w, h = img.size
    px = np.array(img.pixels[:], np.float32).reshape(h, w, 4)[::-1]
    bpy.data.images.remove(img)
    return px


def luminance(rgb):
    return 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]


def render_flowlight(d, name, spp):
    cfg = os.path.join(d, "flowlight.toml")
    with open(cfg, "w") as f:
        f.write(
            f'scene = "{name}.gltf"\n\n[render]\nwidth = {RES}\nheight = {RES}\nspp = {spp}\nseed = 1\n\n'
            '[integrator]\nplugin = "mcpt"\n\n[environment]\ncolor = [1.0, 1.0, 1.0]\n\n'
            '[output]\nexr = "flowlight.exr"\npng = "flowlight.png"\n'
        )
    exe = os.path.join(REPO, "target", "debug", "flowlight")
    subprocess.run([exe, "render", cfg], check=True, cwd=d)
    return read_exr(os.path.join(d, "flowlight.exr"))[..., :3]


def setup_cycles_material(mat, name, exts):
    """What the importer does not read, set by hand on the imported node tree."""
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.distribution = "GGX"
    aniso = exts.get("KHR_materials_anisotropy")
    if aniso and name.endswith("_matched"):
        alpha = bsdf.inputs["Roughness"].default_value ** 2
        s = aniso.get("anisotropyStrength", 0.0)
        alpha_t, alpha_b = alpha + (1 - alpha) * s * s, max(alpha, 1e-3)
        bsdf.inputs["Roughness"].default_value = (alpha_t * alpha_b) ** 0.25
        bsdf.inputs["Anisotropic"].default_value = min(max((1 - alpha_b / alpha_t) / 0.9, 0.0), 1.0)
    irid = exts.get("KHR_materials_iridescence")
    if irid:
        bsdf.inputs["Thin Film Thickness"].default_value = irid.get("iridescenceThicknessMaximum", 400)
        bsdf.inputs["Thin Film IOR"].default_value = irid.get("iridescenceIor", 1.3)
    dt = exts.get("KHR_materials_diffuse_transmission")
    if dt:
        t = dt.get("diffuseTransmissionFactor", 0.0)
        c = dt.get("diffuseTransmissionColorFactor", [1, 1, 1])
        base = bsdf.inputs["Base Color"].default_value
        bsdf.inputs["Base Color"].default_value = [base[0] * (1 - t), base[1] * (1 - t), base[2] * (1 - t), 1]
        out = next(n for n in nt.nodes if n.type == "OUTPUT_MATERIAL")
        tr = nt.nodes.new("ShaderNodeBsdfTranslucent")
        tr.inputs["Color"].default_value = [c[0] * t, c[1] * t, c[2] * t, 1]
        add = nt.nodes.new("ShaderNodeAddShader")
        nt.links.new(bsdf.outputs[0], add.inputs[0])
        nt.links.new(tr.outputs[0], add.inputs[1])
        nt.links.new(add.outputs[0], out.inputs["Surface"])


def render_cycles(d, name, exts, spp):
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=os.path.join(d, f"{name}.gltf"))
    sc = bpy.context.scene
    sc.camera = next(o for o in sc.objects if o.type == "CAMERA")
    for m in bpy.data.materials:
        if m.use_nodes:
            setup_cycles_material(m, name, exts)
    world = bpy.data.worlds.new("white")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1, 1, 1, 1)
    bg.inputs["Strength"].default_value = 1.0
    sc.world = world
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = spp
    sc.cycles.use_denoising = False
    sc.cycles.seed = 1
    sc.render.film_transparent = True
    sc.render.resolution_x = RES
    sc.render.resolution_y = RES
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    out = os.path.join(d, "cycles.exr")
    sc.render.filepath = out
    bpy.ops.render.render(write_still=True)
    return read_exr(out)


def side_by_side(d, fl, cy):
    """Flowlight (left) and Cycles (right), sRGB-encoded, as one PNG."""
    import bpy

    both = np.concatenate([fl, cy[..., :3]], 1)
    h, w, _ = both.shape
    img = bpy.data.images.new("side_by_side", w, h, alpha=True, float_buffer=True)
    rgba = np.concatenate([np.clip(both, 0, 1), np.ones((h, w, 1), np.float32)], -1)
    img.pixels = np.ascontiguousarray(rgba[::-1]).ravel()
    img.filepath_raw = os.path.join(d, "flowlight_vs_cycles.png")
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--only", nargs="*")
    a = ap.parse_args()
    rows = []
    for name, (pbr, exts) in MATERIALS.items():
        if a.only and name not in a.only:
            continue
        d = os.path.join(a.out, name)
        os.makedirs(d, exist_ok=True)
        write_gltf(os.path.join(d, f"{name}.gltf"), name, pbr, exts)
        fl = render_flowlight(d, name, a.spp)
        cy = render_cycles(d, name, exts, a.spp)
        mask = cy[..., 3] > 0.999
        lf, lc = luminance(fl)[mask].mean(), luminance(cy[..., :3])[mask].mean()
        rows.append((name, int(mask.sum()), lf, lc, lf / lc - 1))
        side_by_side(d, fl, cy)
        print(f"{name}: Flowlight {lf:.4f}  Cycles {lc:.4f}  ({100 * (lf / lc - 1):+.1f}%)", flush=True)
    with open(os.path.join(a.out, "summary.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["material", "object_pixels", "flowlight_mean_luminance", "cycles_mean_luminance", "relative_difference"])
        for r in rows:
            w.writerow([r[0], r[1], f"{r[2]:.5f}", f"{r[3]:.5f}", f"{r[4]:+.4f}"])


if __name__ == "__main__":
    sys.exit(main())
