"""docs/notebooks/erpt-sweep.ipynb runs from top to bottom (nbclient, a fresh kernel of this
interpreter) and draws its figure, so the notebook cannot rot."""

from __future__ import annotations

import nbformat
from nbclient import NotebookClient

from conftest import ROOT


def test_the_erpt_sweep_notebook_runs_and_plots():
    path = ROOT / "docs" / "notebooks" / "erpt-sweep.ipynb"
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    printed = "".join(o.get("text", "") for o in outputs if o.get("output_type") == "stream")
    assert printed.count("efficiency") == 5, printed
    pngs = [o for o in outputs if "image/png" in o.get("data", {})]
    # The plot and the best image.
    assert len(pngs) == 2
