"""Where the specular-glossiness spheres of `scenes/spec-gloss/` differ from Blender Cycles,
and why: the three spheres rendered by Flowlight and by Cycles three ways, the mean luminance
over each sphere's disk (as `cycles_gltf.py` measures it) and the ratios.

    /path/to/bpy-venv/bin/python crates/flowlight-bench/peers/spec_gloss_layering.py \\
        --flowlight target/release/flowlight --out /tmp/spec-gloss [--spp 256]

The Cycles columns:
- `imported`: Blender's importer as a user gets it (IOR 1000 and the specular colour as
  Specular Tint: a Fresnel that stays near F0 up to grazing angles);
- `matched`: the Fresnel set to the extension's (and Flowlight's) curve from F0 = specular to
  1: the dielectrics get IOR 1.5 (F0 0.04) and 3 (F0 0.25) with a white tint, the gold-like
  sphere becomes a metal with the specular colour as base colour; single-scattering GGX;
- `matched, multiscatter`: the same with Cycles' Multiscatter GGX.

Needs the PyPI `bpy` 4.5; Flowlight renders as in `cycles_gltf.py` (MCPT, path depth 8).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cycles_gltf as cg  # noqa: E402

# Material name -> the Principled inputs that give it the extension's Fresnel.
MATCHED = {
    "red-plastic": {"IOR": 1.5, "Specular Tint": (1.0, 1.0, 1.0, 1.0)},
    "grey-semigloss": {"IOR": 3.0, "Specular Tint": (1.0, 1.0, 1.0, 1.0)},
    "gold-like": {
        "Metallic": 1.0,
        "Base Color": (1.0, 0.77, 0.34, 1.0),
        "Specular Tint": (1.0, 1.0, 1.0, 1.0),
    },
}


def matched(distribution):
    def adjust(mat, node):
        for key, value in MATCHED[mat.name].items():
            node.inputs[key].default_value = value
        node.distribution = distribution

    return adjust


def main():
    args = cg.arguments(256)
    name, path, pos, target, ortho, w, h, disks = next(a for a in cg.ASSETS if a[0] == "spec-gloss-spheres")
    spec = (name, path, pos, target, ortho, w, h, args.spp, args.out)
    masks = cg.disk_masks(ortho, w, h, disks)

    def means(img):
        return [cg.luminance(img)[m].mean() for m in masks]

    ours = means(cg.render_flowlight(os.path.abspath(args.flowlight), *spec))
    cycles = [
        means(cg.render_cycles(*spec, tag="cycles-imported")),
        means(cg.render_cycles(*spec, adjust=matched("GGX"), tag="cycles-matched")),
        means(cg.render_cycles(*spec, adjust=matched("MULTI_GGX"), tag="cycles-matched-ms")),
    ]
    print("| sphere | Flowlight | Cycles imported | matched | matched, multiscatter | Flowlight / each |")
    print("|---|---:|---:|---:|---:|---|")
    for k, sphere in enumerate(["red plastic", "gold-like", "grey semi-gloss"]):
        c = [col[k] for col in cycles]
        ratios = ", ".join(f"{ours[k] / x:.4f}" for x in c)
        print(f"| {sphere} | {ours[k]:.4f} | {c[0]:.4f} | {c[1]:.4f} | {c[2]:.4f} | {ratios} |")


if __name__ == "__main__":
    main()
