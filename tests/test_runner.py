"""The runner of the sweeps (issue 45): sweeps, maps and diagrams compute and return
results; :class:`jaxgear.Runner` alone owns their output folders, checkpoints, resume and
progress bars."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest

import jaxgear as jg
from jaxgear.sweep import _basins as basins_module

ROOT = Path(__file__).resolve().parent.parent
SWEEP_MODULES = ("_basins.py", "_basin_map.py", "_bifurcation.py", "_parameter_map.py")
DUFF = dict(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3)
FILE_MODULES = {"pathlib", "os", "shutil", "json", "tempfile", "io", "glob"}
"""Standard modules of file handling, which only the runner's modules import."""


def _file_handling(source: str) -> list[str]:
    """What in a module's ``source`` handles files or folders itself: imports of the
    modules of :data:`FILE_MODULES`, of the checkpoints or of :func:`jaxgear.load`,
    calls of ``open``/``Path``, and a parameter named like the runner's fields."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name.split(".")[0] in FILE_MODULES]
        elif isinstance(node, ast.ImportFrom):
            mod = "." * node.level + (node.module or "")
            if mod.split(".")[0] in FILE_MODULES or mod.endswith("_checkpoint"):
                found.append(f"from {mod} import ...")
            found += [f"from {mod} import {a.name}" for a in node.names
                      if a.name in ("Checkpoint", "open_shared_checkpoint", "checkpoint_on_zero", "shared_block",
                                    "progress_bar", "load", "atomic_write", "wait_for_parts")]
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("open", "Path"):
            found.append(f"{node.func.id}(...) at line {node.lineno}")
        elif isinstance(node, ast.arguments):
            found += [f"parameter {a.arg}" for a in (*node.args, *node.kwonlyargs) if a.arg in jg.sweep._runner.MOVED]
    return found


@pytest.mark.parametrize("name", SWEEP_MODULES)
def test_the_sweep_modules_hold_no_file_handling(name):
    source = (ROOT / "jaxgear" / "sweep" / name).read_text()
    assert _file_handling(source) == [], f"jaxgear/sweep/{name} handles files: leave them to jaxgear.Runner"


def test_the_file_check_finds_file_handling():
    planted = ("from pathlib import Path\nfrom ._checkpoint import checkpoint_on_zero\nfrom .._io import load\n"
               "def f(x, *, out=None):\n    with open(x) as fh:\n        return Path(fh.read())\n")
    assert set(_file_handling(planted)) == {"from pathlib import ...", "from ._checkpoint import ...",
                                            "from ._checkpoint import checkpoint_on_zero", "from .._io import load",
                                            "parameter out", "open(...) at line 5", "Path(...) at line 6"}


SWEEP_CALLS = {
    "basin_sweep": lambda **kw: jg.basin_sweep(jg.DUFFING, jg.DuffingParams(**DUFF, omega=1.3), "omega", [1.3, 1.4],
                                               **kw),
    "basin_map": lambda **kw: jg.basin_map(jg.DUFFING, jg.DuffingParams(**DUFF, omega=1.3), "omega", [1.3, 1.4],
                                           "gamma", [0.2, 0.3], **kw),
    "bifurcation_diagram": lambda **kw: jg.bifurcation_diagram(jg.DUFFING, jg.DuffingParams(**DUFF, omega=1.3),
                                                               "omega", [1.3, 1.4], [[0.0, 0.0]], **kw),
    "parameter_map": lambda **kw: jg.parameter_map(jg.DUFFING, jg.DuffingParams(**DUFF, omega=1.3), "omega",
                                                   [1.3, 1.4], "gamma", [0.2, 0.3], [[0.0, 0.0]], **kw),
}


@pytest.mark.parametrize("sweep", SWEEP_CALLS)
@pytest.mark.parametrize("old", [{"progress": False}, {"out": Path("run"), "restart": True}, {"save": False}])
def test_the_old_keywords_point_to_the_runner(sweep, old, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(TypeError) as exc:
        SWEEP_CALLS[sweep](**old)
    msg = str(exc.value)
    fields = ", ".join(f"{k}={str(v)!r}" if isinstance(v, Path) else f"{k}={v!r}" for k, v in old.items())
    assert msg.startswith(f"{sweep}() no longer takes {', '.join(k + '=' for k in old)}: "), msg
    assert f"runner=jg.Runner({fields})" in msg and f"jg.Runner({fields}).run(jg.{sweep}, ...)" in msg, msg
    assert list(tmp_path.iterdir()) == []  # refused before anything is written


@pytest.mark.parametrize("bad, name", [(dict(out=3), "out"), (dict(out=""), "out"), (dict(restart=1), "restart"),
                                       (dict(progress="no"), "progress"), (dict(save=None), "save")])
def test_the_runner_checks_its_fields(bad, name):
    with pytest.raises(ValueError, match=f"^{name}="):
        jg.Runner(**bad)
    with pytest.raises(ValueError, match="jaxgear.Runner"):
        SWEEP_CALLS["bifurcation_diagram"](runner={"out": "run"})


def test_a_runner_without_save_writes_only_the_parts_and_a_rerun_resumes(tmp_path, monkeypatch):
    """``Runner(out=..., save=False)`` leaves the parts and the manifest, no ``basins.nc``;
    the same sweep rerun with ``Runner(out=...)`` computes nothing and writes the file,
    equal to the first run's result."""
    p = jg.DuffingParams(**DUFF, omega=1.3)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (5, 5), names=("x", "v"))
    kw = dict(method=jg.Direct(integrator=jg.RK4(32), max_period=4), uncertainty=0)
    values = [1.30, 1.35, 1.40, 1.45]
    real, calls = basins_module._analyze_values, []

    def analyze(system, params_list, *a, **k):
        calls.extend(float(q.omega) for q in params_list)
        return real(system, params_list, *a, **k)

    monkeypatch.setattr(basins_module, "_analyze_values", analyze)
    runner = jg.Runner(out=tmp_path / "run", progress=False, save=False)
    first = runner.run(jg.basin_sweep, jg.DUFFING, p, "omega", values, grid, **kw)
    assert calls == values
    assert sorted(f.name for f in (tmp_path / "run").iterdir()) == ["manifest.json", "parts"]
    assert json.loads((tmp_path / "run" / "manifest.json").read_text())["kind"] == "basins"
    assert sorted(f.name for f in (tmp_path / "run" / "parts").glob("*.nc")) == [f"value_{i:05d}.nc" for i in range(4)]
    calls.clear()
    again = jg.basin_sweep(jg.DUFFING, p, "omega", values, grid, runner=jg.Runner(out=tmp_path / "run", progress=False),
                           **kw)
    assert calls == []  # every value read from its part
    assert (tmp_path / "run" / "basins.nc").is_file()
    loaded = jg.load(tmp_path / "run" / "basins.nc", expected="BasinSweep")
    for s in (again, loaded):
        np.testing.assert_array_equal(s.labels, first.labels)
        np.testing.assert_array_equal(s.shares, first.shares)


def test_a_runner_without_a_folder_writes_nothing(tmp_path, monkeypatch):
    """``Runner()``: the sweep computes and returns; no file or folder anywhere (the
    options of ``test_kill_and_resume_bifurcation``: its compiled programs)."""
    monkeypatch.chdir(tmp_path)
    d = jg.bifurcation_diagram(jg.DUFFING, jg.DuffingParams(**DUFF, omega=1.0), "omega", np.linspace(1.0, 1.6, 12),
                               [[0.0, 0.0], [2.0, 0.0]], runner=jg.Runner(progress=False), transient=30, record=17,
                               direction="independent", integrator=jg.RK4(32), max_period=8, chunk_size=8)
    assert d.points.shape[:3] == (1, 12, 2) and list(tmp_path.iterdir()) == []
