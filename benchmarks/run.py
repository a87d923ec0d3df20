"""Benchmark suite of jaxgear: plain script, figures printed, nothing asserted.

    python benchmarks/run.py            # full run (~20 min on 2 cores)
    python benchmarks/run.py --quick    # ~5 min (no cell-label agreement, n <= 400, fewer sizes)
    python benchmarks/run.py --json out.json
    python benchmarks/run.py --kink-jax # item 1b alone (~3 min)

Measures, in one run on one machine (compile time reported apart from execution:
``compile = first call - steady state``, ``steady state = min(timeit.repeat(...))``):

1. the kernel: the stroboscopic map of the 90,000 paper-grid cell centres (region D of
   paper eq. 10, 50 x 30 x 60 cells on x4 = 0) over one forcing period, 200 steps per
   period, float64, with the default integrator ``jaxgear.KinkAwareRK4(200)`` (the
   compiled CPU kernel), its pure-JAX path, plain ``jaxgear.RK4(200)``, and the numba
   baselines of ``benchmarks/baselines.py`` written for the benchmark (blocked,
   tabulated, vectorised: plain RK4 and kink-aware); the *kernel ratio* = default
   integrator / numba kink-aware;
1b. the pure-JAX kink-aware step (what a GPU and every derivative run) against pure-JAX
   plain RK4 on the paper grid (CPU time, one process), the fraction of steps that cross
   a switching surface, HLO operation/fusion counts of one step and its compile time, the
   first-call time of a shooting solve and of a 20,000-lane advance, and user systems
   (Duffing, spur pair with and without declared surfaces);
2. other CPU styles of the same map: numba naive per-cell, ``scipy.integrate.solve_ivp``
   (RK45) in a Python loop, diffrax Tsit5 vmapped;
3. the whole job: ``jaxgear analyze`` (the command line, a fresh process: cold with an
   empty compilation cache, then warm: the median of three runs), with and without
   figures, and the in-process
   ``jaxgear.analyze_global()``; wall time, CPU utilisation, and the *whole-job ratio*
   = wall time / numba blocked plain RK4 time of one period of the grid ("numba-periods",
   goal <= 100), beside the same in numba kink-aware periods;
4. convergence at the defaults: the paper preset's unstable P-1 and stable P-4 by
   shooting with ``KinkAwareRK4(n)`` and ``RK4(n)``, n = 100 ... 3200 steps per period,
   and (full run) the agreement of the cell labels of the default analysis at n and 2n;
5. the global analysis per method (``jaxgear.Direct``, ``jaxgear.PoincareCellMap``,
   ``jaxgear.StroboscopicCellMap``);
6. a bifurcation-diagram workload (200 values x 8 states x 500 periods) and batched
   Newton shooting (``jaxgear.find_periodic_orbits``);
7. time and peak resident memory against the number of cells (fresh subprocess per size).

Prints a table whose LAST line is the headline, the whole-job ratio of item 3, and
writes every figure plus a machine description to a JSON file.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import timeit

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

STEPS = 200  # steps per forcing period (jaxgear's default, paper §4.1)
P1_SEED = (5.579052, -0.619948, 10.674853, -0.253884)  # the paper preset's unstable P-1
P4_SEED = (5.8576, -0.6063, 12.1897, -0.9568)  # and its stable P-4
TARGET_KERNEL_RATIO = 1.5
TARGET_WHOLE_JOB_RATIO = 100.0


# =========================================================================== helpers
def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def machine_info() -> dict:
    """CPU model, cores, caches, library versions, C++ compiler, load average."""
    info = {"python": platform.python_version(), "platform": platform.platform()}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
    except OSError:
        info["cpu"] = platform.processor()
    info["logical_cpus"] = os.cpu_count()
    info["usable_cpus"] = usable_cores()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        for line in out.splitlines():
            key = line.split(":")[0].strip()
            if key in ("L1d cache", "L2 cache", "L3 cache", "Model name", "Hypervisor vendor"):
                info[key] = line.split(":", 1)[1].strip()
        flags = next((ln for ln in out.splitlines() if ln.startswith("Flags")), "")
        info["simd"] = [f for f in ("avx2", "fma", "avx512f") if f" {f}" in flags]
    except (OSError, subprocess.SubprocessError):
        pass
    try:
        with open("/proc/meminfo") as fh:
            info["mem_total_GiB"] = round(int(fh.readline().split()[1]) / 2**20, 1)
    except OSError:
        pass
    cxx = os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++") or shutil.which("clang++")
    if cxx:
        try:
            info["cxx"] = subprocess.run([cxx, "--version"], capture_output=True, text=True,
                                         timeout=10).stdout.splitlines()[0]
        except (OSError, subprocess.SubprocessError, IndexError):
            info["cxx"] = None
    import diffrax
    import jax
    import jaxlib
    import scipy

    import jaxgear
    from jaxgear.integrate._native import native_available

    info["jaxgear"] = jaxgear.__version__
    info["jax"] = jax.__version__
    info["jaxlib"] = jaxlib.__version__
    info["diffrax"] = diffrax.__version__
    info["scipy"] = scipy.__version__
    info["numpy"] = np.__version__
    info["native_kernel"] = bool(native_available())
    try:
        import numba

        info["numba"] = numba.__version__
        info["numba_threads"] = numba.get_num_threads()
    except ImportError:
        info["numba"] = None
    info["jax_devices"] = [str(d) for d in jax.devices()]
    info["XLA_FLAGS"] = os.environ.get("XLA_FLAGS", "")
    return info


def loadavg():
    try:
        return list(os.getloadavg())
    except OSError:
        return None


def measure(fn, repeat: int) -> dict:
    """First call (compile + run) and steady state ``min(timeit.repeat(fn, number=1))``."""
    return measure_result(fn, repeat)[0]


def measure_result(fn, repeat: int):
    """:func:`measure`, and what the first call returned (no extra call for the result)."""
    t = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t
    steady = min(timeit.repeat(fn, number=1, repeat=repeat)) if repeat > 0 else first
    return {"first_s": first, "steady_s": steady, "compile_s": max(first - steady, 0.0), "repeats": repeat}, out


def ns_per_step(seconds: float, n_cells: int, periods: float = 1, steps: int = STEPS) -> float:
    return seconds / (n_cells * periods * steps) * 1e9


def max_diff(A, B) -> dict:
    """Largest difference of two ``(n, dim)`` results: absolute, and relative to
    ``max(|B|, 1)`` (states are O(1-50); a plain relative error is meaningless at zero)."""
    A, B = np.asarray(A), np.asarray(B)
    d = np.abs(A - B)
    return {"abs": float(np.max(d)), "rel": float(np.max(d / np.maximum(np.abs(B), 1.0)))}


def paper_centres() -> np.ndarray:
    """The cell centres of the paper's region D (eq. 10) on x4 = 0: ``(90000, 4)``."""
    import jaxgear

    return jaxgear.CellGrid.paper().centres()


def random_states(n: int, seed: int = 0) -> np.ndarray:
    """``n`` states uniform in region D on x4 = 0 (for the scaling runs)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-25.0, -10.0, -10.0]), np.array([25.0, 20.0, 50.0])
    return np.concatenate([rng.uniform(lo, hi, (n, 3)), np.zeros((n, 1))], axis=1)


def _block(x):
    import jax

    return jax.block_until_ready(x)


def _have_numba() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


# =========================================================================== item 1
def bench_kernel(X, repeat, R):
    """Item 1: one period of the paper grid, jaxgear's integrators and the numba baselines."""
    import baselines as B
    import jax
    import jax.numpy as jnp

    import jaxgear

    p = jaxgear.paper_params()
    Xj = jnp.asarray(X)
    n = len(X)
    out = {}
    Ys = {}

    def strobe(integrator):
        return lambda: _block(jaxgear.stroboscopic_map(jaxgear.REDUCED, p, Xj, periods=1, integrator=integrator))

    jax.clear_caches()
    for key, integrator, rep in (("default", jaxgear.KinkAwareRK4(STEPS), repeat),
                                 ("kink_jax", jaxgear.KinkAwareRK4(STEPS, native=False), 1),
                                 ("rk4", jaxgear.RK4(STEPS), repeat)):
        m, Y = measure_result(strobe(integrator), rep)
        Ys[key] = np.asarray(Y)
        m["integrator"] = repr(integrator)
        m["non_finite"] = int((~np.isfinite(Ys[key]).all(axis=1)).sum())
        out[key] = m

    if _have_numba():
        import numba

        for key, fn in (("numba_blocked", lambda: B.numba_blocked(p, X, block=512)),
                        ("numba_blocked_kink", lambda: B.numba_blocked_kink(p, X, block=512))):
            m, Y = measure_result(fn, repeat)
            Ys[key] = np.asarray(Y)
            m["threads"] = numba.get_num_threads()
            m["block"] = 512
            out[key] = m
            nt = numba.get_num_threads()
            numba.set_num_threads(1)
            m1 = measure(fn, max(1, repeat - 2))
            numba.set_num_threads(nt)
            out[key + "_1thread"] = m1
    else:
        out["numba_blocked"] = out["numba_blocked_kink"] = {"skipped": "numba is not installed"}

    for m in out.values():
        if "steady_s" in m:
            m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
    diffs = {"kink_jax_vs_default": max_diff(Ys["kink_jax"], Ys["default"]),
             "rk4_vs_default": max_diff(Ys["rk4"], Ys["default"])}
    if "numba_blocked_kink" in Ys:
        diffs["default_vs_numba_kink"] = max_diff(Ys["default"], Ys["numba_blocked_kink"])
        diffs["numba_kink_vs_kink_jax"] = max_diff(Ys["numba_blocked_kink"], Ys["kink_jax"])
        diffs["numba_plain_vs_rk4"] = max_diff(Ys["numba_blocked"], Ys["rk4"])
        out["kernel_ratio"] = out["default"]["steady_s"] / out["numba_blocked_kink"]["steady_s"]
        out["kernel_ratio_plain"] = out["default"]["steady_s"] / out["numba_blocked"]["steady_s"]
    out["diffs"] = diffs
    out["n_cells"] = n
    out["kink_jax_ratio"] = out["kink_jax"]["steady_s"] / out["rk4"]["steady_s"]
    R["kernel"] = out
    R["_Y"] = Ys


# =========================================================================== item 1b
HLO_BEFORE = {"ops": 277, "fusions": 200, "instructions": 6201, "compile_s": None,
              "note": "main before the chunked gather (kink step of 2026-12-03, f8edbcd): see RESULTS.md"}
""":func:`hlo_counts` of one pure-JAX kink-aware step of the paper grid as it was before the
lanes with an event were gathered in chunks (measured once on that code, printed beside
today's figures)."""


def bench_kink_jax(R, X, repeat: int = 5, first_calls: bool = True):
    """Item 1b: the pure-JAX kink-aware step (what a GPU and every derivative run) against
    pure-JAX plain RK4, in one process: CPU time (``time.process_time``, all threads) best
    of ``repeat`` of one period of the paper grid, and the same on one core in fresh
    processes (:func:`one_core_ratios`), the fraction of steps that cross a
    switching surface, HLO operation and fusion counts of one step with its compile time,
    the first-call time of a shooting solve and the compile time of a 20,000-lane advance
    (fresh processes), and user systems (Duffing, spur pair) kink-aware vs plain RK4."""
    import jax.numpy as jnp

    import jaxgear

    p = jaxgear.paper_params()
    Y0 = jnp.asarray(X).T
    n = Y0.shape[1]
    out = {"n_cells": n}
    out.update(plain_and_kink(p, Y0, repeat))
    out["ratio"] = out["kink_jax"]["cpu_s"] / out["rk4"]["cpu_s"]
    out["one_core"] = one_core_ratios(rounds=3 if first_calls else 2)
    out["crossing_fraction"] = crossing_fraction(p, Y0)
    out["hlo_one_step"] = {"rk4": step_hlo_counts(p, Y0, "rk4"), "kink_jax": step_hlo_counts(p, Y0, "kink"),
                           "kink_jax_before": HLO_BEFORE}
    if first_calls:
        out["first_calls"] = {k: _first_call(k) for k in ("periodic_orbit", "advance_20k")}
    out["user_systems"] = user_systems(repeat)
    R["kink_jax"] = out


def plain_and_kink(p, Y0, repeat: int) -> dict:
    """:func:`cpu_best` of one period of the states ``Y0 (4, n)`` by pure-JAX plain RK4
    (``"rk4"``) and the pure-JAX kink-aware steps (``"kink_jax"``)."""
    import jaxgear

    return {key: cpu_best(lambda Y, integ=integ: integ.advance(jaxgear.REDUCED, p, Y, 0.0, 1), Y0, repeat)
            for key, integ in (("rk4", jaxgear.RK4(STEPS)), ("kink_jax", jaxgear.KinkAwareRK4(STEPS, native=False)))}


def cpu_best(fn, Y, repeat: int) -> dict:
    """``jax.jit(fn)(Y)``: first call (wall) and the best CPU time of ``repeat`` calls."""
    import jax

    f = jax.jit(fn)
    t = time.perf_counter()
    _block(f(Y))
    first = time.perf_counter() - t
    best = math.inf
    for _ in range(repeat):
        c = time.process_time()
        _block(f(Y))
        best = min(best, time.process_time() - c)
    return {"first_s": first, "cpu_s": best, "ns_per_step_cell": ns_per_step(best, Y.shape[1])}


def crossing_fraction(p, Y, periods: int = 2) -> list[float]:
    """Fraction of the kink-aware steps of the grid whose step changes the side of a
    switching surface, per period (the lanes that pay the split)."""
    import jax
    import jax.numpy as jnp

    import jaxgear
    from jaxgear.integrate._kink import _sides, _switching, kink_step

    S = jaxgear.REDUCED
    h = S.period(p) / STEPS

    @jax.jit
    def one_period(Y):
        def body(Y, i):
            t = i * h
            Y1 = kink_step(S, p, t, Y, h)
            cr = jnp.any(_sides(_switching(S, p, t, Y)) != _sides(_switching(S, p, t + h, Y1)), axis=0)
            return Y1, jnp.sum(cr)

        return jax.lax.scan(body, Y, jnp.arange(STEPS, dtype=jnp.float64))

    out = []
    for _ in range(periods):
        Y, c = one_period(Y)
        out.append(float(np.sum(np.asarray(c))) / (STEPS * Y.shape[1]))
    return out


def hlo_counts(text: str) -> dict:
    """Operations of a compiled HLO module outside fused computations (parameters,
    constants and tuple plumbing left out: what would each be a kernel launch on a GPU),
    the number of fusions, and all instructions."""
    comps, cur = {}, None
    for line in text.splitlines():
        m = re.match(r"^(?:ENTRY\s+)?%?([\w.\-]+)\s+\(.*\{\s*$", line)
        if m:
            cur = m.group(1)
            comps[cur] = []
        elif line.strip() == "}":
            cur = None
        elif cur is not None and " = " in line:
            comps[cur].append(line)
    fused = {c for ls in comps.values() for ln in ls if " fusion(" in ln for c in re.findall(r"calls=%?([\w.\-]+)", ln)}
    skip = ("parameter(", "constant(", "get-tuple-element(", "tuple(", "bitcast(")
    return {"ops": sum(1 for c, ls in comps.items() if c not in fused for ln in ls if not any(k in ln for k in skip)),
            "fusions": sum(1 for ls in comps.values() for ln in ls if " fusion(" in ln),
            "instructions": sum(len(ls) for ls in comps.values())}


def step_hlo_counts(p, Y, kind: str) -> dict:
    """:func:`hlo_counts` of one pure-JAX step (plain RK4 or kink-aware) of the grid, and its
    compile time."""
    import jax

    import jaxgear
    from jaxgear.integrate._kink import kink_step
    from jaxgear.integrate._rk4 import rk4_step

    S = jaxgear.REDUCED
    step = rk4_step if kind == "rk4" else kink_step
    h = S.period(p) / STEPS
    t = time.perf_counter()
    text = jax.jit(lambda Y, tt: step(S, p, tt, Y, h)).lower(Y, 0.3).compile().as_text()
    return {**hlo_counts(text), "compile_s": time.perf_counter() - t}


def one_core_ratios(rounds: int) -> dict:
    """The pure-JAX ratio on one core: ``rounds`` fresh processes, each pinned to one CPU
    (``os.sched_setaffinity`` before JAX starts), measure plain and kink-aware RK4 in
    turn (best of 5 each). In the two-thread measurement the kink-aware step's CPU time
    is up to 1.5 times its one-core time, plain RK4's is not (most likely XLA's second
    thread waiting for work between the step's many small operations); the spread of
    the rounds shows the machine's noise. Returns the rounds' plain and kink-aware ns
    per step and cell and their ratios."""
    rows = []
    for _ in range(rounds):
        row = _in_fresh_process("one-core")
        if "error" in row:
            return row
        rows.append(row)
    return {"rk4": [r["rk4"] for r in rows], "kink_jax": [r["kink_jax"] for r in rows],
            "ratios": [r["kink_jax"] / r["rk4"] for r in rows]}


def _one_core_worker() -> dict:
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # before JAX starts its backend
    import jax.numpy as jnp

    import jaxgear

    pair = plain_and_kink(jaxgear.paper_params(), jnp.asarray(paper_centres()).T, 5)
    return {key: m["ns_per_step_cell"] for key, m in pair.items()}


def _in_fresh_process(worker: str, *args: str) -> dict:
    """The JSON dict a ``--worker`` run of this script (more arguments ``args``) prints
    last, or ``{"error": ...}``."""
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", worker, *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900, check=False)
    try:
        return json.loads(proc.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError):
        return {"error": (proc.stderr or proc.stdout)[-500:]}


def _first_call(kind: str) -> dict:
    """First-call wall time in a fresh process: ``periodic_orbit`` (the paper preset's P-1
    from a seed, one shooting solve: its compile is mostly the kink step's derivatives) or
    the compile of a ``jax.jit`` advance of 20,000 lanes with ``native=False``."""
    return _in_fresh_process("first:" + kind)


def _first_call_worker(kind: str) -> dict:
    import jax
    import jax.numpy as jnp

    import jaxgear

    p = jaxgear.paper_params()
    t = time.perf_counter()
    if kind == "periodic_orbit":
        jaxgear.periodic_orbit(jaxgear.REDUCED, p, np.array([5.4, -0.2, 8.3, -0.8]), period=1)
    else:
        integ = jaxgear.KinkAwareRK4(STEPS, native=False)
        Y = jnp.asarray(paper_centres()[:20_000]).T
        jax.jit(lambda Y: integ.advance(jaxgear.REDUCED, p, Y, 0.0, 1)).lower(Y).compile()
    return {"first_s": time.perf_counter() - t}


def spur_with_surfaces():
    """``jaxgear.SPUR_PAIR`` with its backlash surfaces ``x -+ b`` declared (a user system
    with switching functions and pieces, as a user would write it)."""
    import jax.numpy as jnp

    import jaxgear

    def pieces(t, x, q, sides):
        k = 1.0 + q.kappa * jnp.sin(q.Omega * t)
        d = jnp.where(sides[0] > 0, x[0] - q.b, jnp.where(sides[1] < 0, x[0] + q.b, 0.0))
        return jnp.stack([x[1], q.f_m + q.e_amp * q.Omega**2 * jnp.sin(q.Omega * t) - 2.0 * q.zeta * x[1] - k * d])

    S = jaxgear.SPUR_PAIR
    return jaxgear.ForcedSystem(vector_field=S.vector_field, period=S.period, state_names=S.state_names,
                                section_index=S.section_index, name="spur-pair-surfaces",
                                switching=lambda t, x, q: jnp.stack([x[0] - q.b, x[0] + q.b]), piece_field=pieces)


def user_systems(repeat: int, n: int = 90_000) -> dict:
    """ns per step and state of the pure-JAX kink-aware and plain RK4 steps on user
    systems (one period, ``STEPS`` steps, ``n`` random states): the Duffing oscillator and
    the built-in spur pair declare no switching functions (the kink-aware integrator is
    plain RK4 for them); the spur pair with its surfaces declared splits its steps."""
    import jax.numpy as jnp

    import jaxgear

    rng = np.random.default_rng(3)
    Y = jnp.asarray(np.stack([rng.uniform(-3, 3, n), rng.uniform(-4, 4, n)]))
    cases = (("duffing", jaxgear.DUFFING, jaxgear.DuffingParams(beta=0.5, gamma=3.0)),
             ("spur_pair", jaxgear.SPUR_PAIR, jaxgear.SpurPairParams(b=0.5, kappa=0.3, e_amp=0.4, Omega=1.3)),
             ("spur_pair_surfaces", spur_with_surfaces(), jaxgear.SpurPairParams(b=0.5, kappa=0.3, e_amp=0.4,
                                                                                 Omega=1.3)))
    out = {}
    for name, S, q in cases:
        row = {"switching": S.switching is not None}
        for key, integ in (("rk4", jaxgear.RK4(STEPS)), ("kink_jax", jaxgear.KinkAwareRK4(STEPS, native=False))):
            row[key] = cpu_best(lambda Y, integ=integ, S=S, q=q: integ.advance(S, q, Y, 0.0, 1), Y, repeat)
        row["ratio"] = row["kink_jax"]["cpu_s"] / row["rk4"]["cpu_s"]
        out[name] = row
    return out


# =========================================================================== item 2
def bench_other_styles(X, repeat, R, scipy_sample, diffrax_sample):
    """Item 2: numba naive, solve_ivp loop, diffrax vmap, each against the default integrator
    and plain RK4 of item 1."""
    import baselines as B
    import jax.numpy as jnp

    import jaxgear

    p = jaxgear.paper_params()
    n = len(X)
    Yk, Yr = R["_Y"]["default"], R["_Y"]["rk4"]
    rng = np.random.default_rng(1)
    out = {}

    if _have_numba():
        fnv = lambda: B.numba_naive(p, X)  # noqa: E731
        m, Yv = measure_result(fnv, max(1, repeat // 2))
        m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
        m["max_abs_diff_vs_rk4"] = float(np.max(np.abs(Yv - Yr)))
        out["numba_naive"] = m
    else:
        out["numba_naive"] = {"skipped": "numba is not installed"}

    # solve_ivp, a sample of cells, extrapolated to all cells.
    idx = np.sort(rng.choice(n, size=min(scipy_sample, n), replace=False))
    t = time.perf_counter()
    Ys = B.scipy_loop(p, X[idx], rtol=1e-8, atol=1e-8)
    ts = time.perf_counter() - t
    out["scipy"] = {
        "sample": int(len(idx)), "sample_s": ts, "steady_s": ts * n / len(idx), "compile_s": 0.0,
        "extrapolated": True, "rtol": 1e-8, "atol": 1e-8, "method": "RK45",
        "max_abs_diff_vs_kink": float(np.max(np.abs(Ys - Yk[idx]))),
        "max_abs_diff_vs_rk4": float(np.max(np.abs(Ys - Yr[idx]))),
    }
    out["scipy"]["ns_per_step_cell"] = ns_per_step(out["scipy"]["steady_s"], n)

    # diffrax Tsit5 vmapped, a sample (same for every call), extrapolated.
    idx_d = np.sort(rng.choice(n, size=min(diffrax_sample, n), replace=False))
    run = B.make_diffrax_vmap(rtol=1e-8, atol=1e-8)
    Xd = jnp.asarray(X[idx_d])
    fd = lambda: _block(run(p, Xd, 0.0, 1))  # noqa: E731
    m, out_d = measure_result(fd, max(1, repeat // 2))
    Yd, nsteps = (np.asarray(a) for a in out_d)
    m.update(sample=int(len(idx_d)), sample_s=m["steady_s"], extrapolated=len(idx_d) < n,
             mean_accepted_steps=float(np.mean(nsteps)), max_steps_in_batch=int(np.max(nsteps)),
             max_abs_diff_vs_kink=float(np.max(np.abs(Yd - Yk[idx_d]))),
             max_abs_diff_vs_rk4=float(np.max(np.abs(Yd - Yr[idx_d]))))
    m["steady_s"] = m["sample_s"] * n / len(idx_d)
    m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
    common = np.intersect1d(idx, idx_d)
    if len(common):
        a = Ys[np.searchsorted(idx, common)]
        b = Yd[np.searchsorted(idx_d, common)]
        m["max_abs_diff_vs_scipy_common_cells"] = float(np.max(np.abs(a - b)))
        m["common_cells"] = int(len(common))
    out["diffrax"] = m
    R["styles"] = out


# =========================================================================== item 3
WARM_RUNS = 3
"""Warm runs of the command (the machine is shared: the row shows the median one)."""

_DONE = re.compile(r"done in ([0-9.]+) s \(mean ([0-9.]+) periods per cell\)")


def _run_cli(args: list[str], env: dict, timeout: float) -> dict:
    """One ``jaxgear ...`` in a fresh process: wall time, CPU time of the process and its
    children (``RUSAGE_CHILDREN`` deltas), and the analysis time it prints."""
    # ``python -m jaxgear`` runs the console script's entry point (jaxgear.cli.main) of the
    # checkout being benchmarked, whatever ``jaxgear`` on PATH points to.
    cmd = [sys.executable, "-m", "jaxgear", *args]
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, cwd=ROOT, check=False)
    wall = time.perf_counter() - t
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    row = {"args": args[:1] + [a for a in args[1:] if a.startswith("--") and a != "--out"], "wall_s": wall,
           "cpu_s": cpu, "cpu_cores": cpu / wall, "utilisation": cpu / wall / usable_cores(),
           "returncode": proc.returncode}
    m = _DONE.search(proc.stdout)
    if m:
        row["analysis_s"], row["mean_periods"] = float(m.group(1)), float(m.group(2))
    if proc.returncode != 0:
        row["error"] = (proc.stderr or proc.stdout)[-500:]
    return row


def bench_whole_job(R, X):
    """Item 3: ``jaxgear analyze`` as a user runs it, and ``analyze_global()`` in-process.

    The command runs cold (an empty ``$JAXGEAR_CACHE_DIR``: the C++ kernel is built and
    every XLA computation compiled) and then warm (the compiled kernel and the XLA
    compilation cache kept there); then warm with ``--no-figures``. In-process: the first
    call of ``jaxgear.analyze_global()`` in this process (compilation included, no
    persistent cache) and a second call (steady state).

    The unit, one numba-period, is numba's blocked plain RK4 map of the grid over one
    period (the issue's goal: at most 100 of them); the same wall time is also given in
    numba kink-aware periods. Both are measured again between the runs here (the machine
    is shared, its load drifts) and taken as the least of those and item 1's steady state
    (conservative: a baseline timed while the machine was busy would flatter the ratio).
    """
    import jaxgear

    baseline = {"plain": [], "kink": []}

    def remeasure():
        if _have_numba():
            import baselines as B

            p = jaxgear.paper_params()
            baseline["plain"].append(measure(lambda: B.numba_blocked(p, X, block=512), 2)["steady_s"])
            baseline["kink"].append(measure(lambda: B.numba_blocked_kink(p, X, block=512), 2)["steady_s"])

    cache = tempfile.mkdtemp(prefix="jaxgear-bench-cache-")
    outdir = tempfile.mkdtemp(prefix="jaxgear-bench-out-")
    env = dict(os.environ, JAXGEAR_CACHE_DIR=cache)
    env["PYTHONPATH"] = ROOT + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    # the command starts as on a default Python, which keeps the bytecode of what it
    # imports (a session that sets PYTHONDONTWRITEBYTECODE compiles jaxgear's sources at
    # every start: about 0.1 s of one core)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    out = {"load_start": loadavg()}
    try:
        for key, extra, runs in (("cold", [], 1), ("warm", [], WARM_RUNS), ("warm_no_figures", ["--no-figures"], 1)):
            remeasure()
            rows = [_run_cli(["analyze", "--out", outdir, "--quiet", *extra], env, timeout=1800) for _ in range(runs)]
            out[key] = sorted(rows, key=lambda r: r["wall_s"])[len(rows) // 2]  # the median run by wall time
            if runs > 1:
                out[key + "_runs"] = rows
            walls = ", ".join(f"{r['wall_s']:.1f}" for r in rows)
            print(f"  jaxgear analyze {key}: {out[key]['wall_s']:.1f} s wall"
                  + (f" (median of {runs}: {walls})" if runs > 1 else ""), flush=True)
        out["cache_MB"] = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(cache) for f in fs) / 2**20
    finally:
        shutil.rmtree(cache, ignore_errors=True)
        shutil.rmtree(outdir, ignore_errors=True)

    for key in ("in_process_first", "in_process_second"):
        remeasure()
        ru0 = resource.getrusage(resource.RUSAGE_SELF)
        t = time.perf_counter()
        res = jaxgear.analyze_global(progress=False)
        wall = time.perf_counter() - t
        ru1 = resource.getrusage(resource.RUSAGE_SELF)
        cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
        out[key] = {"wall_s": wall, "cpu_s": cpu, "cpu_cores": cpu / wall, "utilisation": cpu / wall / usable_cores(),
                    "mean_periods": float(res.mean_periods),
                    "attractors": [{"period": int(a.period), "share": round(float(a.share), 4)} for a in res.attractors]}
        print(f"  analyze_global() {key[11:]} call: {wall:.1f} s", flush=True)
    remeasure()
    out["load_end"] = loadavg()
    for kind, key, col in (("plain", "numba_blocked", "numba_periods"),
                           ("kink", "numba_blocked_kink", "numba_kink_periods")):
        item1 = R.get("kernel", {}).get(key, {}).get("steady_s")
        measured = ([item1] if item1 else []) + baseline[kind]
        out[f"numba_{kind}_period_s_measured"] = measured
        unit = min(measured) if measured else None
        out[f"numba_{kind}_period_s"] = unit
        if unit:
            for row in out.values():
                if isinstance(row, dict) and "wall_s" in row:
                    row[col] = row["wall_s"] / unit
    out["cores"] = usable_cores()
    R["whole_job"] = out


# =========================================================================== item 4
def _leading(lam) -> complex:
    """The leading multiplier (the one of a complex pair with positive imaginary part)."""
    lam = np.asarray(lam)
    lead = lam[0]
    if len(lam) > 1 and abs(lam[1] - np.conj(lead)) <= 1e-12 * (1 + abs(lead)) and lead.imag < 0:
        lead = lam[1]
    return complex(lead)


def _fd_multiplier(system, params, x, k, integrator, eps=1e-6) -> complex:
    """Leading eigenvalue of the central-difference Jacobian of ``P^k`` at ``x`` (the map as
    computed: compiled kernel for KinkAwareRK4), a check on the ``jax.jacfwd`` multipliers."""
    import jax.numpy as jnp

    import jaxgear

    dim = len(x)
    Xs = np.concatenate([x + eps * np.eye(dim), x - eps * np.eye(dim)])
    Y = np.asarray(jaxgear.stroboscopic_map(system, params, jnp.asarray(Xs), periods=k, integrator=integrator))
    M = ((Y[:dim] - Y[dim:]) / (2 * eps)).T
    lam = np.linalg.eigvals(M)
    return _leading(lam[np.argsort(-np.abs(lam), kind="stable")])


def bench_convergence(R, ns):
    """Item 4a: the P-1 and P-4 of the paper preset by shooting at n steps per period,
    KinkAwareRK4 and RK4, each n seeded from the previous point."""
    import jaxgear

    p = jaxgear.paper_params()
    out = {}
    for name, k, seed in (("P-1", 1, P1_SEED), ("P-4", 4, P4_SEED)):
        for cls in (jaxgear.KinkAwareRK4, jaxgear.RK4):
            rows = []
            x = np.asarray(seed, dtype=float)
            for n in ns:
                integ = cls(n)
                t = time.perf_counter()
                r = jaxgear.periodic_orbit(jaxgear.REDUCED, p, x, period=k, integrator=integ)
                wall = time.perf_counter() - t
                pt = np.asarray(r.point, dtype=float)
                row = {"n": n, "status": str(jaxgear.Status(int(r.status)).name), "iterations": int(r.iterations),
                       "residual": float(r.residual), "min_period": int(r.min_period), "s": wall,
                       "point": pt.tolist()}
                if np.all(np.isfinite(pt)):
                    lam = np.asarray(r.multipliers)
                    l1 = _leading(lam)
                    lf = _fd_multiplier(jaxgear.REDUCED, p, pt, k, integ)
                    row.update(multipliers=[[float(z.real), float(z.imag)] for z in lam],
                               lead=[l1.real, l1.imag], lead_abs=abs(l1), stable=bool(r.stable),
                               lead_fd=[lf.real, lf.imag])
                    if rows and "lead" in rows[-1]:
                        prev = rows[-1]
                        row["d_state"] = float(np.max(np.abs(pt - np.asarray(prev["point"]))))
                        row["d_lead"] = abs(l1 - complex(*prev["lead"]))
                        row["d_lead_fd"] = abs(lf - complex(*prev["lead_fd"]))
                        for d in ("d_state", "d_lead", "d_lead_fd"):
                            if d in prev and prev[d] > 0 and row[d] > 0:
                                row["order_" + d[2:]] = math.log2(prev[d] / row[d])
                    x = pt
                rows.append(row)
            out[f"{name}/{cls.__name__}"] = rows
            print(f"  {name} {cls.__name__}: " + ", ".join(f"n={r['n']} {r['s']:.1f}s" for r in rows), flush=True)
    R["convergence"] = out


def bench_label_agreement(R, ns=(100, 200, 400)):
    """Item 4b: the default analysis (``Direct``) of the paper grid at each n; the fraction
    of cells with the same label at n and 2n (attractors matched by their points)."""
    import jaxgear
    from jaxgear._matching import match_attractors

    res = {}
    out = {"runs": {}}
    for n in ns:
        t = time.perf_counter()
        r = jaxgear.analyze_global(method=jaxgear.Direct(integrator=jaxgear.KinkAwareRK4(n)), progress=False)
        res[n] = r
        out["runs"][n] = {"s": time.perf_counter() - t, "mean_periods": float(r.mean_periods),
                          "attractors": [{"period": int(a.period), "share": round(float(a.share), 5)}
                                         for a in r.attractors]}
        print(f"  analysis at n={n}: {out['runs'][n]['s']:.1f} s", flush=True)
    pairs = {}
    for a, b in zip(ns[:-1], ns[1:]):
        A, Bres = res[a], res[b]
        idx = match_attractors([(x.points, x.period) for x in A.attractors],
                               [(x.points, x.period) for x in Bres.attractors], max_distance=1e-2)
        mapping = {x.id: (A.attractors[j].id if j >= 0 else -1000 - x.id) for x, j in zip(Bres.attractors, idx)}
        la = np.asarray(A.labels)
        lb = np.array([mapping.get(int(v), int(v)) for v in np.asarray(Bres.labels).ravel()]).reshape(la.shape)
        pairs[f"{a}-{b}"] = {"agreement": float(np.mean(la == lb)), "differ": int(np.sum(la != lb)),
                             "cells": int(la.size)}
    out["pairs"] = pairs
    R["label_agreement"] = out


# =========================================================================== item 5
def bench_global_analysis(R, quick: bool, repeat_cheap: bool):
    """Item 5: the whole global analysis per method (``jaxgear.analyze_global``).

    One cold call per method (compile included); in a full run each method is called a
    second time for its steady-state figure.
    """
    import warnings

    import jaxgear
    from jaxgear import CellGrid

    if quick:
        sec_grid = CellGrid.paper(counts=(10, 6, 12))
        strobe_grid = CellGrid.box([(-25, 25), (-10, 20), (-10, 50), (-10, 10)], (10, 6, 12, 4),
                                   names=jaxgear.REDUCED.state_names)
    else:
        sec_grid = CellGrid.paper()
        strobe_grid = CellGrid.box([(-25, 25), (-10, 20), (-10, 50), (-10, 10)], (25, 15, 30, 10),
                                   names=jaxgear.REDUCED.state_names)
    out = {}
    for method, grid in ((jaxgear.PoincareCellMap(), sec_grid), (jaxgear.StroboscopicCellMap(), strobe_grid),
                         (jaxgear.Direct(), sec_grid)):
        row = {"cells": grid.n_cells, "grid": list(grid.counts), "method": repr(method)}
        try:
            with warnings.catch_warnings(record=True) as w:
                warnings.simplefilter("always")
                t = time.perf_counter()
                res = jaxgear.analyze_global(method=method, grid=grid, progress=False)
                row["first_s"] = time.perf_counter() - t
                if repeat_cheap:
                    t = time.perf_counter()
                    res = jaxgear.analyze_global(method=method, grid=grid, progress=False)
                    row["steady_s"] = time.perf_counter() - t
                    row["compile_s"] = max(row["first_s"] - row["steady_s"], 0.0)
            row["warnings"] = [str(x.message)[:200] for x in w]
            row["attractors"] = [{"period": int(a.period), "share": round(float(a.share), 4)}
                                 for a in res.attractors]
            row["n_sink"] = int(res.n_sink)
            row["n_unresolved"] = int(res.n_unresolved)
            row["mean_periods"] = float(res.mean_periods)
            tsec = row.get("steady_s", row["first_s"])
            row["ns_per_step_cell"] = ns_per_step(tsec, grid.n_cells, periods=max(res.mean_periods, 1e-12))
        except Exception as e:  # a benchmark reports, it does not stop
            row["error"] = f"{type(e).__name__}: {e}"[:300]
        out[method.name] = row
    R["global_analysis"] = out


# =========================================================================== item 6
def bench_bifurcation(R, quick: bool):
    """Item 6a: bifurcation diagram, 200 values x 8 initial states x 500 periods.

    ``jaxgear.bifurcation_diagram`` (all values and starts batched in one kernel), swept
    in the half backlash ``b`` (the forcing period is shared by every value) and, in a
    full run, in ``Omega`` (each value has its own period and step size).
    """
    import jaxgear

    n_par, n_states = 200, 8
    periods = 100 if quick else 500
    record = 40  # >= 2 max_period + 1 points for the period test
    p = jaxgear.paper_params()
    X8 = random_states(n_states, seed=3)
    out = {}
    for name, values in (("b", np.linspace(0.25, 6.0, n_par)), ("Omega", np.linspace(0.6, 1.2, n_par)))[: 1 if quick else 2]:
        opts = jaxgear.SequenceOptions(transient=periods - record, record=record)
        fn = lambda name=name, values=values, opts=opts: jaxgear.bifurcation_diagram(  # noqa: E731
            jaxgear.REDUCED, p, name, values, X8, direction="independent", options=opts,
            runner=jaxgear.Runner(progress=False))
        m, d = measure_result(fn, 1)
        total = n_par * n_states
        m.update(n_params=n_par, n_states=n_states, periods=periods, param=name,
                 ns_per_step_state=ns_per_step(m["steady_s"], total, periods))
        try:
            m["summary"] = {k: v for k, v in d.summary().items() if isinstance(v, (int, float, str))}
        except Exception:  # a summary is a courtesy here
            pass
        if quick:
            m["extrapolated_500_periods_s"] = m["steady_s"] * 500 / periods
        out[name] = m
    R["bifurcation"] = out


def bench_shooting(R, quick: bool):
    """Item 6b: batched Newton shooting (``jaxgear.find_periodic_orbits``) from random
    seeds for period-4 orbits of the paper preset."""
    import jaxgear

    p = jaxgear.paper_params()
    guesses = random_states(32, seed=5)  # the search itself: benchmarks/shooting.py
    try:
        fn = lambda: jaxgear.find_periodic_orbits(jaxgear.REDUCED, p, guesses, period=4, progress=False)  # noqa: E731
        m, res = measure_result(fn, 1)
        m["guesses"] = len(guesses)
        m["orbits"] = [{"period": int(o.period), "stable": bool(o.stable), "max_abs_multiplier": float(o.max_multiplier)}
                       for o in res.orbits]
        m["status_counts"] = {str(k): int(v) for k, v in dict(res.status_counts).items()}
        R["shooting"] = m
    except Exception as e:  # a benchmark reports, it does not stop
        R["shooting"] = {"error": f"{type(e).__name__}: {e}"[:300]}


# =========================================================================== item 7
def peak_rss_mb() -> float:
    """Peak resident set size of this process (VmHWM), MB.

    ``getrusage(...).ru_maxrss`` is not used: Linux carries it across ``execve``, so a
    fresh subprocess would report its parent's peak.
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _worker(kind: str, n: int, repeat: int) -> dict:
    """Run in a fresh process: one kernel on ``n`` cells, time and peak RSS."""
    import jax.numpy as jnp

    import jaxgear

    p = jaxgear.paper_params()
    X = random_states(n, seed=7)
    rss0 = peak_rss_mb()
    if kind in ("jaxgear", "jaxgear-rk4"):
        integrator = jaxgear.KinkAwareRK4(STEPS) if kind == "jaxgear" else jaxgear.RK4(STEPS)
        Xj = jnp.asarray(X)
        fn = lambda: _block(jaxgear.stroboscopic_map(jaxgear.REDUCED, p, Xj, periods=1, integrator=integrator))  # noqa: E731
    elif kind == "direct":
        # The whole direct global analysis on a paper-region grid of about n cells.
        from jaxgear import CellGrid

        side = round(n ** (1 / 3))
        grid = CellGrid.paper(counts=(side, side, side))
        m = {}
        t = time.perf_counter()
        res = jaxgear.analyze_global(method=jaxgear.Direct(), grid=grid, progress=False)
        m["first_s"] = m["steady_s"] = time.perf_counter() - t
        m["compile_s"] = float("nan")
        m["mean_periods"] = res.mean_periods
        m["cells"] = grid.n_cells
        m["attractors"] = [(int(a.period), round(float(a.share), 4)) for a in res.attractors]
        m["ns_per_step_cell"] = ns_per_step(m["steady_s"], grid.n_cells, periods=res.mean_periods)
        m["peak_rss_MB"] = peak_rss_mb()
        m["rss_before_kernel_MB"] = rss0
        m["state_MB"] = X.nbytes / 2**20
        return m
    elif kind == "numba-blocked-kink":
        import baselines as B

        fn = lambda: B.numba_blocked_kink(p, X, block=512)  # noqa: E731
    else:
        raise ValueError(kind)
    m = measure(fn, repeat)
    m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
    m["peak_rss_MB"] = peak_rss_mb()
    m["rss_before_kernel_MB"] = rss0
    m["state_MB"] = X.nbytes / 2**20
    return m


def bench_scaling(R, sizes, kinds):
    """Item 7: time and peak memory against the number of cells, one subprocess each.

    Kinds: the default integrator (compiled kernel), plain RK4 (XLA), the numba
    kink-aware baseline, and the whole direct analysis. (Dropped: the RK4 loop before
    chunking and plain numba — the default path is now the compiled kernel, which blocks
    its lanes itself, and its baseline is the kink-aware numba kernel.)
    """
    out = {}
    for kind in kinds:
        for n in sizes:
            repeat = 3 if n <= 100_000 else 2
            t = time.perf_counter()
            m = _in_fresh_process(kind, "--n", str(n), "--repeat", str(repeat))
            m["process_wall_s"] = time.perf_counter() - t
            out[f"{kind}/{n}"] = m
            print(f"  scaling {kind:18s} n={n:>9,d}: "
                  + (f"{m['steady_s']:.3f} s, {m['ns_per_step_cell']:.2f} ns, peak RSS {m['peak_rss_MB']:.0f} MB"
                     if "steady_s" in m else m.get("error", "?")[-200:]), flush=True)
    R["scaling"] = out


# =========================================================================== table
def _fmt(x, spec=".3f", dash="-"):
    return dash if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _cplx(z) -> str:
    re_, im = z
    return f"{re_:+.7f}" + (f"{im:+.7f}i" if abs(im) > 0 else "")


def headline(R) -> str:
    wj = R.get("whole_job", {})
    w = wj.get("warm", {})
    if "numba_periods" not in w:
        return "whole job: jaxgear analyze = n/a numba-periods (" + (w.get("error", "numba missing")[-80:]) + ")"
    return (f"whole job: jaxgear analyze = {w['numba_periods']:.0f} numba plain-RK4 periods (warm, {w['wall_s']:.1f} s wall, "
            f"CPU {w['cpu_cores']:.2f}/{wj['cores']} cores; target <= {TARGET_WHOLE_JOB_RATIO:.0f})")


def print_table(R) -> list[str]:
    L = []
    mi = R["machine"]
    L.append(f"jaxgear benchmark  ({'quick' if R['quick'] else 'full'} run, {R['date']})")
    L.append(f"machine: {mi.get('cpu')}, {mi.get('usable_cpus')} usable cores, L2 {mi.get('L2 cache')}, "
             f"L3 {mi.get('L3 cache')}, SIMD {'/'.join(mi.get('simd', []))}")
    L.append(f"software: jaxgear {mi.get('jaxgear')}, jax {mi['jax']}, numba {mi.get('numba')}, scipy {mi['scipy']}, "
             f"diffrax {mi['diffrax']}, {mi.get('cxx')}; compiled kernel {'on' if mi.get('native_kernel') else 'OFF'}")
    L.append(f"load average at start {_fmt((R['load_start'] or [None])[0], '.2f')}, "
             f"end {_fmt((R['load_end'] or [None])[0], '.2f')} (a shared machine: compare figures within one run)")
    L.append("")

    K = R.get("kernel", {})
    L.append(f"1. kernel: stroboscopic map, paper grid ({K.get('n_cells', 0):,d} cells), 1 period, {STEPS} steps, float64")
    L.append(f"  {'implementation':52s} {'compile s':>9s} {'run s':>8s} {'ns/step/cell':>12s}")
    rows = [
        ("default: KinkAwareRK4(200), compiled CPU kernel", "default"),
        ("KinkAwareRK4(200, native=False), pure JAX", "kink_jax"),
        ("RK4(200), plain (XLA)", "rk4"),
        ("numba blocked+tabulated+vectorised, plain RK4", "numba_blocked"),
        ("  same, 1 thread", "numba_blocked_1thread"),
        ("numba blocked+tabulated+vectorised, kink-aware", "numba_blocked_kink"),
        ("  same, 1 thread", "numba_blocked_kink_1thread"),
    ]
    for label, key in rows:
        m = K.get(key)
        if not m or "steady_s" not in m:
            L.append(f"  {label:52s} {'skipped':>9s}  {(m or {}).get('skipped', '')}")
            continue
        L.append(f"  {label:52s} {_fmt(m.get('compile_s'), '.2f'):>9s} {m['steady_s']:8.3f} {m['ns_per_step_cell']:12.2f}")
    D = K.get("diffs", {})
    names = (("default_vs_numba_kink", "compiled kernel vs numba kink-aware"),
             ("numba_kink_vs_kink_jax", "numba kink-aware vs pure-JAX kink-aware"),
             ("kink_jax_vs_default", "pure-JAX vs compiled kernel"),
             ("numba_plain_vs_rk4", "numba plain vs RK4(200)"),
             ("rk4_vs_default", "plain RK4 vs kink-aware (RK4's kink error, 1 period)"))
    for key, label in names:
        if key in D:
            L.append(f"  max |diff| {label:54s} {D[key]['abs']:.1e} (rel {D[key]['rel']:.1e})")
    if "kernel_ratio" in K:
        L.append(f"  kernel ratio = default / numba kink-aware: {K['kernel_ratio']:.2f} "
                 f"(target <= {TARGET_KERNEL_RATIO})")
    if "kernel_ratio_plain" in K:
        L.append(f"  headline kernel ratio = default / numba blocked plain RK4: {K['kernel_ratio_plain']:.2f} "
                 "(goal <= 1.5)")
    if "kink_jax_ratio" in K:
        L.append(f"  pure-JAX ratio = kink-aware / plain RK4, pure JAX (wall): {K['kink_jax_ratio']:.2f} (goal <= 3)")
    L.append("")
    L += kink_jax_table(R)

    S = R.get("styles", {})
    L.append("2. other CPU styles of the same map")
    for label, key in (("numba naive per-cell prange (plain RK4)", "numba_naive"),
                       ("scipy solve_ivp RK45 loop (rtol=atol=1e-8)", "scipy"),
                       ("diffrax Tsit5 vmap (rtol=atol=1e-8)", "diffrax")):
        m = S.get(key)
        if not m or "steady_s" not in m:
            L.append(f"  {label:52s} {'skipped':>9s}  {(m or {}).get('skipped', '')}")
            continue
        if key == "numba_naive":
            txt = f"max |diff| vs RK4(200) {m['max_abs_diff_vs_rk4']:.1e}"
        else:
            txt = (f"{m['sample']} cells in {m['sample_s']:.2f} s, x{K.get('n_cells', 1) / m['sample']:.0f}; |diff| vs "
                   f"kink-aware {m['max_abs_diff_vs_kink']:.1e}, vs RK4 {m['max_abs_diff_vs_rk4']:.1e}")
            if "mean_accepted_steps" in m:
                txt += f"; {m['mean_accepted_steps']:.0f} steps/period"
        L.append(f"  {label:52s} {_fmt(m.get('compile_s'), '.2f'):>9s} {m['steady_s']:8.3f} "
                 f"{m['ns_per_step_cell']:12.2f}  {txt}")
    if "max_abs_diff_vs_scipy_common_cells" in S.get("diffrax", {}):
        d = S["diffrax"]
        L.append(f"  (diffrax vs scipy on {d['common_cells']} common cells: max |diff| "
                 f"{d['max_abs_diff_vs_scipy_common_cells']:.1e})")
    L.append("")

    W = R.get("whole_job", {})
    L.append("3. whole job: jaxgear analyze (paper grid, direct method, default integrator)")
    L.append(f"  {'run':44s} {'wall s':>7s} {'analysis s':>10s} {'CPU s':>7s} {'cores used':>10s} {'numba-periods':>13s}"
             f" {'kink-periods':>12s}")
    for label, key in (("jaxgear analyze, cold (empty cache dir)", "cold"),
                       ("jaxgear analyze, warm", "warm"),
                       ("jaxgear analyze --no-figures, warm", "warm_no_figures"),
                       ("analyze_global() in-process, first call", "in_process_first"),
                       ("analyze_global() in-process, second call", "in_process_second")):
        m = W.get(key)
        if not m:
            continue
        if m.get("returncode", 0) != 0:
            L.append(f"  {label:44s} error: {m.get('error', '')[-120:]!r}")
            continue
        L.append(f"  {label:44s} {m['wall_s']:7.1f} {_fmt(m.get('analysis_s'), '.1f'):>10s} {m['cpu_s']:7.1f} "
                 f"{m['cpu_cores']:7.2f}/{W['cores']} {_fmt(m.get('numba_periods'), '.0f'):>13s}"
                 f" {_fmt(m.get('numba_kink_periods'), '.0f'):>12s}")
    if W.get("numba_plain_period_s"):
        att = ", ".join(f"P-{a['period']}:{a['share']:.3f}" for a in W.get("in_process_second", {}).get("attractors", []))
        L.append("  cold: an empty $JAXGEAR_CACHE_DIR (the C++ kernel is built, every computation compiled); "
                 "warm: the same folder again")
        if W.get("warm_runs"):
            runs = W["warm_runs"]
            L.append(f"  warm: the median of {len(runs)} runs by wall time; the runs: "
                     + ", ".join(f"{r['wall_s']:.1f} s at {r['utilisation']:.3f}" for r in runs)
                     + " (wall, CPU utilisation)")
        for kind, name in (("plain", "numba-period = numba blocked plain RK4"),
                           ("kink", "kink-period = numba blocked kink-aware")):
            meas = ", ".join(f"{v:.3f}" for v in W.get(f"numba_{kind}_period_s_measured", []))
            L.append(f"  1 {name}, one period of the grid = {W[f'numba_{kind}_period_s'] or float('nan'):.3f} s "
                     f"(least of {meas} s: item 1, then between the runs)")
        L.append(f"  {W.get('in_process_second', {}).get('mean_periods', float('nan')):.1f} periods per cell; {att}; "
                 f"compilation cache {W.get('cache_MB', 0):.0f} MB; load average "
                 f"{_fmt((W.get('load_start') or [None])[0], '.2f')} -> {_fmt((W.get('load_end') or [None])[0], '.2f')}")
        kernel_s = R.get("kernel", {}).get("default", {}).get("steady_s")
        second = W.get("in_process_second", {})
        if kernel_s and second.get("mean_periods"):
            integ = second["mean_periods"] * kernel_s
            L.append(f"  integration alone: {second['mean_periods']:.1f} periods per cell x {kernel_s:.3f} s per period "
                     f"of the grid (item 1's kernel) = {integ:.1f} s, "
                     f"{integ / W['numba_plain_period_s']:.0f} numba-periods; the in-process second call "
                     f"{second['wall_s']:.1f} s")
    L.append("")

    C = R.get("convergence", {})
    if C:
        L.append("4. convergence: periodic_orbit at n steps per period (seeded from the previous n); "
                 "|d| = change from the previous n, ord = log2 of the ratio of successive changes")
        L.append("   lambda1: leading multiplier from jax.jacfwd (as reported); FD: central differences of the map itself")
        for key, rows in C.items():
            L.append(f"  {key}")
            L.append(f"  {'n':>6s}  {'point (x1, x2, x3, x4)':47s} {'|d|':>8s} {'ord':>4s}  {'lambda1 (jacfwd)':26s} "
                     f"{'|d|':>8s} {'ord':>4s}  {'lambda1 (FD)':26s} {'|d|':>8s} {'ord':>4s}")
            for r in rows:
                if "lead" not in r:
                    L.append(f"  {r['n']:6d}  {r['status']}")
                    continue
                pt = " ".join(f"{v:11.8f}" for v in r["point"])
                L.append(f"  {r['n']:6d}  {pt:47s} {_fmt(r.get('d_state'), '8.1e'):>8s} "
                         f"{_fmt(r.get('order_state'), '4.1f'):>4s}  {_cplx(r['lead']):26s} "
                         f"{_fmt(r.get('d_lead'), '8.1e'):>8s} {_fmt(r.get('order_lead'), '4.1f'):>4s}  "
                         f"{_cplx(r['lead_fd']):26s} {_fmt(r.get('d_lead_fd'), '8.1e'):>8s} "
                         f"{_fmt(r.get('order_lead_fd'), '4.1f'):>4s}")
    A = R.get("label_agreement")
    if A:
        L.append("  cell labels of the default analysis (Direct, KinkAwareRK4(n)) on the paper grid, n vs 2n:")
        for n, run in A["runs"].items():
            att = ", ".join(f"P-{a['period']}:{a['share']:.4f}" for a in run["attractors"])
            L.append(f"    n={n}: {run['s']:.1f} s, {run['mean_periods']:.1f} periods per cell; {att}")
        for pair, d in A["pairs"].items():
            L.append(f"    n={pair}: {100 * d['agreement']:.3f} % equal labels ({d['differ']} of {d['cells']} cells differ)")
    elif C:
        L.append("  (cell-label agreement at n vs 2n: full run only)")
    L.append("")

    L.append("5. global analysis per method (jaxgear.analyze_global)")
    ga = R.get("global_analysis", {})
    if "skipped" in ga:
        L.append(f"  skipped: {ga['skipped']}")
    else:
        L.append(f"  {'method':16s} {'cells':>8s} {'first s':>9s} {'steady s':>9s} {'periods/cell':>12s} "
                 f"{'ns/step/cell':>12s}  attractors (period:share), sink")
        for method, row in ga.items():
            if "error" in row:
                L.append(f"  {method:16s} {row['cells']:8d}  error: {row['error'][:120]}")
                continue
            att = ", ".join(f"P-{a['period']}:{a['share']:.3f}" for a in row["attractors"])
            L.append(f"  {method:16s} {row['cells']:8d} {row['first_s']:9.2f} {_fmt(row.get('steady_s'), '9.2f'):>9s} "
                     f"{row['mean_periods']:12.1f} {row['ns_per_step_cell']:12.2f}  {att}; sink {row['n_sink']}")
    L.append("")

    L.append("6. parameter sweep and shooting (default integrator)")
    for b in (R.get("bifurcation") or {}).values():
        L.append(f"  bifurcation_diagram in {b['param']}: {b['n_params']} values x {b['n_states']} states x "
                 f"{b['periods']} periods: compile {b['compile_s']:.2f} s, run {b['steady_s']:.2f} s, "
                 f"{b['ns_per_step_state']:.2f} ns/step/state"
                 + (f" (500 periods ~ {b['extrapolated_500_periods_s']:.1f} s)" if "extrapolated_500_periods_s" in b
                    else ""))
    s = R.get("shooting", {})
    if "steady_s" not in s:
        L.append(f"  shooting: {s.get('error', s.get('skipped', '?'))}")
    else:
        orbs = ", ".join(f"P-{o['period']}{' stable' if o['stable'] else ' unstable'}" for o in s["orbits"])
        L.append(f"  find_periodic_orbits, {s['guesses']} random seeds, period 4 (Newton, jacfwd): compile "
                 f"{s['compile_s']:.2f} s, run {s['steady_s']:.2f} s; distinct orbits: {orbs or 'none'}")
    L.append("")

    L.append("7. scaling: one period, 200 steps, fresh process per size; peak RSS (VmHWM) of the "
             "process, 'before' = after imports and input, before the kernel")
    sc = R.get("scaling", {})
    L.append(f"  {'kernel':20s} {'cells':>10s} {'compile s':>9s} {'run s':>9s} {'ns/step/cell':>12s} "
             f"{'peak RSS MB':>11s} {'before MB':>9s}")
    for key, m in sc.items():
        kind, n = key.split("/")
        if "steady_s" not in m:
            L.append(f"  {kind:20s} {int(n):10,d}  error")
            continue
        extra = (f"  whole direct analysis, {m['cells']:,d} cells, {m['mean_periods']:.1f} periods/cell"
                 if kind == "direct" else "")
        L.append(f"  {kind:20s} {int(n):10,d} {_fmt(m['compile_s'], '9.2f'):>9s} {m['steady_s']:9.3f} "
                 f"{m['ns_per_step_cell']:12.2f} {m['peak_rss_MB']:11.0f} {m['rss_before_kernel_MB']:9.0f}{extra}")
    L.append("")
    if "kernel_ratio" in K:
        L.append(f"kernel: default integrator = {K['kernel_ratio']:.2f} x numba kink-aware "
                 f"({K['default']['ns_per_step_cell']:.2f} vs {K['numba_blocked_kink']['ns_per_step_cell']:.2f} "
                 f"ns/step/cell; target <= {TARGET_KERNEL_RATIO})")
    L.append(headline(R))
    return L


def kink_jax_table(R) -> list[str]:
    J = R.get("kink_jax")
    if not J:
        return []
    L = [f"1b. pure-JAX kink-aware step (GPU and derivative path), paper grid ({J['n_cells']:,d} cells), "
         f"1 period, {STEPS} steps; CPU time best of the repeats"]
    for key, label in (("rk4", "RK4(200), plain, pure JAX"), ("kink_jax", "KinkAwareRK4(200, native=False)")):
        m = J[key]
        L.append(f"  {label:44s} first call {m['first_s']:6.2f} s  CPU {m['cpu_s']:7.3f} s  "
                 f"{m['ns_per_step_cell']:8.2f} ns/step/cell")
    L.append(f"  pure-JAX ratio = kink-aware / plain RK4 (CPU time): {J['ratio']:.2f} (goal <= 3)")
    one = J.get("one_core", {})
    if one.get("ratios"):
        L.append("  the same on one core, fresh processes: plain " + ", ".join(f"{x:.2f}" for x in one["rk4"])
                 + "; kink-aware " + ", ".join(f"{x:.2f}" for x in one["kink_jax"]) + " ns/step/cell; ratios "
                 + ", ".join(f"{x:.2f}" for x in one["ratios"]))
    elif one:
        L.append(f"  the same on one core: {one.get('error', '?')[-200:]}")
    L.append("  fraction of steps that cross a switching surface, per period: "
             + ", ".join(f"{100 * v:.2f} %" for v in J["crossing_fraction"]))
    for key, H in J["hlo_one_step"].items():
        c = "" if H.get("compile_s") is None else f", compiled in {H['compile_s']:.2f} s"
        L.append(f"  compiled HLO of one {key} step: {H['ops']} unfused operations, {H['fusions']} fusions, "
                 f"{H['instructions']} instructions{c}")
    for key, m in J.get("first_calls", {}).items():
        L.append(f"  first call, fresh process, {key}: " + (f"{m['first_s']:.1f} s" if "first_s" in m
                                                            else m.get("error", "?")[-200:]))
    for name, row in J.get("user_systems", {}).items():
        L.append(f"  user system {name:20s} (switching functions: {'yes' if row['switching'] else 'no '}): "
                 f"plain {row['rk4']['ns_per_step_cell']:.2f}, kink-aware {row['kink_jax']['ns_per_step_cell']:.2f} "
                 f"ns/step/state (x{row['ratio']:.2f})")
    L.append("")
    return L


# =========================================================================== main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a few minutes' version")
    ap.add_argument("--json", default=None, help="output JSON path (default benchmarks/results[-quick].json)")
    ap.add_argument("--skip-global", action="store_true", help="skip item 5 (the global analysis per method)")
    ap.add_argument("--kink-jax", action="store_true",
                    help="only item 1b (the pure-JAX kink-aware step against pure-JAX plain RK4; a few minutes)")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--repeat", type=int, default=3, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    import jaxgear  # noqa: F401  (enables float64 before any kernel is built)

    if a.worker:
        if a.worker == "one-core":
            print(json.dumps(_one_core_worker()))
        elif a.worker.startswith("first:"):
            print(json.dumps(_first_call_worker(a.worker[len("first:"):])))
        else:
            print(json.dumps(_worker(a.worker, a.n, a.repeat)))
        return
    if a.kink_jax:
        R = {"load_start": loadavg(), "date": time.strftime("%Y-%m-%d %H:%M:%S")}
        bench_kink_jax(R, paper_centres(), repeat=5)
        R["load_end"] = loadavg()
        print(f"load average at start {_fmt((R['load_start'] or [None])[0], '.2f')}, "
              f"end {_fmt((R['load_end'] or [None])[0], '.2f')}")
        print("\n".join(kink_jax_table(R)), flush=True)
        if a.json:
            with open(a.json, "w") as fh:
                json.dump(R, fh, indent=1, default=float)
        return

    R = {"quick": bool(a.quick), "date": time.strftime("%Y-%m-%d %H:%M:%S"), "load_start": loadavg()}
    R["machine"] = machine_info()
    t_all = time.perf_counter()
    X = paper_centres()
    repeat = 3 if a.quick else 5
    print("item 1: kernel ...", flush=True)
    bench_kernel(X, repeat, R)
    print("item 1b: pure-JAX kink-aware step ...", flush=True)
    bench_kink_jax(R, X, repeat, first_calls=not a.quick)
    print("item 2: other CPU styles ...", flush=True)
    bench_other_styles(X, repeat, R, scipy_sample=50 if a.quick else 200, diffrax_sample=500 if a.quick else 2000)
    print("item 3: whole job ...", flush=True)
    bench_whole_job(R, X)
    print("item 4: convergence ...", flush=True)
    bench_convergence(R, (100, 200, 400) if a.quick else (100, 200, 400, 800, 1600, 3200))
    if not a.quick:
        bench_label_agreement(R)
    print("item 5: global analysis per method ...", flush=True)
    if a.skip_global:
        R["global_analysis"] = {"skipped": "--skip-global"}
    else:
        bench_global_analysis(R, a.quick, repeat_cheap=not a.quick)
    print("item 6: parameter sweep, shooting ...", flush=True)
    bench_bifurcation(R, a.quick)
    bench_shooting(R, a.quick)
    print("item 7: scaling ...", flush=True)
    sizes = [100_000] if a.quick else [10_000, 100_000, 1_000_000]
    # (quick: the direct analysis is item 3's; plain RK4 is item 1's)
    kinds = ["jaxgear", "numba-blocked-kink"] if a.quick else ["jaxgear", "jaxgear-rk4", "numba-blocked-kink", "direct"]
    bench_scaling(R, sizes, kinds)
    R["load_end"] = loadavg()
    R["total_wall_s"] = time.perf_counter() - t_all
    R.pop("_Y", None)
    lines = print_table(R)
    path = a.json or os.path.join(HERE, "results-quick.json" if a.quick else "results.json")
    with open(path, "w") as fh:
        json.dump({**R, "table": lines}, fh, indent=1, default=float)
    print(f"(json: {os.path.relpath(path, ROOT)}; total {R['total_wall_s']:.0f} s)", file=sys.stderr, flush=True)
    print()
    print("\n".join(lines), flush=True)  # its last line, the headline, is the last line of the output


if __name__ == "__main__":
    main()
