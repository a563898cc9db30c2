"""Shared fixtures of the Python package's tests (`.ci/run` builds the wheel with the dev
profile, installs it into target/py-venv and runs pytest there).

- `root`: the repository;
- `cli`: the `flowlight` executable the workspace build made (FLOWLIGHT_CLI, else
  target/debug/flowlight), for the comparisons with the command line;
- `wheel`: the wheel built for the tests (FLOWLIGHT_WHEEL, else the newest in
  target/py-wheel/).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORNELL = ROOT / "scenes" / "cornell-box" / "cornell-box.toml"


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def cli() -> Path:
    exe = Path(os.environ.get("FLOWLIGHT_CLI", ROOT / "target" / "debug" / "flowlight"))
    if not exe.is_file():
        pytest.fail(f"{exe}: the flowlight executable is missing (cargo build --workspace)")
    return exe


@pytest.fixture(scope="session")
def wheel() -> Path:
    given = os.environ.get("FLOWLIGHT_WHEEL")
    if given:
        return Path(given)
    wheels = sorted((ROOT / "target" / "py-wheel").glob("flowlight-*.whl"), key=lambda p: p.stat().st_mtime)
    if not wheels:
        pytest.fail("no wheel in target/py-wheel (build it as .ci/run does)")
    return wheels[-1]


def run_cli(cli: Path, *args: str) -> subprocess.CompletedProcess:
    """The command line with `args`, its output captured."""
    return subprocess.run([str(cli), *args], capture_output=True, text=True, cwd=ROOT)


def cli_error(proc: subprocess.CompletedProcess) -> str:
    """The one-line message of a failed command (`error: MESSAGE` on stderr)."""
    assert proc.returncode != 0, proc.stdout
    lines = [l for l in proc.stderr.splitlines() if l.startswith("error: ")]
    assert len(lines) == 1, proc.stderr
    return lines[0][len("error: "):]
