"""The whole job against its engine: what a user waits for, as multiples of the integration
it needs. Plain script, figures printed, nothing asserted.

    python benchmarks/job.py             # ~5 min on 2 cores
    python benchmarks/job.py --no-sweep  # without the 10-value basin sweep (~2 min)
    python benchmarks/job.py --cold      # also the README's first command with empty caches

The *integration floor* is one forcing period of the 90,000 paper-grid cell centres with
the default integrator (best of 5) times the mean periods per cell of the paper preset's
analysis: the integration the main job cannot avoid. Measured in the same run, so the
ratios hold on a busy machine too:

- ``jaxgear analyze --no-figures`` as a whole process with a warm compilation cache
  (median of 3; its CPU use as a share of the cores);
- ``jaxgear.analyze_global()`` in this process, second call, with the default label
  uncertainty and without it (best of 2 each);
- ``jaxgear.analyze_global()`` as the first call of a new Python process with a warm
  compilation cache (``jaxgear.enable_compilation_cache()``; the import apart);
- what the extra measures (label uncertainty, uncertainty exponent, exponents, basin
  entropy) add, as a share of the analysis without them;
- what the gear view of every attractor (contact regimes, transmission error, mesh forces,
  spectra in physical units: ``jaxgear.gear_views``, as ``jaxgear analyze`` prints it)
  adds, warm, as a share of the analysis;
- a 10-value basin sweep over the backlash on the paper grid, per value;
- (``--cold``) the README's first command, ``jaxgear analyze``, with empty caches.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

FIRST_CALL = """
import time
t0 = time.perf_counter()
import jaxgear
jaxgear.enable_compilation_cache()
t1 = time.perf_counter()
jaxgear.analyze_global(progress=False)
t2 = time.perf_counter()
print(f"{t1 - t0:.3f} {t2 - t1:.3f}")
"""


def integration_floor(repeat: int = 5) -> tuple[float, float]:
    """Seconds of one period of the paper grid with the default integrator, and the mean
    periods per cell of the default analysis."""
    import jax
    import jax.numpy as jnp

    import jaxgear as jg

    p, grid, integrator = jg.paper_params(), jg.CellGrid.paper(), jg.default_integrator()
    Y = jax.device_put(jnp.asarray(grid.centres().T))
    period = jax.jit(lambda Y: integrator.advance(jg.REDUCED, p, Y, jnp.asarray(0.0), 1))
    period(Y).block_until_ready()
    best = min(_timed(lambda: period(Y).block_until_ready()) for _ in range(repeat))
    r = jg.analyze_global(progress=False, uncertainty=0)
    return best, float(r.mean_periods)


def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def _process(cmd: list[str], env: dict) -> tuple[float, float]:
    """Wall seconds and CPU seconds (user + system) of a child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-sweep", action="store_true", help="skip the 10-value basin sweep")
    ap.add_argument("--cold", action="store_true", help="also the README's first command with empty caches")
    args = ap.parse_args(argv)

    import jaxgear as jg

    jg.enable_compilation_cache()
    cores = len(os.sched_getaffinity(0))
    env = dict(os.environ)
    rows = []

    one, periods = integration_floor()
    floor = one * periods
    print(f"integration floor: {one * 1e3:.1f} ms per period x {periods:.2f} periods = {floor:.2f} s", flush=True)

    def row(what, seconds, goal, note=""):
        rows.append((what, seconds, seconds / floor, goal, note))
        print(f"{what}: {seconds:.2f} s = {seconds / floor:.2f} x floor {note}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        cli = [sys.executable, "-m", "jaxgear", "analyze", "--no-figures", "--out", os.path.join(tmp, "out")]
        _process(cli, env)  # fills the compilation cache
        runs = [_process(cli, env) for _ in range(3)]
        wall = statistics.median(w for w, _ in runs)
        cpu = statistics.median(c / w for w, c in runs) / cores
        row("jaxgear analyze --no-figures, warm cache (process)", wall, "<= 2", f"(CPU {cpu:.0%} of {cores} cores)")

    t_unc = min(_timed(lambda: jg.analyze_global(progress=False)) for _ in range(2))
    t_plain = min(_timed(lambda: jg.analyze_global(progress=False, uncertainty=0)) for _ in range(2))
    row("analyze_global() second call, default", t_unc, "<= 1.25")
    row("analyze_global(uncertainty=0) second call", t_plain, "-")

    out = subprocess.run([sys.executable, "-c", FIRST_CALL], env=env, check=True, capture_output=True, text=True)
    t_import, t_first = (float(x) for x in out.stdout.split()[-2:])
    row("analyze_global() first call, new process, warm cache", t_first, "<= 2.5", f"(import {t_import:.2f} s)")

    extra = (t_unc - t_plain) / t_plain
    rows.append(("extra measures / analysis without them", extra, None, "<= 25 %", ""))
    print(f"extra measures: {extra:.0%} of the analysis without them (goal <= 25 %)", flush=True)

    result = jg.analyze_global(progress=False, uncertainty=0)
    views = lambda: jg.gear_views(jg.REDUCED, jg.paper_params(), result.attractors, jg.paper_gear_set())  # noqa: E731
    views()  # compiles its programs
    t_views = min(_timed(views) for _ in range(3))
    rows.append(("gear view of every attractor / analysis", t_views / t_unc, None, "within the quarter", ""))
    print(f"gear view of the {len(result.attractors)} attractors: {t_views:.2f} s = {t_views / t_unc:.0%} of the "
          "analysis", flush=True)

    if not args.no_sweep:
        values = np.linspace(1.0, 3.0, 10)
        t = _timed(lambda: jg.basin_sweep(jg.REDUCED, jg.paper_params(), "b", values, jg.CellGrid.paper(),
                                          runner=jg.Runner(progress=False)))
        row("basin sweep of 10 backlash values, per value", t / len(values), "-")

    if args.cold:
        with tempfile.TemporaryDirectory() as tmp:
            cold = dict(env, JAXGEAR_CACHE_DIR=os.path.join(tmp, "cache"), XDG_CACHE_HOME=os.path.join(tmp, "xdg"))
            wall, _ = _process([sys.executable, "-m", "jaxgear", "analyze", "--out", os.path.join(tmp, "out")], cold)
        rows.append(("jaxgear analyze, cold (no caches), s", wall, None, "< 60 s", ""))
        print(f"cold first run of jaxgear analyze: {wall:.1f} s (goal < 60 s)", flush=True)

    print()
    print(f"| what a user runs | wall time | x the integration ({floor:.2f} s) | goal |")
    print("|---|---|---|---|")
    for what, value, ratio, goal, note in rows:
        if ratio is None:
            shown = f"{value:.0%}" if "measures" in what else f"{value:.1f} s"
            print(f"| {what} | {shown} | | {goal} |")
        else:
            print(f"| {what} {note}".rstrip() + f" | {value:.2f} s | {ratio:.2f} | {goal} |")


if __name__ == "__main__":
    main()
