"""Cost of the analysis in the chaotic band, and a backlash basin sweep through it: plain script, figures printed, nothing asserted.

    python benchmarks/attractors.py            # paper grid 50 x 30 x 60; sweep on 25 x 15 x 30
    python benchmarks/attractors.py --quick    # grid 10 x 6 x 12; sweep on 5 x 3 x 6
    python benchmarks/attractors.py --figure docs/attractors_backlash.png   # also draw the sweep

1. The global analysis of the reduced gear model (``jaxgear.analyze_global``, the default
   ``Direct`` method, no label-uncertainty sample) on the paper's region D at the paper
   preset (half backlash b_sp = b_rp = 5: P-4 and P-8) and at b_sp = b_rp = 2 (a chaotic
   attractor), one after the other in this process after a warm-up on a small grid (the
   compiled kernels are shared): the mean periods per cell and the wall time of each,
   and their ratio (the goal: b = 2 costs at most twice the paper preset).
2. A 12-value basin sweep of b = b_sp = b_rp from 1 to 3.5 (``jaxgear.basin_sweep``,
   attractors matched across values, no uncertainty sample) on the grid over region D,
   with its wall time; per value, each attractor's label, share and largest Lyapunov
   exponent, and the boundary basin entropy S_bb of the labels (boxes of 5^3 cells; read
   from the per-value results the sweep saves in its folder), and the largest share of
   unresolved cells over the values (the goal: none; b = 1.455, whose chaotic attractor
   spans about a box of the partition, once left every cell unresolved).

The LAST line is the headline. Runs on JAX's default device; on a shared machine run
the full version once.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

import jaxgear as jg
from jaxgear._model import REDUCED
from jaxgear.analysis._fractal import basin_entropy

FULL = dict(grid=(50, 30, 60), sweep_grid=(25, 15, 30))
QUICK = dict(grid=(10, 6, 12), sweep_grid=(5, 3, 6))
SWEEP_VALUES = np.linspace(1.0, 3.5, 12)


def analysis_cost(b: float, counts, say=print) -> dict:
    """One analysis of region D at half backlash ``b``: wall time, mean periods per cell,
    the attractors (label, share, largest exponent)."""
    params = jg.paper_params(b_sp=b, b_rp=b)
    t = time.perf_counter()
    r = jg.analyze_global(REDUCED, params, jg.CellGrid.paper(tuple(counts)), progress=False, uncertainty=0)
    wall = time.perf_counter() - t
    found = ", ".join(f"{a.label} {100 * a.share:.1f} % (lambda_1 {a.largest_exponent:+.3f})" for a in r.attractors)
    say(f"b = {b:g}: {r.n_cells} cells, {wall:.1f} s, mean {r.mean_periods:.1f} periods per cell, "
        f"unresolved {r.n_unresolved}; {found}")
    return dict(b=b, wall=wall, periods=float(r.mean_periods), cells=int(r.n_cells), unresolved=int(r.n_unresolved))


def backlash_sweep(counts, folder: Path, say=print):
    """The 12-value basin sweep of ``b`` on ``counts`` cells over region D: the sweep, its
    wall time and the per-value results (saved by the sweep in ``folder/parts``)."""
    grid = jg.CellGrid.paper(tuple(counts))
    t = time.perf_counter()
    sweep = jg.basin_sweep(REDUCED, jg.paper_params(), "b", SWEEP_VALUES, grid, options=jg.BasinOptions(uncertainty=0),
                           runner=jg.Runner(out=folder, progress=False, save=False))
    wall = time.perf_counter() - t
    parts = [jg.load(p) for p in sorted((folder / "parts").glob("value_*.nc"))]
    for v, r in zip(SWEEP_VALUES, parts):
        found = ", ".join(f"{a.label} {100 * a.share:.0f} % ({a.largest_exponent:+.3f})" for a in r.attractors)
        labels = np.asarray(r.labels).reshape(r.grid.counts)
        box = 5 if min(r.grid.counts) >= 5 else 2
        ent = basin_entropy(labels, box=box)
        boundary = f"S_bb {ent.S_bb:.3f} (box {box})" if ent.n_boundary_boxes else "no box with two outcomes"
        say(f"  b = {v:.3f}: {found}; unresolved {100 * r.n_unresolved / r.n_cells:.0f} %, "
            f"{r.mean_periods:.0f} periods per cell; {boundary}")
    return sweep, parts, wall


def figure(parts, path: Path) -> None:
    """Two panels against b: the share of region D attracted to periodic, chaotic and
    quasi-periodic attractors (and unresolved or escaped), and the largest Lyapunov
    exponent of every attractor (per forcing period)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxgear._lyapunov import AttractorType

    b = SWEEP_VALUES
    kinds = [(AttractorType.PERIODIC, "periodic (P-k)", "tab:blue"), (AttractorType.CHAOTIC, "chaotic", "tab:red"),
             (AttractorType.QUASI_PERIODIC, "quasi-periodic", "tab:green")]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True, height_ratios=(3, 2))
    bottom_y = np.zeros(len(b))
    width = 0.8 * (b[1] - b[0])
    for kind, name, colour in kinds:
        share = np.array([sum(a.share for a in r.attractors if a.type == kind) for r in parts])
        top.bar(b, 100 * share, width, bottom=100 * bottom_y, color=colour, label=name)
        bottom_y += share
    rest = 1.0 - bottom_y
    top.bar(b, 100 * rest, width, bottom=100 * bottom_y, color="0.8", label="unresolved or escaped")
    top.set_ylabel("share of region D (%)")
    top.set_ylim(0, 100)
    top.legend(loc="lower right", fontsize=8)
    top.set_title("Reduced gear model, paper preset with half backlash b = b_sp = b_rp")
    for kind, _, colour in kinds:
        pts = [(v, a.largest_exponent, a.exponent_errors[0]) for v, r in zip(b, parts) for a in r.attractors
               if a.type == kind and len(a.exponent_errors)]
        if pts:
            x, y, err = np.array(pts).T
            bottom.errorbar(x, y, yerr=err, fmt="o", color=colour, capsize=2)
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.set_ylabel("largest Lyapunov exponent\n(per forcing period)")
    bottom.set_xlabel("half backlash b")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="small grids (a check that the script runs)")
    p.add_argument("--figure", type=Path, default=None, help="draw the sweep into this PNG")
    a = p.parse_args()
    size = QUICK if a.quick else FULL
    print(f"{jax.devices()[0].platform}, {jax.device_count()} device(s); analysis grid "
          f"{'x'.join(map(str, size['grid']))}, sweep grid {'x'.join(map(str, size['sweep_grid']))}")
    analysis_cost(5.0, (4, 3, 4), say=lambda s: None)  # warm-up: compile the kernels once
    paper = analysis_cost(5.0, size["grid"])
    chaotic = analysis_cost(2.0, size["grid"])
    print(f"b = 2 against the paper preset: {chaotic['periods'] / paper['periods']:.2f}x the periods per cell, "
          f"{chaotic['wall'] / paper['wall']:.2f}x the wall time")
    with tempfile.TemporaryDirectory(prefix="jaxgear-bench-") as tmp:
        print(f"basin sweep of b over {len(SWEEP_VALUES)} values from {SWEEP_VALUES[0]:g} to {SWEEP_VALUES[-1]:g}:")
        sweep, parts, wall = backlash_sweep(size["sweep_grid"], Path(tmp))
        worst = max(r.n_unresolved / r.n_cells for r in parts)
        if a.figure is not None:
            figure(parts, a.figure)
            print(f"wrote {a.figure}")
    print(f"paper grid: b = 5 {paper['periods']:.1f} and b = 2 {chaotic['periods']:.1f} mean periods per cell "
          f"(ratio {chaotic['periods'] / paper['periods']:.2f}; {paper['wall']:.1f} s and {chaotic['wall']:.1f} s); "
          f"12-value backlash sweep on {sweep.grid.n_cells} cells per value: {wall:.1f} s, "
          f"at most {100 * worst:.1f} % unresolved")


if __name__ == "__main__":
    main()
