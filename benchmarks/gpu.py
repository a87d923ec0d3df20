"""What a lent GPU measures, in one call: plain script, figures printed, nothing asserted.

    python benchmarks/gpu.py --out DIR              # on the GPU, within --budget seconds (default 420)
    python benchmarks/gpu.py --quick --out DIR      # a dry run of every section at small sizes, any device

A GPU machine may be lent for a few minutes only, so every GPU figure the benchmarks
report comes from this one script. It runs on JAX's default device, which it names,
and starts each section only while the budget lasts (a skipped section says so), the
most telling first:

1. *agreement*: the same work here and in a fresh CPU-only process (``JAX_PLATFORMS=cpu``,
   where the compiled CPU kernel runs): the direct analysis of the reduced model (paper
   preset) on 20 x 12 x 24 cells (the share of cells with the same label, the largest
   share difference), and each of its attractors shot to a periodic orbit (the largest
   difference of the orbit points and of the Floquet multipliers);
2. *paper grid*: :func:`jaxgear.analyze_global` on the 90,000 cells: the first call
   (compilation included), then the best of 3 with the label uncertainty (the default)
   and without;
3. *one pool*: the basin sweep of 8 backlash values on 20 x 12 x 24 cells in one lane
   pool against 8 separate analyses (``benchmarks/sweep_scale.py``);
4. *basin map*: :func:`jaxgear.basin_map` over kappa_amp x b at ``--points`` on the paper
   grid, and the 30 x 30 map projected at that rate (``benchmarks/basin_map.py``);
5. *sweep*: the basin sweep of 50 backlash values in [4, 6] on the paper grid in one pool
   (``batched=True``), compilation included.

Every figure also goes to ``DIR/gpu.json``, with the device, the host and the versions.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

import jax
import numpy as np

import jaxgear as jg

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import basin_map  # noqa: E402
import sweep_scale  # noqa: E402

AGREEMENT_COUNTS = (20, 12, 24)


def agreement_work(counts) -> dict:
    """The direct analysis on ``counts`` cells and its attractors shot to periodic orbits,
    on the default device: labels, shares, and per attractor its orbit point and Floquet
    multipliers (sorted by decreasing modulus, then imaginary part)."""
    p = jg.paper_params()
    r = jg.analyze_global(jg.REDUCED, p, jg.CellGrid.paper(tuple(counts)), progress=False, uncertainty=0)
    points, mus = [], []
    for a in r.attractors:
        if a.period <= 0:
            continue
        o = jg.periodic_orbit(jg.REDUCED, p, np.asarray(a.points)[:1], period=int(a.period), tol=1e-12)
        m = np.asarray(o.multipliers)[0]
        points.append(np.asarray(o.point)[0])
        mus.append(m[np.lexsort((m.imag, -np.abs(m)))])
    return dict(labels=np.asarray(r.labels), shares=np.array([a.share for a in r.attractors]),
                periods=np.array([a.period for a in r.attractors]), points=np.array(points), multipliers=np.array(mus))


def start_cpu_reference(counts, path: Path) -> subprocess.Popen:
    """Section 1's CPU-only process, started at once: it runs on the host's cores while this
    process works on the device."""
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    return subprocess.Popen([sys.executable, __file__, "--worker", str(path), "--counts", *map(str, counts)], env=env)


def agreement(counts, reference: subprocess.Popen, path: Path, say) -> dict:
    """Section 1: :func:`agreement_work` here and in the CPU-only process, compared."""
    here = agreement_work(counts)
    if reference.wait() != 0:
        raise RuntimeError(f"the CPU-only process failed (exit code {reference.returncode})")
    cpu = dict(np.load(path))
    out = dict(counts=list(counts), same_attractors=bool(np.array_equal(here["periods"], cpu["periods"])))
    out["same_labels_share"] = float(np.mean(here["labels"] == cpu["labels"]))
    if out["same_attractors"]:
        out["share_diff"] = float(np.abs(here["shares"] - cpu["shares"]).max())
        out["orbit_diff"] = float(np.abs(here["points"] - cpu["points"]).max(initial=0.0))
        out["multiplier_diff"] = float(np.abs(here["multipliers"] - cpu["multipliers"]).max(initial=0.0))
    say(f"1. agreement with a CPU-only process on {np.prod(counts)} cells: periods {here['periods'].tolist()} "
        f"here, {cpu['periods'].tolist()} on the CPU; same label on {100 * out['same_labels_share']:.2f} % of "
        f"the cells" + (f"; largest differences: share {out['share_diff']:.1e}, orbit point {out['orbit_diff']:.1e}, "
                        f"Floquet multiplier {out['multiplier_diff']:.1e}" if out["same_attractors"] else ""))
    return out


def paper_grid(counts, repeat: int, say) -> dict:
    """Section 2: the global analysis of the paper grid, first call and best of ``repeat``."""
    p, grid = jg.paper_params(), jg.CellGrid.paper(tuple(counts))
    out = dict(counts=list(counts), cells=grid.n_cells)
    for key, unc in (("with_uncertainty", jg.analysis.DEFAULT_SAMPLES), ("without_uncertainty", 0)):
        run = lambda: jg.analyze_global(jg.REDUCED, p, grid, progress=False, uncertainty=unc)  # noqa: B023
        t = time.perf_counter()
        r = run()
        first = time.perf_counter() - t
        times = []
        for _ in range(repeat):
            t = time.perf_counter()
            r = run()
            times.append(time.perf_counter() - t)
        t_best = min(times, default=first)
        out[key] = dict(first_s=first, best_s=t_best, mean_periods=float(r.mean_periods),
                        shares=[[a.label, a.share] for a in r.attractors])
        say(f"2. paper grid ({grid.n_cells} cells), {key.replace('_', ' ')}: first call {first:.2f} s, best of "
            f"{repeat} {t_best:.3f} s; " + ", ".join(f"{a.label} {100 * a.share:.2f} %" for a in r.attractors))
    return out


def one_pool(n_values: int, counts, repeat: int, say) -> dict:
    """Section 3: :func:`sweep_scale.measure`, in one line."""
    m = sweep_scale.measure(n_values, counts, repeat)
    say(f"3. basin sweep of {n_values} values on {m['cells']} cells: separate analyses {m['separate_s']:.2f} s, "
        f"one pool {m['batched_s']:.2f} s (same labels: {m['same_labels']}); ceiling of any pooling "
        f"{m['ceiling']:.2f}x; separate / one pool {m['ratio']:.2f}x")
    return m


def sweep(n_values: int, counts, say) -> dict:
    """Section 5: a basin sweep of ``n_values`` backlash values in one pool, first call."""
    p, grid = jg.paper_params(), jg.CellGrid.paper(tuple(counts))
    t = time.perf_counter()
    s = jg.basin_sweep(jg.REDUCED, p, "b", np.linspace(4.0, 6.0, n_values), grid,
                       options=jg.BasinOptions(batched=True), runner=jg.Runner(progress=False))
    wall = time.perf_counter() - t
    say(f"5. basin sweep of {n_values} values of b on {grid.n_cells} cells, one pool, compilation included: "
        f"{wall:.1f} s ({wall / n_values:.2f} s per value); {s.n_attractors} attractors over the sweep")
    return dict(values=n_values, counts=list(counts), cells=grid.n_cells, wall_s=wall, attractors=int(s.n_attractors))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="gpu-out", help="folder of gpu.json (default gpu-out)")
    ap.add_argument("--budget", type=float, default=420.0, help="seconds: no section starts after (default 420)")
    ap.add_argument("--points", type=int, nargs=2, default=(3, 3), help="basin map points (default 3 3)")
    ap.add_argument("--quick", action="store_true", help="small sizes: a dry run of every section")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--counts", type=int, nargs=3, default=AGREEMENT_COUNTS, help=argparse.SUPPRESS)
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    if a.worker:  # section 1's CPU-only process
        np.savez(a.worker, **agreement_work(a.counts))
        return
    start = time.perf_counter()
    out_dir = Path(a.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    dev = jax.devices()[0]
    paper = (10, 6, 12) if a.quick else (50, 30, 60)
    small = (6, 4, 8) if a.quick else AGREEMENT_COUNTS
    res = dict(device=f"{dev.platform} {dev.device_kind}", devices=jax.device_count(), host=platform.node(),
               cpu=platform.processor() or platform.machine(), jax=jax.__version__, jaxgear=jg.__version__,
               quick=a.quick, budget_s=a.budget, sections={})

    def say(line):
        print(line, flush=True)

    say(f"device: {res['device']} ({res['devices']} device(s)); host {res['host']}; jax {res['jax']}, "
        f"jaxgear {res['jaxgear']}")
    reference = start_cpu_reference(small, out_dir / "cpu-reference.npz")
    sections = [
        ("agreement", 0, lambda: agreement(small, reference, out_dir / "cpu-reference.npz", say)),
        ("paper_grid", 0, lambda: paper_grid(paper, 1 if a.quick else 3, say)),
        ("one_pool", 60, lambda: one_pool(2 if a.quick else 8, small, 1 if a.quick else 2, say)),
        ("basin_map", 60, lambda: basin_map.measure((2, 2) if a.quick else tuple(a.points), paper,
                                                    say=lambda s: say("4. " + s))),
        ("sweep", 90, lambda: sweep(3 if a.quick else 50, paper, say)),
    ]
    for name, needs, fn in sections:
        left = a.budget - (time.perf_counter() - start)
        if left < needs:
            say(f"{name}: skipped, {left:.0f} s of the budget left (it needs about {needs} s)")
            res["sections"][name] = "skipped"
            continue
        t = time.perf_counter()
        try:
            res["sections"][name] = fn()
        except Exception as e:  # a failing section is a finding: report it and go on
            say(f"{name}: FAILED: {type(e).__name__}: {e}")
            res["sections"][name] = dict(error=f"{type(e).__name__}: {e}")
        say(f"   ({name}: {time.perf_counter() - t:.1f} s)")
        (out_dir / "gpu.json").write_text(json.dumps(res, indent=1, default=float))
    say(f"all sections: {time.perf_counter() - start:.1f} s; figures in {out_dir / 'gpu.json'}")


if __name__ == "__main__":
    main()
