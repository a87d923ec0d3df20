"""What one analysis compiles: the pool's programs are shared by every pool of the same
role and shapes, so repeating an analysis compiles nothing and the extra measures add only
the programs that differ in what they compute (the label uncertainty's halved step and
its one pool of start moves)."""

import numpy as np
import pytest

import jaxgear as jg
from tests.conftest import count_compilations

GRID = jg.CellGrid.box([(-3, 3), (-3, 3)], (9, 7), names=("x", "v"))
"""A grid of 63 cells that no other test uses (its pool shapes are compiled here first)."""
METHOD = jg.Direct(integrator=jg.RK4(52))
PARAMS = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)


def _analyze(uncertainty: int):
    return jg.analyze_global(jg.DUFFING, PARAMS, GRID, method=METHOD, progress=False, uncertainty=uncertainty)


def test_the_extra_measures_add_only_the_programs_that_differ():
    with count_compilations("_run_one") as first:
        r = _analyze(0)
    assert len(first) >= 1 and len(r.attractors) == 2
    with count_compilations("_run_one") as again:
        q = _analyze(0)
    assert again == [] and np.array_equal(q.labels, r.labels)  # the same analysis compiles nothing
    with count_compilations("_run_one") as extra:
        u = _analyze(32).uncertainty
    # one pool with the halved step, one pool for every start move: not a program per move
    assert len(extra) <= 2, extra
    assert u.samples == 32 and len(u.start_fractions) == 6


@pytest.mark.slow  # about 10 s: two pools of 10,000 cells
def test_the_pilot_and_the_tail_of_the_main_pool_are_one_program(monkeypatch):
    """On 10,000 cells the main pool (9,216 lanes) drains into a pool of the pilot's 1,024
    lanes over the same queue shape: two pool programs in all (a ladder ending on 1,152
    lanes would compile a third), and the labels do not depend on it (those of a pool
    that never shrinks)."""
    from jaxgear.analysis import _pool

    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (100, 100), names=("x", "v"))
    method = jg.Direct(integrator=jg.RK4(44))  # a step count no other test compiles
    with count_compilations("_run_one") as programs:
        r = jg.analyze_global(jg.DUFFING, PARAMS, grid, method=method, progress=False, uncertainty=0)
    assert len(programs) == 2, programs
    monkeypatch.setattr(_pool, "_next_pool", lambda L: L)
    q = jg.analyze_global(jg.DUFFING, PARAMS, grid, method=method, progress=False, uncertainty=0)
    np.testing.assert_array_equal(q.labels, r.labels)
