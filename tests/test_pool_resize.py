"""The pool's shrinking on a grid of tens of thousands of cells (every default 90,000-cell
run shrinks its pool as the queue drains): the labels of a pool that moves its last busy
lanes to a smaller pool equal those of every cell integrated on its own, far past its
transient, and matched to the nearest attractor."""

import numpy as np
import pytest

import jaxgear as jg
from jaxgear.analysis._placement import OneDevice

PARAMS = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)  # two coexisting P-1 cycles
GRID = jg.CellGrid.box([(-3, 3), (-3, 3)], (150, 150), names=("x", "v"))  # 22,500 cells
INTEGRATOR = jg.RK4(52)


@pytest.mark.slow  # about 50 s of CPU, most of it compiling the pools of 16,384 and 2,048 lanes
def test_a_shrinking_pool_labels_every_cell_as_its_own_long_integration(monkeypatch):
    sizes = []
    resize = OneDevice.resize

    def spy(self, s, L=None, A=None):
        sizes.append((s.Y.shape[-1], L))
        return resize(self, s, L=L, A=A)

    monkeypatch.setattr(OneDevice, "resize", spy)
    r = jg.analyze_global(jg.DUFFING, PARAMS, GRID, method=jg.Direct(integrator=INTEGRATOR, chunk_size=16384),
                          progress=False, uncertainty=0)
    shrinks = [(a, b) for a, b in sizes if b is not None]
    assert shrinks and all(b < a for a, b in shrinks), sizes  # the pool did shrink
    assert r.n_sink == 0 and r.n_unresolved == 0
    cycles = [a for a in r.attractors if a.period == 1]
    assert len(cycles) == 2 == len(r.attractors)

    # every cell alone: 400 periods (the cycles contract by about 0.8 per period), then the nearest cycle
    end = np.asarray(jg.stroboscopic_map(jg.DUFFING, PARAMS, GRID.centres(), periods=400, integrator=INTEGRATOR))
    d = np.stack([np.linalg.norm(end - a.points[0], axis=1) for a in cycles], axis=1)
    settled = d.min(axis=1) < 1e-6
    assert settled.mean() > 0.999
    want = np.array([cycles[i].id for i in np.argmin(d, axis=1)])
    got = np.asarray(r.labels).ravel()  # (grid order, as the centres)
    assert np.array_equal(got[settled], want[settled]), np.count_nonzero(got[settled] != want[settled])
