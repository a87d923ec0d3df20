"""Feedback: warnings that name what to change when a global analysis looks unreliable,
and progress bars that ``progress=False`` silences (cell mapping and shooting).

Each warning has a case built to trigger it (a region that misses the attractor, a
too-small period limit, a too-coarse grid, ...) and a well-posed case that must not.
"""

import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import CellGrid, ForcedSystem


class Params(eqx.Module):
    a: jnp.ndarray = eqx.field(converter=lambda v: jnp.asarray(v, jnp.float64), default=1.0)


# x' = a x - x^3: attractors x = +-sqrt(a) (P-1 for any forcing period), separatrix x = 0
BISTABLE = ForcedSystem(vector_field=lambda t, x, p: p.a * x - x**3, period=lambda p: 1.0 + 0 * p.a,
                        state_names=("x",), name="bistable-1d")

# r' = r (1 - r^2), theta' = pi: attracted to the unit circle, rotated by pi every period,
# so every point of the circle lies on a P-2 orbit (and nothing is P-1 but the origin)
ROTATION = ForcedSystem(
    vector_field=lambda t, x, p: jnp.array([x[0] * (p.a - x[0] ** 2 - x[1] ** 2) - jnp.pi * x[1],
                                            x[1] * (p.a - x[0] ** 2 - x[1] ** 2) + jnp.pi * x[0]]),
    period=lambda p: 1.0 + 0 * p.a, state_names=("x", "y"), name="rotation")


def _run(system, grid, params=None, method="direct", **options):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = jg.analyze_global(system, params or Params(), grid, jg.analysis.method_from_name(method, **options),
                              progress=False, uncertainty=0)
    # a read of the session's shared compilation cache that meets an entry another worker
    # is still writing is JAX's warning (it compiles instead), not the analysis's
    return r, [str(x.message) for x in w if not str(x.message).startswith("Error reading persistent compilation")]


def _has(messages, *words):
    return any(all(word in m for word in words) for m in messages)


WELL_POSED = dict(method="stroboscopic", mapping_steps=2, settle_periods=60)


@pytest.fixture(scope="module")
def well_posed():
    """Both attractors inside a symmetric region, 40 cells: no warning at all."""
    return _run(BISTABLE, CellGrid.box([(-2, 2)], (40,), names=("x",)), **WELL_POSED)


def test_well_posed_analysis_warns_nothing(well_posed):
    r, msgs = well_posed
    assert sorted(a.period for a in r.attractors) == [1, 1]
    assert msgs == []


def test_many_sink_cells_say_enlarge_the_region(well_posed):
    # region [1.5, 4] misses the attractor x = 1: every image leaves it
    r, msgs = _run(BISTABLE, CellGrid.box([(1.5, 4.0)], (20,), names=("x",)), **WELL_POSED)
    assert r.n_sink == r.n_cells
    assert _has(msgs, "sink", "enlarge the region")
    assert not _has(well_posed[1], "sink")


def test_attractor_on_the_edge_says_enlarge_the_region(well_posed):
    # direct method on [1.2, 3]: every cell reaches x = 1, outside the region
    r, msgs = _run(BISTABLE, CellGrid.box([(1.2, 3.0)], (10,), names=("x",)), method="direct")
    assert [a.period for a in r.attractors] == [1] and abs(r.attractors[0].points[0, 0] - 1.0) < 1e-8
    assert _has(msgs, "edge", "along x", "enlarge the region")
    # stroboscopic on [0.99, 3]: the attractor is inside but within 2 % of the lower bound
    _, msgs = _run(BISTABLE, CellGrid.box([(0.99, 3.0)], (20,), names=("x",)), **WELL_POSED)
    assert _has(msgs, "edge", "enlarge the region")
    assert not _has(well_posed[1], "edge")


@pytest.mark.slow
def test_unresolved_cells_say_raise_max_periods():
    # a = 0.02: transients ~ 1/(2a) = 25 periods; 10 periods are not enough to see a recurrence
    grid = CellGrid.box([(-0.4, 0.4)], (8,), names=("x",))
    slow = Params(a=0.02)
    r, msgs = _run(BISTABLE, grid, slow, method="direct", max_period=2, max_periods=10, round_periods=5)
    assert r.n_unresolved > 0
    assert _has(msgs, "not resolved", "raise max_periods")
    r, msgs = _run(BISTABLE, grid, slow, method="direct", max_period=2, max_periods=4000, round_periods=5)
    assert r.n_unresolved == 0 and not _has(msgs, "not resolved")


def test_no_period_found_says_raise_max_period():
    grid = CellGrid.box([(-1.5, 1.5), (-1.5, 1.5)], (8, 8), names=("x", "y"))
    r, msgs = _run(ROTATION, grid, method="stroboscopic", settle_periods=40, max_period=1)
    assert any(a.period == 0 for a in r.attractors)
    assert _has(msgs, "no period <= max_period=1", "raise max_period")
    r, msgs = _run(ROTATION, grid, method="stroboscopic", settle_periods=40, max_period=2)
    assert r.attractors and all(a.period == 2 for a in r.attractors)
    assert not _has(msgs, "no period")


def test_too_few_cells_per_attractor_say_refine_the_grid(well_posed):
    r, msgs = _run(BISTABLE, CellGrid.box([(-2, 2)], (6,), names=("x",)), **WELL_POSED)
    assert sorted(a.cell_count for a in r.attractors) == [3, 3]
    assert _has(msgs, "only 3 cell", "refine the grid")
    assert not _has(well_posed[1], "refine the grid")


def test_direct_method_does_not_ask_to_refine_a_coarse_grid():
    # direct integration classifies each cell centre exactly: a coarse grid is not unreliable
    _, msgs = _run(BISTABLE, CellGrid.box([(-2, 2)], (6,), names=("x",)), method="direct")
    assert not _has(msgs, "refine the grid")


# ---------------------------------------------------------------- progress bars
def test_progress_false_silences_cell_mapping(capsys):
    grid = CellGrid.box([(-2, 2)], (40,), names=("x",))
    for method in ("stroboscopic", "direct"):
        capsys.readouterr()
        jg.analyze_global(BISTABLE, Params(), grid, method=method, progress=True, uncertainty=0)
        assert "cell" in capsys.readouterr().err  # tqdm writes its bar to stderr
        jg.analyze_global(BISTABLE, Params(), grid, method=method, progress=False, uncertainty=0)
        out = capsys.readouterr()
        assert out.err == "" and out.out == ""


def test_progress_false_silences_shooting(capsys):
    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)
    seeds = np.array([[1.0, 1.1], [-0.3, 0.1], [0.5, 0.5]])
    capsys.readouterr()
    jg.find_periodic_orbits(jg.DUFFING, p, seeds, chunk_size=2, progress=True, trajectory_samples=0)
    assert "shooting" in capsys.readouterr().err
    jg.find_periodic_orbits(jg.DUFFING, p, seeds, chunk_size=2, progress=False, trajectory_samples=0)
    out = capsys.readouterr()
    assert out.err == "" and out.out == ""
