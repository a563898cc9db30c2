"""Flowlight from Python: load a scene once, render it many times into numpy arrays.

    import flowlight
    scene = flowlight.load("scenes/cornell-box/cornell-box.toml")
    img = scene.render(spp=16, set={"path_depth": 10})
    img.rgb          # H x W x 3 float32, linear
    img.save("out.exr")

The API is documented in docs/python.md.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence, Tuple, Union

_HERE = Path(__file__).resolve().parent

# The Embree library the wheel carries (with TBB beside it) is opened from here unless the
# user names one (FLOWLIGHT_EMBREE_LIB, read by the host when it first builds an Embree scene).
_bundled_embree = sorted((_HERE / "lib").glob("libembree4*.so*")) if (_HERE / "lib").is_dir() else []
if _bundled_embree and "FLOWLIGHT_EMBREE_LIB" not in os.environ:
    os.environ["FLOWLIGHT_EMBREE_LIB"] = str(_bundled_embree[0])

from . import _native  # noqa: E402
from ._native import (  # noqa: E402
    ConfigError,
    Error,
    Image,
    OutputError,
    PluginError,
    RenderError,
    SceneError,
)
from ._progress import make_progress  # noqa: E402

_native.set_package_dir(str(_HERE))

__version__: str = _native.__version__

__all__ = [
    "Error",
    "ConfigError",
    "SceneError",
    "PluginError",
    "RenderError",
    "OutputError",
    "Image",
    "Scene",
    "load",
    "plugins",
    "compare",
    "read_exr",
    "bench",
    "loads_so_far",
]

PathLike = Union[str, "os.PathLike[str]"]
ImageLike = Union[Image, PathLike, Any]


class Scene:
    """A scene loaded and built once; `render` creates only the integrator."""

    def __init__(self, native: "_native.Scene") -> None:
        self._native = native

    def render(
        self,
        *,
        spp: Optional[int] = None,
        time: Optional[float] = None,
        threads: Optional[int] = None,
        seed: Optional[int] = None,
        set: Optional[Mapping[str, Any]] = None,
        progress: Union[None, bool, Callable[[dict], Any]] = None,
        denoise: bool = False,
    ) -> Image:
        """Renders with the config's budget, or `spp` samples per pixel, or `time` seconds.

        `set` holds integrator parameters (and the settable `render.*` keys) as the command
        line's `--set KEY=VALUE` does. `progress`: None shows a bar (tqdm when installed, else
        a plain line), False is silent, a callable receives a dict per update. `denoise`
        adds the layers `albedo`, `normal` and `denoised` (Open Image Denoise, found as the
        command line's `--denoise` finds it; the beauty stays the unbiased estimate).
        """
        callback, close = make_progress(progress, self._native, spp=spp, time=time)
        try:
            return self._native.render(
                spp=spp,
                time=time,
                threads=threads,
                seed=seed,
                set=dict(set) if set is not None else None,
                progress=callback,
                denoise=denoise,
            )
        finally:
            close()

    @property
    def width(self) -> int:
        return self._native.width

    @property
    def height(self) -> int:
        return self._native.height

    @property
    def load_seconds(self) -> float:
        return self._native.load_seconds

    @property
    def build_seconds(self) -> float:
        return self._native.build_seconds

    @property
    def load_id(self) -> int:
        return self._native.load_id

    @property
    def renders(self) -> int:
        return self._native.renders

    @property
    def intersector(self) -> str:
        return self._native.intersector

    @property
    def triangles(self) -> int:
        return self._native.triangles

    @property
    def integrator(self) -> str:
        return self._native.integrator

    @property
    def config_path(self) -> Path:
        return Path(self._native.config_path)

    def __repr__(self) -> str:
        return repr(self._native)


def load(config: Union[PathLike, Mapping[str, Any]], *, base_dir: Optional[PathLike] = None) -> Scene:
    """Loads a config (a TOML file, or a dict with the file's keys) and its scene.

    For a dict, relative paths (the scene, outputs, plugins) are relative to `base_dir`
    (default: the current folder).
    """
    if isinstance(config, Mapping):
        base = Path(base_dir) if base_dir is not None else Path.cwd()
        return Scene(_native.load_table(dict(config), str(base)))
    if base_dir is not None:
        raise ConfigError("base_dir applies to a config given as a dict, not to a file")
    return Scene(_native.load_path(os.fspath(config)))


def plugins() -> list:
    """The plugins on the search path (the package's own first), as `flowlight plugins`."""
    return _native.plugins()


def read_exr(path: PathLike) -> dict:
    """An EXR as `flowlight compare` reads it: rgb, layers, variance (or None), spp, metadata."""
    return _native.read_exr(os.fspath(path))


def _pixels(x: Any) -> Tuple[Any, Optional[Any]]:
    """An image argument as (H x W x 3 float32 array, its variance or None)."""
    import numpy as np

    if isinstance(x, Image):
        return x.rgb, None
    if isinstance(x, (str, os.PathLike)):
        r = read_exr(x)
        return r["rgb"], r["variance"]
    return np.ascontiguousarray(x, dtype=np.float32), None


def compare(
    a: ImageLike,
    b: Union[ImageLike, Tuple[ImageLike, ImageLike]],
    *,
    eps: float = 1e-2,
    spp: Optional[Tuple[float, float]] = None,
) -> dict:
    """Errors of image `a` against reference `b` (`flowlight compare`).

    Images are `Image`s, arrays or EXR paths. `b` may be a two-half reference `(b1, b2)`:
    its mean is the reference and the halves' difference estimates its variance (`spp` gives
    the halves' sample counts; equal by default), so the result holds the reference floor and
    `relmse_corrected` = relMSE less the floor. An EXR reference with a variance layer
    (`flowlight reference`) is floor-corrected too.
    """
    pa, _ = _pixels(a)
    if isinstance(b, tuple):
        b1, _ = _pixels(b[0])
        b2, _ = _pixels(b[1])
        na, nb = spp if spp is not None else (1.0, 1.0)
        pb, var = _native.combine_halves(b1, float(na), b2, float(nb))
    else:
        pb, var = _pixels(b)
    return _native.compare(pa, pb, var, eps)


def bench(
    suite: PathLike,
    *,
    out: Optional[PathLike] = None,
    budgets: Optional[Sequence[float]] = None,
    seeds: Optional[Sequence[int]] = None,
    threads: Optional[int] = None,
) -> dict:
    """Runs a benchmark suite (`flowlight bench`); returns {"summary": [rows], "files": [...]}."""
    return _native.bench(
        os.fspath(suite),
        out=os.fspath(out) if out is not None else None,
        budgets=list(budgets) if budgets is not None else None,
        seeds=list(seeds) if seeds is not None else None,
        threads=threads,
    )


def loads_so_far() -> int:
    """How many scenes this process has loaded."""
    return _native.loads_so_far()
