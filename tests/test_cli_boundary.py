"""The one error boundary of the command line (``jaxgear.cli.main``): Ctrl-C, a full disk,
a loop of links, memory exhausted (``MemoryError``, XLA's ``RESOURCE_EXHAUSTED``) each end
a command with one line and its exit status, the previous result in ``--out`` whole; one
run owns an ``--out`` at a time; a sweep's parts carry its settings.

The work of each command is replaced by a stand-in that fails as the real one would (the
writer raising ``OSError(ENOSPC)``, the analysis raising ``KeyboardInterrupt``), so every
test runs in a second or two.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from jaxgear.cli import main

ROOT = Path(__file__).resolve().parent.parent
PREVIOUS = {"result.nc": "previous result", "summary.json": "{}", "notes.txt": "the user's file"}


def _previous(out: Path) -> None:
    out.mkdir(parents=True)
    for name, text in PREVIOUS.items():
        (out / name).write_text(text)


def _unchanged(out: Path) -> None:
    """``out`` holds the previous result and nothing else: no staging folder, no lock."""
    assert {p.name: p.read_text() for p in out.iterdir()} == PREVIOUS
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(".jaxgear")] == []


def _run(argv, capsys) -> tuple[int, list[str], str]:
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    cap = capsys.readouterr()
    return rc, cap.err.strip().splitlines(), cap.out


def _fail_in_analysis(monkeypatch, exc):
    """``jaxgear analyze``'s analysis raises ``exc`` (after the header: the run holds --out)."""
    import jaxgear.analysis

    def fail(*a, **k):
        raise exc

    monkeypatch.setattr(jaxgear.analysis, "analyze_global", fail)


ANALYZE = ["analyze", "--grid", "3,3,3", "--quiet", "--no-figures", "--uncertainty-samples", "0"]


# ----------------------------------------------------------------- row 4: Ctrl-C
@pytest.mark.parametrize("command", ["analyze", "shoot", "sweep"])
def test_ctrl_c_is_one_line_and_status_130(command, tmp_path, capsys, monkeypatch):
    import jaxgear.analysis
    import jaxgear.shooting
    import jaxgear.sweep

    def stop(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr({"analyze": jaxgear.analysis, "shoot": jaxgear.shooting, "sweep": jaxgear.sweep}[command],
                        {"analyze": "analyze_global", "shoot": "find_periodic_orbits",
                         "sweep": "bifurcation_diagram"}[command], stop)
    out = tmp_path / "out"
    _previous(out)
    argv = {"analyze": ANALYZE, "shoot": ["shoot", "--from", "5,0,8,0", "--quiet"],
            "sweep": ["sweep", "--param", "b", "--values", "4:6:3", "--starts", "2", "--quiet"]}[command]
    rc, lines, _ = _run([*argv, "--out", str(out)], capsys)
    assert rc == 130
    assert lines == [f"jaxgear {command}: interrupted; "
                     + ("no value was finished; " if command == "sweep" else "") + "the previous result is unchanged"]
    _unchanged(out)


def test_ctrl_c_in_a_sweep_says_how_many_values_a_rerun_resumes_from(tmp_path, capsys, monkeypatch):
    """Two of three values of a basin sweep saved (tagged parts), then Ctrl-C."""
    import jaxgear.sweep
    from jaxgear.sweep._checkpoint import Checkpoint

    def two_then_stop(system, params, param, values, grid, *, runner, **kw):
        ck = Checkpoint(runner.out, "basins", {"kind": "basins", "values": list(values)}, runner.restart)
        for i in range(2):
            ck.path(f"value_{i:05d}.nc").write_text("a value")
        raise KeyboardInterrupt

    monkeypatch.setattr(jaxgear.sweep, "basin_sweep", two_then_stop)
    out = tmp_path / "S"
    rc, lines, _ = _run(["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "3,2,3",
                         "--quiet", "--no-figures", "--out", str(out)], capsys)
    assert rc == 130
    assert lines == ["jaxgear sweep: interrupted; the sweep resumes from 2 of 3 values (run the same command again)"]
    assert not (out / ".jaxgear-lock").exists()


def test_a_real_sigint_ends_the_console_command_with_one_line(tmp_path):
    """The ``jaxgear`` process itself (console()), stopped by SIGINT while it computes."""
    script = textwrap.dedent("""
        import signal, sys, time
        signal.signal(signal.SIGINT, signal.default_int_handler)  # also where the test runs with SIGINT ignored
        import jaxgear.analysis
        def slow(*a, **k):
            print("computing", flush=True)
            time.sleep(120)
        jaxgear.analysis.analyze_global = slow
        sys.argv = ["jaxgear", "analyze", "--grid", "3,3,3", "--quiet", "--out", sys.argv[1]]
        from jaxgear.cli import console
        console()
    """)
    out = tmp_path / "out"
    _previous(out)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    proc = subprocess.Popen([sys.executable, "-c", script, str(out)], env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:
        while "computing" not in proc.stdout.readline():
            assert proc.poll() is None, proc.stderr.read()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["jaxgear analyze: interrupted; the previous result is unchanged"], err
    _unchanged(out)


# ----------------------------------------------------------------- row 3: file errors
def _fail_writing(monkeypatch, make_error):
    """``jaxgear analyze``'s writer: writes part of result.nc into the staging folder, then
    raises ``make_error(path)``."""
    import jaxgear.cli.analyze as analyze_cli

    def write(args, system, params, grid, method, out, gear_set=None):
        tmp = out / ".jaxgear-tmp-result.nc.k3j9x0ab"  # as an atomic write names its temporary file
        tmp.write_text("half")
        raise make_error(tmp)

    monkeypatch.setattr(analyze_cli, "_analyze", write)


ERRORS = {
    "ENOSPC": (lambda p: OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(p)),
               "error: no space left on device (writing {out}/result.nc)"),
    "HDF5 ENOSPC": (lambda p: OSError(errno.ENOSPC, "Can't close file (file write failed: time = Sun Dec 6 2026\n, "
                                      f"filename = '{p}', file descriptor = 5, errno = 28, error message = 'No space "
                                      "left on device', buf = 0x5597e5361350, total write size = 2048)"),
                    "error: no space left on device (writing {out}/result.nc)"),
    "ELOOP": (lambda p: OSError(errno.ELOOP, os.strerror(errno.ELOOP), str(p)),
              "error: too many levels of symbolic links ({out}/result.nc)"),
    "EDQUOT": (lambda p: OSError(errno.EDQUOT, os.strerror(errno.EDQUOT), str(p)),
               "error: disk quota exceeded (writing {out}/result.nc)"),
}


@pytest.mark.parametrize("kind", list(ERRORS))
def test_a_file_error_is_one_line_and_the_previous_result_stays_whole(kind, tmp_path, capsys, monkeypatch):
    make, expected = ERRORS[kind]
    _fail_writing(monkeypatch, make)
    out = tmp_path / "out"
    _previous(out)
    rc, lines, _ = _run([*ANALYZE, "--out", str(out)], capsys)
    assert rc == 1
    assert lines == ["jaxgear analyze: " + expected.format(out=out)], lines
    _unchanged(out)


@pytest.mark.parametrize("exc, fragment", [
    (MemoryError(), "error: out of memory; ask for less work"),
    (RuntimeError("RESOURCE_EXHAUSTED: Out of memory allocating 256020811936 bytes.\nmore lines of XLA"),
     "error: out of memory on the device (XLA RESOURCE_EXHAUSTED: Out of memory allocating 256020811936 bytes.)"),
])
def test_memory_exhausted_is_one_line(exc, fragment, tmp_path, capsys, monkeypatch):
    _fail_in_analysis(monkeypatch, exc)
    out = tmp_path / "out"
    _previous(out)
    rc, lines, _ = _run([*ANALYZE, "--out", str(out)], capsys)
    assert rc == 1 and len(lines) == 1 and lines[0].startswith("jaxgear analyze: " + fragment), lines
    _unchanged(out)


def test_other_errors_keep_their_traceback(tmp_path, monkeypatch):
    """The boundary turns only the failures it names into a line: a bug stays a bug."""
    _fail_in_analysis(monkeypatch, RuntimeError("a bug"))
    with pytest.raises(RuntimeError, match="a bug"):
        main([*ANALYZE, "--out", str(tmp_path / "out")])


# ----------------------------------------------------------------- row 2: one owner per --out
@pytest.mark.parametrize("command", [
    ["sweep", "--param", "b", "--values", "4:6:3", "--starts", "2"],
    ["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "3,2,3"],
    ANALYZE,
    ["shoot", "--from", "5,0,8,0"],
])
def test_a_second_run_on_a_held_out_is_refused_before_work(command, tmp_path, capsys, monkeypatch):
    import jaxgear.analysis
    import jaxgear.shooting
    import jaxgear.sweep
    from jaxgear._outdir import OutputFolder

    def forbidden(*a, **k):
        raise AssertionError("the second run started working")

    for mod, names in ((jaxgear.analysis, ("analyze_global",)), (jaxgear.shooting, ("find_periodic_orbits",)),
                       (jaxgear.sweep, ("bifurcation_diagram", "basin_sweep"))):
        for n in names:
            monkeypatch.setattr(mod, n, forbidden)
    out = tmp_path / "D"
    out.mkdir()
    (out / "parts").mkdir()
    half = out / "parts" / ".jaxgear-tmp-value_00000.nc.x1"
    with OutputFolder(out, ("result.nc",), create=True):  # another run holds D (a second open file: flock)
        half.write_text("half")  # the holder's part being written
        rc, lines, stdout = _run([*command, "--quiet", "--out", str(out)], capsys)
        assert half.read_text() == "half"  # not removed by the refused run
    assert rc == 2 and stdout == ""
    assert lines == [f"jaxgear {command[0]}: error: --out='{out}' is in use by another jaxgear run (pid "
                     f"{os.getpid()}): wait for it to end, or give another folder."], lines


def test_a_link_as_out_keeps_the_link_and_fills_its_target(tmp_path, capsys, monkeypatch):
    import jaxgear.cli.analyze as analyze_cli

    def write(args, system, params, grid, method, out, gear_set=None):
        (out / "result.nc").write_text("new")
        return ["result.nc"]

    monkeypatch.setattr(analyze_cli, "_analyze", write)
    target = tmp_path / "target"
    _previous(target)
    link = tmp_path / "link"
    link.symlink_to(target, target_is_directory=True)
    rc, _, _ = _run([*ANALYZE, "--out", str(link)], capsys)
    assert rc == 0 and link.is_symlink() and link.resolve() == target.resolve()
    assert {p.name: p.read_text() for p in target.iterdir()} == {"result.nc": "new", "notes.txt": "the user's file"}


# ----------------------------------------------------------------- row 2: tagged parts
S1 = {"kind": "basins", "param": "b", "values": [4.0, 5.0, 6.0], "grid": {"counts": [4, 4, 4]}}
S2 = dict(S1, grid={"counts": [3, 3, 3]})


def test_a_part_of_other_settings_is_never_read_as_this_sweeps(tmp_path):
    """Sweep A (settings S1) saved a part; its manifest was then replaced by a sweep of S2
    (two runs at once): resuming S2 is refused naming the field in which the part's
    settings differ, and the part is never loaded as S2's."""
    from jaxgear.sweep._checkpoint import Checkpoint

    a = Checkpoint(tmp_path, "basins", S1)
    a.save("block_00000.npz", x=np.arange(3.0))
    (tmp_path / "manifest.json").write_text(json.dumps({"kind": "basins", "hash": Checkpoint(None, "basins", S2).key,
                                                        "settings": S2}))
    with pytest.raises(ValueError, match=r"differing: grid.counts: \[4, 4, 4\] saved vs \[3, 3, 3\] now") as exc:
        Checkpoint(tmp_path, "basins", S2)
    assert "block_00000.npz" in str(exc.value)
    b = Checkpoint(tmp_path, "basins", S2, restart=True)  # discarding it is the user's choice
    assert not b.has("block_00000.npz") and not (tmp_path / "parts" / "block_00000.npz").exists()
    resumed = Checkpoint(tmp_path, "basins", S1, restart=True)
    assert not resumed.has("block_00000.npz")


def test_parts_without_a_tag_of_these_settings_are_computed_again(tmp_path):
    from jaxgear.sweep._checkpoint import Checkpoint, saved_parts

    ck = Checkpoint(tmp_path, "basins", S1)
    ck.save("block_00000.npz", x=np.arange(3.0))
    ck.path("value_00001.nc").write_text("a result")
    (tmp_path / "parts" / "block_00002.npz").write_bytes((tmp_path / "parts" / "block_00000.npz").read_bytes())
    again = Checkpoint(tmp_path, "basins", S1)
    assert again.has("block_00000.npz") and again.has("value_00001.nc")
    np.testing.assert_array_equal(again.load("block_00000.npz")["x"], np.arange(3.0))
    assert not again.has("block_00002.npz")  # copied in without its tag: not trusted
    assert [p.name for p in saved_parts(tmp_path)] == ["block_00000.npz", "value_00001.nc"]
