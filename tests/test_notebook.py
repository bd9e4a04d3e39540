"""The example notebook docs/example.ipynb runs from top to bottom (nbclient, the python3 kernel) and shows
what it says: a fit report as HTML tables, a hemisphere plot as PNG, a small fit whose saved directory reads back
to the same report - without writing anything into the repository's fits/."""

from __future__ import annotations

import os
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "docs" / "example.ipynb"


def _tree(root: Path) -> dict:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in root.rglob("*")}


def _outputs(nb, output_type=None):
    for cell in nb.cells:
        for out in cell.get("outputs", []):
            if output_type is None or out["output_type"] == output_type:
                yield cell, out


def test_example_notebook_executes(monkeypatch):
    nb = nbformat.read(NOTEBOOK, as_version=4)
    assert all(not cell.get("outputs") for cell in nb.cells if cell.cell_type == "code"), "committed with outputs"
    fits_before = _tree(ROOT / "fits")
    # the kernel inherits the environment: this checkout's clothlab, a headless matplotlib
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    client = NotebookClient(nb, timeout=120, kernel_name="python3",
                            resources={"metadata": {"path": str(ROOT / "docs")}})
    client.execute()  # raises CellExecutionError (with the traceback) if a cell fails
    assert _tree(ROOT / "fits") == fits_before, "the notebook wrote into fits/"

    html = [out["data"]["text/html"] for _, out in _outputs(nb) if "text/html" in out.get("data", {})]
    assert len(html) == 2  # the saved fit and the fresh one display as report tables
    assert all("<table>" in h and "Parameters" in h and "Coefficients" in h for h in html)
    assert "posterior median and 95 % interval" in html[0]
    assert "Gauss-Newton" in html[1]
    pngs = [out for _, out in _outputs(nb) if "image/png" in out.get("data", {})]
    assert len(pngs) == 1
    text = "".join(out.get("text", "") for _, out in _outputs(nb, "stream") if out["name"] == "stdout")
    assert "[[Parameters]]" in text and "[[Errors]]" in text and "cross-validated" in text
    assert "same report: True" in text
    assert "fit.json" in text and "predictions.csv" in text
