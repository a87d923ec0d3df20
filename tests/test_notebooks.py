"""Every notebook runs top to bottom on its reduced setting (FULL = False).

Key numbers are asserted inside the notebooks; a failing assert fails the test.
"""

import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).parent.parent / "notebooks").glob("*.ipynb"))


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


def test_notebooks_match_their_sources():
    """Each notebook is built from notebooks/src/<name>.py (``python tools/make_notebook.py``)."""
    import importlib.util

    root = Path(__file__).parent.parent
    spec = importlib.util.spec_from_file_location("make_notebook", root / "tools" / "make_notebook.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for src in sorted((root / "notebooks" / "src").glob("*.py")):
        built = mod.notebook(src)
        stored = nbformat.read(root / "notebooks" / (src.stem + ".ipynb"), as_version=4)
        assert [c.source for c in built.cells] == [c.source for c in stored.cells], src.name
