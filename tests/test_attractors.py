"""Attractors of every type through the global analysis (jaxgear.analyze_global, Direct).

Each test runs the whole chain -- the lane pool with its detection by recurrences, the
reduction and merging of attractors, their types and Lyapunov exponents, the result file
-- and checks it against references that do not come from that code: a brute-force numpy
integration of random states (its own RK4), closed forms (Liouville's formula for the
product of the multipliers, averaging theory for the van der Pol oscillator), the Floquet
multipliers of the shooting module, and the round trip of a saved result.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxgear
from jaxgear._examples import DUFFING, VAN_DER_POL, DuffingParams, VanDerPolParams
from jaxgear._lyapunov import AttractorType
from jaxgear.integrate import RK4

# --------------------------------------------------------------------------- a chaotic and a periodic attractor

# x'' + 0.15 x' - x + x^3 = 0.3 cos t: a chaotic attractor coexists with a P-1 cycle
# (about 2/3 of the states of [-2, 2]^2 reach the chaotic one).
DUFF = dict(delta=0.15, alpha=-1.0, beta=1.0, gamma=0.3, omega=1.0)
DUFF_T = 2 * np.pi / DUFF["omega"]
DUFF_STEPS = 64
DUFF_BOX = (-2.0, 2.0)
DUFF_GRID = jaxgear.CellGrid.box([DUFF_BOX, DUFF_BOX], [12, 12])
METHOD = jaxgear.Direct(integrator=RK4(DUFF_STEPS))  # one method (one compilation) for the planar systems


@pytest.fixture(scope="module")
def duffing_result():
    """analyze_global of the Duffing oscillator on a 12 x 12 grid of [-2, 2]^2."""
    return jaxgear.analyze_global(DUFFING, DuffingParams(**DUFF), DUFF_GRID, METHOD, progress=False, uncertainty=0)


def _duffing_brute_force(X, periods, tail, steps):
    """numpy RK4 (``steps`` per period) of every state of ``X (n, 2)`` over ``periods +
    tail`` periods: ``(periodic (n,) bool, section points of the tail (tail, n, 2))``; a state
    is periodic when its last ``tail`` section points repeat with some period k <= 8 to
    1e-6, otherwise it ended on the bounded aperiodic attractor."""
    d, a, b, g, w = (DUFF[k] for k in ("delta", "alpha", "beta", "gamma", "omega"))
    h = DUFF_T / steps

    def acc(t, x, v):
        return g * np.cos(w * t) - d * v - a * x - b * x**3

    x, v = X[:, 0].copy(), X[:, 1].copy()
    tail_pts = []
    for p in range(periods + tail):
        for i in range(steps):
            t = i * h  # the forcing is T-periodic: every period repeats the same step times
            k1x, k1v = v, acc(t, x, v)
            k2x, k2v = v + h / 2 * k1v, acc(t + h / 2, x + h / 2 * k1x, v + h / 2 * k1v)
            k3x, k3v = v + h / 2 * k2v, acc(t + h / 2, x + h / 2 * k2x, v + h / 2 * k2v)
            k4x, k4v = v + h * k3v, acc(t + h, x + h * k3x, v + h * k3v)
            x = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
            v = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        if p >= periods:
            tail_pts.append(np.stack([x, v], axis=1))
    pts = np.array(tail_pts)
    assert np.all(np.abs(pts) < 10)  # every state stays bounded: no sink
    periodic = np.zeros(len(X), bool)
    for k in range(1, 9):
        periodic |= np.max(np.abs(pts[k:] - pts[:-k]), axis=(0, 2)) < 1e-6
    return periodic, pts


@pytest.fixture(scope="module")
def duffing_brute_force():
    """The brute force of 300 random states of the grid's region (another step than the
    analysis: 72 per period)."""
    X = np.random.default_rng(11).uniform(*DUFF_BOX, (300, 2))
    return _duffing_brute_force(X, periods=250, tail=30, steps=72)


def test_chaotic_and_periodic_attractors_coexist(duffing_result, duffing_brute_force):
    """Both attractors are found with their types (a P-1 cycle, periodic; a chaotic one of
    period 0 with a cloud), every cell is decided, and the shares agree with the brute
    force of random states of the same region within 3 binomial standard errors (of the
    grid and the random sample together)."""
    r = duffing_result
    assert r.n_sink == 0 and r.n_unresolved == 0
    assert sorted(a.label for a in r.attractors) == ["P-1", "chaotic"]
    chaotic = next(a for a in r.attractors if a.period == 0)
    cycle = next(a for a in r.attractors if a.period == 1)
    assert chaotic.type is AttractorType.CHAOTIC and cycle.type is AttractorType.PERIODIC
    assert chaotic.largest_exponent > 3 * chaotic.exponent_errors[0]
    assert cycle.largest_exponent < -3 * cycle.exponent_errors[0]
    assert chaotic.points.shape[0] > 500 and cycle.points.shape == (1, 2)

    periodic, tail = duffing_brute_force
    n_ref, n_grid = len(periodic), r.n_cells
    ref_share = np.mean(~periodic)
    assert 0.2 < ref_share < 0.9  # both basins sizeable
    se = np.sqrt(ref_share * (1 - ref_share) * (1 / n_ref + 1 / n_grid))
    assert abs(chaotic.share - ref_share) <= 3 * se
    assert abs(cycle.share - (1 - ref_share)) <= 3 * se
    assert chaotic.cell_count + cycle.cell_count == n_grid

    # the cycle is the brute force's cycle; the brute force's chaotic states lie on the cloud
    np.testing.assert_allclose(tail[-1][periodic], np.broadcast_to(cycle.points[0], tail[-1][periodic].shape),
                               atol=1e-3)
    ends = tail[:, ~periodic].reshape(-1, 2)
    dist = np.min(np.linalg.norm(ends[:, None, :] - chaotic.points[None, :, :], axis=-1), axis=1)
    assert np.mean(dist < 0.05) > 0.95
    # and the cloud lies on the brute force's attractor (its points near those end points)
    back = np.min(np.linalg.norm(chaotic.points[:, None, :] - ends[None, :, :], axis=-1), axis=1)
    assert np.mean(back < 0.05) > 0.95


# Just past the boundary crisis (about gamma = 0.31515 with this RK4 step) the chaotic
# attractor above is a chaotic saddle: states wander on it for a mean of about 500 periods
# (half of those on it after 600 periods are still there) and then settle on the cycles.
SADDLE_GAMMA = 0.315151


def _numpy_period(x, steps: int = DUFF_STEPS):
    """One forcing period of the Duffing oscillator (``SADDLE_GAMMA``) from the states ``x
    (n, 2)`` by numpy RK4 (``steps`` per period)."""
    d, a, b, w = (DUFF[k] for k in ("delta", "alpha", "beta", "omega"))

    def f(t, y):
        return np.stack([y[:, 1], SADDLE_GAMMA * np.cos(w * t) - d * y[:, 1] - a * y[:, 0] - b * y[:, 0] ** 3], axis=1)

    return _numpy_rk4(f, x, DUFF_T, steps)


def _numpy_rk4(f, x, T, steps):
    """The states ``x (n, 2)`` after time ``T`` of ``y' = f(t, y)`` from t = 0, by a plain
    numpy RK4 of ``steps`` steps (independent of jaxgear's integrators)."""
    h = T / steps
    y = np.array(x, dtype=float)
    for i in range(steps):
        t = i * h
        k1 = f(t, y)
        k2 = f(t + h / 2, y + h / 2 * k1)
        k3 = f(t + h / 2, y + h / 2 * k2)
        k4 = f(t + h, y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


@pytest.fixture(scope="module")
def saddle_result():
    p = DuffingParams(**{**DUFF, "gamma": SADDLE_GAMMA})
    return jaxgear.analyze_global(DUFFING, p, DUFF_GRID, METHOD, progress=False, uncertainty=0)


def test_a_long_chaotic_transient_is_no_attractor(saddle_result):
    """A chaotic saddle (a long chaotic transient into cycles) is not reported as an
    attractor: its cells are labelled with the cycles the brute force's long integration
    of the same states ends on (in its shares), or left unresolved, never given an
    aperiodic attractor.

    The brute force integrates every cell centre 3,000 periods (the stroboscopic orbit,
    outside the analysis's lane pool) and checks that its ends are cycles with a numpy
    RK4 of its own; at 300 periods a large share still wanders (the transient outlasts
    the 80-period wait and the 600-period cloud of a candidate attractor of boxes)."""
    p = DuffingParams(**{**DUFF, "gamma": SADDLE_GAMMA})
    X = DUFF_GRID.centres()
    orbit = np.asarray(jaxgear.stroboscopic_orbit(DUFFING, p, X, n_points=3000, integrator=RK4(DUFF_STEPS)))

    def cycle_period(tail):  # (n, m, 2) -> period of each (0: none within 1e-6 over the tail)
        k_of = np.zeros(len(tail), int)
        for k in range(8, 0, -1):
            k_of[np.max(np.abs(tail[:, k:] - tail[:, :-k]), axis=(1, 2)) < 1e-6] = k
        return k_of

    assert np.mean(cycle_period(orbit[:, 270:300]) == 0) > 0.3  # a long transient
    period = cycle_period(orbit[:, -30:])
    # (nearly) every state ends on a cycle ... (the transients' lengths spread out
    # exponentially and round-off decides each: one state in a hundred may still wander)
    settled = period > 0
    assert settled.mean() >= 0.97
    period, ends = period[settled], orbit[settled, -1]
    # ... which an independent numpy RK4 confirms: each end returns after its period
    y, after = ends, []
    for _ in range(max(period)):
        y = _numpy_period(y)
        after.append(y)
    returned = np.stack(after)[period - 1, np.arange(len(ends))]
    assert np.max(np.abs(returned - ends)) < 1e-5

    r = saddle_result
    assert all(a.period > 0 for a in r.attractors), [a.label for a in r.attractors]
    assert r.n_sink == 0 and r.n_unresolved <= 0.05 * r.n_cells
    # the cycles reported are those the brute force ends on, with its shares within 3
    # binomial standard errors (which cycle a wandering state takes is decided by round-off
    # over hundreds of chaotic periods: the same cell may take another in the analysis)
    covered = np.zeros(len(ends), bool)
    for a in r.attractors:
        on = np.array([np.min(np.linalg.norm(a.points - e, axis=1)) < 1e-4 for e in ends])
        covered |= on
        se = np.sqrt(2 * on.mean() * (1 - on.mean()) / len(ends))
        assert on.any() and abs(a.share - on.mean()) <= 3 * se + r.n_unresolved / r.n_cells, (a.label, a.share)
    assert covered.mean() >= 0.95


def test_the_saddle_is_reported_with_the_lifetime_of_its_transient(saddle_result):
    """The analysis reports the chaotic saddle with the mean lifetime of its transient
    (its escape rate, from 1,024 of its points). An independent measure: 1,024 cell
    centres of a 32 x 32 grid integrated 1,600 periods, a state still wandering when its
    last 20 points repeat with no period up to 8; from 400 periods on the count still
    wandering decays exponentially, and a weighted log-linear fit gives its lifetime. The
    two agree within 3 of their combined errors, and the analysis's error is below 15 %."""
    (saddle,) = saddle_result.saddles
    assert np.isfinite(saddle.lifetime) and saddle.lifetime_error < 0.15 * saddle.lifetime
    assert saddle.left > 0.9 and "chaotic saddle" in saddle_result.table()
    p = DuffingParams(**{**DUFF, "gamma": SADDLE_GAMMA})
    X = jaxgear.CellGrid.box([DUFF_BOX, DUFF_BOX], [32, 32]).centres()
    orbit = np.asarray(jaxgear.stroboscopic_orbit(DUFFING, p, X, n_points=1600, integrator=RK4(DUFF_STEPS)))

    def wandering(t):
        tail = orbit[:, t - 20:t]
        cycle = np.zeros(len(tail), bool)
        for k in range(1, 9):
            cycle |= np.max(np.abs(tail[:, k:] - tail[:, :-k]), axis=(1, 2)) < 1e-6
        return int(np.sum(~cycle))

    ts = np.arange(400, 1601, 100)
    n = np.array([wandering(t) for t in ts])
    assert n[-1] >= 20 and n[0] > 5 * n[-1]  # an exponential decay over the range, well sampled
    slope = np.polyfit(ts, np.log(n), 1, w=np.sqrt(n))[0]
    reference = -1 / slope
    ref_error = reference / np.sqrt(n[0] - n[-1])  # (the departures counted)
    assert abs(saddle.lifetime - reference) <= 3 * np.hypot(saddle.lifetime_error, ref_error), (
        saddle.lifetime, saddle.lifetime_error, reference, ref_error)


def test_escape_rate_of_exponential_departures_is_within_its_error():
    """The estimator of a saddle's escape rate on synthetic departures: exponential times
    (rate 1/500 per period) seen 40 periods late, a tenth of the points gone at once (a
    cloud's points not on the saddle), in 32 stages of 63 periods: the rate within 3
    stated errors, the error that of the departures counted (about 1/sqrt(D))."""
    from jaxgear.analysis._saddles import escape_rate

    rng = np.random.default_rng(1)
    kappa, stage = 1 / 500, 63
    t = rng.exponential(1 / kappa, 20000) + 40.0
    t[:2000] = 1.0
    stage_left = np.where(t < 32 * stage, np.floor(t / stage).astype(int) + 1, 0)
    got, err = escape_rate(stage_left, 32, stage)
    D = np.sum(stage_left > 4)
    assert abs(got - kappa) <= 3 * err and err == pytest.approx(kappa / np.sqrt(D), rel=0.3)
    assert escape_rate(np.zeros(10, int), 32, stage)[0] == 0.0  # nothing left: no rate (an infinite lifetime)


def test_a_saddle_left_within_the_burn_in_has_no_measured_lifetime():
    """Every point gone within the burn-in stages: the rate is infinite and the lifetime is
    unmeasurable (NaN, printed as shorter than the burn-in), not 0 and not infinite; no
    point gone: an infinite lifetime, printed as beyond the run; else 1 / kappa."""
    from jaxgear.analysis._saddles import SADDLE_BURN_IN, escape_rate, mean_lifetime

    gone = escape_rate(np.full(10, SADDLE_BURN_IN), 32, 63)
    assert gone[0] == np.inf and np.isnan(mean_lifetime(*gone)[0])
    assert mean_lifetime(0.0, np.nan)[0] == np.inf
    life, err = mean_lifetime(1 / 500, 1e-4)
    assert life == pytest.approx(500) and err == pytest.approx(1e-4 * 500**2)
    saddle = dict(points=np.zeros((3, 2)), lifetime_error=np.nan, starts=1024, periods=2016, left=1.0)
    assert "below about 252 periods" in jaxgear.ChaoticSaddle(lifetime=np.nan, **saddle).describe()
    assert "beyond about 2016 periods" in jaxgear.ChaoticSaddle(lifetime=np.inf, **saddle).describe()


def _gear_on_a_chaotic_transient(**options):
    """The paper preset at b = 1.15 on 5 x 3 x 6 cells: its cells wander on a chaotic saddle
    for thousands of periods (a lifetime of about 5,000) before they settle on the one P-6
    cycle."""
    p = jaxgear.with_param(jaxgear.paper_params(), "b", 1.15)
    return jaxgear.analyze_global(jaxgear.REDUCED, p, jaxgear.CellGrid.paper((5, 3, 6)), jaxgear.Direct(**options),
                                  progress=False, uncertainty=0)


def test_a_gear_value_on_a_long_chaotic_transient_is_resolved():
    """The pool finds the saddle and lets its value's cells run past ``max_periods``, up to
    ``saddle_periods``: at most 1 % are left unresolved, all the others on the P-6."""
    r = _gear_on_a_chaotic_transient()
    assert r.n_unresolved <= 0.01 * r.n_cells and r.n_sink == 0
    assert [a.period for a in r.attractors] == [6]
    assert r.mean_periods > 2 * r.method.max_periods  # its cells did run past max_periods
    # the saddle, with its lifetime (about 5,000 periods: longer than the 2,000 of max_periods)
    (saddle,) = r.saddles
    assert 2000 < saddle.lifetime < 20000 and saddle.lifetime_error < 0.15 * saddle.lifetime


@pytest.mark.slow
def test_without_the_longer_run_the_transient_leaves_cells_unresolved():
    """The same with ``saddle_periods = max_periods``: a third or more of the cells are
    still on the saddle after 2,000 periods, and the warning names ``saddle_periods`` (so
    the test above can fail)."""
    with pytest.warns(UserWarning, match="saddle_periods"):
        cut = _gear_on_a_chaotic_transient(saddle_periods=2000)
    assert cut.n_unresolved >= 0.3 * cut.n_cells


@pytest.mark.slow  # about 2 min on one core: to whichever worker is free (its file's other tests run elsewhere)
@pytest.mark.spread
def test_backlash_scan_leaves_no_value_unresolved_and_one_type_per_attractor():
    """The backlash scan of the paper preset from 1.0 to 3.0 in steps of 0.1, and b = 1.15,
    on 10 x 6 x 12 cells (a basin sweep): no value leaves more than 1 % of its cells
    unresolved (b = 1.15, a long chaotic transient, left 60 % before saddle_periods), and the
    chaotic attractor that the sweep follows from about b = 1.2 to 2.7 keeps one type,
    chaotic, at every value."""
    values = np.union1d(np.round(np.arange(1.0, 3.0001, 0.1), 10), [1.15])
    s = jaxgear.basin_sweep(jaxgear.REDUCED, jaxgear.paper_params(), "b", values, jaxgear.CellGrid.paper((10, 6, 12)),
                            runner=jaxgear.Runner(progress=False), uncertainty=0)
    assert np.all(s.unresolved_share <= 0.01), dict(zip(values[s.unresolved_share > 0.01],
                                                        s.unresolved_share[s.unresolved_share > 0.01]))
    kinds = np.asarray(s.attractor_type)
    band = [g for g in range(s.shares.shape[1]) if np.sum(s.present[:, g] & (kinds[:, g] == AttractorType.CHAOTIC)) >= 6]
    assert band, "no chaotic attractor followed over the band"
    for g in band:
        at = s.present[:, g]
        assert set(kinds[at, g].tolist()) == {int(AttractorType.CHAOTIC)}, (g, values[at], kinds[at, g])


def test_duffing_exponents_obey_liouville(duffing_result):
    """The divergence of the field is -delta: every period contracts areas by exp(-delta T),
    so the two exponents of each attractor sum to -delta T (to the RK4 map's error at 64
    steps, ~1e-4); the cycle's multipliers are a complex pair (as the shooting module
    says), so both of its exponents are -delta T / 2."""
    want = -DUFF["delta"] * DUFF_T
    for a in duffing_result.attractors:
        assert a.exponents.shape == (2,)
        assert a.exponents[0] >= a.exponents[1] - 3 * a.exponent_errors.max()  # largest first (a pair: equal)
        np.testing.assert_allclose(a.exponents.sum(), want, atol=2e-4)
    chaotic = next(a for a in duffing_result.attractors if a.period == 0)
    # Kaplan-Yorke dimension of the map: 1 + lambda_1 / |lambda_2|, between 1 and 2
    np.testing.assert_allclose(chaotic.kaplan_yorke, 1 + chaotic.exponents[0] / abs(chaotic.exponents[1]),
                               rtol=1e-12)
    assert 1 < chaotic.kaplan_yorke < 2
    cycle = next(a for a in duffing_result.attractors if a.period == 1)
    mu = np.asarray(jaxgear.floquet_multipliers(DUFFING, DuffingParams(**DUFF), cycle.points[0],
                                                integrator=RK4(DUFF_STEPS)))
    assert abs(mu[0].imag) > 0.1 and np.isclose(mu[0], np.conj(mu[1]))
    np.testing.assert_allclose(cycle.exponents, [want / 2] * 2, atol=1e-4 + 3 * cycle.exponent_errors[0])
    assert cycle.kaplan_yorke == 0.0


def test_types_exponents_and_cloud_survive_save_and_load(duffing_result, tmp_path):
    """Saved and loaded, the chaotic attractor and the cycle keep their kind, exponents,
    errors, Kaplan-Yorke dimension and points (the chaotic one's cloud), bit for bit."""
    back = jaxgear.load(duffing_result.save(tmp_path / "duffing.nc"))
    assert len(back.attractors) == len(duffing_result.attractors)
    for a, b in zip(duffing_result.attractors, back.attractors):
        assert (b.kind, b.type, b.period, b.label) == (a.kind, a.type, a.period, a.label)
        for name in ("exponents", "exponent_errors", "points"):
            np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
        assert b.kaplan_yorke == a.kaplan_yorke
    assert {b.type for b in back.attractors} == {AttractorType.CHAOTIC, AttractorType.PERIODIC}
    np.testing.assert_array_equal(back.labels, duffing_result.labels)


# --------------------------------------------------------------------------- a torus

VDP_MU, VDP_F = 0.1, 0.05
GOLDEN = (5**0.5 - 1) / 2


def _rotation_number(omega, periods=600):
    """scipy reference: the rotation of the van der Pol section points about the origin,
    turns per forcing period (clockwise, mod 1), after a transient of 200 periods."""
    T = 2 * np.pi / omega

    def f(t, y):
        return [y[1], VDP_MU * (1 - y[0] ** 2) * y[1] - y[0] + VDP_F * np.cos(omega * t)]

    sol = solve_ivp(f, (0.0, (200 + periods) * T), [2.0, 0.0], method="DOP853", rtol=1e-10, atol=1e-10,
                    t_eval=T * np.arange(200, 200 + periods + 1))
    ang = np.unwrap(np.arctan2(sol.y[1], sol.y[0]))  # (a step of ~0.38 turn: unwrapped uniquely)
    return -(ang[-1] - ang[0]) / (2 * np.pi * periods) % 1.0


def _check_one_torus(r, omega):
    """One quasi-periodic attractor of period 0 takes every cell: its largest exponent is zero
    within its error, its second is the limit cycle's transverse exponent -mu per unit time
    (averaging theory, to O(mu^2)); its cloud is a closed curve around the unstable origin
    near the unforced limit cycle's circle of radius 2."""
    assert r.n_sink == 0 and r.n_unresolved == 0
    assert [a.label for a in r.attractors] == ["quasi-periodic"]
    a = r.attractors[0]
    assert a.period == 0 and a.type is AttractorType.QUASI_PERIODIC
    lam, err = a.exponents, a.exponent_errors
    assert abs(lam[0]) <= max(3 * err[0], 1e-7)
    assert err[0] < 1e-3 * abs(lam[1])  # zero to 0.1 % of the transverse contraction (measured: 2e-5), not a wide error
    assert lam[1] < -3 * err[1]
    np.testing.assert_allclose(lam[1] * omega / (2 * np.pi), -VDP_MU, rtol=0.03)
    pts = a.points
    radius = np.linalg.norm(pts, axis=1)
    assert len(pts) > 500 and np.all((1.8 < radius) & (radius < 2.2))
    ang = np.sort(np.arctan2(pts[:, 1], pts[:, 0]))
    assert np.max(np.diff(np.concatenate([ang, [ang[0] + 2 * np.pi]]))) < 0.1  # no gap: the whole curve
    # a curve of the map: Kaplan-Yorke dimension 1 (lambda_1 = 0, to its error) or 0 (lambda_1 < 0 by round-off)
    assert a.kaplan_yorke == (pytest.approx(1.0, abs=max(1e-6, 3 * err[0] / abs(lam[1]))) if lam[0] >= 0 else 0.0)


VDP_GRID = jaxgear.CellGrid.box([(-3.0, 3.0), (-3.0, 3.0)], [4, 4])  # (no cell centre at the origin)


def test_unlocked_van_der_pol_is_quasi_periodic():
    """The weakly forced van der Pol oscillator (mu = 0.1, F = 0.05) unlocked: the forcing
    frequency is the golden mean times the limit cycle's frequency 1 - mu^2/16, so that the
    rotation number (scipy) is within 1e-5 of the golden mean, far from every p/q with
    q <= 100: the motion is on a torus (one quasi-periodic attractor, see
    :func:`_check_one_torus`)."""
    omega = (1 - VDP_MU**2 / 16) / GOLDEN
    rho = _rotation_number(omega)
    assert abs(rho - GOLDEN) < 1e-5
    q = np.arange(1, 101)
    assert np.min(np.abs(rho * q - np.round(rho * q))) > 1e-3
    r = jaxgear.analyze_global(VAN_DER_POL, VanDerPolParams(mu=VDP_MU, F=VDP_F, omega=omega), VDP_GRID, METHOD,
                               progress=False, uncertainty=0)
    _check_one_torus(r, omega)


@pytest.mark.parametrize("omega", [1.617, GOLDEN])
def test_torus_at_a_generic_frequency_is_found(omega):
    """The same oscillator at forcing frequencies next to the unlocked one (1.617) and at
    the golden mean itself (0.618, a torus that wraps slowly: its curve crosses about 280
    boxes): one quasi-periodic attractor takes every cell, as at the neighbouring value of
    :func:`test_unlocked_van_der_pol_is_quasi_periodic`. A torus keeps a candidate's copies
    together, so its first cloud came back to only 55-70 % of its boxes (below
    accept_share) and every cell was left unresolved; the continuation of such a cloud
    (jaxgear.analysis._cloud.CONTINUE_SHARE) finds it. Rotation number (scipy) off every
    p/q with q <= 20, so the motion is not a locked cycle."""
    rho = _rotation_number(omega)
    q = np.arange(1, 21)
    assert np.min(np.abs(rho * q - np.round(rho * q))) > 1e-3
    r = jaxgear.analyze_global(VAN_DER_POL, VanDerPolParams(mu=VDP_MU, F=VDP_F, omega=omega), VDP_GRID, METHOD,
                               progress=False, uncertainty=0)
    _check_one_torus(r, omega)


@pytest.mark.slow
def test_near_resonant_torus_is_one_attractor():
    """The case of tests/test_lyapunov.py (forcing frequency the golden mean itself): its
    rotation number (scipy) is 21/34 to 1e-5 (the limit cycle's frequency 1 - mu^2/16
    shifts it off the golden mean), still quasi-periodic by its exponents: one torus. The
    cloud of one cell is 34 tight clusters, and the clouds of cells at other phases along
    the curve share no boxes with it: the analysis joins them by the continuity of the
    phase along a segment between them (jaxgear.analysis._tori)."""
    omega = 1 / GOLDEN
    rho = _rotation_number(omega)
    assert abs(rho - 21 / 34) < 1e-5
    r = jaxgear.analyze_global(VAN_DER_POL, VanDerPolParams(mu=VDP_MU, F=VDP_F, omega=omega), VDP_GRID, METHOD,
                               progress=False, uncertainty=0)
    assert r.n_unresolved == 0 and all(a.type is AttractorType.QUASI_PERIODIC for a in r.attractors)
    _check_one_torus(r, omega)
    # its type is the same from ten other samples of starts on it (before the zero floor, a
    # torus whose finite-time zero exponent averaged 1e-6 +- 3e-7 was typed chaotic)
    from jaxgear.analysis._global import attractor_exponents

    (a,) = r.attractors
    p = VanDerPolParams(mu=VDP_MU, F=VDP_F, omega=omega)
    for seed in range(10):
        cloud = np.random.default_rng(seed).permutation(a.points)
        kinds, _ = attractor_exponents(VAN_DER_POL, p, [(cloud, 0)], METHOD.integrator, [None])
        assert kinds[0] == int(AttractorType.QUASI_PERIODIC), seed


class _Turn(NamedTuple):
    w: float


def _two_circles(r2):
    """Two attracting circles of the plane, r = 1 and r = r2, the circle between them
    repelling (their basins' boundary), both turning at ``w`` per unit time (period 2 pi)."""
    def f(t, z, p):
        r = jnp.hypot(z[0], z[1])
        g = -200.0 * (r - 1.0) * (r - (1.0 + r2) / 2) * (r - r2)
        return jnp.stack([g * z[0] - p.w * z[1], g * z[1] + p.w * z[0]])

    return jaxgear.ForcedSystem(f, lambda p: 2 * jnp.pi, ("x", "y"), section_index=1, name="two-circles")


def _clusters(r, shift, q=34, per=20):
    """A near-resonant cloud on the circle of radius r: q tight clusters at angles
    2 pi (k / q + shift)."""
    a = 2 * np.pi * (np.arange(q)[:, None] / q + shift) + np.linspace(-1e-4, 1e-4, per)[None, :]
    return r * np.stack([np.cos(a.ravel()), np.sin(a.ravel())], axis=1)


def test_clouds_of_one_curve_are_joined_and_of_two_curves_not():
    """The join of quasi-periodic attractors (jaxgear.analysis._tori): interleaved clusters
    on one attracting circle are one attractor; clusters on two circles 0.1 apart (closer
    than the clouds' nearest points, 0.14) stay two, and so do attractors of other types."""
    from jaxgear.analysis._tori import joined_tori

    system, p, rk = _two_circles(1.1), _Turn(w=0.6180339887), RK4(200)
    qp, exps = int(AttractorType.QUASI_PERIODIC), np.array([0.0, -6.0])
    one, other, far = _clusters(1.0, 0.0), _clusters(1.0, 0.5 / 34), _clusters(1.1, 0.5 / 34)
    got = joined_tori(system, p, rk, [one, other, far], [qp] * 3, [exps] * 3)
    assert got is not None and list(got) == [0, 0, 1]
    assert joined_tori(system, p, rk, [one, far], [qp] * 2, [exps] * 2) is None
    chaotic = int(AttractorType.CHAOTIC)
    assert joined_tori(system, p, rk, [one, other], [chaotic, qp], [exps] * 2) is None


def test_a_cycle_longer_than_max_period_gets_its_period():
    """The parametrically excited Duffing in its first tongue (zeta = 0.05, epsilon = 0.4,
    Omega = 2): every start ends on one P-2 cycle. Analysed with ``max_period = 1`` the pool
    finds it by its boxes; its exponents say it contracts, and it is then given its
    period: a P-2 with no warning. Its two points map to each other under an independent
    numpy RK4 of the period, and its two exponents sum to the phase-space contraction
    -2 zeta T per period (T = 2 pi / Omega; Liouville), to 1e-6."""
    p = jaxgear.ParamDuffingParams(zeta=0.05, epsilon=0.4, beta=1.0, Omega=2.0)
    grid = jaxgear.CellGrid.box([(-1.5, 1.5), (-1.5, 1.5)], (8, 8))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = jaxgear.analyze_global(jaxgear.PARAM_DUFFING, p, grid, jaxgear.Direct(integrator=RK4(64), max_period=1),
                                   progress=False, uncertainty=0)
    (a,) = r.attractors
    assert a.period == 2 and a.type is AttractorType.PERIODIC and a.cell_count == grid.n_cells and a.multiplier < 1
    T = 2 * np.pi / 2.0

    def f(t, y):
        k = 1.0 + 0.4 * np.cos(2.0 * t)
        return np.stack([y[:, 1], -0.1 * y[:, 1] - k * y[:, 0] - y[:, 0] ** 3], axis=1)

    np.testing.assert_allclose(_numpy_rk4(f, a.points, T, 400), a.points[::-1], atol=1e-6)
    assert np.abs(a.points[0] - a.points[1]).max() > 0.1  # two distinct points: no fixed point
    assert abs(np.sum(a.exponents) + 2 * 0.05 * T) < 1e-6


# --------------------------------------------------------------------------- periodic attractors

# x'' + 3 x' + x + x^3 = cos t: an overdamped oscillator whose P-1 cycle has two real
# multipliers (~5.6e-2 and ~1.2e-7)
OVERDAMPED = dict(delta=3.0, alpha=1.0, beta=1.0, gamma=1.0, omega=1.0)


def _cycle_exponents_and_floquet(result, params):
    """(exponents stored on the result's P-k attractor, ln|mu_i| / k of the Floquet
    multipliers of the same cycle from the shooting module, the attractor)."""
    (a,) = [a for a in result.attractors if a.period > 0]
    orbit = jaxgear.periodic_orbit(DUFFING, params, a.points[0], period=a.period, integrator=RK4(DUFF_STEPS))
    assert int(orbit.status) == 0 and bool(orbit.stable)
    np.testing.assert_allclose(np.asarray(orbit.point), a.points[0], atol=1e-9)
    mu = np.asarray(jaxgear.floquet_multipliers(DUFFING, params, orbit.point, period=a.period,
                                                integrator=RK4(DUFF_STEPS)))
    np.testing.assert_allclose(np.abs(mu).max(), a.multiplier, rtol=1e-4)  # the table's max |mu|
    return a.exponents, np.sort(np.log(np.abs(mu)))[::-1] / a.period, a


def test_periodic_exponents_equal_floquet_multipliers_real_pair():
    """A P-1 cycle with real multipliers: the exponents analyze_global stores are
    ln|mu_i| / k of the shooting module's Floquet multipliers to 1e-6."""
    p = DuffingParams(**OVERDAMPED)
    r = jaxgear.analyze_global(DUFFING, p, DUFF_GRID, METHOD, progress=False, uncertainty=0)
    assert r.n_sink == 0 and r.n_unresolved == 0 and len(r.attractors) == 1
    got, want, a = _cycle_exponents_and_floquet(r, p)
    assert a.type is AttractorType.PERIODIC and a.label == "P-1"
    assert want[0] - want[1] > 10  # two real multipliers far apart
    np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)


def test_periodic_exponents_complex_pair_within_their_errors(duffing_result):
    """The coexisting Duffing's P-1 cycle (a complex pair of multipliers): the stored
    exponents agree with ln|mu_i| / k within 3 of their stated errors."""
    got, want, a = _cycle_exponents_and_floquet(duffing_result, DuffingParams(**DUFF))
    assert np.all(a.exponent_errors == 0)  # a cycle's exponents are exact (its multipliers), not estimates
    np.testing.assert_array_less(np.abs(got - want), 1e-6)


def test_periodic_exponents_complex_pair_to_1e_6(duffing_result):
    """The same cycle to 1e-6, as for real multipliers."""
    got, want, _ = _cycle_exponents_and_floquet(duffing_result, DuffingParams(**DUFF))
    np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)


# --------------------------------------------------------------------------- the gear train at b = 2


@pytest.mark.slow
def test_gear_chaotic_attractor_survives_save_and_load(tmp_path):
    """The paper preset at b_sp = b_rp = 2 (inside the chaotic band of the backlash sweep)
    on a tiny grid of the paper region: every cell reaches one chaotic attractor (period 0,
    largest exponent positive beyond its error); two states of its cloud 1e-9 apart part to
    the attractor's size within 100 periods (the sensitivity, measured without the Lyapunov
    code); saved and loaded, its type, exponents, errors, Kaplan-Yorke dimension and cloud
    are the same. (~15 s of CPU: slow.)"""
    params = jaxgear.paper_params(b_sp=2, b_rp=2)
    g = jaxgear.Direct().default_grid(jaxgear.REDUCED)
    grid = jaxgear.CellGrid.box(list(zip(g.lower, g.upper)), [3, 2, 3], axes=g.axes, dim=4, base=g.base,
                                names=g.names)
    r = jaxgear.analyze_global(jaxgear.REDUCED, params, grid, jaxgear.Direct(), progress=False, uncertainty=0)
    assert r.n_unresolved == 0 and r.n_sink == 0
    assert len(r.attractors) == 1
    a = r.attractors[0]
    assert a.period == 0 and a.type is AttractorType.CHAOTIC and a.label == "chaotic"
    assert a.exponents.shape == (2,)
    assert a.largest_exponent > 3 * a.exponent_errors[0] and a.largest_exponent > 0.1
    assert a.points.shape[1] == 4 and len(a.points) > 500 and np.all(np.isfinite(a.points))
    assert 1 < a.kaplan_yorke < 2
    x0 = np.stack([a.points[0], a.points[0] + 1e-9 * np.array([1.0, 0.0, 0.0, 0.0])])
    orbit = np.asarray(jaxgear.stroboscopic_orbit(jaxgear.REDUCED, params, x0, n_points=100))
    assert np.all(np.abs(orbit) < 100)
    scale = np.ptp(a.points, axis=0).max()
    assert np.max(np.abs(orbit[0] - orbit[1])) > 0.1 * scale

    path = r.save(tmp_path / "b2.nc")
    back = jaxgear.load(path)
    (b,) = back.attractors
    assert b.kind == a.kind and b.type is AttractorType.CHAOTIC and b.period == 0 and b.label == "chaotic"
    np.testing.assert_array_equal(b.exponents, a.exponents)
    np.testing.assert_array_equal(b.exponent_errors, a.exponent_errors)
    assert b.kaplan_yorke == a.kaplan_yorke
    np.testing.assert_array_equal(b.points, a.points)
    np.testing.assert_array_equal(back.labels, r.labels)
    assert back.table() == r.table()


@pytest.fixture(scope="module")
def gear_cycles():
    """The paper preset (b = 5: P-4 and P-8) on a tiny grid of the paper region: the result
    and, per attractor, ``(exponents, ln|mu_i| / k from the shooting module's multipliers
    at its first point, errors)``."""
    params = jaxgear.paper_params()
    g = jaxgear.Direct().default_grid(jaxgear.REDUCED)
    grid = jaxgear.CellGrid.box(list(zip(g.lower, g.upper)), [3, 2, 3], axes=g.axes, dim=4, base=g.base,
                                names=g.names)
    method = jaxgear.Direct()
    r = jaxgear.analyze_global(jaxgear.REDUCED, params, grid, method, progress=False, uncertainty=0)
    out = []
    for a in r.attractors:
        orbit = jaxgear.periodic_orbit(jaxgear.REDUCED, params, a.points[0], period=max(a.period, 1),
                                       integrator=method.integrator)
        assert int(orbit.status) == 0 and bool(orbit.stable)
        want = np.sort(np.log(np.abs(np.asarray(orbit.multipliers))))[::-1][: len(a.exponents)] / a.period
        out.append((a.exponents, want, a.exponent_errors))
    return r, out


@pytest.mark.slow
def test_gear_attractors_at_the_paper_preset_are_cycles(gear_cycles):
    """Every attractor is periodic (the P-4 and the P-8 of the paper preset), and its
    largest exponent is negative, as ln of its largest multiplier modulus (< 1) says."""
    r, cycles = gear_cycles
    assert r.n_unresolved == 0 and r.n_sink == 0
    assert sorted(a.label for a in r.attractors)[0] == "P-4"
    assert all(a.period in (4, 8) and a.type is AttractorType.PERIODIC for a in r.attractors)
    for a, (got, want, err) in zip(r.attractors, cycles):
        assert want[0] < 0 and got[0] < -3 * err[0]
        assert a.kaplan_yorke == 0.0


@pytest.mark.slow
def test_gear_periodic_exponents_equal_floquet_multipliers(gear_cycles):
    """Each cycle's exponents are ln|mu_i| / k of the shooting module's multipliers: within
    3 of their stated errors, and to 1e-6."""
    for got, want, err in gear_cycles[1]:
        np.testing.assert_array_less(np.abs(got - want), 3 * err + 1e-6)
        np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)


# --------------------------------------------------------------------------- fractal basin measures
def _entropy_by_definition(labels: np.ndarray, box: int) -> tuple[float, float]:
    """Basin entropy and boundary basin entropy from their definition (Daza et al. 2016),
    box by box: the Gibbs entropy of the outcomes in each box of ``box^d`` cells, averaged
    over all boxes and over the boxes holding more than one outcome."""
    import collections
    import itertools

    per_box = []
    for corner in itertools.product(*(range(0, n - box + 1, box) for n in labels.shape)):
        cells = labels[tuple(slice(c, c + box) for c in corner)].ravel().tolist()
        counts = collections.Counter(cells)
        S = -sum(c / len(cells) * math.log(c / len(cells)) for c in counts.values())
        per_box.append((S, len(counts) > 1))
    S_b = sum(S for S, _ in per_box) / len(per_box)
    boundary = [S for S, b in per_box if b]
    return S_b, (sum(boundary) / len(boundary) if boundary else float("nan"))


def test_basin_measures_of_an_analysis_and_their_figure(duffing_result):
    """The analysis's basin entropies equal those of its labels counted box by box from the
    definition; the figure draws the stored uncertain fractions at the stored start moves
    and, for fractions that follow a power law, the fit line of slope alpha through them
    over the scaling range only, the points outside it apart."""
    from jaxgear.plotting import plot_basin_measures

    r = duffing_result
    box = min(5, *r.grid.counts)
    S_b, S_bb = _entropy_by_definition(np.asarray(r.labels).reshape(r.grid.counts), box)
    assert r.basin_entropy.box == box
    assert r.basin_entropy.S_b == pytest.approx(S_b, rel=1e-12)
    assert r.basin_entropy.S_bb == pytest.approx(S_bb, rel=1e-12) and S_bb > 0
    # smaller boxes, some inside one basin: S_bb (boundary boxes only) differs from S_b
    from jaxgear.analysis import basin_entropy

    S_b3, S_bb3 = _entropy_by_definition(np.asarray(r.labels).reshape(r.grid.counts), 3)
    e3 = basin_entropy(np.asarray(r.labels).reshape(r.grid.counts), box=3)
    assert S_bb3 > S_b3 > 0
    assert (e3.S_b, e3.S_bb) == (pytest.approx(S_b3, rel=1e-12), pytest.approx(S_bb3, rel=1e-12))
    u = jaxgear.with_label_uncertainty(r, DUFFING, DuffingParams(**DUFF), METHOD, 64).uncertainty
    assert len(u.perturbations) == 6 and u.perturbations[0] == u.perturbation and u.start_fractions[0] == u.start
    assert np.allclose(np.asarray(u.perturbations) / u.perturbation, 10.0 ** -np.arange(6), rtol=1e-12)
    assert all(0.0 <= f <= 1.0 for f in u.start_fractions)
    # 64 cells of a smooth boundary: too few uncertain ones at moves of 1e-8 to 1e-3 cell
    assert np.isnan(u.alpha) and u.alpha_range is None and u.alpha_reason.startswith("no scaling range")
    eps = np.asarray(u.perturbations)
    # fractions on a power law 0.2 eps^0.5 below 1e-4 cell and flat above, with the exponent
    # and the range of such data: the fit line has slope 0.5 through the points of the range
    # (filled), the two flat ones drawn apart (open)
    f = np.minimum(0.2 * eps**0.5, 0.2 * 1e-4**0.5)
    law = dataclasses.replace(u, start_fractions=tuple(f), alpha=0.5, alpha_error=0.01, alpha_range=(1e-8, 1e-4),
                              alpha_chi2=0.0, alpha_reason=None)
    fig = plot_basin_measures(dataclasses.replace(r, uncertainty=law))
    inside, outside = fig.axes[0].containers
    assert inside.lines[0].get_markerfacecolor() != "none" and outside.lines[0].get_markerfacecolor() == "none"
    np.testing.assert_allclose(sorted(inside.lines[0].get_xdata()), eps[eps <= 1e-4 * 1.001][::-1])
    np.testing.assert_allclose(sorted(outside.lines[0].get_xdata()), eps[eps > 1e-4 * 1.001][::-1])
    fit = next(line for line in fig.axes[0].get_lines() if line.get_label().startswith("fit"))
    x, y = np.asarray(fit.get_xdata()), np.asarray(fit.get_ydata())
    assert x.min() == pytest.approx(1e-8) and x.max() == pytest.approx(1e-4)  # over the range only
    np.testing.assert_allclose(np.diff(np.log(y)) / np.diff(np.log(x)), 0.5, rtol=1e-12)
    np.testing.assert_allclose(y, 0.2 * x**0.5, rtol=1e-12)
    # no scaling range: every fraction above zero drawn open, no fit line
    fig = plot_basin_measures(dataclasses.replace(r, uncertainty=dataclasses.replace(law, alpha=np.nan,
                                                                                       alpha_range=None)))
    (points,) = fig.axes[0].containers
    assert points.lines[0].get_markerfacecolor() == "none" and len(points.lines[0].get_xdata()) == 6
    assert not [line for line in fig.axes[0].get_lines() if line.get_label().startswith("fit")]


@pytest.mark.slow  # about 50 s of CPU on 2 cores (16,384 cells analysed, then 8 x 16,384 lanes relabelled)
def test_a_smooth_basin_boundary_has_uncertainty_exponent_one():
    """The unforced damped double-well Duffing: two wells, their basins bounded by the
    stable manifolds of the saddle, smooth curves, so alpha = 1 (Grebogi et al. 1983).
    Every cell of a 128 x 128 grid is sampled (alpha = 1 needs about 10^4 samples for
    counts over three decades) with start moves up to 10 cells (1e-4 to 10 cells): the
    exponent over its scaling range is within 3 errors of 1."""
    from jaxgear.analysis import label_uncertainty

    p = DuffingParams(delta=0.25, alpha=-1.0, beta=1.0, gamma=0.0, omega=1.0)
    grid = jaxgear.CellGrid.box([DUFF_BOX, DUFF_BOX], (128, 128))
    method = jaxgear.Direct(integrator=RK4(16))
    r = jaxgear.analyze_global(DUFFING, p, grid, method, progress=False, uncertainty=0)
    assert sorted(a.label for a in r.attractors) == ["P-1", "P-1"] and r.n_sink == r.n_unresolved == 0
    u = label_uncertainty(DUFFING, p, grid, r.labels, r.attractors, method, samples=grid.n_cells, perturbation=10.0)
    assert u.alpha_reason is None and u.alpha_range[1] >= 999 * u.alpha_range[0], u
    assert abs(u.alpha - 1.0) <= 3 * u.alpha_error and u.alpha_error < 0.2, u


@pytest.mark.slow  # about 25 s on 2 cores: an analysis and two label uncertainties of the gear model
def test_label_uncertainty_looks_for_no_new_set_where_the_result_has_none(monkeypatch):
    """A result with cycles only and no chaotic saddle (the paper preset on 10 x 6 x 12
    cells): the label uncertainty's pools choose no candidate for a new attractor of boxes
    once they are told the result's saddles (none), and give the labels of the pools that
    look for one, whose every candidate there is a slow transient with a rejected cloud:
    the same step and start fractions."""
    from jaxgear.analysis import _placement, label_uncertainty

    p, grid = jaxgear.paper_params(), jaxgear.CellGrid.paper((10, 6, 12))
    r = jaxgear.analyze_global(jaxgear.REDUCED, p, grid, progress=False, uncertainty=0)
    assert r.attractors and all(0 < a.period <= r.method.max_period for a in r.attractors) and not r.saddles
    calls = []
    characterise = _placement.OneDevice.characterise
    monkeypatch.setattr(_placement.OneDevice, "characterise", lambda self, *a: calls.append(1) or characterise(self, *a))
    looking = label_uncertainty(jaxgear.REDUCED, p, grid, r.labels, r.attractors, r.method, samples=256)
    n_looking = len(calls)
    calls.clear()
    told = label_uncertainty(jaxgear.REDUCED, p, grid, r.labels, r.attractors, r.method, samples=256,
                             saddles=r.saddles)
    assert n_looking > 0 and calls == []
    assert (told.step, told.start_fractions) == (looking.step, looking.start_fractions)
