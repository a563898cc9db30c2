#!/usr/bin/env python3
"""Flowlight side by side with LuxCore 2.11 (path tracing with its Metropolis and random
samplers, bidirectional path tracing with and without Metropolis, bidirectional with vertex
merging) on the glass caustic, the Cornell box or the two caustic scenes kept out of tuning
(lens-spot, glass-rod), at equal wall time: relMSE against a Flowlight reference and
efficiency 1/(relMSE x wall time), as ratios to the baselines present, printed as a markdown
table (docs/results.md, "Flowlight against LuxCore").

Run `setup-luxcore.sh` once (a venv with pyluxcore 2.11.2 from PyPI, pinned by hash), build
the release binaries (`cargo build --release --workspace`), then, from anywhere:

    crates/flowlight-bench/peers/luxcore.py                 # glass caustic, 128^2, 8 s, seeds 1-4
    crates/flowlight-bench/peers/luxcore.py --seconds 30 --seeds 1 2
    crates/flowlight-bench/peers/luxcore.py --scene cornell-box \
        --renderers flowlight-mcpt,luxcore-bidir,luxcore-bidirvm

Renderers (`--renderers`, comma separated; the default is the first four):
  flowlight-erpt            the scene's erpt.toml (ERPT's default for it)
  flowlight-mcpt            the scene's MCPT config (the glass caustic's with termination "expo")
  luxcore-metropolis        PATHCPU, sampler METROPOLIS
  luxcore-random            PATHCPU, sampler RANDOM
  luxcore-bidir             BIDIRCPU, sampler SOBOL (LuxCore's default sampler)
  luxcore-bidir-metropolis  BIDIRCPU, sampler METROPOLIS
  luxcore-bidirvm           BIDIRVMCPU with its defaults: sampler SOBOL,
                            bidirvm.lightpath.count 16384, bidirvm.startradius.scale 0.003 (of
                            the scene's bounding-sphere radius), bidirvm.alpha 0.95
  luxcore-light             LIGHTCPU (light tracing only: no directly seen lamp, no surface seen
                            through glass; a diagnostic of the export, not a competitor)
  flowlight-lighttrace, flowlight-bdpt, flowlight-vcm, flowlight-pssmlt, flowlight-mmlt
                            the scene's MCPT config with its [integrator] replaced by `plugin =
                            "lighttrace" | "bdpt" | "vcm" | "pssmlt" | "mmlt"` and its
                            path_depth; refused up front, in one line, when `flowlight plugins`
                            does not list the plugin.
PATHCPU gets path.pathdepth.{total,diffuse,glossy,specular} = --depth; BIDIRCPU, BIDIRVMCPU
and LIGHTCPU get path.maxdepth = --depth + 1 (the eye subpath may hit the lamp after --depth
bounces) and light.maxdepth = --depth. LuxCore bounds each subpath, not their sum, and counts
specular bounces as well; on the glass caustic without the sphere path.maxdepth = light.maxdepth
= 32 gave the same mean luminance as 11/11 to 1e-4.

What it does:
  1. writes the scene for both renderers from scenes/<scene>/<scene>.gltf. Every material but
     the glass is made Lambertian for Flowlight (KHR_materials_specular factor 0: the glTF
     BRDF's GGX layer has no LuxCore twin); LuxCore gets PLY meshes read straight from the
     buffers (with their normals where the glTF has them, for the same smooth shading), `matte`
     with the glTF base colour, a smooth transmissive material as `glass` (kr = kt = 1: exact
     Fresnel, as Flowlight's dielectric; interiorior the KHR_materials_ior, exteriorior 1, no
     dispersion), an emissive material as `matte` emitting the glTF's radiance
     (emissiveFactor x emissiveStrength; gain 1, power and efficiency 0, so the radiance is
     used as given) from its front face only (Flowlight's default, and LuxCore's for mesh
     lights), the glTF camera (a root node: matrix or translation and rotation; position,
     forward, up, yfov; the screen window moved by the one pixel LuxCore's film is off, see
     `luxcore_scene`) and a one-pixel box filter. Textures, metallic, rough or tinted
     transmissive, volume-attenuated and alpha-blended materials are refused with the
     material's name. `--without NODE` leaves a mesh node out of both scenes;
  2. renders (or reuses, while the settings are unchanged) a reference of the Lambertian
     scene with Flowlight (the glass caustic: ERPT's default, the best method there; the
     Cornell box: its MCPT config) at --reference-spp (two independent halves, for the
     reference's own noise floor), and refuses the comparison when that floor exceeds 1/10 of
     the smallest relMSE compared;
  3. each round (one per seed) renders every renderer one after the other, in an order that
     alternates between rounds, each for --seconds of wall time with --threads threads;
  4. compares every image with the reference (`flowlight compare`: relMSE, mean luminance
     ratio), checks that every renderer's mean luminance is within 1% of the reference's
     (else it says so and exits with status 2), and prints each renderer's efficiency against
     each baseline present (flowlight-mcpt, luxcore-metropolis, luxcore-bidir,
     luxcore-bidirvm) in the same round (median and range over rounds).

LuxCore's time is the wall time of its render loop (scene parsing and its acceleration
structure before Start() are left out, as Flowlight's wall time leaves out loading).
BIDIRCPU's light-tracing strategy splats to the film (a screen-normalised channel added to the
pixel-normalised one); docs/results.md has what that does to its mean luminance.
"""
import argparse
import json
import os
import re
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import peers  # noqa: E402  (the shared glTF -> PLY, run, field and compare helpers)

ROOT = peers.ROOT
VENV = os.environ.get("LUXCORE_VENV", os.path.join(ROOT, "target", "peers", "luxcore-venv"))
DEFAULT_RENDERERS = ("flowlight-erpt", "flowlight-mcpt", "luxcore-metropolis", "luxcore-random")
# LuxCore renderers: (engine, sampler, engine properties beyond the depths).
LUXCORE = {
    "luxcore-metropolis": ("PATHCPU", "METROPOLIS", []),
    "luxcore-random": ("PATHCPU", "RANDOM", []),
    "luxcore-bidir": ("BIDIRCPU", "SOBOL", []),
    "luxcore-bidir-metropolis": ("BIDIRCPU", "METROPOLIS", []),
    "luxcore-bidirvm": ("BIDIRVMCPU", "SOBOL", ["bidirvm.lightpath.count = 16384",
                                                "bidirvm.startradius.scale = 0.003",
                                                "bidirvm.alpha = 0.95"]),
    "luxcore-light": ("LIGHTCPU", "SOBOL", []),
}
# Flowlight renderers whose integrator is only the plugin's name: renderer -> plugin.
FLOWLIGHT_PLUGIN_ONLY = {"flowlight-lighttrace": "lighttrace", "flowlight-bdpt": "bdpt",
                         "flowlight-vcm": "vcm", "flowlight-pssmlt": "pssmlt",
                         "flowlight-mmlt": "mmlt"}
RENDERERS = ("flowlight-erpt", "flowlight-mcpt", *FLOWLIGHT_PLUGIN_ONLY, *LUXCORE)
# Efficiency columns, in this order, for those present in --renderers.
BASELINES = {"flowlight-mcpt": "Flowlight MCPT", "luxcore-metropolis": "LuxCore Metropolis",
             "luxcore-bidir": "LuxCore BIDIR", "luxcore-bidirvm": "LuxCore BIDIRVM"}
# The scenes that export: their title, Flowlight configs (scenes/<name>/), the MCPT settings
# compared, and the config whose plugin defaults render the reference.
SCENES = {
    "glass-caustic": {"title": "Glass caustic", "mcpt": "glass-caustic.toml",
                      "mcpt_sets": ["termination=expo"], "mcpt_label": "entangled, expo",
                      "reference": "erpt.toml", "reference_label": "ERPT"},
    "cornell-box": {"title": "Cornell box", "mcpt": "cornell-box.toml", "mcpt_sets": [],
                    "mcpt_label": "entangled, throughput", "reference": "cornell-box.toml",
                    "reference_label": "MCPT"},
    # The two caustic scenes kept out of every tuning (crates/flowlight-testkit/src/caustics.rs).
    "lens-spot": {"title": "Lens spot", "mcpt": "lens-spot.toml", "mcpt_sets": [],
                  "mcpt_label": "entangled, throughput", "reference": "bdpt.toml",
                  "reference_label": "BDPT"},
    "glass-rod": {"title": "Glass rod", "mcpt": "glass-rod.toml", "mcpt_sets": [],
                  "mcpt_label": "entangled, throughput", "reference": "bdpt.toml",
                  "reference_label": "BDPT"},
}
ALLOWED_EXTENSIONS = {"KHR_materials_emissive_strength", "KHR_materials_ior",
                      "KHR_materials_transmission", "KHR_materials_volume",
                      "KHR_materials_specular"}


def die(msg):
    print(f"luxcore.py: error: {msg}", file=sys.stderr)
    sys.exit(1)


def quaternion_axes(q):
    """The x, y, z axes (rotation matrix columns) of the unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return ([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)],
            [2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w)],
            [2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)])


def camera(g, path):
    """(origin, forward, up, yfov in degrees) of the glTF's first camera node, a root node with
    a column-major matrix or a translation and rotation (the camera looks down its local
    -Z)."""
    index = next((i for i, n in enumerate(g["nodes"]) if "camera" in n), None)
    if index is None:
        die(f"{path}: no camera node")
    node = g["nodes"][index]
    if any(index in n.get("children", []) for n in g["nodes"]):
        die(f"{path}: camera node '{node.get('name')}' has a parent (only a root camera exports)")
    cam = g["cameras"][node["camera"]]
    if cam.get("type") != "perspective":
        die(f"{path}: camera '{node.get('name')}' is not perspective")
    if "matrix" in node:
        m = node["matrix"]
        up, forward, origin = m[4:7], [-m[8], -m[9], -m[10]], m[12:15]
    else:
        if node.get("scale", [1, 1, 1]) != [1, 1, 1]:
            die(f"{path}: camera node '{node.get('name')}' is scaled")
        _, up, z = quaternion_axes(node.get("rotation", [0, 0, 0, 1]))
        forward, origin = [-c for c in z], node.get("translation", [0, 0, 0])
    return origin, forward, up, cam["perspective"]["yfov"] * 180.0 / 3.141592653589793


def luxcore_material(path, mat):
    """The LuxCore material properties (without the `scene.materials.<name>.` prefix) of a
    glTF material, or a one-line refusal of what does not export."""
    name = mat.get("name", "?")
    where = f"{path}: material '{name}'"
    pbr = mat.get("pbrMetallicRoughness", {})
    ext = mat.get("extensions", {})
    textures = [k for k in [*mat, *pbr] if k.endswith("Texture")]
    if textures:
        die(f"{where} has textures ({', '.join(textures)}): textured materials do not export")
    if mat.get("alphaMode", "OPAQUE") != "OPAQUE":
        die(f"{where}: alphaMode {mat['alphaMode']} does not export")
    exotic = sorted(set(ext) - ALLOWED_EXTENSIONS)
    if exotic:
        die(f"{where} uses {', '.join(exotic)}, which does not export")
    if pbr.get("metallicFactor", 1.0) != 0.0:
        die(f"{where} is metallic (metallicFactor {pbr.get('metallicFactor', 1.0)}; glTF's "
            "default is 1): only dielectrics export")
    fmt3 = lambda v: " ".join(f"{x:.9g}" for x in v)  # noqa: E731
    base = pbr.get("baseColorFactor", [1, 1, 1, 1])[:3]
    emissive = mat.get("emissiveFactor", [0, 0, 0])
    if any(emissive):
        strength = ext.get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
        return ["type = matte", f"kd = {fmt3(base)}",
                f"emission = {fmt3([c * strength for c in emissive])}",
                "emission.gain = 1 1 1", "emission.power = 0", "emission.efficency = 0"]
    if "KHR_materials_transmission" in ext:
        factor = ext["KHR_materials_transmission"].get("transmissionFactor", 0.0)
        volume = ext.get("KHR_materials_volume", {})
        if factor != 1.0 or pbr.get("roughnessFactor", 1.0) != 0.0 or base != [1, 1, 1]:
            die(f"{where}: only smooth, white, fully transmissive glass exports (transmission "
                f"{factor}, roughness {pbr.get('roughnessFactor', 1.0)}, base colour {base})")
        if "attenuationDistance" in volume or "attenuationColor" in volume:
            die(f"{where}: volume attenuation does not export")
        ior = ext.get("KHR_materials_ior", {}).get("ior", 1.5)
        return ["type = glass", "kr = 1 1 1", "kt = 1 1 1", "exteriorior = 1",
                f"interiorior = {ior}"]
    return ["type = matte", f"kd = {fmt3(base)}"]


def luxcore_scene(a, gltf_path, out):
    """Writes the PLY files (named after the glTF file and the node, so scenes rendered into the
    same --out do not share them) and returns the scene's LuxCore properties as text lines."""
    g = json.load(open(gltf_path))
    fmt3 = lambda v: " ".join(f"{x:.9g}" for x in v)  # noqa: E731
    lines, exported = [], set()
    for name, mat, pos, idx, nrm in peers.gltf_meshes(gltf_path, normals=True):
        if name in a.without:
            continue
        if name in exported:
            die(f"{gltf_path}: two mesh nodes are named '{name}' (LuxCore's objects need "
                "distinct names)")
        exported.add(name)
        lines += [f"scene.materials.{name}.{p}" for p in luxcore_material(gltf_path, mat)]
        ply = os.path.join(out, f"{os.path.basename(gltf_path)[:-len('.gltf')]}-{name}.ply")
        peers.write_ply(ply, pos, idx, nrm)
        lines += [f"scene.shapes.{name}.type = mesh",
                  f"scene.shapes.{name}.ply = {ply}",
                  f"scene.objects.{name}.shape = {name}",
                  f"scene.objects.{name}.material = {name}"]
    missing = sorted(set(a.without) - {n.get("name") for n in g["nodes"] if "mesh" in n})
    if missing:
        die(f"--without: {gltf_path} has no mesh node named {', '.join(missing)}")
    origin, forward, up, fov = camera(g, gltf_path)
    target = [o + f for o, f in zip(origin, forward)]
    lines += ["scene.camera.type = perspective",
              f"scene.camera.lookat.orig = {fmt3(origin)}",
              f"scene.camera.lookat.target = {fmt3(target)}",
              f"scene.camera.up = {fmt3(up)}",
              f"scene.camera.fieldofview = {fov:.9g}",
              # LuxCore 2.11's image lies one pixel lower than the one its screen window
              # describes, against Flowlight's (and glTF's) raster with the optical axis at the
              # film's centre: measured on the glass caustic, relMSE 0.17 with the default
              # window, 0.033 with it moved up by one pixel (0.042 by half a pixel, 0.82 down by
              # one).
              f"scene.camera.screenwindow = -1 1 {-1 - 2 / a.height:.9g} {1 - 2 / a.height:.9g}"]
    return lines


def luxcore_render(a, scene_lines, renderer, seed, out):
    py = os.path.join(VENV, "bin", "python")
    if not os.path.exists(py):
        peers.die(f"{py} is missing: run crates/flowlight-bench/peers/setup-luxcore.sh first")
    engine, sampler, extra = LUXCORE[renderer]
    job = {"scene": scene_lines, "engine": engine, "sampler": sampler, "extra": extra,
           "seed": seed, "seconds": a.seconds, "threads": a.threads, "width": a.width,
           "height": a.height, "depth": a.depth, "out": out}
    text = peers.run([py, os.path.abspath(__file__), "--luxcore-worker", json.dumps(job)])
    return json.loads(text.strip().splitlines()[-1])


def luxcore_worker(job):
    """In the venv: parse the scene, render for `seconds` of wall time, save linear RGB."""
    import pyluxcore
    pyluxcore.Init(lambda msg: None)
    d = job["depth"]
    if job["engine"] == "PATHCPU":
        depths = [f"path.pathdepth.total = {d}", f"path.pathdepth.diffuse = {d}",
                  f"path.pathdepth.glossy = {d}", f"path.pathdepth.specular = {d}"]
    else:
        depths = [f"path.maxdepth = {d + 1}", f"light.maxdepth = {d}"]
    cfg = pyluxcore.Properties()
    cfg.SetFromString("\n".join([
        f"renderengine.type = {job['engine']}",
        f"sampler.type = {job['sampler']}",
        f"renderengine.seed = {job['seed']}",
        f"native.threads.count = {job['threads']}",
        *depths, *job["extra"],
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


def lambert_gltf(a, scene_dir, name, out):
    """The scene's glTF with every material but the glass Lambertian (`peers.lambertian`), the
    --without nodes' meshes left out, buffers embedded as they are or referenced where they
    are."""
    g = peers.lambertian(json.load(open(os.path.join(scene_dir, f"{name}.gltf"))))
    for b in g["buffers"]:
        if not b["uri"].startswith("data:"):
            b["uri"] = os.path.relpath(os.path.join(scene_dir, b["uri"]), out)
    for node in g["nodes"]:
        if node.get("name") in a.without:
            node.pop("mesh", None)
    suffix = "".join(f"-without-{n}" for n in a.without)
    path = os.path.join(out, f"{name}-lambert{suffix}.gltf")
    json.dump(g, open(path, "w"))
    return path


def flowlight_config(a, src, gltf, out, plugin=None):
    """`src` (a scene's TOML) on `gltf` at the comparison's size, with no outputs of its own;
    with `plugin`, its [integrator] tables replaced by `plugin = "<plugin>"` and the scene's
    `path_depth` (every renderer renders the reference's layers of path space, as the bench)."""
    lines, section = [], None
    for line in open(src):
        s = line.strip()
        if s.startswith("["):
            section = s
        replaced = plugin and section is not None and section.strip("[]").startswith("integrator")
        if section == "[output]" or replaced:
            if replaced and s == "[integrator]":
                lines.append(f'[integrator]\nplugin = "{plugin}"\n')
            elif replaced and section == "[integrator]" and s.startswith("path_depth"):
                lines.append(line)
            continue
        if s.startswith("scene ="):
            line = f"scene = {json.dumps(gltf)}\n"
        elif section == "[render]" and s.split("=")[0].strip() in ("width", "height"):
            line = f"{s.split('=')[0].strip()} = {a.width if 'width' in s else a.height}\n"
        lines.append(line)
    open(out, "w").write("".join(lines))
    return out


def check_plugins(a, renderers):
    """One line, before anything renders, for a Flowlight renderer whose plugin is not built."""
    wanted = {r: FLOWLIGHT_PLUGIN_ONLY[r] for r in renderers if r in FLOWLIGHT_PLUGIN_ONLY}
    if not wanted:
        return
    listing = peers.run([a.flowlight, "plugins"])
    found = set(re.findall(r"^(\S+) \(Integrator\)", listing, re.M))
    for r, plugin in wanted.items():
        if plugin not in found:
            die(f"{r}: {a.flowlight} finds no `{plugin}` integrator plugin (`flowlight plugins` "
                "lists those built; `cargo build --release --workspace` builds them)")


def parse_renderers(text):
    renderers = [r for r in text.split(",") if r]
    for r in renderers:
        if r not in RENDERERS:
            die(f"--renderers: unknown renderer '{r}' (known: {', '.join(RENDERERS)})")
    if len(set(renderers)) != len(renderers) or not renderers:
        die("--renderers: give each renderer once, at least one")
    return tuple(renderers)


def render_one(a, spec, configs, scene_lines, r, seed, img):
    budget = ["--time", str(a.seconds)]
    if r == "flowlight-erpt":
        return peers.flowlight_render(a, configs["erpt"], seed, img, budget, sets=[])
    if r == "flowlight-mcpt":
        return peers.flowlight_render(a, configs["mcpt"], seed, img, budget, spec["mcpt_sets"])
    if r in FLOWLIGHT_PLUGIN_ONLY:
        return peers.flowlight_render(a, configs[r], seed, img, budget, sets=[])
    return luxcore_render(a, scene_lines, r, seed, img)


def label(spec, r):
    return BASELINES[r] + (f" ({spec['mcpt_label']})" if r == "flowlight-mcpt" else "")


def report(a, spec, renderers, rows):
    """Prints the table; False when a renderer's mean luminance is off by more than 1%."""
    floor = statistics.fmean(x["floor"] for x in rows[renderers[0]])
    smallest = min(statistics.fmean(x["relmse"] for x in rows[r]) for r in renderers)
    if floor > 0.1 * smallest:
        peers.die(f"the reference's floor {floor:.2e} exceeds 1/10 of the smallest relMSE "
                  f"compared ({smallest:.2e}): raise --reference-spp and pass --rebuild-reference")
    baselines = [b for b in BASELINES if b in renderers]
    against = f" against {label(spec, baselines[0])} in the same round" if baselines else ""
    title = spec["title"] + "".join(f" without {n}" for n in a.without)
    print(f"{title}, {a.width}x{a.height}, {a.seconds:g} s, {a.threads} threads, seeds "
          f"{a.seeds}; efficiency = 1/(relMSE x wall){against}, median (range) over rounds; "
          f"reference {a.reference_spp} spp of Flowlight {spec['reference_label']}, floor "
          f"{floor:.2e}.\n")
    print("| renderer | relMSE (mean) | luminance / reference (mean) |"
          + "".join(f" efficiency vs {BASELINES[b]} |" for b in baselines))
    print("|---|---:|---:|" + "---:|" * len(baselines))
    ok = True
    fmt2 = lambda v: f"{v:.2f}"  # noqa: E731
    for r in renderers:
        paired = lambda ref: [(b["relmse"] * b["wall"]) / (x["relmse"] * x["wall"])  # noqa: E731
                              for x, b in zip(rows[r], ref)]
        lum = statistics.fmean(x["lum"] for x in rows[r])
        if abs(lum - 1.0) > 0.01:
            ok = False
            print(f"luxcore.py: {r}: mean luminance {lum:.4f} of the reference's: the scenes do "
                  "not match, its efficiency means nothing", file=sys.stderr)
        print(f"| {r} | {statistics.fmean(x['relmse'] for x in rows[r]):.3e} | {lum:.4f} |"
              + "".join(f" {peers.med_range(paired(rows[b]), fmt2)} |" for b in baselines))
    return ok


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", choices=sorted(SCENES), default="glass-caustic")
    p.add_argument("--renderers", default=",".join(DEFAULT_RENDERERS),
                   help=f"comma separated, from: {', '.join(RENDERERS)}")
    p.add_argument("--without", action="append", default=[], metavar="NODE",
                   help="leave this mesh node out of both scenes (repeatable)")
    p.add_argument("--seconds", type=float, default=8.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--depth", type=int, help="LuxCore's path depth (default: the scene's "
                   "path_depth in its MCPT config)")
    p.add_argument("--reference-spp", type=int, default=4096)
    p.add_argument("--rebuild-reference", action="store_true")
    p.add_argument("--flowlight", default=os.path.join(ROOT, "target", "release", "flowlight"))
    p.add_argument("--out", default=os.path.join(ROOT, "target", "peers", "luxcore"))
    p.add_argument("--luxcore-worker", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.luxcore_worker:
        luxcore_worker(json.loads(a.luxcore_worker))
        return 0
    renderers = parse_renderers(a.renderers)
    spec = SCENES[a.scene]
    scene_dir = os.path.join(ROOT, "scenes", a.scene)
    if a.depth is None:
        mcpt_toml = open(os.path.join(scene_dir, spec["mcpt"])).read()
        m = re.search(r"^path_depth\s*=\s*(\d+)", mcpt_toml, re.M)
        a.depth = int(m.group(1)) if m else 8
    a.out = os.path.abspath(a.out)
    if a.width != a.height:
        die("square images only (LuxCore's screen window is set for a square film)")
    if not os.access(a.flowlight, os.X_OK):
        die(f"{a.flowlight} is not an executable: `cargo build --release --workspace`, or pass "
            "--flowlight")
    check_plugins(a, renderers)
    os.makedirs(a.out, exist_ok=True)
    scene_lines = luxcore_scene(a, os.path.join(scene_dir, f"{a.scene}.gltf"), a.out)
    gltf = lambert_gltf(a, scene_dir, a.scene, a.out)
    tag = f"{a.scene}-" if a.scene != "glass-caustic" else ""
    configs = {
        "mcpt": flowlight_config(a, os.path.join(scene_dir, spec["mcpt"]), gltf,
                                 os.path.join(a.out, f"{tag}mcpt.toml")),
    }
    # The scene's own configs: its ERPT default (not every scene has one) and the reference's.
    for name in ("erpt.toml", spec["reference"]):
        if name not in configs and os.path.exists(os.path.join(scene_dir, name)):
            configs[name] = flowlight_config(a, os.path.join(scene_dir, name), gltf,
                                             os.path.join(a.out, f"{tag}{name}"))
    if "erpt.toml" in configs:
        configs["erpt"] = configs["erpt.toml"]
    elif "flowlight-erpt" in renderers:
        die(f"--renderers: scene '{a.scene}' has no erpt.toml for flowlight-erpt")
    for r, plugin in FLOWLIGHT_PLUGIN_ONLY.items():
        configs[r] = flowlight_config(a, os.path.join(scene_dir, spec["mcpt"]), gltf,
                                      os.path.join(a.out, f"{tag}{plugin}.toml"), plugin)
    ref_cfg = configs.get(spec["reference"], configs["mcpt"])
    ref_name = os.path.basename(gltf)[:-len(".gltf")]
    ref = peers.reference(a, ref_name, ref_cfg, a.out)
    rows = {r: [] for r in renderers}
    for k, seed in enumerate(a.seeds):
        order = renderers if k % 2 == 0 else tuple(reversed(renderers))
        for r in order:
            img = os.path.join(a.out, f"{tag}{r}-{seed}.exr")
            t = render_one(a, spec, configs, scene_lines, r, seed, img)
            t.update(peers.compare(a, img, ref))
            rows[r].append(t)
            print(f"seed {seed} {r}: wall {t['wall']:.2f} s, relMSE {t['relmse']:.4e}, "
                  f"luminance {t['lum']:.4f}", file=sys.stderr)
    return 0 if report(a, spec, renderers, rows) else 2


if __name__ == "__main__":
    sys.exit(main())
