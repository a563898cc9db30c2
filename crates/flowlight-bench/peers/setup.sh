#!/usr/bin/env bash
# Installs what the Mitsuba 3 side-by-side comparison (peers.py) needs:
#   - Debian's libllvm19 (apt-get), the LLVM that Dr.Jit's `llvm_*` variants JIT-compile with;
#   - a virtual environment at $PEERS_VENV (default: <repo>/target/peers/venv, ignored by git)
#     with Mitsuba 3.9.1 and Dr.Jit 1.5.0 from PyPI, pinned by version and sha256
#     (requirements.txt, `pip install --require-hashes`);
#   - <venv>/llvm.env, which exports DRJIT_LIBLLVM_PATH for peers.py (it sources nothing itself:
#     peers.py reads the path from this file).
# Then checks that the `scalar_rgb` and `llvm_ad_rgb` variants load and render a tiny scene.
# Idempotent; needs root (or sudo) for apt-get, Python 3.11-3.13 and the package registries.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
VENV="${PEERS_VENV:-$ROOT/target/peers/venv}"
PY="${PYTHON:-python3}"

SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
if ! dpkg -s libllvm19 >/dev/null 2>&1; then
    $SUDO apt-get update
    $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends libllvm19
fi
LIBLLVM="$(dpkg -L libllvm19 | grep -E '/libLLVM(-19)?\.so(\.[0-9.]+)?$' | head -n1)"
if [ -z "$LIBLLVM" ] || [ ! -e "$LIBLLVM" ]; then
    echo "error: libllvm19 is installed but no libLLVM .so was found in its file list" >&2
    exit 1
fi

if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
    --require-hashes --only-binary=:all: -r "$HERE/requirements.txt"
echo "export DRJIT_LIBLLVM_PATH=$LIBLLVM" > "$VENV/llvm.env"

# Smoke test: both variants render a 4x4 image of a lit sphere (non-zero mean).
DRJIT_LIBLLVM_PATH="$LIBLLVM" "$VENV/bin/python" - <<'PYEOF'
import drjit as dr
import mitsuba as mi
for variant in ("scalar_rgb", "llvm_ad_rgb"):
    mi.set_variant(variant)
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 4, "height": 4},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "sphere": {"type": "sphere", "bsdf": {"type": "diffuse"}},
        "light": {"type": "constant"},
    })
    img = mi.render(scene)
    mean = float(dr.mean(img.array)[0]) if hasattr(dr.mean(img.array), "__len__") else float(dr.mean(img.array))
    assert mean > 0, f"{variant}: black test image"
    print(f"peers setup: mitsuba {mi.__version__} {variant} ok (test image mean {mean:.4f})")
PYEOF
echo "peers setup: venv $VENV, DRJIT_LIBLLVM_PATH=$LIBLLVM"
