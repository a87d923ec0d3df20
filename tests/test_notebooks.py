"""The notebooks: each runs top to bottom on its reduced setting (FULL = False), writes
nothing into the repository, and matches its paired script. The runs are ``slow``, every
one of them: ``python -m pytest -m slow tests/test_notebooks.py``; the default suite checks
the pairing and where each writes.

Key numbers are asserted inside the notebooks; a failing assert fails the test. Each
notebooks/<name>.ipynb (stored without outputs) is paired by jupytext with
notebooks/<name>.py (percent format, notebooks/jupytext.toml); files a notebook writes go
to its SCRATCH folder (``$JAXGEAR_SCRATCH``, else a new temporary folder).
"""

import ast
import os
import shutil
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).parent.parent
NOTEBOOK_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
IDS = [p.stem for p in NOTEBOOKS]
RUNS = [pytest.param(p, id=p.stem, marks=[pytest.mark.slow, pytest.mark.spread]) for p in NOTEBOOKS]
"""Every notebook runs in ``pytest -m slow``: each takes a minute or more on the 2-core CI
machine even at its reduced size, and its asserts are checks that no other test makes, so
none is left out."""


def _listing(folder: Path) -> set[Path]:
    return {p.relative_to(folder) for p in folder.rglob("*")}


def _execute(path: Path, tmp: Path) -> dict:
    """Run the notebook as a user who opens it would: the kernel works in notebooks/,
    ``JAXGEAR_SCRATCH`` is unset and jaxgear is imported from this source tree, with strict
    dtype promotion (``JAX_NUMPY_DTYPE_PROMOTION=strict``) as in every test. Temporary
    folders (the default SCRATCH) go under ``tmp``. Anything new under notebooks/ is
    recorded and removed again."""
    nb = nbformat.read(path, as_version=4)
    before = _listing(NOTEBOOK_DIR)
    error = None
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
        mp.delenv("JAXGEAR_SCRATCH", raising=False)
        mp.setenv("JAX_NUMPY_DTYPE_PROMOTION", "strict")  # as every test (tests/conftest.py)
        mp.setenv("TMPDIR", str(tmp))
        client = NotebookClient(nb, timeout=600, kernel_name="python3",
                                resources={"metadata": {"path": str(NOTEBOOK_DIR)}})
        try:
            client.execute()
        except Exception as e:  # reported by test_notebook_runs
            error = e
        finally:
            new = sorted(_listing(NOTEBOOK_DIR) - before)
            for rel in new:  # leave the repository as it was
                target = NOTEBOOK_DIR / rel
                if target.is_dir() and not target.is_symlink():
                    shutil.rmtree(target, ignore_errors=True)
                else:
                    target.unlink(missing_ok=True)
    return {"error": error, "new": new, "scratch": sorted(tmp.glob("jaxgear-*/*"))}


@pytest.mark.parametrize("path", RUNS)
def test_notebook_runs_and_leaves_the_repository_clean(path, tmp_path):
    """Each notebook runs top to bottom (its asserts hold) and, run from notebooks/ without
    ``JAXGEAR_SCRATCH``, writes nothing there (one test, so that a notebook runs once even
    when the tests are spread over several processes)."""
    nb = nbformat.read(path, as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "store notebooks without outputs"
    assert any("FULL = False" in c.source for c in nb.cells), "a FULL switch at the top selects the full size"
    run = _execute(path, tmp_path)
    assert not run["new"], f"{path.name} wrote into notebooks/: {[str(p) for p in run['new']]}"
    if run["error"] is not None:
        raise run["error"]
    if _writes(_code(path)):
        assert run["scratch"], f"{path.name} writes files but none arrived in its temporary SCRATCH folder"


# -- static check: every write goes under SCRATCH -------------------------------------------

WRITE_METHODS = {"save", "savefig", "savez", "savez_compressed", "to_netcdf", "to_csv", "to_json"}
PATH_METHODS = {"write_text", "write_bytes", "touch", "mkdir"}  # the path is the receiver


def _code(path: Path) -> list[str]:
    return [c.source for c in nbformat.read(path, as_version=4).cells if c.cell_type == "code"]


def _writes(cells: list[str]) -> list[tuple[str, ast.expr | None]]:
    """Every place the code writes a file: (what, the path expression or None if none given)."""
    found = []
    for node in ast.walk(ast.parse("\n".join(cells))):
        if not isinstance(node, ast.Call):
            continue
        func, kw = node.func, {k.arg: k.value for k in node.keywords}
        name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
        if name in WRITE_METHODS:
            arg = node.args[0] if node.args else kw.get("path", kw.get("fname", kw.get("file")))
            found.append((f"{name}(", arg))
        elif name in PATH_METHODS and isinstance(func, ast.Attribute):
            found.append((f".{name}(", func.value))
        elif name == "open" and node.args:
            mode = node.args[1] if len(node.args) > 1 else kw.get("mode")
            if isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+"):
                found.append(("open(", node.args[0]))
        if "out" in kw:
            found.append(("out=", kw["out"]))
    return found


def _under_scratch(cells: list[str]) -> set[str]:
    """SCRATCH and every name assigned from an expression that uses it (or such a name)."""
    tree = ast.parse("\n".join(cells))
    names, changed = {"SCRATCH"}, True
    while changed:
        changed = False
        for node in ast.walk(tree):
            if isinstance(node, (ast.Assign, ast.AnnAssign, ast.NamedExpr)) and node.value is not None:
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                if _uses(node.value, names):
                    new = {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)} - names
                    names |= new
                    changed |= bool(new)
    return names


def _uses(expr: ast.expr | None, names: set[str]) -> bool:
    return expr is not None and any(isinstance(n, ast.Name) and n.id in names for n in ast.walk(expr))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_notebook_writes_only_under_scratch(path):
    """Every ``.save(``, ``savefig(``, ``out=`` (and file ``open``/``write_text``) targets
    SCRATCH, which comes from ``$JAXGEAR_SCRATCH`` or a new temporary folder, set in the
    first code cell and announced in the markdown."""
    cells = _code(path)
    writes = _writes(cells)
    if not writes:
        return
    scratch = _under_scratch(cells)
    outside = [f"{what}{ast.unparse(arg) if arg is not None else ''}{')' if what.endswith('(') else ''}"
               for what, arg in writes if not _uses(arg, scratch)]
    assert not outside, f"{path.name} writes outside SCRATCH: {outside}"
    first = ast.parse(cells[0])
    defined = [n.value for n in ast.walk(first) if isinstance(n, ast.Assign)
               and any(isinstance(t, ast.Name) and t.id == "SCRATCH" for t in n.targets)]
    assert defined, f"{path.name}: define SCRATCH in the first code cell"
    text = ast.unparse(defined[0])
    assert "JAXGEAR_SCRATCH" in text and "mkdtemp" in text, f"{path.name}: SCRATCH = $JAXGEAR_SCRATCH or mkdtemp()"
    markdown = [c.source for c in nbformat.read(path, as_version=4).cells if c.cell_type == "markdown"]
    assert any("JAXGEAR_SCRATCH" in m for m in markdown), f"{path.name}: say in the markdown where files go"


# -- pairing ---------------------------------------------------------------------------------


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
