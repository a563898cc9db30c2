#!/usr/bin/env python3
"""Instructions per camera sample of each renderer on the peers' scenes, by library, counted
by callgrind: Flowlight's plugin, host and Embree against Mitsuba 3's compiled kernels, Dr.Jit
and Embree. Exact counts, where ray_share.py's times move by 10-20% from run to run.

    crates/flowlight-bench/peers/peers.py --reference-only          # once: writes the configs
    crates/flowlight-bench/peers/instructions.py                    # the Cornell box, 1 branch
    crates/flowlight-bench/peers/instructions.py --scenes stanford-dragon --set branches=4

Each renderer runs twice under `valgrind --tool=callgrind`, at --spp and at twice that, one
thread, and the counts per library are differences of the two runs: loading, the
acceleration-structure build, Mitsuba's Python and the image writing cancel, and what is left
is --spp samples per pixel of rendering (Mitsuba renders each pass twice, the untimed warm-up
and the timed pass, both counted). Mitsuba's kernels are the instructions without an object
file (Dr.Jit's JIT code; `--smc-check=all-non-file` lets valgrind see it). Its "other" column
also holds any kernel compilation that one run did and the other found in Dr.Jit's cache, so
only its kernels, Dr.Jit and Embree columns are per-sample figures. Needs `valgrind` (Debian:
valgrind); each Mitsuba run of the dragon takes minutes under it.
"""
import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import peers  # noqa: E402
import ray_share  # noqa: E402  (its checks, scenes and Mitsuba command)

ROOT = ray_share.ROOT
die = peers.die_as("instructions.py")


def counts_by_object(path):
    """{object file: instructions} of a callgrind output (its compressed names resolved; the
    cost line after a `calls=` line is the call's inclusive cost and is skipped)."""
    names, obj, after_call = {}, None, False
    counts = collections.Counter()
    with open(path) as f:
        for line in f:
            if line.startswith(("ob=", "cob=")):
                m = re.match(r"c?ob=(?:\((\d+)\))?\s*(.*)", line.strip())
                ident, name = m.group(1), m.group(2)
                if ident and name:
                    names[ident] = name
                if line.startswith("ob="):
                    obj = name or names.get(ident, "?")
            elif line.startswith("calls="):
                after_call = True
            elif line[:1].isdigit() or line[:1] in "+-*":
                if after_call:
                    after_call = False
                    continue
                fields = line.split()
                if len(fields) >= 2:
                    counts[obj] += int(fields[1])
            else:
                after_call = False
    return counts


def group(obj):
    base = os.path.basename(obj)
    if obj == "???":
        return "kernels"
    if "libembree" in base:
        return "Embree"
    if base.startswith("libflowlight_"):
        return "plugin"
    if base == "flowlight":
        return "host"
    if base.startswith(("libdrjit", "libnanothread")):
        return "Dr.Jit"
    return "other"


def callgrind(cmd, out, env=None):
    cg = ["valgrind", "--tool=callgrind", "--smc-check=all-non-file", f"--callgrind-out-file={out}"]
    r = subprocess.run(cg + cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        die(f"`{' '.join(cmd)}` failed under valgrind ({r.returncode}):\n{r.stderr[-2000:]}")
    groups = collections.Counter()
    for obj, n in counts_by_object(out).items():
        groups[group(obj)] += n
    return groups


def ours(a, scene, spp, tmp):
    cmd = peers.flowlight_argv(a, scene.cfg, 1, os.path.join(tmp, "ours.exr"), budget=["--spp", str(spp)])
    return callgrind(cmd, os.path.join(tmp, "ours.cg"))


def mitsuba(a, scene, spp, tmp):
    cmd, env = ray_share.mitsuba_command(a, scene, spp)
    return callgrind(cmd, os.path.join(tmp, "mitsuba.cg"), env)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="cornell-box")
    ap.add_argument("--flowlight", default=os.path.join(ROOT, "target", "release", "flowlight"))
    ap.add_argument("--set", action="append", default=None, metavar="KEY=VALUE",
                    help="Flowlight MCPT parameter (repeatable; default branches=1, one path per camera sample as Mitsuba's)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--sampler", default="multijitter", help="Mitsuba's sampler")
    ap.add_argument("--spp", type=int, default=1, help="the difference of the two runs (at SPP and 2 SPP)")
    ap.add_argument("--out", default=os.path.join(ROOT, "target", "peers", "out"),
                    help="peers.py's --out, where its configs are")
    a = ap.parse_args()
    a.set = a.set if a.set is not None else ["branches=1"]
    a.threads = 1  # callgrind runs one thread at a time anyway
    ray_share.check_inputs(a, "valgrind", "valgrind", die)
    rev = subprocess.run(["git", "-C", ROOT, "describe", "--always", "--dirty"], capture_output=True, text=True).stdout.strip()
    print(f"# Instructions per camera sample: Flowlight {rev} ({', '.join(a.set)}) vs Mitsuba "
          f"{peers.MITSUBA_VERSION} {a.variant}/{a.sampler}; peers.py's image size, difference of "
          f"{a.spp} and {2 * a.spp} spp, one thread, callgrind\n")
    print("| scene | renderer | total | by library |")
    print("|---|---|---:|---|")
    for scene in a.scenes.split(","):
        files = ray_share.scene_files(a, scene, die)
        # Mitsuba renders each run's pass twice (warm-up and timed).
        for name, fn, renders in (("Flowlight", ours, 1), ("Mitsuba", mitsuba, 2)):
            with tempfile.TemporaryDirectory() as tmp:
                low, high = fn(a, files, a.spp, tmp), fn(a, files, 2 * a.spp, tmp)
            samples = renders * a.spp * files.width * files.height
            per = {g: (high[g] - low[g]) / samples for g in set(low) | set(high)}
            # A library that renders nothing differs by a handful of instructions (the vDSO).
            per = {g: v for g, v in per.items() if abs(v) >= 1}
            shown = {g: v for g, v in per.items() if g != "other" or name == "Flowlight"}
            total = sum(shown.values())
            parts = ", ".join(f"{g} {v:,.0f}" for g, v in sorted(per.items(), key=lambda kv: -kv[1]))
            print(f"| {scene} | {name} | {total:,.0f} | {parts} |", flush=True)


if __name__ == "__main__":
    main()
