"""The example notebook (examples/api.ipynb) runs from top to bottom in a Jupyter kernel
(nbclient) and shows the hemidisk's headline, its fields and its figure."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "api.ipynb"


def test_the_example_notebook_runs(tmp_path) -> None:
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    src = str(Path(__file__).resolve().parents[1] / "src")  # this tree's brainbulge
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [src, *filter(None, [os.environ.get("PYTHONPATH")])])
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    headline = nb.cells[1].outputs[-1]["data"]["text/plain"]
    assert headline.startswith("(0.1") and headline.endswith("True)")  # max |u| ~0.16 R
    assert any("image/png" in o.get("data", {}) for o in nb.cells[3].outputs)
