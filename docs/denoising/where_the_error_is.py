"""Where the denoised Cornell box's error is: the relMSE of the `denoised` layer of a
`flowlight render --denoise` EXR against the committed reference, split into the pixels
within 4 of the lamp (reference luminance > 5) and the rest (docs/denoising.md, "The
target"). Needs the `flowlight` Python package (README, "Python").

    python docs/denoising/where_the_error_is.py c16.exr
"""

import sys
from pathlib import Path

import numpy as np

import flowlight

REFERENCE = Path(__file__).resolve().parents[2] / "scenes/cornell-box/reference/cornell-box.exr"
EPSILON = 1e-2  # flowlight compare's


def main(path: str) -> None:
    img = flowlight.read_exr(path)
    ref = flowlight.read_exr(REFERENCE)["rgb"]
    lamp = ref.mean(axis=2) > 5.0
    ys, xs = np.nonzero(lamp)
    near = np.zeros_like(lamp)
    near[max(ys.min() - 4, 0) : ys.max() + 5, max(xs.min() - 4, 0) : xs.max() + 5] = True
    for name, layer in (("beauty", img["rgb"]), ("denoised", img["layers"].get("denoised"))):
        if layer is None:
            continue
        err = ((layer - ref) ** 2 / (ref**2 + EPSILON)).mean(axis=2)
        total = err.mean()
        print(
            f"{name:9s} relMSE {total:.3e}: around the lamp ({near.sum()} px) {err[near].sum() / err.size:.3e}"
            f" ({err[near].sum() / err.sum():.0%}), the other pixels {err[~near].sum() / err.size:.3e}"
        )


if __name__ == "__main__":
    main(sys.argv[1])
