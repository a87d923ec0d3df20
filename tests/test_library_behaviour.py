"""jaxgear behaves like a library: importing it sets float64 and nothing else global, an
analysis starts no Python threads or processes, and nothing in a cache folder is ever
unpickled or otherwise executed as Python.

Each check runs in a fresh interpreter (the state before the import is that of plain
``import jax``), so the tests see exactly what the package changes.
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _python(code: str, env=None, timeout=600) -> subprocess.CompletedProcess:
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *[p for p in sys.path if p]])
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=timeout)


IMPORT_SCRIPT = r'''
import gc, json, sys, threading, warnings
import jax
names = [n for n in dir(jax.config) if n.startswith("jax_")]
def config():
    out = {}
    for n in names:
        try:
            out[n] = repr(getattr(jax.config, n))
        except Exception:
            pass
    return out
before = dict(config=config(), threads=sorted(t.name for t in threading.enumerate()), gc=gc.isenabled(),
              filters=len(warnings.filters), hook=repr(sys.excepthook), frozen=gc.get_freeze_count())
import jaxgear
after = dict(config=config(), threads=sorted(t.name for t in threading.enumerate()), gc=gc.isenabled(),
             filters=len(warnings.filters), hook=repr(sys.excepthook), frozen=gc.get_freeze_count())
print(json.dumps(dict(before=before, after=after)))
'''


def test_import_sets_float64_and_nothing_else():
    r = _python(IMPORT_SCRIPT)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    before, after = out["before"], out["after"]
    changed = {k for k in before["config"] if before["config"][k] != after["config"].get(k)}
    assert changed == {"jax_enable_x64"}, changed
    for key in ("threads", "gc", "filters", "hook", "frozen"):
        assert before[key] == after[key], key


def test_import_starts_no_backend_so_a_multi_process_run_can_begin():
    """``jax.distributed.initialize`` must come before any JAX computation; a package whose
    import builds an array (a default option, a constant) makes every multi-process run
    fail. A one-process JAX program starts after ``import jaxgear``, and its analysis runs."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    r = _python(f"""
import jax, jaxgear
jax.config.update("jax_cpu_collectives_implementation", "gloo")
jax.distributed.initialize(coordinator_address="127.0.0.1:{port}", num_processes=1, process_id=0)
print(jax.process_count(), float(jax.numpy.sum(jax.numpy.ones(3))))
jax.distributed.shutdown()
""", timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["1", "3.0"]


class _Planted:
    """An object whose unpickling runs code: it writes ``marker`` (the attack a shared
    cache folder allows when a library unpickles from it)."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (Path(self.marker).write_text, ("executed",))


LINEAR_MODEL = """
import jax.numpy as jnp
import jaxgear as jg

def field(t, x, p):
    return jnp.stack([x[1], p["gamma"] * jnp.cos(p["omega"] * t) - p["delta"] * x[1] - x[0]])

SYSTEM = jg.ForcedSystem(field, period=lambda p: 2 * jnp.pi / p["omega"], state_names=("x", "v"), name="linear")
PARAMS = {"delta": 0.2, "gamma": 1.0, "omega": 1.3}
REGION = ((-3.0, 3.0), (-3.0, 3.0))
GRID = (4, 4)
"""


def test_an_analysis_executes_no_planted_pickle_and_starts_no_threads_or_processes(tmp_path):
    """Every file name a cache could hold computations under (the old ``kept/*.bin``,
    JAX's ``xla/`` entries, anything else) holds a pickle that writes a marker when
    loaded; a command run with that folder as its cache leaves no marker, and when it has
    finished the interpreter runs no thread but its main one and no child process. (The
    analysis is of a forced linear oscillator given as a model file: the cache is read
    the same way for any system, and a small system compiles in a fraction of the gear
    model's time.)"""
    cache, marker, model = tmp_path / "cache", tmp_path / "marker", tmp_path / "linear_model.py"
    payload = pickle.dumps(_Planted(marker))
    for rel in ("kept/a.bin", "kept/index.pkl", "xla/jit_run-0123456789abcdef", "analysis.pkl", "pool.bin"):
        (cache / rel).parent.mkdir(parents=True, exist_ok=True)
        (cache / rel).write_bytes(payload)
    model.write_text(LINEAR_MODEL)
    env = dict(os.environ, JAXGEAR_CACHE_DIR=str(cache))
    r = _python("import multiprocessing, threading\n"
                "from jaxgear.cli import main\n"
                f"rc = main(['analyze', '--system', {str(model) + ':SYSTEM'!r}, '--no-figures', '--quiet', "
                f"'--uncertainty-samples', '0', '--out', {str(tmp_path / 'out')!r}])\n"
                "print(rc, sorted(t.name for t in threading.enumerate()), len(multiprocessing.active_children()))",
                env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip().splitlines()[-1] == "0 ['MainThread'] 0"
    assert (tmp_path / "out" / "result.nc").exists()
    assert len(list((cache / "xla").iterdir())) > 1  # the run did use that folder as its cache
    assert not marker.exists()
