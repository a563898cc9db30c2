#!/usr/bin/env bash
# Installs what the LuxCore side-by-side comparison (luxcore.py) needs: a virtual environment
# at $LUXCORE_VENV (default: <repo>/target/peers/luxcore-venv, ignored by git) with pyluxcore
# 2.11.2 from PyPI, pinned by version and sha256 (requirements-luxcore.txt, `pip install
# --require-hashes`). Then checks that it loads. Idempotent; needs Python 3.10-3.13 and PyPI.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../../.." && pwd)"
VENV="${LUXCORE_VENV:-$ROOT/target/peers/luxcore-venv}"
PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
    "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
    --require-hashes --only-binary=:all: -r "$HERE/requirements-luxcore.txt"
# (os._exit: pyluxcore 2.11's log callback crashes the interpreter's finalisation.)
"$VENV/bin/python" -c 'import os, sys, pyluxcore; pyluxcore.Init(lambda m: None); print("pyluxcore", pyluxcore.Version()); sys.stdout.flush(); os._exit(0)'
