"""The figure painter of the command line: forked workers share the figures, report
errors, and end with their parent."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from jaxgear.cli._painter import Painter

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the workers are forked on Linux only")

ROOT = Path(__file__).resolve().parents[1]


def _prepare():
    pass


def _draw(result, folder, part=0, parts=1):
    """Writes one file per name of its share, with the process id that wrote it."""
    names = [f"{result}-{i}.txt" for i in range(5)][part::parts]
    for name in names:
        (Path(folder) / name).write_text(str(os.getpid()))
    return names


def _fail(result, folder, part=0, parts=1):
    if part == parts - 1:
        raise ValueError(f"no figure for {result}")
    return []


def _in_a_child(body: str, tmp_path) -> subprocess.CompletedProcess:
    """Run ``body`` in a fresh interpreter (the painter forks before JAX starts)."""
    script = f"import sys\nsys.path.insert(0, {str(ROOT / 'tests')!r})\n" + textwrap.dedent(body)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", script, str(tmp_path)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=120)


def test_two_workers_share_the_figures_and_return_every_name(tmp_path):
    r = _in_a_child("""
        from test_painter import _draw, _prepare
        from jaxgear.cli._painter import Painter
        with Painter(_prepare, _draw, workers=2) as p:
            assert p.forked and p.workers == 2
            p.submit("fig", sys.argv[1])
            print(" ".join(p.names()))
    """, tmp_path)
    assert r.returncode == 0, r.stderr
    names = r.stdout.split()
    assert sorted(names) == [f"fig-{i}.txt" for i in range(5)]
    writers = {(tmp_path / n).read_text() for n in names}
    assert len(writers) == 2 and str(os.getpid()) not in writers  # two processes drew, neither this one


def test_a_failing_share_is_reported(tmp_path):
    r = _in_a_child("""
        from test_painter import _fail, _prepare
        from jaxgear.cli._painter import Painter
        with Painter(_prepare, _fail, workers=2) as p:
            p.submit("fig", sys.argv[1])
            try:
                p.names()
            except RuntimeError as e:
                print("raised:", e)
    """, tmp_path)
    assert r.returncode == 0, r.stderr
    assert "raised: drawing the figures failed" in r.stdout and "no figure for fig" in r.stdout


def test_workers_end_with_their_parent(tmp_path):
    """A parent killed before it hands over a result leaves no worker behind."""
    script = f"import sys, time\nsys.path.insert(0, {str(ROOT / 'tests')!r})\n" + textwrap.dedent("""
        from test_painter import _draw, _prepare
        from jaxgear.cli._painter import Painter
        import os
        p = Painter(_prepare, _draw, workers=2)
        time.sleep(1.0)  # the first worker has forked the second by now
        print(" ".join(str(c) for c in _children(os.getpid())), flush=True)
        time.sleep(60)
    """).replace("_children(", "__import__('test_painter')._descendants(")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True) as proc:
        workers = [int(x) for x in proc.stdout.readline().split()]
        os.kill(proc.pid, signal.SIGKILL)  # the with block closes its pipe (no unclosed-file warning later)
    assert len(workers) == 2
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and any(_alive(w) for w in workers):
        time.sleep(0.1)
    assert not any(_alive(w) for w in workers)


def test_on_a_thread_when_no_fork(tmp_path, monkeypatch):
    """Where JAX already runs (this test process), one thread draws every figure."""
    import jax.numpy as jnp

    jnp.zeros(1).block_until_ready()  # the runtime has started: no fork
    with Painter(_prepare, _draw, workers=2) as p:
        assert not p.forked and p.workers == 1
        p.submit("fig", tmp_path)
        assert sorted(p.names()) == [f"fig-{i}.txt" for i in range(5)]


def _descendants(pid: int) -> list[int]:
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        try:
            kids = Path(f"/proc/{p}/task/{p}/children").read_text().split()
        except OSError:
            kids = []
        out += [int(k) for k in kids]
        todo += [int(k) for k in kids]
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split()[2]
    except OSError:
        return False
    return state != "Z"
