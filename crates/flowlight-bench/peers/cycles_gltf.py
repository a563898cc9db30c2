"""glTF assets side by side with Blender Cycles under a uniform white sky, through one
orthographic camera: the mean luminance of each image, their ratio, and the mean absolute
per-pixel difference over the mean (which a texture turned the wrong way raises even where
the mean luminance agrees).

    /path/to/bpy-venv/bin/python crates/flowlight-bench/peers/cycles_gltf.py \\
        --flowlight target/debug/flowlight --out /tmp/cycles-gltf [--spp 64] [--only NAME]

Needs the PyPI `bpy` 4.5 (Cycles and Blender's own glTF importer) and the assimp-testmodels
(`.ci/setup` fetches them into scenes/assimp-testmodels). Both renderers use single-scattering
GGX (the Principled BSDF's distribution is set to GGX), path depth 8, a box pixel filter, no
denoising. Blender imports `KHR_materials_pbrSpecularGlossiness` with its own conversion, which
is what a Blender user gets.
"""
import argparse
import os
import subprocess
import sys

import bpy
import numpy as np
from mathutils import Vector

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
MODELS = os.path.join(ROOT, "scenes", "assimp-testmodels", "glTF2")

# name, file, camera position and target (glTF coordinates, +Y up), ortho height, width,
# height, and disks (x, y, radius in the image plane's world units, y up) whose means are
# reported one by one
ASSETS = [
    (
        "TextureTransformTest",
        os.path.join(MODELS, "textureTransform", "TextureTransformTest.gltf"),
        (0.0, 0.0, 10.0),
        (0.0, 0.0, 0.0),
        2.4,
        360,
        240,
        [],
    ),
    (
        "spec-gloss-spheres",
        os.path.join(ROOT, "scenes", "spec-gloss", "spec_gloss.gltf"),
        (0.0, 0.0, 10.0),
        (0.0, 0.0, 0.0),
        2.4,
        330,
        120,
        [(-2.2, 0.0, 0.95), (0.0, 0.0, 0.95), (2.2, 0.0, 0.95)],
    ),
    (
        "BoxTextured-pbrSpecularGlossiness",
        os.path.join(MODELS, "BoxTextured-glTF-pbrSpecularGlossiness", "BoxTextured.gltf"),
        (6.0, 4.0, 8.0),
        (0.0, 0.0, 0.0),
        2.4,
        240,
        240,
        [],
    ),
]


def blender(v):
    """glTF (+Y up) to Blender (+Z up) coordinates, as Blender's importer converts them."""
    x, y, z = v
    return Vector((x, -z, y))


def read_exr(path):
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float64).reshape(h, w, 4)[::-1]
    bpy.data.images.remove(img)
    return px[:, :, :3]


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def render_flowlight(binary, name, path, pos, target, ortho, w, h, spp, out):
    toml = os.path.join(out, f"{name}.toml")
    exr = os.path.join(out, f"{name}-flowlight.exr")
    with open(toml, "w") as f:
        f.write(
            f'scene = "{path}"\n[render]\nwidth = {w}\nheight = {h}\nspp = {spp}\nseed = 1\n'
            f'[camera]\nprojection = "orthographic"\northo_height = {ortho}\n'
            f"position = {list(pos)}\nlook_at = {list(target)}\nup = [0.0, 1.0, 0.0]\n"
            f'[integrator]\nplugin = "mcpt"\npath_depth = 8\n'
            f"[environment]\ncolor = [1.0, 1.0, 1.0]\n"
        )
    subprocess.run([binary, "render", toml, "--out", exr], check=True, capture_output=True)
    return read_exr(exr)


def render_cycles(name, path, pos, target, ortho, w, h, spp, out, adjust=None, tag="cycles"):
    """Renders with Cycles; `adjust(material, principled_node)`, if given, runs on every
    Principled BSDF after the distribution is set to single-scattering GGX, and `tag` names
    the EXR ({name}-{tag}.exr)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=path)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("white")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1, 1, 1, 1)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = ortho * max(w, h) / h
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    cam.location = blender(pos)
    cam.rotation_euler = (blender(target) - blender(pos)).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = spp
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 8
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.render.resolution_x = w
    scene.render.resolution_y = h
    scene.render.image_settings.file_format = "OPEN_EXR"
    exr = os.path.join(out, f"{name}-{tag}.exr")
    scene.render.filepath = exr
    for mat in bpy.data.materials:
        for node in mat.node_tree.nodes if mat.node_tree else []:
            if node.type == "BSDF_PRINCIPLED":
                node.distribution = "GGX"
                if adjust:
                    adjust(mat, node)
    bpy.ops.render.render(write_still=True)
    return read_exr(exr)


def disk_masks(ortho, w, h, disks):
    """Pixel masks of `disks` (x, y, radius in the image plane's world units, y up) under the
    orthographic camera (`ortho` world units over `h` pixels)."""
    ys, xs = np.mgrid[0:h, 0:w]
    px = ortho / h
    wx, wy = (xs + 0.5 - w / 2) * px, (h / 2 - ys - 0.5) * px
    return [(wx - cx) ** 2 + (wy - cy) ** 2 < r * r for cx, cy, r in disks]


def arguments(spp, only=False, extend=None):
    """The command line (after `--` when Blender passes its own): --flowlight, --out (made
    if missing), --spp (default `spp`), with `only` --only NAME, and what `extend(parser)`
    adds."""
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser()
    ap.add_argument("--flowlight", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--spp", type=int, default=spp)
    if only:
        ap.add_argument("--only")
    if extend:
        extend(ap)
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    return args


def main():
    args = arguments(64, only=True)
    print("| asset | Flowlight | Cycles | ratio | mean abs. difference / mean |")
    print("|---|---|---|---|---|")
    for name, path, pos, target, ortho, w, h, disks in ASSETS:
        if args.only and args.only != name:
            continue
        spec = (name, path, pos, target, ortho, w, h, args.spp, args.out)
        fl = render_flowlight(os.path.abspath(args.flowlight), *spec)
        cy = render_cycles(*spec)
        lf, lc = luminance(fl), luminance(cy)
        diff = np.abs(lf - lc).mean() / lc.mean()
        print(f"| {name} | {lf.mean():.4f} | {lc.mean():.4f} | {lf.mean() / lc.mean():.4f} | {diff:.4f} |")
        for k, m in enumerate(disk_masks(ortho, w, h, disks)):
            a, b = lf[m].mean(), lc[m].mean()
            print(f"| {name}, disk {k} | {a:.4f} | {b:.4f} | {a / b:.4f} | {np.abs(lf - lc)[m].mean() / b:.4f} |")


if __name__ == "__main__":
    main()
