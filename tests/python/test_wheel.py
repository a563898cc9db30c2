"""The wheel installs into a fresh virtual environment, with no Rust toolchain on PATH and
away from the build tree, and renders: the plugins and Embree come from the package."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

from conftest import ROOT

SCRIPT = """
import json, os, flowlight
scene = flowlight.load("cornell-box.toml")
img = scene.render(spp=2, progress=False)
print(json.dumps({
    "mean": float(img.rgb.mean()),
    "shape": list(img.rgb.shape),
    "intersector": img.stats["intersector"],
    "package": os.path.dirname(flowlight.__file__),
    "plugins": sorted(str(p["file"]) for p in flowlight.plugins()),
    "embree": os.environ.get("FLOWLIGHT_EMBREE_LIB"),
}))
"""


def wheelhouse() -> Path:
    """numpy's wheel for the fresh environment (.ci/setup downloads it)."""
    return Path(os.environ.get("FLOWLIGHT_WHEELHOUSE", ROOT / "target" / "py-wheelhouse"))


def test_the_wheel_renders_in_a_fresh_venv_without_cargo(wheel, tmp_path):
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    python = env_dir / "bin" / "python"
    subprocess.run(
        [str(python), "-m", "pip", "install", "-q", "--no-index", "--find-links", str(wheelhouse()), str(wheel)],
        check=True,
    )
    work = tmp_path / "work"
    work.mkdir()
    for name in ("cornell-box.toml", "cornell-box.gltf", "cornell-box.bin"):
        shutil.copy(ROOT / "scenes" / "cornell-box" / name, work / name)
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("CARGO", "RUSTUP", "FLOWLIGHT"))}
    clean["PATH"] = str(env_dir / "bin")
    assert shutil.which("cargo", path=clean["PATH"]) is None
    proc = subprocess.run([str(python), "-c", SCRIPT], cwd=work, env=clean, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["shape"] == [512, 512, 3] and got["mean"] > 0.01
    package = Path(got["package"]).resolve()
    assert env_dir.resolve() in package.parents
    assert got["plugins"] and all(Path(p).resolve().parent == package / "plugins" for p in got["plugins"])
    if (package / "lib").is_dir():
        # Embree is the package's own, and it is the one the render used.
        assert Path(got["embree"]).resolve().parent == package / "lib"
        assert got["intersector"] == "embree"
    assert sys.prefix not in str(package)
