"""Computations kept across commands (:mod:`jaxgear._kept`): a warm command loads the lane
pools and the section crossings instead of tracing them, and computes the same result."""

import os
import re
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import _kept
from jaxgear.analysis._pool import _options

ROOT = Path(__file__).resolve().parent.parent
KEPT = ("_run", "_crossings")  # the pools' rounds and the section crossings (the costly traces)


def _traced(stderr: str) -> set[str]:
    """Names of the functions JAX reports tracing (``JAX_LOG_COMPILES=1``)."""
    return set(re.findall(r"Finished tracing(?: \+ transforming)? (\S+) for", stderr))


def test_fingerprints_take_jaxgear_objects_and_refuse_user_code():
    """Built-in systems, integrators and options have a fingerprint, the same in another
    process; a system made of the user's functions, a closure or a foreign class has none
    (its computations must be traced: their source is not jaxgear's)."""
    m = jg.Direct()
    o = _options(5, 2000, m.max_period, m.period_tol, "auto", 1e6, m.merge_tol)
    mine = _kept.fingerprint((jg.REDUCED, m.integrator, o, 3))
    code = ("import jaxgear as jg; from jaxgear import _kept; from jaxgear.analysis._pool import _options; "
            "m = jg.Direct(); o = _options(5, 2000, m.max_period, m.period_tol, 'auto', 1e6, m.merge_tol); "
            "print(_kept.fingerprint((jg.REDUCED, m.integrator, o, 3)))")
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert other.stdout.strip() == mine
    assert _kept.fingerprint(jg.DUFFING) != _kept.fingerprint(jg.REDUCED)
    assert _kept.fingerprint(jg.RK4(64)) != _kept.fingerprint(jg.RK4(65))

    def field(t, x, p):
        return jnp.stack([x[1], -x[0]])

    user = jg.ForcedSystem(vector_field=field, period=lambda p: 2 * jnp.pi, state_names=("x", "v"))
    scale = 2.0
    for bad in (user, lambda x: x * scale, np.ones(3), object()):
        with pytest.raises(_kept.Unkeepable):
            _kept.fingerprint(bad)


@pytest.fixture(scope="module")
def two_commands(tmp_path_factory):
    """``jaxgear analyze`` on 720 cells run twice with one cache folder: the first command
    exports the pools and the section crossings, the second loads them."""
    tmp = tmp_path_factory.mktemp("kept")
    env = dict(os.environ, JAXGEAR_CACHE_DIR=str(tmp / "cache"), JAX_LOG_COMPILES="1", JAX_PLATFORMS="cpu")
    runs = []
    for i in (1, 2):
        out = tmp / f"run{i}"
        r = subprocess.run([sys.executable, "-m", "jaxgear", "analyze", "--grid", "10,6,12", "--uncertainty-samples",
                            "0", "--no-figures", "--quiet", "--out", str(out)], cwd=ROOT, env=env,
                           capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, r.stderr[-2000:]
        runs.append((jg.load(out / "result.nc"), r.stderr))
    return runs, tmp / "cache" / "kept"


def test_a_warm_command_loads_instead_of_tracing(two_commands):
    ((first, err1), (second, err2)), folder = two_commands
    kept = list(folder.glob("*.bin"))
    assert len(kept) >= 3  # the pool's start, its rounds, the section crossings
    assert {"_run", "_crossings"} <= _traced(err1)  # the first command traced them (the check can see it)
    assert not _traced(err2) & set(KEPT), _traced(err2)


def test_a_loaded_computation_gives_the_traced_one_s_result(two_commands):
    """Both commands, and the analysis in this process (nothing kept, plain ``jax.jit``),
    give the same labels and attractors, bit for bit."""
    ((first, _), (second, _)), _ = two_commands
    here = jg.analyze_global(jg.REDUCED, jg.paper_params(), jg.CellGrid.paper((10, 6, 12)), progress=False,
                             uncertainty=0)
    for r in (first, second):
        assert np.array_equal(np.asarray(r.labels), np.asarray(here.labels))
        assert len(r.attractors) == len(here.attractors)
        for a, b in zip(r.attractors, here.attractors):
            assert a.period == b.period and a.share == b.share
            np.testing.assert_array_equal(a.points, b.points)
            np.testing.assert_array_equal(a.section_points, b.section_points)


def test_a_broken_kept_file_is_replaced_not_used(tmp_path):
    """A kept file that cannot be read is removed and the computation exported again; the
    call still gives the jitted function's value."""

    @_kept.kept_jit(static_argnames=("k",))
    def scaled(x, k):
        return x * k + 1.0

    folder = _kept.enable(tmp_path)
    try:
        x = jnp.arange(4.0)
        scaled.prepare(x, k=3)
        files = list(folder.glob("*.bin"))
        assert len(files) == 1
        files[0].write_bytes(b"not a kept computation")
        again = _kept.kept_jit(static_argnames=("k",))(scaled.__wrapped__)
        again.prepare(x, k=3)
        assert files[0].read_bytes() != b"not a kept computation"
        assert np.array_equal(np.asarray(again(x, k=3)), np.asarray(x * 3 + 1.0))
        assert again._runners  # the call went through the kept computation
    finally:
        _kept.disable()
