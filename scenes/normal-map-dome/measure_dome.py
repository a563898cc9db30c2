"""Mean luminance of each cell of dome.gltf (make_dome.py) over the dome's disk, from a
Flowlight EXR rendered with dome.toml, and optionally from Blender Cycles rendering the same
file under the same white sky and orthographic camera.

    /path/to/bpy-venv/bin/python scenes/normal-map-dome/measure_dome.py dome.exr [--cycles SPP]
        [--multiscatter]

With `--multiscatter` Cycles renders with its Multiscatter GGX (compare with an EXR rendered
from dome-multiscatter.toml); without, with single-scattering GGX, as dome.toml.

Needs the PyPI `bpy` (4.5) for reading the EXR and for Cycles. Prints one line per cell and
the ratio of each normal-mapped cell to the geometric one at its roughness.
"""
import math
import os
import sys

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
SIZE = 240
ORTHO_HEIGHT = 4.8
CELLS = [("mapped", -1.2), ("geometry", 1.2)]
ROWS = [(0.15, -1.2), (0.4, 1.2)]


def read_exr(path):
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.array(img.pixels[:], dtype=np.float64).reshape(h, w, 4)[::-1]
    return px[:, :, :3]


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def cell_means(rgb):
    """Mean luminance over the disk of radius 0.95 around each cell's centre (world x right,
    z down the image, 50 pixels a unit)."""
    h, w, _ = rgb.shape
    scale = w / ORTHO_HEIGHT
    ys, xs = np.mgrid[0:h, 0:w]
    wx = (xs + 0.5 - w / 2) / scale
    wz = (ys + 0.5 - h / 2) / scale
    lum = luminance(rgb)
    out = {}
    for rough, cz in ROWS:
        for name, cx in CELLS:
            mask = (wx - cx) ** 2 + (wz - cz) ** 2 < 0.95**2
            out[(name, rough)] = float(lum[mask].mean())
    return out


def render_cycles(spp, distribution):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=os.path.join(HERE, "dome.gltf"))
    scene = bpy.context.scene
    world = bpy.data.worlds.new("white")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    scene.world = world
    cam_data = bpy.data.cameras.new("top")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = ORTHO_HEIGHT
    cam = bpy.data.objects.new("top", cam_data)
    scene.collection.objects.link(cam)
    # Blender is Z-up: glTF's +Y is Blender's +Z, glTF's +Z is Blender's -Y. Looking down -Z
    # with glTF -Z (Blender +Y) at the top of the image: no rotation.
    cam.location = (0.0, 0.0, 10.0)
    cam.rotation_euler = (0.0, 0.0, 0.0)
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = spp
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 8
    scene.render.resolution_x = SIZE
    scene.render.resolution_y = SIZE
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    out = os.path.join("/tmp", "dome-cycles.exr")
    scene.render.filepath = out
    # Single-scattering GGX on both sides, or Multiscatter GGX against `multiscatter = true`.
    for mat in bpy.data.materials:
        if mat.node_tree:
            for node in mat.node_tree.nodes:
                if node.type == "BSDF_PRINCIPLED":
                    node.distribution = distribution
    bpy.ops.render.render(write_still=True)
    return read_exr(out)


def report(label, means):
    for rough, _ in ROWS:
        m, g = means[("mapped", rough)], means[("geometry", rough)]
        print(f"{label}: roughness {rough}: mapped {m:.4f} geometry {g:.4f} ratio {m / g:.4f}")


def main():
    args = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    report(os.path.basename(args[0]), cell_means(read_exr(args[0])))
    if "--cycles" in args:
        spp = int(args[args.index("--cycles") + 1])
        distribution = "MULTI_GGX" if "--multiscatter" in args else "GGX"
        report(f"cycles {distribution} {spp} spp", cell_means(render_cycles(spp, distribution)))


if __name__ == "__main__":
    main()
