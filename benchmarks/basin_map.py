"""Cost of a basin map over two parameters: plain script, figures printed, nothing asserted.

    python benchmarks/basin_map.py                          # 3 x 3 points, paper grid
    python benchmarks/basin_map.py --points 30 30           # the full 30 x 30 map (on a GPU)
    python benchmarks/basin_map.py --points 4 2 --counts 20 12 24 --one-pool

Runs :func:`jaxgear.basin_map` of the reduced gear model (paper preset, default method
:class:`jaxgear.Direct` with its label uncertainty, the paper's region D on ``--counts``
cells) over ``kappa_amp`` in [0.33, 0.38] x ``b`` in [4, 6] at ``--points NX NY``,
after one warm-up analysis (compilation apart), on JAX's default device, which it
names. Prints the wall time, the time per parameter point, the cells integrated per
second, and the time a 30 x 30 map at the same grid would take at that rate. With
``--one-pool`` it also times the same map with ``batched=True`` (the points of a
block in one lane pool; after a warm-up run of it) and checks that both give the same
shares. The cost of a point varies with the parameters (slowly converging cells, more
attractors): a projection from a few points is rough. The LAST line is
the headline.
"""

from __future__ import annotations

import argparse
import platform
import time
import warnings

import jax
import numpy as np

import jaxgear as jg


def measure(points=(3, 3), counts=(50, 30, 60), one_pool: bool = False, say=print) -> dict:
    """The module's measurement (``say`` prints each figure as it comes): a dict of the
    device, the warm-up, the map's wall time and rate, and the 30 x 30 projection."""
    nx, ny = points
    params = jg.paper_params()
    grid = jg.CellGrid.paper(tuple(counts))
    method = jg.Direct()
    kappa, b = np.linspace(0.33, 0.38, nx), np.linspace(4.0, 6.0, ny)
    dev = jax.devices()[0]
    out = dict(points=[nx, ny], counts=list(counts), cells=grid.n_cells, device=f"{dev.platform} {dev.device_kind}")
    say(f"basin map: kappa_amp x b = {nx} x {ny} points, {grid.n_cells} cells each ({tuple(counts)}), "
        f"direct method")
    say(f"device: {dev.platform} {dev.device_kind} ({jax.device_count()} device(s)); host {platform.node()}, "
        f"{platform.processor() or platform.machine()}; jax {jax.__version__}, jaxgear {jg.__version__}")
    t = time.perf_counter()
    jg.analyze_global(jg.REDUCED, jg.with_param(jg.with_param(params, "kappa_amp", kappa[0]), "b", b[0]), grid,
                      method, progress=False)
    out["warm_up_s"] = time.perf_counter() - t
    say(f"warm-up (one analysis, compilation included): {out['warm_up_s']:.1f} s")

    def run(batched):
        t = time.perf_counter()
        m = jg.basin_map(jg.REDUCED, params, "kappa_amp", kappa, "b", b, grid, method=method,
                         options=jg.BasinOptions(batched=batched), runner=jg.Runner(progress=False))
        return time.perf_counter() - t, m

    wall, m = run(False)
    n = nx * ny
    per = wall / n
    out.update(map_s=wall, per_point_s=per, cells_per_s=n * grid.n_cells / wall, attractors=int(m.n_attractors),
               coexisting=int(m.coexisting.max()), map_30x30_s=900 * per)
    say(f"map, one analysis after another: {wall:.1f} s, {per:.2f} s per point, "
        f"{n * grid.n_cells / wall:.3g} cells/s; {m.n_attractors} global attractors, "
        f"up to {int(m.coexisting.max())} coexisting")
    if one_pool:
        run(True)  # warm-up: the pools of several points compile for their own shapes
        wall1, m1 = run(True)
        same = np.array_equal(m.shares, m1.shares) and np.array_equal(m.labels, m1.labels)
        out.update(one_pool_s=wall1, one_pool_same=bool(same))
        say(f"map, one pool per block: {wall1:.1f} s (same shares and labels: {same}); "
            f"separate / one pool: {wall / wall1:.2f}x")
    say(f"30 x 30 map on {grid.n_cells} cells at this rate ({out['device']}): "
        f"{900 * per:.0f} s = {900 * per / 3600:.2f} h ({'measured' if n == 900 else 'projected from ' + str(n)}"
        f"{'' if n == 900 else ' points'})")
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, nargs=2, default=(3, 3), metavar=("NX", "NY"),
                    help="kappa_amp values x b values (default 3 3)")
    ap.add_argument("--counts", type=int, nargs=3, default=(50, 30, 60), help="cells (default the paper grid)")
    ap.add_argument("--one-pool", action="store_true", help="also time the map with batched=True")
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    measure(a.points, a.counts, a.one_pool)


if __name__ == "__main__":
    main()
