#!/usr/bin/env python3
"""Where each renderer's CPU goes on the peers' scenes: Embree's ray queries against the rest
(sampling, shading, surface data, film), per camera sample, Flowlight beside Mitsuba 3.

    crates/flowlight-bench/peers/peers.py --reference-only          # once: writes the configs
    crates/flowlight-bench/peers/ray_share.py                       # both scenes, 64 spp, 2 threads
    crates/flowlight-bench/peers/ray_share.py --set branches=1 --scenes cornell-box
    crates/flowlight-bench/peers/ray_share.py --render-set robust=false   # Embree in Mitsuba's mode

Each render runs under `perf record -F 999` (cpu-clock samples; Debian: linux-perf). A sample
counts as Embree's when it falls in Embree's library: libembree4 for Flowlight, the
libembree3 that Mitsuba's wheel bundles. What is left out:
  * Flowlight: every thread but the render workers (`flowlight-worke`: the loader, the
    acceleration-structure build and the EXR writer run elsewhere);
  * Mitsuba: every sample outside the timed pass (loading, the untimed warm-up pass that
    JIT-compiles the kernels, writing), by the samples' CLOCK_MONOTONIC time stamps.
The CPU per camera sample is each renderer's own clock, as peers.py takes it (Flowlight's
summary `cpu time`; `time.process_time()` around Mitsuba's timed pass), split by the shares.
The rest is split by library too: Flowlight's plugin (`libflowlight_*`), its host (the
`flowlight` binary: batch callbacks, accumulation) and the others (libc, the kernel);
Mitsuba's compiled kernels (JIT code, perf's `perf-PID.map`), Dr.Jit's runtime and the others.

Why: both path tracers trace the same kinds of rays per path (a camera ray, then per vertex a
shadow ray and an extension ray), so what separates their costs beyond Embree's own (robust
here, fast there: `--render-set robust=false` puts ours in Mitsuba's mode) is the rest of a
path, Mitsuba's compiled wavefront loop against Flowlight's walker.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from typing import NamedTuple

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
sys.path.insert(0, HERE)
import peers  # noqa: E402  (the same venv, configs and renderer arguments)


die = peers.die_as("ray_share.py")


def perf_record(out, cmd, env=None):
    rec = ["perf", "record", "-q", "-F", "999", "-k", "CLOCK_MONOTONIC", "-o", out, "--"]
    r = subprocess.run(rec + cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        die(f"`{' '.join(rec + cmd)}` failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
    return r.stdout


def check_inputs(a, tool, package, fail):
    """One-line errors (through `fail`) for what a measurement needs: `tool` on the PATH (its
    Debian `package`), the Flowlight binary, the peers' venv and known --scenes."""
    if shutil.which(tool) is None:
        fail(f"{tool} is missing (Debian: {package})")
    if not os.access(a.flowlight, os.X_OK):
        fail(f"{a.flowlight} is not an executable: `cargo build --release -p flowlight -p flowlight-mcpt`, or pass --flowlight")
    if not os.path.exists(os.path.join(peers.VENV, "bin", "python")):
        fail(f"{peers.VENV} has no Python: run crates/flowlight-bench/peers/setup.sh first")
    unknown = [s for s in a.scenes.split(",") if s not in peers.SCENES]
    if unknown:
        fail(f"--scenes: unknown scene '{unknown[0]}' (known: {', '.join(peers.SCENES)})")


class Scene(NamedTuple):
    """A peers' scene as peers.py writes it into --out: Flowlight's config, Mitsuba's scene,
    and the config's image size and path depth (a --set path_depth in its place), which
    Mitsuba renders with."""
    cfg: str
    xml: str
    width: int
    height: int
    depth: int


def scene_files(a, name, fail):
    """The [`Scene`] `name`, or a one-line error (through `fail`) where peers.py has not
    written it."""
    cfg, xml = peers.scene_paths(a.out)[name]
    for path in (cfg, xml):
        if not os.path.exists(path):
            fail(f"{path} is missing: run peers.py --reference-only --out {a.out} first")
    config = tomllib.load(open(cfg, "rb"))
    sets = dict(s.split("=", 1) for s in a.set if "=" in s)
    depth = int(sets.get("path_depth", config["integrator"]["path_depth"]))
    return Scene(cfg, xml, config["render"]["width"], config["render"]["height"], depth)


def mitsuba_command(a, scene, spp):
    """peers.py's Mitsuba worker for `scene` at `spp` (one untimed pass, then one timed pass,
    no image written) with `a.threads` threads: (its command, its environment)."""
    job = {"variant": a.variant, "sampler": a.sampler, "xml": scene.xml, "spp": spp, "pass_spp": spp,
           "seed": 1, "threads": a.threads, "depth": scene.depth + 1, "width": scene.width,
           "height": scene.height}
    py = os.path.join(peers.VENV, "bin", "python")
    return [py, peers.__file__, "--mitsuba-worker", json.dumps(job)], peers.mitsuba_env()


def ours(a, scene, tmp):
    data = os.path.join(tmp, "ours.data")
    text = perf_record(data, peers.flowlight_argv(a, scene.cfg, 1, os.path.join(tmp, "ours.exr")))
    cpu = peers.field(text, "cpu time", "flowlight render")
    rep = subprocess.run(["perf", "report", "-i", data, "--no-children", "--sort", "comm,dso",
                          "--stdio"], capture_output=True, text=True).stdout
    groups = {}
    for line in rep.splitlines():
        f = line.split()
        if len(f) >= 3 and f[1] == "flowlight-worke" and f[0].endswith("%"):
            group = ("Embree" if f[2].startswith("libembree4") else
                     "plugin" if f[2].startswith("libflowlight_") else
                     "host" if f[2] == "flowlight" else "other")
            groups[group] = groups.get(group, 0.0) + float(f[0][:-1])
    if not groups:
        die("no samples of Flowlight's render threads (is perf allowed? kernel.perf_event_paranoid)")
    return cpu, groups


def mitsuba(a, scene, tmp):
    data = os.path.join(tmp, "mitsuba.data")
    cmd, env = mitsuba_command(a, scene, a.spp)
    last = perf_record(data, cmd, env).strip().splitlines()[-1]
    w = json.loads(last[last.index("{"):])  # after any colour codes of Mitsuba's log
    script = subprocess.run(["perf", "script", "-i", data, "-F", "time,ip,dso"],
                            capture_output=True, text=True).stdout
    groups = {}
    for line in script.splitlines():
        m = re.match(r"\s*([0-9.]+):\s+\S+\s+\((.*)\)", line)
        if not m or not w["t0"] <= float(m.group(1)) <= w["t1"]:
            continue
        dso = os.path.basename(m.group(2))
        group = ("Embree" if dso.startswith("libembree3") else
                 "kernels" if dso.startswith("perf-") or dso in ("unknown", "[unknown]") else
                 "Dr.Jit" if dso.startswith(("libdrjit", "libnanothread")) else "other")
        groups[group] = groups.get(group, 0) + 1
    if not groups:
        die("no samples inside Mitsuba's timed pass")
    return w["cpu"], groups


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="cornell-box,stanford-dragon")
    ap.add_argument("--flowlight", default=os.path.join(ROOT, "target", "release", "flowlight"))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="Flowlight MCPT parameter (repeatable), e.g. branches=1")
    ap.add_argument("--render-set", action="append", default=[], metavar="KEY=VALUE",
                    help="a [render] setting of Flowlight's render, TOML syntax (repeatable), "
                         "e.g. robust=false (Embree's fast mode, Mitsuba's own)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--sampler", default="multijitter", help="Mitsuba's sampler")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(ROOT, "target", "peers", "out"),
                    help="peers.py's --out, where its configs are")
    a = ap.parse_args()
    check_inputs(a, "perf", "linux-perf", die)
    rev = subprocess.run(["git", "-C", ROOT, "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
    print(f"# Embree's share: Flowlight {rev} ({', '.join(a.set + a.render_set) or 'defaults'}) vs Mitsuba "
          f"{peers.MITSUBA_VERSION} {a.variant}/{a.sampler}; peers.py's image size, {a.spp} spp, "
          f"{a.threads} threads, perf -F 999\n")
    print("| scene | run | renderer | CPU per camera sample (µs) | Embree's share | Embree (µs) | the rest (µs) | the rest by library |")
    print("|---|---:|---|---:|---:|---:|---:|---|")
    for scene in a.scenes.split(","):
        files = scene_files(a, scene, die)
        files = files._replace(cfg=peers.with_render_settings(files.cfg, a.render_set))
        pixels = files.width * files.height * a.spp
        for run in range(1, a.runs + 1):
            with tempfile.TemporaryDirectory() as tmp:
                for name, fn in (("Flowlight", ours), ("Mitsuba", mitsuba)):
                    cpu, groups = fn(a, files, tmp)
                    total = sum(groups.values())
                    share = groups.get("Embree", 0) / total
                    us = cpu / pixels * 1e6
                    rest = ", ".join(f"{g} {us * v / total:.3f}" for g, v in
                                     sorted(groups.items(), key=lambda kv: -kv[1]) if g != "Embree")
                    print(f"| {scene} | {run} | {name} | {us:.3f} | {share:.3f} | "
                          f"{us * share:.3f} | {us * (1 - share):.3f} | {rest} |", flush=True)


if __name__ == "__main__":
    main()
