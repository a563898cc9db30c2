"""Every ```python example of docs/python.md runs, in order, in one interpreter started in the
repository's root (as a reader would paste them)."""

from __future__ import annotations

import re
import subprocess
import sys

from conftest import ROOT


def examples() -> list[str]:
    text = (ROOT / "docs" / "python.md").read_text()
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_the_python_examples_of_the_docs_run():
    blocks = examples()
    assert len(blocks) >= 5
    script = "\n".join(f"# example {i}\n{b}" for i, b in enumerate(blocks))
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "(512, 512, 3) float32" in out
    assert "unknown parameter 'path_depht' for plugin 'mcpt'" in out
    assert "mcpt" in out and "erpt" in out
    assert (ROOT / "target" / "cornell-box-py.exr").is_file()
