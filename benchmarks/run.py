"""Benchmark suite of jaxgear: plain script, figures printed, nothing asserted.

    python benchmarks/run.py            # full run (~5-10 min on 2 cores)
    python benchmarks/run.py --quick    # ~1-2 min version
    python benchmarks/run.py --json out.json

Measures, in one run on one machine (compile time reported apart from execution:
``compile = first call - steady state``, ``steady state = min(timeit.repeat(...))``):

1. the stroboscopic map of the 90,000 paper-grid cell centres (region D of paper eq. 10,
   50 x 30 x 60 cells on x4 = 0) over one forcing period, classical RK4, 200 steps per
   period, float64 — ``jaxgear.stroboscopic_map``;
2. the same map in baselines written for the benchmark (``benchmarks/baselines.py``):
   numba blocked/tabulated/vectorised (strongest CPU style), numba naive per-cell,
   ``scipy.integrate.solve_ivp`` (RK45) in a Python loop, diffrax Tsit5 vmapped;
3. the whole global analysis per method (``jaxgear.analyze_global``, if present);
4. a bifurcation-diagram workload (200 Omega x 8 states x 500 periods, ``jax.vmap``
   over parameters) and batched Newton shooting (``jaxgear.find_periodic_orbits``,
   if present);
5. time and peak resident memory against the number of cells (fresh subprocess per
   size), jaxgear's kernel before/after chunking and numba.

Prints a table (its LAST line is the ratio jaxgear / numba-blocked for item 1) and
writes every figure plus a machine description to a JSON file.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import subprocess
import sys
import time
import timeit

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

STEPS = 200  # RK4 steps per forcing period (jaxgear's default, paper §4.1)


# =========================================================================== helpers
def machine_info() -> dict:
    """CPU model, cores, caches, library versions, load average."""
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
    try:
        info["usable_cpus"] = len(os.sched_getaffinity(0))
    except AttributeError:
        pass
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
    import diffrax
    import jax
    import jaxlib
    import scipy

    info["jax"] = jax.__version__
    info["jaxlib"] = jaxlib.__version__
    info["diffrax"] = diffrax.__version__
    info["scipy"] = scipy.__version__
    info["numpy"] = np.__version__
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
    t = time.perf_counter()
    fn()
    first = time.perf_counter() - t
    steady = min(timeit.repeat(fn, number=1, repeat=repeat)) if repeat > 0 else first
    return {"first_s": first, "steady_s": steady, "compile_s": max(first - steady, 0.0), "repeats": repeat}


def ns_per_step(seconds: float, n_cells: int, periods: int = 1, steps: int = STEPS) -> float:
    return seconds / (n_cells * periods * steps) * 1e9


def paper_centres(counts=(50, 30, 60)) -> np.ndarray:
    """The cell centres of the paper's region D (eq. 10) on x4 = 0: ``(n, 4)``, x1 slowest."""
    bounds = ((-25.0, 25.0), (-10.0, 20.0), (-10.0, 50.0))
    axes = [lo + (hi - lo) / c * (np.arange(c) + 0.5) for (lo, hi), c in zip(bounds, counts)]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.concatenate([g, np.zeros((len(g), 1))], axis=1)


def random_states(n: int, seed: int = 0) -> np.ndarray:
    """``n`` states uniform in region D on x4 = 0 (for the scaling runs)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-25.0, -10.0, -10.0]), np.array([25.0, 20.0, 50.0])
    return np.concatenate([rng.uniform(lo, hi, (n, 3)), np.zeros((n, 1))], axis=1)


def _block(x):
    import jax

    return jax.block_until_ready(x)


# =========================================================================== item 1
def bench_strobe(X, repeat, R):
    """Item 1: jaxgear.stroboscopic_map of all cells over one period."""
    import jax
    import jax.numpy as jnp

    import jaxgear

    p = jaxgear.paper_params()
    Xj = jnp.asarray(X)
    n = len(X)
    jax.clear_caches()
    fn = lambda: _block(jaxgear.stroboscopic_map(jaxgear.REDUCED, p, Xj, periods=1))  # noqa: E731
    m = measure(fn, repeat)
    m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
    m["n_cells"] = n
    R["strobe_jaxgear"] = m
    Y = np.asarray(fn())
    R["_Y_jaxgear"] = Y
    m["non_finite"] = int((~np.isfinite(Y).all(axis=1)).sum())

    # The same map in chunks of 16,384 cells (analyze_global's default chunk_size),
    # one call per chunk: the cost of cutting the batch small on this machine.
    C = 16384
    Xp = np.concatenate([X, np.repeat(X[:1], (-n) % C, axis=0)])
    parts = [jnp.asarray(Xp[i:i + C]) for i in range(0, len(Xp), C)]
    fc = lambda: [_block(jaxgear.stroboscopic_map(jaxgear.REDUCED, p, q, periods=1)) for q in parts]  # noqa: E731
    mc = measure(fc, max(1, repeat - 2))
    mc["ns_per_step_cell"] = ns_per_step(mc["steady_s"], n)
    mc["chunk"] = C
    R["strobe_jaxgear_chunks16k"] = mc


# =========================================================================== item 2
def bench_baselines(X, repeat, R, scipy_sample, diffrax_sample):
    """Item 2: numba (blocked, naive), solve_ivp loop, diffrax vmap; agreement checks."""
    import jax
    import jax.numpy as jnp

    import baselines as B
    import jaxgear

    p = jaxgear.paper_params()
    n = len(X)
    Yj = R["_Y_jaxgear"]
    rng = np.random.default_rng(1)

    try:
        import numba
    except ImportError:
        numba = None
    if numba is not None:
        fb = lambda: B.numba_blocked(p, X, block=512)  # noqa: E731
        m = measure(fb, repeat)
        m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
        Yb = fb()
        m["max_abs_diff_vs_jaxgear"] = float(np.max(np.abs(Yb - Yj)))
        m["threads"] = numba.get_num_threads()
        m["block"] = 512
        R["strobe_numba_blocked"] = m

        nt = numba.get_num_threads()
        numba.set_num_threads(1)
        m1 = measure(fb, repeat)
        numba.set_num_threads(nt)
        m1["ns_per_step_cell"] = ns_per_step(m1["steady_s"], n)
        R["strobe_numba_blocked_1thread"] = m1

        fnv = lambda: B.numba_naive(p, X)  # noqa: E731
        m = measure(fnv, max(1, repeat // 2))
        m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
        m["max_abs_diff_vs_jaxgear"] = float(np.max(np.abs(fnv() - Yj)))
        R["strobe_numba_naive"] = m
    else:
        R["strobe_numba_blocked"] = {"skipped": "numba is not installed"}

    # solve_ivp, a sample of cells, extrapolated to all cells.
    idx = np.sort(rng.choice(n, size=min(scipy_sample, n), replace=False))
    t = time.perf_counter()
    Ys = B.scipy_loop(p, X[idx], rtol=1e-8, atol=1e-8)
    ts = time.perf_counter() - t
    R["strobe_scipy"] = {
        "sample": int(len(idx)), "sample_s": ts, "steady_s": ts * n / len(idx), "compile_s": 0.0,
        "extrapolated": True, "rtol": 1e-8, "atol": 1e-8, "method": "RK45",
        "max_abs_diff_vs_jaxgear_rk4": float(np.max(np.abs(Ys - Yj[idx]))),
    }
    R["strobe_scipy"]["ns_per_step_cell"] = ns_per_step(R["strobe_scipy"]["steady_s"], n)

    # diffrax Tsit5 vmapped, a sample (same for every call), extrapolated.
    idx_d = np.sort(rng.choice(n, size=min(diffrax_sample, n), replace=False))
    run = B.make_diffrax_vmap(rtol=1e-8, atol=1e-8)
    Xd = jnp.asarray(X[idx_d])
    fd = lambda: _block(run(p, Xd, 0.0, 1))  # noqa: E731
    m = measure(fd, max(1, repeat // 2))
    Yd, nsteps = (np.asarray(a) for a in fd())
    m.update(sample=int(len(idx_d)), sample_s=m["steady_s"], extrapolated=len(idx_d) < n,
             mean_accepted_steps=float(np.mean(nsteps)), max_steps_in_batch=int(np.max(nsteps)),
             max_abs_diff_vs_jaxgear_rk4=float(np.max(np.abs(Yd - Yj[idx_d]))))
    m["steady_s"] = m["sample_s"] * n / len(idx_d)
    m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
    common = np.intersect1d(idx, idx_d)
    if len(common):
        a = Ys[np.searchsorted(idx, common)]
        b = Yd[np.searchsorted(idx_d, common)]
        m["max_abs_diff_vs_scipy_common_cells"] = float(np.max(np.abs(a - b)))
        m["common_cells"] = int(len(common))
    R["strobe_diffrax"] = m
    del jax


# =========================================================================== item 3
def bench_global_analysis(R, quick: bool, repeat_cheap: bool):
    """Item 3: the whole global analysis per method (``jaxgear.analyze_global``).

    Skipped with a note while ``jaxgear.analyze_global`` does not exist. One cold call
    per method (compile included); in a full run the cheaper methods are called a
    second time for their steady-state figure.
    """
    import jaxgear

    if not hasattr(jaxgear, "analyze_global"):
        R["global_analysis"] = {"skipped": "jaxgear.analyze_global does not exist in this tree"}
        return
    import warnings

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
    for method, grid, again in (("poincare-like", sec_grid, repeat_cheap),
                                 ("stroboscopic", strobe_grid, repeat_cheap),
                                 ("direct", sec_grid, repeat_cheap)):
        row = {"cells": grid.n_cells, "grid": list(grid.counts)}
        try:
            with warnings.catch_warnings(record=True) as w:
                warnings.simplefilter("always")
                t = time.perf_counter()
                res = jaxgear.analyze_global(method=method, grid=grid, progress=False)
                row["first_s"] = time.perf_counter() - t
                if again:
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
        out[method] = row
    R["global_analysis"] = out


# =========================================================================== item 4
def bench_bifurcation(R, quick: bool):
    """Item 4a: bifurcation diagram, 200 values x 8 initial states x 500 periods.

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
        fn = lambda: jaxgear.bifurcation_diagram(jaxgear.REDUCED, p, name, values, X8, transient=periods - record,  # noqa: E731
                                                 record=record, direction="independent", progress=False)
        m = measure(fn, 1)
        d = fn()
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
    """Item 4b: batched Newton shooting (``jaxgear.find_periodic_orbits``), if present.

    Placeholder while the shooting module is not in this tree: records a note. When it
    lands, this calls it on 64 random guesses for period-4 orbits of the paper preset.
    """
    import jaxgear

    if not hasattr(jaxgear, "find_periodic_orbits"):
        R["shooting"] = {"skipped": "jaxgear.find_periodic_orbits does not exist in this tree"}
        return
    import inspect

    p = jaxgear.paper_params()
    guesses = random_states(32 if quick else 256, seed=5)
    try:
        fn = lambda: jaxgear.find_periodic_orbits(jaxgear.REDUCED, p, guesses, period=4, progress=False)  # noqa: E731
        m = measure(fn, 1)
        res = fn()
        m["guesses"] = len(guesses)
        m["orbits"] = [{"period": int(o.period), "stable": bool(o.stable), "max_abs_multiplier": float(o.max_multiplier)}
                       for o in res.orbits]
        m["status_counts"] = {str(k): int(v) for k, v in dict(res.status_counts).items()}
        R["shooting"] = m
    except TypeError as e:
        R["shooting"] = {"skipped": f"adapt bench_shooting to the signature "
                                    f"{inspect.signature(jaxgear.find_periodic_orbits)}: {e}"[:300]}


# =========================================================================== item 5
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
    import jax
    import jax.numpy as jnp

    import jaxgear

    p = jaxgear.paper_params()
    X = random_states(n, seed=7)
    rss0 = peak_rss_mb()
    if kind == "jaxgear":
        Xj = jnp.asarray(X)
        fn = lambda: _block(jaxgear.stroboscopic_map(jaxgear.REDUCED, p, Xj, periods=1))  # noqa: E731
    elif kind == "jaxgear-unchunked":
        # The kernel before chunking: one fori_loop over the whole (4, n) batch.
        from jaxgear.integrate import rk4_step

        Yj = jnp.asarray(X.T.copy())

        def unchunked(p, Y):
            h = jaxgear.REDUCED.period(p) / STEPS
            return jax.lax.fori_loop(0, STEPS, lambda i, Z: rk4_step(jaxgear.REDUCED, p, i * h, Z, h), Y)

        f = jax.jit(unchunked)
        fn = lambda: _block(f(p, Yj))  # noqa: E731
    elif kind == "direct":
        # The whole direct global analysis on a paper-region grid of about n cells.
        from jaxgear import CellGrid

        side = round((n / 1.0) ** (1 / 3))
        grid = CellGrid.paper(counts=(side, side, side))
        m = {}
        t = time.perf_counter()
        res = jaxgear.analyze_global(method="direct", grid=grid, progress=False)
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
    elif kind == "numba-blocked":
        import baselines as B

        fn = lambda: B.numba_blocked(p, X, block=512)  # noqa: E731
    else:
        raise ValueError(kind)
    m = measure(fn, repeat)
    m["ns_per_step_cell"] = ns_per_step(m["steady_s"], n)
    m["peak_rss_MB"] = peak_rss_mb()
    m["rss_before_kernel_MB"] = rss0
    m["state_MB"] = X.nbytes / 2**20
    return m


def bench_scaling(R, sizes, kinds):
    """Item 5: time and peak memory against the number of cells, one subprocess each."""
    out = {}
    for kind in kinds:
        for n in sizes:
            repeat = 3 if n <= 100_000 else 2
            cmd = [sys.executable, os.path.abspath(__file__), "--worker", kind, "--n", str(n),
                   "--repeat", str(repeat)]
            t = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
            wall = time.perf_counter() - t
            try:
                m = json.loads(proc.stdout.strip().splitlines()[-1])
            except (IndexError, json.JSONDecodeError):
                m = {"error": (proc.stderr or proc.stdout)[-500:]}
            m["process_wall_s"] = wall
            out[f"{kind}/{n}"] = m
            print(f"  scaling {kind:18s} n={n:>9,d}: "
                  + (f"{m['steady_s']:.3f} s, {m['ns_per_step_cell']:.2f} ns, peak RSS {m['peak_rss_MB']:.0f} MB"
                     if "steady_s" in m else m.get("error", "?")[-200:]), flush=True)
    R["scaling"] = out


# =========================================================================== table
def _fmt(x, spec=".3f", dash="-"):
    return dash if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def print_table(R) -> list[str]:
    L = []
    mi = R["machine"]
    L.append(f"jaxgear benchmark  ({'quick' if R['quick'] else 'full'} run, {R['date']})")
    L.append(f"machine: {mi.get('cpu')}, {mi.get('usable_cpus')} usable cores, L2 {mi.get('L2 cache')}, "
             f"L3 {mi.get('L3 cache')}, SIMD {'/'.join(mi.get('simd', []))}")
    L.append(f"software: jax {mi['jax']}, numba {mi.get('numba')}, scipy {mi['scipy']}, diffrax {mi['diffrax']}; "
             f"load average at start {_fmt((R['load_start'] or [None])[0], '.2f')}, "
             f"end {_fmt((R['load_end'] or [None])[0], '.2f')}")
    L.append("")
    L.append("1-2. stroboscopic map, paper grid (90,000 cells), 1 period, RK4 200 steps, float64")
    hdr = f"  {'implementation':48s} {'compile s':>9s} {'run s':>9s} {'ns/step/cell':>12s}  note"
    L.append(hdr)
    rows = [
        ("jaxgear.stroboscopic_map", "strobe_jaxgear", ""),
        ("jaxgear, 6 calls of 16,384 cells (cell-map chunk)", "strobe_jaxgear_chunks16k", ""),
        ("numba parallel, blocked+tabulated+vectorised", "strobe_numba_blocked", "diff"),
        ("  same, 1 thread", "strobe_numba_blocked_1thread", ""),
        ("numba parallel, naive per-cell prange", "strobe_numba_naive", "diff"),
        ("scipy solve_ivp RK45 loop (rtol=atol=1e-8)", "strobe_scipy", "sample"),
        ("diffrax Tsit5 vmap (rtol=atol=1e-8)", "strobe_diffrax", "sample"),
    ]
    for label, key, note in rows:
        m = R.get(key)
        if not m or "skipped" in m:
            L.append(f"  {label:48s} {'skipped':>9s}  {m.get('skipped', '') if m else ''}")
            continue
        txt = ""
        if note == "diff":
            txt = f"max |diff| vs jaxgear {m['max_abs_diff_vs_jaxgear']:.1e}"
        elif note == "sample":
            txt = (f"{m['sample']} cells in {m['sample_s']:.2f} s, x{R['strobe_jaxgear']['n_cells'] / m['sample']:.0f}; "
                   f"|diff| vs RK4-200 {m['max_abs_diff_vs_jaxgear_rk4']:.1e}")
            if "mean_accepted_steps" in m:
                txt += f"; {m['mean_accepted_steps']:.0f} steps/period"
        L.append(f"  {label:48s} {_fmt(m.get('compile_s'), '.2f'):>9s} {m['steady_s']:9.3f} "
                 f"{m['ns_per_step_cell']:12.2f}  {txt}")
    if "strobe_diffrax" in R and "max_abs_diff_vs_scipy_common_cells" in R["strobe_diffrax"]:
        d = R["strobe_diffrax"]
        L.append(f"  (diffrax vs scipy on {d['common_cells']} common cells: max |diff| "
                 f"{d['max_abs_diff_vs_scipy_common_cells']:.1e})")
    L.append("")
    L.append("3. global analysis (jaxgear.analyze_global)")
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
    L.append("4. parameter sweep and shooting")
    for b in (R.get("bifurcation") or {}).values():
        L.append(f"  bifurcation_diagram in {b['param']}: {b['n_params']} values x {b['n_states']} states x "
                 f"{b['periods']} periods: compile {b['compile_s']:.2f} s, run {b['steady_s']:.2f} s, "
                 f"{b['ns_per_step_state']:.2f} ns/step/state"
                 + (f" (500 periods ~ {b['extrapolated_500_periods_s']:.1f} s)" if "extrapolated_500_periods_s" in b
                    else ""))
    s = R.get("shooting", {})
    if "skipped" in s or "steady_s" not in s:
        L.append(f"  shooting: skipped: {s.get('skipped', '?')}")
    else:
        orbs = ", ".join(f"P-{o['period']}{' stable' if o['stable'] else ' unstable'}" for o in s["orbits"])
        L.append(f"  batched shooting, {s['guesses']} random seeds, period 4 (Newton, jacfwd): compile "
                 f"{s['compile_s']:.2f} s, run {s['steady_s']:.2f} s; distinct orbits: {orbs or 'none'}")
    L.append("")
    L.append("5. scaling: one period, RK4 200 steps, fresh process per size; peak RSS (VmHWM) of the "
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
    if "strobe_numba_blocked" in R and "steady_s" in R["strobe_numba_blocked"]:
        j, nb = R["strobe_jaxgear"]["steady_s"], R["strobe_numba_blocked"]["steady_s"]
        sp = R["strobe_scipy"]["steady_s"] / j
        L.append(f"jaxgear vs solve_ivp loop: {sp:.0f}x faster;  item-1 compile {R['strobe_jaxgear']['compile_s']:.2f} s")
        R["ratio_jaxgear_over_numba_blocked"] = j / nb
        L.append(f"ratio jaxgear / numba(blocked), item 1: {j / nb:.2f}")
    else:
        L.append("ratio jaxgear / numba(blocked), item 1: n/a (numba missing)")
    return L


# =========================================================================== main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="~1-2 minute version")
    ap.add_argument("--json", default=None, help="output JSON path (default benchmarks/results[-quick].json)")
    ap.add_argument("--skip-global", action="store_true", help="skip item 3 (the global analysis)")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--repeat", type=int, default=3, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    import jaxgear  # noqa: F401  (enables float64 before any kernel is built)

    if a.worker:
        print(json.dumps(_worker(a.worker, a.n, a.repeat)))
        return

    R = {"quick": bool(a.quick), "date": time.strftime("%Y-%m-%d %H:%M:%S"), "load_start": loadavg()}
    R["machine"] = machine_info()
    t_all = time.perf_counter()
    X = paper_centres()
    repeat = 3 if a.quick else 5
    print("item 1: jaxgear stroboscopic map ...", flush=True)
    bench_strobe(X, repeat, R)
    print("item 2: baselines ...", flush=True)
    bench_baselines(X, repeat, R, scipy_sample=50 if a.quick else 200,
                    diffrax_sample=500 if a.quick else 2000)
    print("item 3: global analysis ...", flush=True)
    if a.skip_global:
        R["global_analysis"] = {"skipped": "--skip-global"}
    else:
        bench_global_analysis(R, a.quick, repeat_cheap=not a.quick)
    print("item 4: parameter sweep, shooting ...", flush=True)
    bench_bifurcation(R, a.quick)
    bench_shooting(R, a.quick)
    print("item 5: scaling ...", flush=True)
    sizes = [10_000, 100_000] if a.quick else [10_000, 100_000, 1_000_000]
    bench_scaling(R, sizes, ["jaxgear", "jaxgear-unchunked", "numba-blocked", "direct"])
    R["load_end"] = loadavg()
    R["total_wall_s"] = time.perf_counter() - t_all
    R.pop("_Y_jaxgear", None)
    lines = print_table(R)
    print()
    print("\n".join(lines))
    path = a.json or os.path.join(HERE, "results-quick.json" if a.quick else "results.json")
    with open(path, "w") as fh:
        json.dump({**R, "table": lines}, fh, indent=1, default=float)
    print(f"\n(json: {path}; total {R['total_wall_s']:.0f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
