#!/usr/bin/env python3
"""Flowlight ERPT and MCPT side by side with LuxCore 2.11 (PATHCPU with its Metropolis
sampler, and with its plain random sampler) on the glass caustic, at equal wall time:
relMSE against the committed reference and efficiency 1/(relMSE x wall time), as ratios to
Flowlight's best MCPT on that scene (entangled, `expo`), printed as a markdown table
(docs/results.md, "ERPT against LuxCore's Metropolis").

Run `setup-luxcore.sh` once (a venv with pyluxcore 2.11.2 from PyPI, pinned by hash), build
the release binaries (`cargo build --release --workspace`), then, from anywhere:

    crates/flowlight-bench/peers/luxcore.py                 # 128^2, 8 s, seeds 1-4
    crates/flowlight-bench/peers/luxcore.py --seconds 30 --seeds 1 2

What it does:
  1. writes the scene for both renderers from scenes/glass-caustic/glass-caustic.gltf. The
     floor's and the wall's glTF material is made Lambertian for Flowlight
     (KHR_materials_specular factor 0: the glTF BRDF's GGX layer has no LuxCore twin). LuxCore
     gets PLY meshes read straight from the
     buffers (the sphere with its normals, for the same smooth shading), `matte` floor and
     wall with the glTF base colours, a `glass` sphere (IOR 1.5 inside, 1 outside,
     kr = kt = 1: exact Fresnel, as Flowlight's dielectric), the lamp as a matte emitter of
     the glTF's radiance (emissiveFactor x emissiveStrength) on its front face (Flowlight's
     default), the glTF camera (position, forward, up, yfov; the screen window moved by the
     one pixel LuxCore's film is off, see `luxcore_scene`) and a one-pixel box filter;
  2. renders (or reuses, while the settings are unchanged) a reference of the Lambertian
     scene with Flowlight's ERPT default, the best method on this scene, at
     --reference-spp (two independent halves, for the reference's own noise floor), and
     refuses the comparison when that floor exceeds 1/10 of the smallest relMSE compared;
  3. each round (one per seed) renders, one after the other in an order that alternates
     between rounds: Flowlight's ERPT default (scenes/glass-caustic/erpt.toml), Flowlight's
     entangled `expo` MCPT (the best MCPT on this scene), LuxCore Metropolis, LuxCore
     random, each for --seconds of wall time with --threads threads;
  4. compares every image with the reference (`flowlight compare`: relMSE, mean luminance
     ratio), checks that every renderer's mean luminance is within 1% of the reference's
     (else the scenes do not match, and it says so), and prints each renderer's efficiency
     against Flowlight's MCPT in the same round (median and range over rounds).

LuxCore's time is the wall time of its render loop (scene parsing and its acceleration
structure before Start() are left out, as Flowlight's wall time leaves out loading).
"""
import argparse
import json
import os
import statistics
import struct
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import peers  # noqa: E402  (the shared glTF -> PLY, run, field and compare helpers)

ROOT = peers.ROOT
VENV = os.environ.get("LUXCORE_VENV", os.path.join(ROOT, "target", "peers", "luxcore-venv"))
SCENE = os.path.join(ROOT, "scenes", "glass-caustic")
RENDERERS = ("flowlight-erpt", "flowlight-mcpt", "luxcore-metropolis", "luxcore-random")


def camera(g):
    """(origin, forward, up, yfov in degrees) of the glTF's camera node (column-major
    matrix; the camera looks down its local -Z)."""
    node = next(n for n in g["nodes"] if "camera" in n)
    m = node["matrix"]
    up = m[4:7]
    forward = [-m[8], -m[9], -m[10]]
    origin = m[12:15]
    yfov = g["cameras"][node["camera"]]["perspective"]["yfov"]
    return origin, forward, up, yfov * 180.0 / 3.141592653589793


def luxcore_scene(a, out):
    """Writes the PLY files and returns the scene's LuxCore properties as text lines."""
    path = os.path.join(SCENE, "glass-caustic.gltf")
    g = json.load(open(path))
    fmt3 = lambda v: " ".join(f"{x:.9g}" for x in v)  # noqa: E731
    lines = []
    for name, mat, pos, idx, nrm in peers.gltf_meshes(path, normals=True):
        pbr = mat.get("pbrMetallicRoughness", {})
        base = pbr.get("baseColorFactor", [1, 1, 1, 1])[:3]
        ext = mat.get("extensions", {})
        if "emissiveFactor" in mat:
            strength = ext.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
            radiance = [c * strength for c in mat["emissiveFactor"]]
            lines += [f"scene.materials.{name}.type = matte",
                      f"scene.materials.{name}.kd = {fmt3(base)}",
                      f"scene.materials.{name}.emission = {fmt3(radiance)}",
                      f"scene.materials.{name}.emission.gain = 1 1 1",
                      f"scene.materials.{name}.emission.power = 0",
                      f"scene.materials.{name}.emission.efficency = 0"]
        elif "KHR_materials_transmission" in ext:
            ior = ext.get("KHR_materials_ior", {}).get("ior", 1.5)
            lines += [f"scene.materials.{name}.type = glass",
                      f"scene.materials.{name}.kr = 1 1 1",
                      f"scene.materials.{name}.kt = 1 1 1",
                      f"scene.materials.{name}.exteriorior = 1",
                      f"scene.materials.{name}.interiorior = {ior}"]
        else:
            lines += [f"scene.materials.{name}.type = matte",
                      f"scene.materials.{name}.kd = {fmt3(base)}"]
        ply = os.path.join(out, f"{name}.ply")
        peers.write_ply(ply, pos, idx, nrm)
        lines += [f"scene.shapes.{name}.type = mesh",
                  f"scene.shapes.{name}.ply = {ply}",
                  f"scene.objects.{name}.shape = {name}",
                  f"scene.objects.{name}.material = {name}"]
    origin, forward, up, fov = camera(g)
    target = [o + f for o, f in zip(origin, forward)]
    lines += ["scene.camera.type = perspective",
              f"scene.camera.lookat.orig = {fmt3(origin)}",
              f"scene.camera.lookat.target = {fmt3(target)}",
              f"scene.camera.up = {fmt3(up)}",
              f"scene.camera.fieldofview = {fov:.9g}",
              # LuxCore 2.11's image lies one pixel lower than the one its screen window
              # describes, against Flowlight's (and glTF's) raster with the optical axis at the
              # film's centre: measured on this scene, relMSE 0.17 with the default window,
              # 0.033 with it moved up by one pixel (0.042 by half a pixel, 0.82 down by one).
              f"scene.camera.screenwindow = -1 1 {-1 - 2 / a.height:.9g} {1 - 2 / a.height:.9g}"]
    return lines


def luxcore_render(a, scene_lines, sampler, seed, out):
    py = os.path.join(VENV, "bin", "python")
    if not os.path.exists(py):
        peers.die(f"{py} is missing: run crates/flowlight-bench/peers/setup-luxcore.sh first")
    job = {"scene": scene_lines, "sampler": sampler, "seed": seed, "seconds": a.seconds,
           "threads": a.threads, "width": a.width, "height": a.height, "depth": a.depth,
           "out": out}
    text = peers.run([py, os.path.abspath(__file__), "--luxcore-worker", json.dumps(job)])
    return json.loads(text.strip().splitlines()[-1])


def luxcore_worker(job):
    """In the venv: parse the scene, render for `seconds` of wall time, save linear RGB."""
    import pyluxcore
    pyluxcore.Init(lambda msg: None)
    d = job["depth"]
    cfg = pyluxcore.Properties()
    cfg.SetFromString("\n".join([
        "renderengine.type = PATHCPU",
        f"sampler.type = {job['sampler']}",
        f"renderengine.seed = {job['seed']}",
        f"native.threads.count = {job['threads']}",
        f"path.pathdepth.total = {d}", f"path.pathdepth.diffuse = {d}",
        f"path.pathdepth.glossy = {d}", f"path.pathdepth.specular = {d}",
        f"film.width = {job['width']}", f"film.height = {job['height']}",
        "film.filter.type = BOX", "film.filter.width = 0.5",
        "film.imagepipelines.0.0.type = NOP",
    ]))
    scene = pyluxcore.Scene()
    props = pyluxcore.Properties()
    props.SetFromString("\n".join(job["scene"]))
    scene.Parse(props)
    renderer = pyluxcore.RenderSession(pyluxcore.RenderConfig(cfg, scene))
    t0 = time.perf_counter()
    renderer.Start()
    while time.perf_counter() - t0 < job["seconds"]:
        time.sleep(0.02)
        renderer.UpdateStats()
    renderer.Stop()
    wall = time.perf_counter() - t0
    renderer.GetFilm().SaveOutput(job["out"], pyluxcore.FilmOutputType.RGB, pyluxcore.Properties())
    print(json.dumps({"wall": wall}))
    # pyluxcore 2.11's log callback crashes the interpreter's finalisation: leave at once.
    sys.stdout.flush()
    os._exit(0)


def lambert_gltf(out):
    """The glass caustic's glTF with every material but the glass Lambertian
    (`peers.lambertian`), buffers embedded as they are."""
    g = peers.lambertian(json.load(open(os.path.join(SCENE, "glass-caustic.gltf"))))
    path = os.path.join(out, "glass-caustic-lambert.gltf")
    json.dump(g, open(path, "w"))
    return path


def flowlight_config(a, src, gltf, out):
    """`src` (a scene's TOML) on `gltf` at the comparison's size, with no outputs of its
    own."""
    lines, section = [], None
    for line in open(src):
        s = line.strip()
        if s.startswith("["):
            section = s
        if section == "[output]":
            continue
        if s.startswith("scene ="):
            line = f"scene = {json.dumps(gltf)}\n"
        elif section == "[render]" and s.split("=")[0].strip() in ("width", "height"):
            line = f"{s.split('=')[0].strip()} = {a.width if 'width' in s else a.height}\n"
        lines.append(line)
    open(out, "w").write("".join(lines))
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=8.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--depth", type=int, default=10, help="path depth (the scene's path_depth)")
    p.add_argument("--reference-spp", type=int, default=4096)
    p.add_argument("--rebuild-reference", action="store_true")
    p.add_argument("--flowlight", default=os.path.join(ROOT, "target", "release", "flowlight"))
    p.add_argument("--out", default=os.path.join(ROOT, "target", "peers", "luxcore"))
    p.add_argument("--luxcore-worker", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.luxcore_worker:
        luxcore_worker(json.loads(a.luxcore_worker))
        return 0
    a.out = os.path.abspath(a.out)
    if a.width != a.height:
        peers.die("square images only (LuxCore's screen window is set for a square film)")
    os.makedirs(a.out, exist_ok=True)
    scene_lines = luxcore_scene(a, a.out)
    gltf = lambert_gltf(a.out)
    erpt = flowlight_config(a, os.path.join(SCENE, "erpt.toml"), gltf,
                            os.path.join(a.out, "erpt.toml"))
    mcpt = flowlight_config(a, os.path.join(SCENE, "glass-caustic.toml"), gltf,
                            os.path.join(a.out, "mcpt.toml"))
    ref = peers.reference(a, "glass-caustic-lambert", erpt, a.out)
    rows = {r: [] for r in RENDERERS}
    for k, seed in enumerate(a.seeds):
        order = RENDERERS if k % 2 == 0 else tuple(reversed(RENDERERS))
        for r in order:
            img = os.path.join(a.out, f"{r}-{seed}.exr")
            if r.startswith("flowlight"):
                budget = ["--time", str(a.seconds)]
                if r == "flowlight-erpt":
                    t = peers.flowlight_render(a, erpt, seed, img, budget, sets=[])
                else:
                    t = peers.flowlight_render(a, mcpt, seed, img, budget, ["termination=expo"])
            else:
                sampler = "METROPOLIS" if r == "luxcore-metropolis" else "RANDOM"
                t = luxcore_render(a, scene_lines, sampler, seed, img)
            t.update(peers.compare(a, img, ref))
            rows[r].append(t)
            print(f"seed {seed} {r}: wall {t['wall']:.2f} s, relMSE {t['relmse']:.4e}, "
                  f"luminance {t['lum']:.4f}", file=sys.stderr)
    ok = True
    floor = statistics.fmean(x["floor"] for x in rows["flowlight-mcpt"])
    smallest = min(statistics.fmean(x["relmse"] for x in rows[r]) for r in RENDERERS)
    if floor > 0.1 * smallest:
        peers.die(f"the reference's floor {floor:.2e} exceeds 1/10 of the smallest relMSE "
                  f"compared ({smallest:.2e}): raise --reference-spp and pass --rebuild-reference")
    print(f"Glass caustic, {a.width}x{a.height}, {a.seconds:g} s, {a.threads} threads, seeds "
          f"{a.seeds}; efficiency = 1/(relMSE x wall) against Flowlight MCPT (entangled, expo) "
          f"in the same round, median (range) over rounds; reference {a.reference_spp} spp of "
          f"Flowlight ERPT, floor {floor:.2e}.\n")
    print("| renderer | relMSE (mean) | luminance / reference (mean) | efficiency vs Flowlight MCPT "
          "| efficiency vs LuxCore Metropolis |")
    print("|---|---:|---:|---:|---:|")
    base, metro = rows["flowlight-mcpt"], rows["luxcore-metropolis"]
    for r in RENDERERS:
        paired = lambda ref: [(b["relmse"] * b["wall"]) / (x["relmse"] * x["wall"])  # noqa: E731
                              for x, b in zip(rows[r], ref)]
        eff = paired(base)
        lum = statistics.fmean(x["lum"] for x in rows[r])
        if abs(lum - 1.0) > 0.01:
            ok = False
            print(f"luxcore.py: {r}: mean luminance {lum:.4f} of the reference's: the scenes do "
                  "not match, its efficiency means nothing", file=sys.stderr)
        fmt2 = lambda v: f"{v:.2f}"  # noqa: E731
        print(f"| {r} | {statistics.fmean(x['relmse'] for x in rows[r]):.3e} | {lum:.4f} | "
              f"{peers.med_range(eff, fmt2)} | {peers.med_range(paired(metro), fmt2)} |")
    return 0 if ok else 2


if __name__ == "__main__":
    sys.exit(main())
