"""Periods per cell of the detection by recurrences: plain script, figures printed, nothing asserted.

    python benchmarks/recurrence.py                       # b = 2 (chaotic band), grid 10 x 6 x 12
    python benchmarks/recurrence.py --b 5 --grid 10,6,12  # the paper preset (periodic attractors)
    python benchmarks/recurrence.py --chunk 128           # lanes refilled: later waves start after
                                                          # the attractors are known

Labels the cell centres of the paper region D (x4 = 0, ``--grid`` cells) of the reduced
gear model, paper preset with half backlash ``b_sp = b_rp = --b``, with
:func:`jaxgear.analysis.classify_by_recurrence` (default options; a view of the direct
method's lane pool with detection by recurrences) on JAX's default device, twice (the
second run is warm). Prints the attractors (period, 0 for an attractor of boxes; the
points kept of it; share), the mean / median / max periods per cell (a cell decided by
its own candidate cloud is charged the cloud and its verification), and the warm wall
time. The direct method without recurrences needs 2,000 periods per cell at b = 2 (all
unresolved) and 64 at the paper preset. The LAST line is the headline.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import jaxgear as jg
from jaxgear._model import REDUCED
from jaxgear.analysis import PoolOptions, classify_by_recurrence


def measure(b: float = 2.0, counts=(10, 6, 12), chunk: int = 1024, say=print) -> dict:
    params = jg.paper_params(b_sp=b, b_rp=b)
    X = jg.CellGrid.paper(tuple(counts)).centres()
    out = {}
    for run in ("cold", "warm"):
        t = time.perf_counter()
        r = classify_by_recurrence(REDUCED, params, X, pool=PoolOptions(lanes=chunk))  # numpy results
        out[run] = time.perf_counter() - t
    labels, used = np.asarray(r.labels), np.asarray(r.periods_used)
    for a, (k, pts) in enumerate(zip(np.asarray(r.periods), np.asarray(r.points))):
        kept = int(np.all(np.isfinite(pts), axis=1).sum())
        say(f"attractor {a}: period {k} ({'boxes' if k == 0 else 'cycle'}), {kept} points, "
            f"share {np.mean(labels == a):.3f}")
    say(f"sink {np.mean(labels == -1):.3f}, unresolved {np.mean(labels == -2):.3f}")
    out.update(n=len(X), mean=float(used.mean()), median=float(np.median(used)), max=int(used.max()))
    say(f"{len(X)} cells, b = {b}, chunk {chunk}, {jax.devices()[0].platform}: cold {out['cold']:.1f} s, "
        f"warm {out['warm']:.1f} s")
    say(f"periods per cell: mean {out['mean']:.1f}, median {out['median']:.0f}, max {out['max']}")
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--b", type=float, default=2.0)
    p.add_argument("--grid", default="10,6,12")
    p.add_argument("--chunk", type=int, default=1024)
    a = p.parse_args()
    measure(a.b, tuple(int(c) for c in a.grid.split(",")), a.chunk)


if __name__ == "__main__":
    main()
