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
checks that both give the same shares and labels at every value. The LAST line is the
headline: separate / batched.
"""

from __future__ import annotations

import argparse
import time
import warnings

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


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--values", type=int, default=8)
    ap.add_argument("--counts", type=int, nargs=3, default=(20, 12, 24))
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    params = jg.paper_params()
    grid = jg.CellGrid.paper(tuple(a.counts))
    values = np.linspace(4.0, 6.0, a.values)

    def batched():
        return jg.basin_sweep(jg.REDUCED, params, "b", values, grid, progress=False, batched=True)

    def separate():
        return [jg.analyze_global(jg.REDUCED, jg.with_param(params, "b", v), grid, progress=False) for v in values]

    t_sep, results = best(separate, a.repeat)
    t_bat, sweep = best(batched, a.repeat)
    same = True
    for i, r in enumerate(results):
        gid = jg.sweep.match_across_values(results, sweep.match_tol)[i]
        lut = np.concatenate([[-2, -1], gid])
        same &= bool(np.array_equal(lut[np.asarray(r.labels) + 2], sweep.labels[i]))
    print(f"machine: {jg.__version__}, grid {a.counts} = {grid.n_cells} cells, {a.values} values of b")
    print(f"separate analyses: {t_sep:8.2f} s")
    print(f"batched pool:      {t_bat:8.2f} s")
    print(f"same labels at every value: {same}")
    print(f"basin sweep, batched pool vs separate analyses: {t_sep / t_bat:.2f}x")


if __name__ == "__main__":
    main()
