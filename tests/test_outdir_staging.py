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
from jaxgear._outdir import FOLDER_LOCK, OWNER_FILE, FolderInUse, OutputFolder, owner_alive

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
    """The files of ``folder`` but the lock of the run that holds it."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != FOLDER_LOCK}


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
def test_a_second_run_on_a_held_out_is_refused(tmp_path, monkeypatch, exchange):
    """Run A (another process) holds --out; run B on the same --out is refused at once,
    naming the folder and A's pid, and touches nothing: A's staging folder and the old
    result stay; then A swaps in its whole result, and no staging folder or lock file is
    left."""
    if not exchange:
        monkeypatch.setattr(_outdir, "_exchange", lambda a, b: False)
    out = _old_folder(tmp_path)
    proc, work_a = _start_holder(str(out), tmp_path)
    try:
        assert work_a.parent == tmp_path and str(proc.pid) in work_a.name
        assert owner_alive(work_a)
        with pytest.raises(FolderInUse, match=rf"--out='{out}' is in use by another jaxgear run \(pid {proc.pid}\)"):
            with OutputFolder(out, OWNED):
                pytest.fail("the second run got the folder")
        assert work_a.is_dir() and (work_a / "result.nc").read_text() == "A"
        assert _snapshot(out) == dict(_whole("old"), **{"attractors.png": b"old figure"})
    finally:
        _finish(proc)
    assert _snapshot(out) == _whole("A")  # A's whole result, the user's files carried over
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert not (out / OWNER_FILE).exists() and not (out / FOLDER_LOCK).exists()


def test_a_second_run_in_the_current_folder_is_refused(tmp_path, monkeypatch):
    """--out is the folder the runs stand in (files moved in one by one): the same lock."""
    out = _old_folder(tmp_path)
    proc, work_a = _start_holder(".", out)
    try:
        assert work_a.resolve().parent == out.resolve()
        monkeypatch.chdir(out)
        with pytest.raises(FolderInUse, match="in use by another jaxgear run"):
            with OutputFolder(".", OWNED):
                pytest.fail("the second run got the folder")
        assert work_a.is_dir() and (work_a / "result.nc").read_text() == "A"
    finally:
        _finish(proc)
    assert {k: v for k, v in _snapshot(out).items() if k != "attractors.png"} == _whole("A")
    assert not [p.name for p in out.iterdir() if p.name.startswith(".jaxgear")]


def test_a_second_run_in_one_process_is_refused(tmp_path):
    out = _old_folder(tmp_path)
    with OutputFolder(out, OWNED) as work_a:
        (work_a / "result.nc").write_text("A")
        (work_a / "summary.json").write_text("A")
        with pytest.raises(FolderInUse):
            with OutputFolder(out, OWNED):
                pytest.fail("the second run got the folder")
        assert _snapshot(out) == dict(_whole("old"), **{"attractors.png": b"old figure"})
    assert _snapshot(out) == _whole("A")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_killed_owner_frees_the_folder(tmp_path):
    """The lock goes with its process: after A is killed (SIGKILL, no clean-up) the next
    run takes the folder, removes A's staging folder and swaps in its own result."""
    out = _old_folder(tmp_path)
    proc, work_a = _start_holder(str(out), tmp_path)
    proc.kill()
    proc.communicate(timeout=60)
    assert work_a.is_dir() and (out / FOLDER_LOCK).exists()  # left behind, unlocked
    with OutputFolder(out, OWNED) as work:
        (work / "result.nc").write_text("B")
        (work / "summary.json").write_text("B")
    assert _snapshot(out) == _whole("B")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"] and not (out / FOLDER_LOCK).exists()


def test_clean_up_of_parts_happens_under_the_lock(tmp_path):
    """A half-written part of the run that holds --out (its temporary file in
    --out/parts) survives a second run's start, which is refused before any clean-up."""
    out = _old_folder(tmp_path)
    half = out / "parts" / ".jaxgear-tmp-value_00001.nc.x1"
    with OutputFolder(out, OWNED, create=True):
        half.write_text("half-written")
        with pytest.raises(FolderInUse):
            with OutputFolder(out, OWNED, create=True):
                pass
        assert half.read_text() == "half-written"
    with OutputFolder(out, OWNED, create=True):  # the next owner removes what a killed write left
        assert not half.exists()


def test_a_link_as_out_writes_into_its_target_and_stays_a_link(tmp_path):
    target = _old_folder(tmp_path)
    link = tmp_path / "link"
    link.symlink_to(target, target_is_directory=True)
    with OutputFolder(link, OWNED) as work:
        (work / "result.nc").write_text("new")
        (work / "summary.json").write_text("new")
    assert link.is_symlink() and link.resolve() == target.resolve()
    assert _snapshot(target) == _whole("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "out"]


@pytest.mark.parametrize("kind", ["loop", "dangling", "file", "loop above"])
def test_a_link_that_leads_nowhere_is_refused_before_any_work(tmp_path, kind):
    from jaxgear._outdir import check_output_folder

    link = tmp_path / "link"
    if kind in ("loop", "loop above"):
        (tmp_path / "other").symlink_to(link)
        link.symlink_to(tmp_path / "other")
    elif kind == "dangling":
        link.symlink_to(tmp_path / "missing")
    else:
        (tmp_path / "f").write_text("x")
        link.symlink_to(tmp_path / "f")
    given = link / "sub" if kind == "loop above" else link
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(ValueError, match={"loop": "a loop of symbolic links", "loop above": "a loop of symbolic links",
                                          "dangling": "which does not exist", "file": "which is not a folder"}[kind]):
        check_output_folder(given)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


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
