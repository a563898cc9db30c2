"""The PEP 517 backend of the `flowlight` wheel (pyproject.toml names it through
`backend-path`): maturin builds one crate, the extension module, but the package also
carries every plugin of the workspace and the provisioned Embree library. So before handing
over to maturin this backend

1. runs `cargo build` for the workspace's plugin crates (their cdylibs), with the profile
   the wheel is built with: `release` unless `FLOWLIGHT_PY_PROFILE` names another (the tests
   use `dev`, sharing the target folder `cargo build --workspace` filled);
2. copies the plugin libraries into `flowlight/plugins/` and the Embree library the build
   provisioned (`EMBREE_DIR`, the system's, or the pinned embreex wheel's; see
   crates/flowlight-embree/build.rs), with the TBB beside it, into `flowlight/lib/`;
3. calls maturin's own `build_wheel` with the same profile.

Plugins whose package name has the word `test` (`flowlight-test-panic`) are left out: they exist to
be refused by the host's tests.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sysconfig
from pathlib import Path
from typing import Any, Mapping, Optional

import maturin

ROOT = Path(__file__).resolve().parents[3]

# maturin's hooks run the `maturin` executable by name: without build isolation (the tests'
# `pip wheel --no-build-isolation` from a venv that is not activated) it is in this
# interpreter's scripts folder, which need not be on PATH.
_SCRIPTS = sysconfig.get_path("scripts")
if _SCRIPTS and _SCRIPTS not in os.environ.get("PATH", "").split(os.pathsep):
    os.environ["PATH"] = _SCRIPTS + os.pathsep + os.environ.get("PATH", "")
PACKAGE = ROOT / "crates" / "flowlight-py" / "python" / "flowlight"


def _profile() -> str:
    return os.environ.get("FLOWLIGHT_PY_PROFILE", "release")


def _cargo() -> str:
    return os.environ.get("CARGO", "cargo")


def _metadata() -> dict:
    out = subprocess.run(
        [_cargo(), "metadata", "--no-deps", "--format-version", "1"],
        cwd=ROOT,
        check=True,
        stdout=subprocess.PIPE,
    ).stdout
    return json.loads(out)


def _plugin_crates(meta: dict) -> list[tuple[str, str]]:
    """(package, library name) of each plugin cdylib in the workspace's plugins/ folder."""
    plugins = ROOT / "plugins"
    found = []
    for pkg in meta["packages"]:
        manifest = Path(pkg["manifest_path"]).resolve()
        if plugins not in manifest.parents or "test" in pkg["name"].split("-"):
            continue
        for target in pkg["targets"]:
            if "cdylib" in target["crate_types"]:
                found.append((pkg["name"], target["name"].replace("-", "_")))
    return found


def _embree_library(build_dir: Path) -> Optional[Path]:
    """The Embree library flowlight-embree's build script provisioned for this profile."""
    outputs = sorted(
        build_dir.glob("build/flowlight-embree-*/output"), key=lambda p: p.stat().st_mtime
    )
    for output in reversed(outputs):
        for line in output.read_text().splitlines():
            key = "cargo:rustc-env=FLOWLIGHT_EMBREE_LIB="
            if line.startswith(key):
                lib = Path(line[len(key):])
                if lib.is_file():
                    return lib
    return None


def _stage() -> None:
    profile = _profile()
    meta = _metadata()
    crates = _plugin_crates(meta)
    if not crates:
        raise RuntimeError(f"no plugin crates found under {ROOT / 'plugins'}")
    cmd = [_cargo(), "build", "--profile", profile]
    for package, _ in crates:
        cmd += ["-p", package]
    print("flowlight_build: " + " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=ROOT, check=True)
    build_dir = Path(meta["target_directory"]) / ("debug" if profile == "dev" else profile)

    plugin_dir = PACKAGE / "plugins"
    shutil.rmtree(plugin_dir, ignore_errors=True)
    plugin_dir.mkdir(parents=True)
    for _, lib in crates:
        src = build_dir / f"lib{lib}.so"
        if not src.is_file():
            raise RuntimeError(f"{src}: the plugin library was not built")
        shutil.copy2(src, plugin_dir / src.name)

    lib_dir = PACKAGE / "lib"
    shutil.rmtree(lib_dir, ignore_errors=True)
    embree = _embree_library(build_dir)
    if embree is None:
        print("flowlight_build: no Embree library provisioned; the wheel renders with the BVH", flush=True)
        return
    lib_dir.mkdir(parents=True)
    # The file itself under the name the build used (its SONAME for the wheel's), and the
    # TBB libraries beside it, which Embree finds through its RPATH ($ORIGIN).
    shutil.copy2(embree.resolve(), lib_dir / embree.name)
    for tbb in embree.resolve().parent.glob("libtbb*.so*"):
        shutil.copy2(tbb.resolve(), lib_dir / tbb.name)


def _settings(config_settings: Optional[Mapping[str, Any]]) -> dict:
    settings = dict(config_settings or {})
    args = settings.get("build-args", "")
    settings["build-args"] = f"{args} --profile {_profile()}".strip()
    return settings


def build_wheel(
    wheel_directory: str,
    config_settings: Optional[Mapping[str, Any]] = None,
    metadata_directory: Optional[str] = None,
) -> str:
    _stage()
    return maturin.build_wheel(wheel_directory, _settings(config_settings), metadata_directory)


def build_editable(
    wheel_directory: str,
    config_settings: Optional[Mapping[str, Any]] = None,
    metadata_directory: Optional[str] = None,
) -> str:
    _stage()
    return maturin.build_editable(wheel_directory, _settings(config_settings), metadata_directory)


get_requires_for_build_wheel = maturin.get_requires_for_build_wheel
get_requires_for_build_editable = maturin.get_requires_for_build_wheel
prepare_metadata_for_build_wheel = maturin.prepare_metadata_for_build_wheel
build_sdist = maturin.build_sdist
get_requires_for_build_sdist = maturin.get_requires_for_build_sdist
