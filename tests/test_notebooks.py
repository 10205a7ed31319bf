"""The tutorial notebooks execute top to bottom (nbclient, kernel python3) and are committed
without outputs."""

import os
import pathlib

import nbformat
import pytest

NOTEBOOKS = sorted((pathlib.Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))


def test_there_are_four_notebooks():
    assert [p.name[:2] for p in NOTEBOOKS] == ["01", "02", "03", "04"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_committed_notebook_has_no_outputs(path):
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, path.name


def _draws(cell) -> bool:
    """A code cell that makes a figure (and does not only save it to a file)."""
    src = cell.source
    return cell.cell_type == "code" and ("viz.plot_" in src or "plt." in src)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes(path, tmp_path, monkeypatch):
    from nbclient import NotebookClient

    # The kernel chooses Jupyter's inline backend unless MPLBACKEND says otherwise; it imports
    # this tree's fourierjax (it runs in tmp_path, and the environment may install another).
    monkeypatch.delenv("MPLBACKEND", raising=False)
    root = str(pathlib.Path(__file__).resolve().parent.parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError on the first failing cell
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
              if o.output_type == "error"]
    assert not errors
    # Every plotting cell shows its figure as an image (issue 25: viz forced Agg on import,
    # and the cells showed "<Figure size 640x810 with 6 Axes>" as text).
    drawing = [c for c in nb.cells if _draws(c)]
    assert drawing, path.name
    for c in drawing:
        kinds = {k for o in c.outputs for k in o.get("data", {})}
        assert "image/png" in kinds, (path.name, c.source[:80], kinds)
