import contextlib
import functools
import logging
import os

# The suite is compile-bound (most of its CPU time is XLA compiling the many small programs
# the tests build once each), so the tests ask XLA for quick compiles: its older CPU
# emitters (about half the compile time of its default fusion emitters), and in the
# default run (`-m 'not slow'`) no LLVM optimisation of the emitted code either (a third
# less again). The code then runs pure-JAX integration several times slower (the older
# emitters 1.5x, without optimisation 4x to 30x), with the same results to round-off:
# right for the default run's short checks, wrong for the slow checks' long integrations
# and for users, so only the default run sets the second flag and only the tests the
# first. Set before JAX starts its backend (importing jaxgear starts none), and inherited
# by the commands the tests run. A choice already in XLA_FLAGS wins:
# `XLA_FLAGS=--xla_cpu_use_fusion_emitters=true python -m pytest` tests with XLA's defaults.
TEST_XLA_FLAGS = {"xla_cpu_use_fusion_emitters": "false"}
DEFAULT_RUN_XLA_FLAGS = {"xla_backend_optimization_level": "0"}


def pytest_configure(config):
    given = os.environ.get("XLA_FLAGS", "")
    if any(name in given for name in (*TEST_XLA_FLAGS, *DEFAULT_RUN_XLA_FLAGS)):
        return
    flags = dict(TEST_XLA_FLAGS)
    if (config.option.markexpr or "").strip() == "not slow":
        flags.update(DEFAULT_RUN_XLA_FLAGS)
    os.environ["XLA_FLAGS"] = " ".join([given, *(f"--{k}={v}" for k, v in flags.items())]).strip()


import jax  # noqa: E402
import pytest  # noqa: E402


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """How the tests are spread over the worker processes (``--dist loadgroup`` in
    ``addopts``): a file's tests stay on one worker, so its module fixtures are built once,
    except the tests marked ``spread`` (each notebook run, each slow documentation page:
    minutes each, sharing nothing), which go to whichever worker is free. Runs before
    pytest-xdist reads the groups."""
    for item in items:
        if item.get_closest_marker("spread") is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))

import jaxgear  # noqa: E402, F401  (enables float64 before any test builds arrays)
from jaxgear._cache import enable_compilation_cache  # noqa: E402


@pytest.fixture(autouse=True, scope="session")
def _strict_dtype_promotion():
    """Every test runs with strict dtype promotion: an implicit promotion between array dtypes
    (int32 with int64, float64 with an integer array, a float with a complex) raises instead
    of silently widening, so the engine's arithmetic stays float64 / int32 by construction
    (Python scalars are still weakly typed). Set for the whole session, so module fixtures
    and threads the code starts are covered too, and through ``JAX_NUMPY_DTYPE_PROMOTION``
    for the processes the tests start (the command line, the notebooks' kernels)."""
    old = jax.config.jax_numpy_dtype_promotion
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("JAX_NUMPY_DTYPE_PROMOTION", "strict")
        jax.config.update("jax_numpy_dtype_promotion", "strict")
        try:
            yield
        finally:
            jax.config.update("jax_numpy_dtype_promotion", old)


MAP_LIMIT = 30_000
"""Memory mappings of a test process above which JAX's caches are dropped after a test."""


def _mappings() -> int:
    try:
        with open("/proc/self/maps", "rb") as fh:
            return sum(1 for _ in fh)
    except OSError:  # not Linux: no such limit to guard
        return 0


@pytest.fixture(autouse=True)
def _bounded_mappings():
    """Keep a long-lived test process below the kernel's limit of memory mappings
    (``vm.max_map_count``, 65,530 by default). Every program XLA compiles for the CPU
    stays mapped (about three mappings each) while JAX's caches hold it, and a worker of
    the slow tier compiles tens of thousands: at the limit a mapping fails and XLA's
    compiler crashes the process (a segmentation fault, seen twice in 2026-12; pytest-xdist
    then waits for ever). Past :data:`MAP_LIMIT` the caches are cleared after the test
    (``jax.clear_caches``): later tests load their programs from the session's
    compilation cache instead of compiling them again."""
    yield
    if _mappings() > MAP_LIMIT:
        import gc

        jax.clear_caches()
        gc.collect()


_CACHE_SETTINGS = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
                   "jax_persistent_cache_min_entry_size_bytes")


@pytest.fixture(scope="session", autouse=True)
def jaxgear_cache_dir(tmp_path_factory):
    """One ``JAXGEAR_CACHE_DIR`` for the whole test session, shared by the xdist workers and
    apart from the user's own cache, with JAX's persistent compilation cache in it switched
    on in every worker (:func:`jaxgear._cache.enable_compilation_cache`, as the command
    line does): a computation that one worker, or a command a test runs, has compiled is
    loaded by the others instead of compiled again. The user's folder is never touched,
    as other programs on the machine may be writing it. (The compiled C++ kernel lives in
    the user's private kernel folder, built once per machine.)"""
    base = tmp_path_factory.getbasetemp()
    path = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "jaxgear-cache"
    path.mkdir(exist_ok=True)
    old = {name: getattr(jax.config, name) for name in _CACHE_SETTINGS}
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("JAXGEAR_CACHE_DIR", str(path))
        enable_compilation_cache()
        try:
            yield path
        finally:
            for name, value in old.items():
                jax.config.update(name, value)


@contextlib.contextmanager
def count_compilations(name: str):
    """Collect JAX's "Compiling <name> ..." log messages while the block runs (a list that
    grows as functions whose name contains ``name`` are compiled)."""
    found: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record):
            msg = record.getMessage()
            if msg.startswith("Compiling") and name in msg.split(" for ")[0].split(" with ")[0]:
                found.append(msg)

    handler = Collect(level=logging.DEBUG)
    logger = logging.getLogger("jax")
    logger.addHandler(handler)
    old = jax.config.jax_log_compiles
    jax.config.update("jax_log_compiles", True)
    try:
        yield found
    finally:
        jax.config.update("jax_log_compiles", old)
        logger.removeHandler(handler)


@pytest.fixture(scope="session")
def gear_reference():
    """:func:`reduced_model_reference`, for tests to call."""
    return reduced_model_reference


def reduced_model_reference(p, x0, periods: int, *, t0: float = 0.0, rtol: float = 1e-11, atol: float = 1e-11):
    """The reduced gear model (model document §4, sine mesh stiffness) integrated by scipy's
    DOP853 from ``x0`` (shape ``(4,)``) over ``periods`` forcing periods, an independent
    reference for jaxgear's integrators: written from the equations, not from jaxgear's code.

    The vector field only has kinks, on the four switching surfaces ``x1 = +-b_sp`` and
    ``X_rp = x3 - x1 - e_sp(t) - e_rp(t) = +-b_rp``. Between them each mesh force uses the
    smooth branch of its side (extended past the surface), every crossing is located as an
    event and the integration restarts there on the new branch, so the solver only ever
    integrates a smooth field and keeps its 8th order. Returns the state at
    ``t0 + periods * T``."""
    import numpy as np
    from scipy.integrate import solve_ivp

    q = {k: float(v) for k, v in p.to_dict().items() if k != "mesh_shape"}
    assert p.mesh_shape == "sine", p.mesh_shape
    W, N = q["Omega"], q["N"]
    b_sp, b_rp = q["b_sp"], q["b_rp"]

    def excitation(t):
        a_sp, a_rp = W * t + q["beta_sp"], W * t + q["beta_rp"] + q["gamma_sr"]
        return (q["kappa_sp_mean"] + q["kappa_sp_amp"] * np.sin(W * t + q["phi_sp"]),
                q["kappa_rp_mean"] + q["kappa_rp_amp"] * np.sin(W * t + q["phi_rp"]),
                q["e_sp_amp"] * np.sin(a_sp) + q["e_rp_amp"] * np.sin(a_rp),  # e_sp + e_rp
                q["e_sp_amp"] * W * np.cos(a_sp) + q["e_rp_amp"] * W * np.cos(a_rp),  # their rate
                -q["e_sp_amp"] * W * W * np.sin(a_sp))  # e_sp''

    def surfaces(t, x):
        """The four switching functions and their rates along the motion."""
        e, de = excitation(t)[2:4]
        X_rp, V_rp = x[2] - x[0] - e, x[3] - x[1] - de
        return (np.array([x[0] - b_sp, x[0] + b_sp, X_rp - b_rp, X_rp + b_rp]),
                np.array([x[1], x[1], V_rp, V_rp]))

    def field(t, x, side):
        k_sp, k_rp, e, de, dde_sp = excitation(t)
        X_rp, V_rp = x[2] - x[0] - e, x[3] - x[1] - de
        f_sp = x[0] - b_sp if side[0] > 0 else (x[0] + b_sp if side[1] < 0 else 0.0)
        f_rp = X_rp - b_rp if side[2] > 0 else (X_rp + b_rp if side[3] < 0 else 0.0)
        g_sp = k_sp * f_sp + q["c_sp"] * x[1]
        g_rp = k_rp * f_rp + q["c_rp"] * V_rp
        return [x[1],
                -(N + q["mu_p"]) * g_sp + (q["mu_p"] - N * q["mu_c"]) * g_rp + q["mu_s"] * q["f_D"]
                + q["mu_c"] * q["f_L"] - dde_sp,
                x[3],
                -N * (q["mu_s"] + 2 * q["mu_c"]) * g_sp - 2 * N * q["mu_c"] * g_rp + q["mu_s"] * q["f_D"]
                + 2 * q["mu_c"] * q["f_L"]]

    t, t_end = float(t0), float(t0) + periods * 2 * np.pi / W
    x = np.asarray(x0, dtype=float)
    s, ds = surfaces(t, x)
    side = np.where(s != 0, np.sign(s), np.sign(ds))
    for _ in range(10_000):  # switchings (a few per period)
        events = []
        for i in range(4):
            event = lambda t, x, i=i: surfaces(t, x)[0][i]  # noqa: E731
            event.terminal, event.direction = True, -side[i]  # the next crossing leaves side[i]
            events.append(event)
        piece = functools.partial(field, side=side)  # this stretch's branches (side is replaced, not changed)
        sol = solve_ivp(piece, (t, t_end), x, method="DOP853", rtol=rtol, atol=atol, events=events)
        assert sol.status in (0, 1), sol.message
        t, x = sol.t[-1], sol.y[:, -1]
        if sol.status == 0:
            return x
        side = side.copy()
        for i in range(4):
            if len(sol.t_events[i]):
                side[i] = -side[i]
    raise AssertionError(f"more than 10,000 switchings before t = {t_end}")
