"""Output files: whole or absent, never mixed; strict JSON; modes from the umask; resume
state that survives a truncated part; kills at random moments."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import jaxgear as jg
from jaxgear import _outdir
from jaxgear._outdir import OutputFolder

ROOT = Path(__file__).resolve().parent.parent


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _old_folder(tmp_path) -> Path:
    out = tmp_path / "out"
    (out / "parts").mkdir(parents=True)
    (out / "result.nc").write_text("old result")
    (out / "summary.json").write_text('{"old": true}')
    (out / "attractors.png").write_text("old figure")  # the new run draws no such figure
    (out / "notes.txt").write_text("the user's file")
    (out / "parts" / "value_0.npz").write_text("resume part")
    (out / ".jaxgear-tmp-result.nc.abc123").write_text("left by a killed write")
    return out


OWNED = ("result.nc", "summary.json", "*.png")


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two-renames"])
def test_output_folder_replaces_the_run_as_a_whole(tmp_path, monkeypatch, exchange):
    if not exchange:
        monkeypatch.setattr(_outdir, "_exchange", lambda a, b: False)
    out = _old_folder(tmp_path)
    with OutputFolder(out, OWNED) as work:
        assert _snapshot(out)["result.nc"] == b"old result"  # nothing changes while the run works
        (work / "result.nc").write_text("new result")
        (work / "summary.json").write_text('{"new": true}')
    snap = _snapshot(out)
    assert snap == {"result.nc": b"new result", "summary.json": b'{"new": true}', "notes.txt": b"the user's file",
                    "parts/value_0.npz": b"resume part"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging folder left


def test_output_folder_failed_run_leaves_the_previous_result(tmp_path):
    out = _old_folder(tmp_path)
    before = {k: v for k, v in _snapshot(out).items() if "jaxgear-tmp" not in k}
    with pytest.raises(RuntimeError):
        with OutputFolder(out, OWNED) as work:
            (work / "result.nc").write_text("half")
            raise RuntimeError("killed")
    assert _snapshot(out) == before  # the stale temporary file is gone, the rest untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_output_folder_undoes_an_interrupted_two_rename_swap(tmp_path):
    """A kill between the two renames of the fallback swap leaves the previous folder
    under a temporary name; the next run puts it back first."""
    out = _old_folder(tmp_path)
    before = {k: v for k, v in _snapshot(out).items() if "jaxgear-tmp" not in k}
    moved = tmp_path / ".jaxgear-tmp-out.run-xyz.old"
    os.rename(out, moved)
    staging = tmp_path / ".jaxgear-tmp-out.run-xyz"
    staging.mkdir()
    with pytest.raises(RuntimeError):
        with OutputFolder(out, OWNED):
            # (the run's lock file aside: it holds the folder while the run works)
            assert {k: v for k, v in _snapshot(out).items() if k != ".jaxgear-lock"} == before
            raise RuntimeError
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_output_folder_in_the_current_folder_replaces_files_in_place(tmp_path, monkeypatch):
    out = _old_folder(tmp_path)
    monkeypatch.chdir(out)
    with OutputFolder(".", OWNED) as work:
        (work / "result.nc").write_text("new")
    assert Path.cwd().samefile(out)  # the folder the user stands in is never moved
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "parts", "result.nc"]


def test_files_follow_the_umask_and_json_is_strict(tmp_path):
    old = os.umask(0o027)
    try:
        import xarray as xr

        from jaxgear._io import atomic_write, write_json

        ds_path = tmp_path / "o" / "x.nc"
        atomic_write(ds_path, lambda t: xr.Dataset({"a": ("i", np.arange(3.0))}).to_netcdf(
            t, engine="h5netcdf"))
        write_json({"a": float("nan"), "b": [1.0, float("inf")], "c": np.float64("nan")}, tmp_path / "s.json")
        with OutputFolder(tmp_path / "new", OWNED) as work:
            (work / "result.nc").write_text("x")
    finally:
        os.umask(old)
    assert ds_path.stat().st_mode & 0o777 == 0o640
    assert (tmp_path / "s.json").stat().st_mode & 0o777 == 0o640
    assert (tmp_path / "new").stat().st_mode & 0o777 == 0o750
    text = (tmp_path / "s.json").read_text()
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {"a": None, "b": [1.0, None], "c": None}


def test_resume_message_lists_only_what_differs(tmp_path):
    from jaxgear.sweep._checkpoint import Checkpoint

    settings = {"kind": "basins", "grid": {"counts": (3, 2, 3), "lower": (-1.0, 0.0, 1.0)}, "values": [1.0, 2.0]}
    Checkpoint(tmp_path, "basins", settings)
    with pytest.raises(ValueError, match="values") as exc:
        Checkpoint(tmp_path, "basins", dict(settings, values=[1.0, 3.0]))
    msg = str(exc.value)
    assert "values" in msg and "grid" not in msg, msg
    Checkpoint(tmp_path, "basins", dict(settings))  # the same settings (tuples read back as lists): resumes


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_truncated_part_is_recomputed(tmp_path, damage):
    from jaxgear.sweep._checkpoint import Checkpoint

    ck = Checkpoint(tmp_path, "basins", {"k": 1})
    ck.save("a.npz", x=np.arange(1000.0))
    part = ck.path("a.npz")
    data = part.read_bytes()
    part.write_bytes({"truncate": data[: len(data) // 2], "garbage": bytes(range(256)), "empty": b""}[damage])
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert ck.load("a.npz") is None and not part.exists()
    assert not [w for w in caught if issubclass(w.category, ResourceWarning)]  # the damaged part's file is closed
    nc = ck.path("b.nc")
    nc.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(64) if damage != "empty" else b"")
    assert ck.load_result("b.nc", jg.load) is None and not nc.exists()


def test_stroboscopic_method_sends_blown_up_settling_to_the_sink():
    """A saddle forced slightly off its equilibrium: the centre cell maps onto itself (a
    periodic group of the cell map), but its motion blows up while settling. It goes to
    the sink, like the other methods do, instead of failing."""
    import jax.numpy as jnp

    def saddle(t, x, p):
        return jnp.stack([x[1], x[0] + p["eps"] * jnp.cos(t)])

    system = jg.ForcedSystem(saddle, period=lambda p: 2 * jnp.pi, state_names=("x", "v"), name="saddle")
    grid = jg.CellGrid.box([(-1, 1), (-1, 1)], (5, 5), names=system.state_names)
    method = jg.StroboscopicCellMap(integrator=jg.RK4(20), settle_periods=150)
    with pytest.warns(UserWarning, match="sink"):
        r = jg.analyze_global(system, {"eps": 1e-6}, grid, method, progress=False, uncertainty=0)
    assert r.attractors == () or len(r.attractors) == 0
    assert np.all(r.labels == -1) and r.n_sink == 25


# ----------------------------------------------------------------- kill tests
def _state(out: Path, kind: str):
    """Which whole result ``out`` holds: ``None`` (none), or the grid/values it was run with."""
    # (a killed run leaves its lock file: the kernel released its lock, the next run takes it)
    files = sorted(p.name for p in out.iterdir() if p.is_file() and p.name not in ("manifest.json", ".jaxgear-lock")) \
        if out.exists() else []
    assert not [f for f in files if "jaxgear-tmp" in f], files
    if not files:
        return None
    if kind == "analyze":
        views = {f for f in files if f.startswith("gear_view_")}  # one per attractor, checked below
        files = sorted(set(files) - views)
        assert set(files) in ({"result.nc", "summary.json"},
                              {"result.nc", "summary.json", "domains.png", "shares.png", "domains_3d.png",
                               "attractors.png"}, {"result.nc", "summary.json", "domains.png", "shares.png",
                                                   "domains_3d.png"}), files
        r = jg.load(out / "result.nc")
        s = json.loads((out / "summary.json").read_text())
        counts = tuple(r.grid.counts)
        assert tuple(s["grid"]["counts"]) == counts
        assert views == {f"gear_view_{a['id']}.nc" for a in s["attractors"]}, (views, files)  # of this run only
        assert ("domains.png" in files) == (counts == (4, 2, 3)), (files, counts)  # the new run draws figures
        return counts
    assert set(files) in ({"bifurcation.nc", "summary.json"},), files
    d = jg.load(out / "bifurcation.nc")
    s = json.loads((out / "summary.json").read_text())
    assert len(s["values"]) == len(d.values)
    return len(d.values)


def _kill_runs(tmp_path, cache, old_cmd, new_cmd, kind, kills: int):
    """The old command runs to the end (twice: the second, with a warm compilation cache,
    times a whole run), then the new one is killed ``kills`` times at random moments of
    such a run; after each kill the folder holds the old result or the new one. Last, the
    new command runs to the end: the folder then holds the new result (a kill that only
    ever left the old one would pass otherwise)."""
    out = tmp_path / "out"
    env = dict(os.environ, JAXGEAR_CACHE_DIR=str(cache))
    assert subprocess.run(old_cmd(out), cwd=ROOT, capture_output=True, env=env, timeout=600).returncode == 0
    t = time.perf_counter()
    assert subprocess.run(old_cmd(out), cwd=ROOT, capture_output=True, env=env, timeout=600).returncode == 0
    span = 1.2 * (time.perf_counter() - t)
    old = _state(out, kind)
    rng = random.Random(1234)
    seen = set()
    for _ in range(kills):
        proc = subprocess.Popen(new_cmd(out), cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                env=env)
        time.sleep(rng.uniform(0.1, span))
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        state = _state(out, kind)
        seen.add(state)
        assert state in (old, _NEW[kind]), state
    assert old is not None and old != _NEW[kind]  # the two runs are told apart
    done = subprocess.run(new_cmd(out), cwd=ROOT, capture_output=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    assert _state(out, kind) == _NEW[kind]
    return seen


_NEW = {"analyze": (4, 2, 3), "sweep": 3}


KILLS = [pytest.param(1, id="one-kill"), pytest.param(3, marks=pytest.mark.slow, id="three-kills")]
"""Kills per test: one by default (each a whole command run), three behind the slow marker."""


@pytest.mark.slow
@pytest.mark.parametrize("kills", KILLS)
def test_analyze_killed_at_random_moments_leaves_a_whole_result(tmp_path, kills):
    def cmd(grid, figures):
        return lambda out: [sys.executable, "-m", "jaxgear", "analyze", "--grid", grid, "--steps-per-period", "40",
                            "--uncertainty-samples", "0", "--quiet", "--out", str(out)] + \
            ([] if figures else ["--no-figures"])

    # a cache of their own: a command killed while JAX writes a cache entry may leave it
    # half written, and no other test may read it (the kernel lives in its private folder)
    _kill_runs(tmp_path, tmp_path / "cache", cmd("3,2,3", False), cmd("4,2,3", True), "analyze", kills=kills)


@pytest.mark.slow
@pytest.mark.parametrize("kills", KILLS)
def test_sweep_killed_at_random_moments_leaves_a_whole_result(tmp_path, kills):
    # (slow: the default suite kills `jaxgear analyze` here, and interrupts sweeps in-process
    # in tests/test_sweep.py)
    def cmd(values, restart):
        return lambda out: [sys.executable, "-m", "jaxgear", "sweep", "--param", "b", "--values", values,
                            "--starts", "2", "--transient", "10", "--record", "33", "--steps-per-period", "30",
                            "--quiet", "--no-figures", "--out", str(out)] + (["--restart"] if restart else [])

    _kill_runs(tmp_path, tmp_path / "cache", cmd("4:6:2", False), cmd("4:6:3", True), "sweep", kills=kills)
