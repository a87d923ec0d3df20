"""Scale benchmark of the basin sweep: plain script, figures printed, nothing asserted.

    python benchmarks/sweep_scale.py                 # 8 backlash values, 20 x 12 x 24 cells
    python benchmarks/sweep_scale.py --values 4 --counts 10 6 12

Measures, in one run on one machine, the basin sweep of the reduced gear model (paper
preset, default method :class:`jaxgear.Direct` with its label uncertainty) over
``--values`` backlash values ``b`` in [4, 6]:

1. *batched*: :func:`jaxgear.basin_sweep` with ``batched=True``, all values in one lane pool over
   (value, cell) pairs;
2. *separate*: :func:`jaxgear.analyze_global` at each value, one after the other (what
   ``basin_sweep`` does by default);

each as ``min`` over ``--repeat`` calls after one warm-up call (compilation apart), and
checks that both give the same shares and labels at every value. Then the ceiling of any
pooling: the separate analyses without the label uncertainty against integrating their
cell-periods (cells x mean periods per cell) alone, all states in one batch with the
method's integrator, no decisions, pilot or draining; no way of pooling the values can be
cheaper than that integration. The LAST line is the headline: separate / batched.
"""

from __future__ import annotations

import argparse
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

import jaxgear as jg


def best(fn, repeat: int):
    fn()  # warm-up: compilation
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def integration_alone(params, grid, results, repeat: int):
    """Wall time of integrating every cell centre of every value for the results' mean
    periods per cell, in one batch, one compiled period at a time (the method's integrator,
    parameters of the first value: the cost of a period does not depend on them)."""
    integrator = jg.Direct().integrator
    periods = int(round(float(np.mean([r.mean_periods for r in results]))))
    one = jax.jit(lambda Y: integrator.advance(jg.REDUCED, params, Y, jnp.asarray(0.0), 1))
    Y0 = jnp.asarray(np.tile(grid.centres(), (len(results), 1)).T)

    def run():
        Y = Y0
        for _ in range(periods):
            Y = one(Y)
        return Y.block_until_ready()

    return best(run, repeat)[0], periods


def measure(n_values: int = 8, counts=(20, 12, 24), repeat: int = 2) -> dict:
    """The module's measurement: seconds of each way (best of ``repeat`` after a warm-up),
    whether both ways give the same labels, and the two ratios."""
    params = jg.paper_params()
    grid = jg.CellGrid.paper(tuple(counts))
    values = np.linspace(4.0, 6.0, n_values)

    def batched():
        return jg.basin_sweep(jg.REDUCED, params, "b", values, grid, options=jg.BasinOptions(batched=True),
                              runner=jg.Runner(progress=False))

    def separate():
        return [jg.analyze_global(jg.REDUCED, jg.with_param(params, "b", v), grid, progress=False) for v in values]

    t_sep, results = best(separate, repeat)
    t_bat, sweep = best(batched, repeat)
    same = True
    for i, r in enumerate(results):
        gid = jg.sweep.match_across_values(results, sweep.match_tol)[i]
        lut = np.concatenate([[-2, -1], gid])
        same &= bool(np.array_equal(lut[np.asarray(r.labels) + 2], sweep.labels[i]))
    t_cls, classified = best(lambda: [jg.analyze_global(jg.REDUCED, jg.with_param(params, "b", v), grid,
                                                        progress=False, uncertainty=0) for v in values], repeat)
    t_int, periods = integration_alone(params, grid, classified, repeat)
    return dict(values=n_values, counts=list(counts), cells=grid.n_cells, separate_s=t_sep, batched_s=t_bat,
                same_labels=same, separate_without_uncertainty_s=t_cls, integration_alone_s=t_int,
                periods=periods, ceiling=t_cls / t_int, ratio=t_sep / t_bat)


def report(m: dict) -> None:
    """Print :func:`measure`'s figures, the headline (separate / batched) last."""
    print(f"machine: {jg.__version__}, grid {tuple(m['counts'])} = {m['cells']} cells, {m['values']} values of b")
    print(f"separate analyses: {m['separate_s']:8.2f} s")
    print(f"batched pool:      {m['batched_s']:8.2f} s")
    print(f"same labels at every value: {m['same_labels']}")
    print(f"separate analyses without the label uncertainty: {m['separate_without_uncertainty_s']:8.2f} s")
    print(f"integration alone of their {m['values'] * m['cells']} cells x {m['periods']} periods (one batch): "
          f"{m['integration_alone_s']:8.2f} s")
    print(f"ceiling of any pooling (separate without uncertainty / integration alone): {m['ceiling']:.2f}x")
    print(f"basin sweep, batched pool vs separate analyses: {m['ratio']:.2f}x")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--values", type=int, default=8)
    ap.add_argument("--counts", type=int, nargs=3, default=(20, 12, 24))
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    report(measure(a.values, a.counts, a.repeat))


if __name__ == "__main__":
    main()
