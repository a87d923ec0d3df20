"""Every notebook runs top to bottom on its reduced setting (FULL = False).

Key numbers are asserted inside the notebooks; a failing assert fails the test.
"""

import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK_DIR = Path(__file__).parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path, monkeypatch):
    nb = nbformat.read(path, as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "store notebooks without outputs"
    assert any("FULL = False" in c.source for c in nb.cells), "a FULL switch at the top selects the full size"
    # the kernel imports jaxgear from this source tree (not whichever copy is installed)
    root = str(Path(__file__).parent.parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    client = NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    client.execute()


def test_notebooks_match_their_paired_scripts():
    """Each notebook is paired with notebooks/<name>.py by jupytext (notebooks/jupytext.toml):
    both hold the same cells, so an edit to one without ``jupytext --sync`` fails here."""
    import jupytext

    scripts = sorted(NOTEBOOK_DIR.glob("*.py"))
    assert [p.stem for p in scripts] == [p.stem for p in NOTEBOOKS], "every notebook has a paired .py and vice versa"
    for path in NOTEBOOKS:
        stored, script = jupytext.read(path), jupytext.read(path.with_suffix(".py"))
        cells = lambda nb: [(c.cell_type, c.source) for c in nb.cells]
        assert cells(stored) == cells(script), f"{path.name} and {path.stem}.py differ: jupytext --sync {path.stem}.py"
