"""examples/notebooks/workflow.ipynb runs from top to bottom in a fresh Jupyter kernel
(nbclient), and is committed without outputs."""

from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[2] / "examples" / "notebooks" / "workflow.ipynb"


def _text(cell):
    return "".join(o.get("text", "") for o in cell.get("outputs", [])
                   if o["output_type"] == "stream")


def test_notebook_is_committed_without_outputs():
    nbformat = pytest.importorskip("nbformat", reason="in the test extra: pip install '.[test]'")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(not c.outputs and c.execution_count is None for c in code)


def test_workflow_notebook_runs(tmp_path, monkeypatch):
    nbformat = pytest.importorskip("nbformat", reason="in the test extra: pip install '.[test]'")
    nbclient = pytest.importorskip("nbclient", reason="in the test extra: pip install '.[test]'")
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("TMPDIR", str(tmp_path))      # the notebook's temporary files go here
    # figures inline, as in Jupyter, whatever backend the tests run with (MPLBACKEND=Agg)
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()                          # raises CellExecutionError on any failing cell
    outputs = "\n".join(_text(c) for c in nb.cells if c.cell_type == "code")
    assert "H (2048, 32, 32) (time, x, y)" in outputs
    assert "full field (61, 32, 32), training field (54, 16, 16)" in outputs
    for name in ("interp", "siren_torch"):
        assert f"{name:12s} NMSE on held-out pixels" in outputs
    for name in ("true (all samples)", "raw (training samples)", "interp", "siren_torch"):
        assert f"{name:24s} SSIM " in outputs
    assert "interp held-out pixels" in outputs and "in both" in outputs
    figures = [o for c in nb.cells for o in c.get("outputs", [])
               if o["output_type"] == "display_data" and "image/png" in o.get("data", {})]
    assert len(figures) == 1
