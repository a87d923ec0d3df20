"""What one analysis compiles: the pool's programs are shared by every pool of the same
role and shapes, so repeating an analysis compiles nothing and the extra measures add only
the programs that differ in what they compute (the label uncertainty's halved step, and
its one pool of start moves where the grid is smaller than that pool)."""

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


def test_the_start_moves_run_in_the_analysis_s_own_pool_programs(monkeypatch):
    """On a grid larger than the pilot, the label uncertainty's pool of start moves takes the
    queue shape and a lane count of the analysis's own pools, so it compiles no pool
    program: the uncertainty adds only its halved step's. Its fractions are those of a
    pool in its own shapes."""
    from jaxgear.analysis import _uncertainty

    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (45, 40), names=("x", "v"))  # 1,800 cells: a pilot, then 776
    method = jg.Direct(integrator=jg.RK4(46))  # a step count no other test compiles
    kw = dict(method=method, progress=False)
    with count_compilations("_run_one") as analysis:
        jg.analyze_global(jg.DUFFING, PARAMS, grid, uncertainty=0, **kw)
    with count_compilations("_run_one") as extra:
        u = jg.analyze_global(jg.DUFFING, PARAMS, grid, uncertainty=64, **kw).uncertainty
    assert len(analysis) >= 1 and len(extra) == 1, (analysis, extra)  # the halved step's pool alone
    monkeypatch.setattr(_uncertainty, "main_queue", lambda counts, pilot: 0)  # the start moves in their own shapes
    with count_compilations("_run_one") as own:
        v = jg.analyze_global(jg.DUFFING, PARAMS, grid, uncertainty=64, **kw).uncertainty
    assert len(own) >= 1  # (the check above can fail)
    assert v.start_fractions == u.start_fractions and v.step == u.step


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


def test_a_candidate_is_characterised_by_one_program_for_every_pool_size():
    """The chaotic attractor of the double-well Duffing is found by a candidate's cloud.
    That characterisation is a program of its own with no lane axis: the first analysis
    compiles it once, and a second analysis whose pool has four times the lanes finds the
    attractor again (a new candidate) and compiles only its pool."""
    chaotic = jg.DuffingParams(delta=0.15, alpha=-1.0, beta=1.0, gamma=0.3, omega=1.0)
    method = jg.Direct(integrator=jg.RK4(58))  # a step count no other test compiles
    small = jg.CellGrid.box([(-2, 2), (-2, 2)], (16, 16))  # 256 cells: a pool of 1,024 lanes
    large = jg.CellGrid.box([(-2, 2), (-2, 2)], (64, 64))  # 4,096 cells: 4,096 lanes
    with count_compilations("_characterise") as first:
        r = jg.analyze_global(jg.DUFFING, chaotic, small, method=method, progress=False, uncertainty=0)
    assert any(a.period == 0 for a in r.attractors) and len(first) == 1, first
    with count_compilations("_run_one") as pools, count_compilations("_characterise") as again:
        q = jg.analyze_global(jg.DUFFING, chaotic, large, method=jg.Direct(integrator=jg.RK4(58), pilot=0),
                              progress=False, uncertainty=0)
    assert any(a.period == 0 for a in q.attractors) and len(pools) >= 1 and again == [], (pools, again)
