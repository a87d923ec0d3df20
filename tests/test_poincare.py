"""Poincaré maps (paper §3, eq. 7-9): the section Σ = {x4 = 0}, direction semantics,
stroboscopic maps and orbits, batches vs loops, no recompilation, bad input.

References: dense samples of the same trajectory (the first sign change of x4 after the
whole periods), the sign of x4' from the vector field, a 4x finer step, loops of
single calls.
"""

import math

import jax
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import REDUCED, Status

STATUS_OK, STATUS_DIVERGED, STATUS_NO_CROSSING = Status.CONVERGED, Status.DIVERGED, Status.NO_CROSSING

P = jg.paper_params()
T = 2 * math.pi / 0.87
PERIODS = 2
STEPS = 200


def _paper_states(n, seed):
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(-25, 25, n), rng.uniform(-10, 20, n), rng.uniform(-10, 50, n), np.zeros(n)], -1)


NX = 64
X0 = _paper_states(NX, seed=0)


@pytest.fixture(scope="module")
def hits():
    out = {d: jg.section_map(REDUCED, P, X0, periods=PERIODS, direction=d, integrator=jg.RK4(STEPS))
           for d in (1, -1, 0)}
    return {d: jax.tree_util.tree_map(np.asarray, h) for d, h in out.items()}


@pytest.fixture(scope="module")
def dense():
    """States on the RK4 step grid from t = 0 to the end of the search (the search uses the same grid)."""
    ts, xs = jg.sample_trajectory(REDUCED, P, X0, periods=PERIODS + 4, samples_per_period=STEPS, integrator=jg.RK4(STEPS))
    return np.asarray(ts), np.asarray(xs)


def _field_at(ts, xs):
    return np.asarray(jax.vmap(lambda t, x: jg.reduced_vector_field(t, x, P))(ts, xs))


# ----------------------------------------------------------------------------- the section
@pytest.mark.parametrize("d", [1, -1, 0])
def test_crossings_lie_on_sigma_after_whole_periods(hits, d):
    h = hits[d]
    assert h.state.shape == (NX, 4) and h.time.shape == (NX,) and h.status.shape == (NX,)
    assert np.all(h.status == STATUS_OK)
    assert np.all(np.abs(h.state[:, 3]) < 1e-12)
    assert np.all(h.time >= PERIODS * T)
    assert np.all(h.time < (PERIODS + 4) * T)
    np.testing.assert_allclose(h.phase, np.mod(2 * np.pi * h.time / T, 2 * np.pi), atol=1e-12)


def test_direction_is_the_sign_of_x4_dot(hits):
    up = _field_at(hits[1].time, hits[1].state)[:, 3]
    down = _field_at(hits[-1].time, hits[-1].state)[:, 3]
    assert np.all(up > 0) and np.all(down < 0)
    # direction 0 takes whichever comes first
    first_up = hits[1].time <= hits[-1].time
    np.testing.assert_array_equal(hits[0].time, np.where(first_up, hits[1].time, hits[-1].time))
    np.testing.assert_array_equal(hits[0].state, np.where(first_up[:, None], hits[1].state, hits[-1].state))
    assert 0 < first_up.sum() < NX  # both kinds occur in this sample


@pytest.mark.parametrize("d", [1, -1, 0])
def test_crossing_is_the_first_after_the_whole_periods(hits, dense, d):
    ts, xs = dense
    k0 = PERIODS * STEPS
    g = xs[:, k0:, 3]                                    # x4 from t = PERIODS*T on
    if d > 0:
        change = (g[:, :-1] < 0) & (g[:, 1:] >= 0)
    elif d < 0:
        change = (g[:, :-1] > 0) & (g[:, 1:] <= 0)
    else:
        change = ((g[:, :-1] < 0) & (g[:, 1:] >= 0)) | ((g[:, :-1] > 0) & (g[:, 1:] <= 0))
    assert np.all(change.any(axis=1))
    k = np.argmax(change, axis=1) + k0                   # first bracketing step
    tc = hits[d].time
    assert np.all(ts[k] <= tc + 1e-12) and np.all(tc <= ts[k + 1] + 1e-12)
    # the crossing state lies within the motion of that step
    lane = np.arange(NX)
    step = np.abs(xs[lane, k + 1] - xs[lane, k]).max(axis=1)
    assert np.all(np.abs(hits[d].state - xs[lane, k]).max(axis=1) <= 1.5 * step)


def test_section_agrees_with_four_times_finer_step(hits):
    """Same map with 4x the steps: same crossings, states within the RK4 error.

    The map is discontinuous where a crossing falls at t = PERIODS*T itself (just before
    it, the next crossing is taken): a lane whose crossing lies within one step of that
    boundary may pick different crossings at the two resolutions; any other lane must not.
    """
    fine = jax.tree_util.tree_map(
        np.asarray, jg.section_map(REDUCED, P, X0, periods=PERIODS, direction=1, integrator=jg.RK4(4 * STEPS)))
    coarse = hits[1]
    assert np.all(fine.status == STATUS_OK)
    assert np.abs(fine.state[:, 3]).max() < 1e-12
    same = np.abs(fine.time - coarse.time) < 0.1 * T
    at_boundary = np.minimum(fine.time, coarse.time) - PERIODS * T < T / STEPS
    assert np.all(same | at_boundary)
    assert same.sum() >= NX - 2
    h2 = (T / STEPS) ** 2  # error ~ C h^2 with backlash (docs/model.md §8), C ~ 5-12 measured
    assert np.abs(fine.state - coarse.state)[same].max() < 40 * h2
    assert np.abs(fine.time - coarse.time)[same].max() < 4 * h2


def test_section_status_codes():
    x = np.array([X0[0], [1e308, 0.0, 0.0, 30.0], [0.0, 0.0, 0.0, 30.0]])
    # the search is shorter than any crossing of lane 3 (x4 = 30 must come down and go up again)
    hit = jg.section_map(REDUCED, P, x, periods=0, max_extra_periods=0.01)
    st = np.asarray(hit.status)
    assert st[1] == STATUS_DIVERGED and st[2] == STATUS_NO_CROSSING
    assert np.all(np.isnan(np.asarray(hit.state)[1:]))
    assert st[0] in (STATUS_OK, STATUS_NO_CROSSING)


# ----------------------------------------------------------------------------- batches
def test_batched_maps_equal_loops_of_single_calls(hits):
    x = X0[:3]
    # stroboscopic map: batch shape kept
    b = np.asarray(jg.stroboscopic_map(REDUCED, P, x.reshape(3, 1, 4), periods=1, t0=0.3))
    assert b.shape == (3, 1, 4)
    loop = np.stack([np.asarray(jg.stroboscopic_map(REDUCED, P, xi, periods=1, t0=0.3)) for xi in x])
    np.testing.assert_allclose(b[:, 0], loop, rtol=1e-13, atol=1e-12)
    # section map: the fixture's batch of 8 vs single calls
    for i in (0, 5):
        s = jg.section_map(REDUCED, P, X0[i], periods=PERIODS, direction=1, integrator=jg.RK4(STEPS))
        assert np.shape(s.time) == () and np.asarray(s.status) == STATUS_OK
        np.testing.assert_allclose(np.asarray(s.state), hits[1].state[i], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(float(s.time), hits[1].time[i], rtol=1e-14)


def test_stroboscopic_orbit_equals_iterated_map():
    x = X0[:3]
    orb = np.asarray(jg.stroboscopic_orbit(REDUCED, P, x, n_points=4, t0=0.3))
    assert orb.shape == (3, 4, 4)
    for i in range(3):
        single = np.asarray(jg.stroboscopic_orbit(REDUCED, P, x[i], n_points=4, t0=0.3))
        assert single.shape == (4, 4)
        np.testing.assert_allclose(single, orb[i], rtol=1e-12, atol=1e-12)
    # P^k by iterating the one-period map from the right phase t0 + k T
    y = x
    for k in range(4):
        y = np.asarray(jg.stroboscopic_map(REDUCED, P, y, periods=1, t0=0.3 + k * T))
        np.testing.assert_allclose(orb[:, k], y, rtol=1e-10, atol=1e-10)
    # periods_between = 2 takes every other point
    orb2 = np.asarray(jg.stroboscopic_orbit(REDUCED, P, x, n_points=2, periods_between=2, t0=0.3))
    np.testing.assert_allclose(orb2, orb[:, 1::2], rtol=1e-10, atol=1e-10)


# ----------------------------------------------------------------------------- compilation
TRACES = {"n": 0}


def _counting_field(t, x, p):
    TRACES["n"] += 1  # Python side effect: runs only while tracing
    return jg.reduced_vector_field(t, x, p)


# the reduced model with its switching surfaces and pieces, without the compiled kernel
COUNTING = jg.ForcedSystem(vector_field=_counting_field, period=REDUCED.period, state_names=REDUCED.state_names,
                           section_index=3, name="counting", switching=REDUCED.switching,
                           piece_field=REDUCED.piece_field, time_breaks=REDUCED.time_breaks)


def test_no_recompilation_when_parameter_values_change():
    x = X0[:2]
    p2 = P.replace(Omega=0.93, b_sp=4.0, c_rp=0.1, kappa_sp_amp=0.2)
    TRACES["n"] = 0
    y1 = jg.stroboscopic_map(COUNTING, P, x, periods=1)
    n_first = TRACES["n"]
    assert n_first > 0
    y2 = jg.stroboscopic_map(COUNTING, p2, x, periods=1)
    jg.stroboscopic_map(COUNTING, P, x + 1.0, periods=1, t0=0.5)
    assert TRACES["n"] == n_first
    assert not np.allclose(np.asarray(y1), np.asarray(y2))  # the new values were used
    np.testing.assert_allclose(np.asarray(y2), np.asarray(jg.stroboscopic_map(REDUCED, p2, x, periods=1)), rtol=1e-12)
    TRACES["n"] = 0
    jg.section_map(COUNTING, P, x, periods=1)
    n_first = TRACES["n"]
    h2 = jg.section_map(COUNTING, p2, x, periods=1)
    assert TRACES["n"] == n_first
    assert np.all(np.asarray(h2.status) == STATUS_OK)
    # a new program at other shapes (here three states and another integrator: cheap to
    # compile) does trace the field: the counter works (the field is traced once per shapes)
    jg.stroboscopic_map(COUNTING, P, X0[:3], periods=1, integrator=jg.RK4(8))
    assert TRACES["n"] > n_first


# ----------------------------------------------------------------------------- bad input
def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 4\)"):
        jg.stroboscopic_map(REDUCED, P, np.zeros(3))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 4\)"):
        jg.section_map(REDUCED, P, np.zeros((2, 8)))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 8\)"):
        jg.stroboscopic_orbit(jg.nplanet_system(3), P, np.zeros(4), n_points=2)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 4\)"):
        jg.sample_trajectory(REDUCED, P, np.zeros(5))
    with pytest.raises(ValueError, match="NaN"):
        jg.stroboscopic_map(REDUCED, P, np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="infinite"):
        jg.section_map(REDUCED, P, np.array([0.0, np.inf, 0.0, 0.0]))
    with pytest.raises(ValueError, match="direction"):
        jg.section_map(REDUCED, P, np.zeros(4), direction=2)
    with pytest.raises(ValueError, match="index"):
        jg.section_map(REDUCED, P, np.zeros(4), index=4)
    with pytest.raises(ValueError, match="max_extra_periods"):
        jg.section_map(REDUCED, P, np.zeros(4), max_extra_periods=0)
    no_section = jg.ForcedSystem(vector_field=jg.reduced_vector_field, period=REDUCED.period,
                                 state_names=REDUCED.state_names, section_index=None)
    with pytest.raises(ValueError, match="index"):
        jg.section_map(no_section, P, np.zeros(4))
    with pytest.raises(ValueError, match="section_index"):
        jg.ForcedSystem(vector_field=jg.reduced_vector_field, period=REDUCED.period,
                        state_names=REDUCED.state_names, section_index=4)
    # check_system: parameters that give a non-finite period or field
    with pytest.raises(ValueError, match="period"):
        jg.check_system(jg.DUFFING, jg.DuffingParams(omega=0.0))
    jg.check_system(REDUCED, P, np.zeros(4))
