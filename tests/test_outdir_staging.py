"""Runs that share one output folder: each run's staging folder survives the start-up
clean-up of the others until its own swap, the folder always holds one whole result, and
only staging folders whose owner process is gone are removed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jaxgear import _outdir
from jaxgear._outdir import OWNER_FILE, OutputFolder, owner_alive

ROOT = Path(__file__).resolve().parent.parent
OWNED = ("result.nc", "summary.json", "*.png")

# A run in another process: enters the output folder, writes its result, prints its
# staging folder and holds it until a line comes on stdin, then swaps it in.
HOLD = r"""
import sys
from jaxgear._outdir import OutputFolder
out, tag = sys.argv[1], sys.argv[2]
with OutputFolder(out, ("result.nc", "summary.json", "*.png")) as work:
    (work / "result.nc").write_text(tag)
    (work / "summary.json").write_text(tag)
    print(work, flush=True)
    sys.stdin.readline()
print("swapped", flush=True)
"""


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _old_folder(tmp_path) -> Path:
    out = tmp_path / "out"
    (out / "parts").mkdir(parents=True)
    (out / "result.nc").write_text("old")
    (out / "summary.json").write_text("old")
    (out / "attractors.png").write_text("old figure")  # neither new run draws it
    (out / "notes.txt").write_text("the user's file")
    (out / "parts" / "value_0.npz").write_text("resume part")
    return out


def _whole(tag: str) -> dict[str, bytes]:
    return {"result.nc": tag.encode(), "summary.json": tag.encode(), "notes.txt": b"the user's file",
            "parts/value_0.npz": b"resume part"}


def _start_holder(out: str, cwd: Path) -> tuple[subprocess.Popen, Path]:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    proc = subprocess.Popen([sys.executable, "-c", HOLD, out, "A"], cwd=cwd, env=env, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    line = proc.stdout.readline().strip()
    if not line:
        proc.kill()
        pytest.fail(f"the holding run did not start: {proc.communicate()[1]}")
    work = Path(line) if Path(line).is_absolute() else cwd / line
    return proc, work


def _finish(proc: subprocess.Popen) -> None:
    out, err = proc.communicate("\n", timeout=120)
    assert proc.returncode == 0 and out.strip() == "swapped", err


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two-renames"])
def test_two_runs_on_one_out_keep_each_others_staging(tmp_path, monkeypatch, exchange):
    """Run A (another process) holds its staging folder; run B starts on the same --out
    (its start-up clean-up runs), finishes and swaps: A's staging folder and files are
    still there, --out holds B's whole result; then A swaps: --out holds A's whole result
    and no staging folder or lock file is left."""
    if not exchange:
        monkeypatch.setattr(_outdir, "_exchange", lambda a, b: False)
    out = _old_folder(tmp_path)
    proc, work_a = _start_holder(str(out), tmp_path)
    try:
        assert work_a.parent == tmp_path and str(proc.pid) in work_a.name
        assert owner_alive(work_a)
        with OutputFolder(out, OWNED) as work_b:
            assert work_a.is_dir() and (work_a / "result.nc").read_text() == "A"  # survived B's start-up
            assert _snapshot(out) == dict(_whole("old"), **{"attractors.png": b"old figure"})
            (work_b / "result.nc").write_text("B")
            (work_b / "summary.json").write_text("B")
        assert _snapshot(out) == _whole("B")  # B's whole result, the old figure gone with the old run
        assert work_a.is_dir() and (work_a / "summary.json").read_text() == "A"  # survived B's swap
    finally:
        _finish(proc)
    assert _snapshot(out) == _whole("A")  # A's whole result (B's user files carried over)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert not (out / OWNER_FILE).exists()


def test_two_runs_in_the_current_folder_keep_each_others_staging(tmp_path, monkeypatch):
    """--out is the folder the runs stand in (files moved in one by one, staging inside
    --out): B's start-up clean-up of --out leaves A's staging folder."""
    out = _old_folder(tmp_path)
    proc, work_a = _start_holder(".", out)
    try:
        assert work_a.resolve().parent == out.resolve()
        monkeypatch.chdir(out)
        with OutputFolder(".", OWNED) as work_b:
            assert work_a.is_dir() and (work_a / "result.nc").read_text() == "A"
            (work_b / "result.nc").write_text("B")
            (work_b / "summary.json").write_text("B")
        assert work_a.is_dir() and (work_a / "result.nc").read_text() == "A"
        assert (out / "result.nc").read_text() == "B" and (out / "summary.json").read_text() == "B"
    finally:
        _finish(proc)
    assert {k: v for k, v in _snapshot(out).items() if k != "attractors.png"} == _whole("A")
    assert not [p.name for p in out.iterdir() if p.name.startswith(".jaxgear")]


def test_two_runs_in_one_process_keep_each_others_staging(tmp_path):
    out = _old_folder(tmp_path)
    with OutputFolder(out, OWNED) as work_a:
        (work_a / "result.nc").write_text("A")
        (work_a / "summary.json").write_text("A")
        with OutputFolder(out, OWNED) as work_b:
            assert work_a.is_dir() and (work_a / "result.nc").read_text() == "A"
            (work_b / "result.nc").write_text("B")
            (work_b / "summary.json").write_text("B")
        assert _snapshot(out) == _whole("B")
    assert _snapshot(out) == _whole("A")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_start_up_clean_up_removes_only_staging_folders_of_gone_runs(tmp_path):
    out = _old_folder(tmp_path)
    dead = _dead_pid()
    prefix = ".jaxgear-tmp-out.run-"
    gone_locked = tmp_path / f"{prefix}{dead}-aa"  # its lock file is free: its owner is gone
    gone_locked.mkdir()
    (gone_locked / OWNER_FILE).write_text(f"{dead}\n")
    gone_named = tmp_path / f"{prefix}{dead}-bb"  # no lock file, its pid is not alive
    gone_named.mkdir()
    reused = tmp_path / f"{prefix}{os.getpid()}-cc"  # a live pid, but the lock is free: a reused pid
    reused.mkdir()
    (reused / OWNER_FILE).write_text(f"{os.getpid()}\n")
    starting = tmp_path / f"{prefix}{os.getpid()}-dd"  # a live pid, no lock file yet: just made
    starting.mkdir()
    old_kind = tmp_path / f"{prefix}xyz"  # no pid, no lock (an earlier version's): no owner
    old_kind.mkdir()
    with OutputFolder(out, OWNED) as work:
        (work / "result.nc").write_text("new")
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted(["out", starting.name]), left
    assert not owner_alive(gone_locked.parent / "nonexistent-run")  # nothing there: no owner


def test_lock_of_a_running_owner_is_seen_from_another_process(tmp_path):
    """The lock decides where there is one: a folder whose lock file another process
    holds is alive whatever pid its name carries."""
    folder = tmp_path / f".jaxgear-tmp-out.run-{_dead_pid()}-ee"
    folder.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, os, sys; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
         "fcntl.flock(fd, fcntl.LOCK_EX); print('locked', flush=True); sys.stdin.readline()",
         str(folder / OWNER_FILE)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert owner_alive(folder)
    finally:
        holder.communicate("\n", timeout=60)
    assert not owner_alive(folder)
