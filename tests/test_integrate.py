"""Integration: RK4 order (smooth cases and with backlash, docs/model.md §8), Adaptive (diffrax)
accuracy, RK4/Adaptive agreement on the paper preset, sampling, failures as data.

References: the closed-form periodic response of the forced linear oscillator
(Duffing with beta = 0), and diffrax Tsit5 at tight tolerance.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import REDUCED

TIGHT = jg.Adaptive(rtol=1e-12, atol=1e-12)


def duffing_linear():
    """x'' + delta x' + alpha x = gamma cos(w t): x_p(t) = Re(H gamma e^{i w t})."""
    d, a, g, w = 0.2, 1.0, 1.0, 1.3
    P = jg.DuffingParams(delta=d, alpha=a, beta=0.0, gamma=g, omega=w)
    H = g / (a - w**2 + 1j * d * w)

    def x_of_t(t):
        z = H * np.exp(1j * w * np.asarray(t, float))
        return np.stack([np.real(z), np.real(1j * w * z)], -1)

    return P, x_of_t


def _paper_states(n, seed):
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(-25, 25, n), rng.uniform(-10, 20, n), rng.uniform(-10, 50, n), np.zeros(n)], -1)


def _order_ratios(errors):
    e = np.asarray(errors)
    return e[:-1] / e[1:]


# ----------------------------------------------------------------------------- smooth: 4th order
def test_rk4_fourth_order_forced_linear_oscillator():
    P, x_ss = duffing_linear()
    t0 = 0.4
    errs = []
    for n in (8, 16, 32, 64, 128):
        y = np.asarray(jg.stroboscopic_map(jg.DUFFING, P, x_ss(t0), periods=1, t0=t0, integrator=jg.RK4(n)))
        errs.append(np.abs(y - x_ss(t0)).max())   # the periodic orbit returns to itself
    r = _order_ratios(errs)
    assert np.all((r > 14.5) & (r < 18.0)), r      # 2^4 = 16 per halving


def test_adaptive_matches_closed_form():
    P, x_ss = duffing_linear()
    t0 = 1.1
    x0 = np.stack([x_ss(t0), x_ss(t0) + np.array([1.0, 0.0])])
    y = np.asarray(jg.stroboscopic_map(jg.DUFFING, P, x0, periods=3, t0=t0, integrator=jg.Adaptive()))
    np.testing.assert_allclose(y[0], x_ss(t0), atol=1e-9)
    # a state off the orbit decays onto it: free response of x'' + 0.2 x' + x = 0 from (1, 0)
    T = 2 * math.pi / 1.3
    s, wd = 3 * T, math.sqrt(1 - 0.1**2)
    free = math.exp(-0.1 * s) * np.array([math.cos(wd * s) + 0.1 / wd * math.sin(wd * s),
                                          -(1 / wd) * math.sin(wd * s)])
    np.testing.assert_allclose(y[1] - x_ss(t0), free, atol=1e-9)


# ----------------------------------------------------------------------------- paper preset (backlash)
STEPS = (200, 400, 800, 1600, 3200)


def _errors_vs_tight_reference(p, x0):
    """Max error of RK4(n), n in STEPS, on P^2 against diffrax Tsit5 at rtol = atol = 1e-12.

    Same shapes, periods and integrators for every parameter set: one compilation each.
    """
    ref = np.asarray(jg.stroboscopic_map(REDUCED, p, x0, periods=2, integrator=TIGHT))
    assert np.all(np.isfinite(ref))
    return {n: np.abs(np.asarray(jg.stroboscopic_map(REDUCED, p, x0, periods=2, integrator=jg.RK4(n))) - ref).max()
            for n in STEPS}


@pytest.fixture(scope="module")
def paper_reference():
    p = jg.paper_params()
    return p, _errors_vs_tight_reference(p, _paper_states(16, seed=0))


def test_rk4_fourth_order_gear_model_without_backlash(paper_reference):
    """b = 0 with the paper's stiffness variation and errors: smooth, parametrically excited."""
    p = jg.paper_params(b_sp=0.0, b_rp=0.0)
    x0 = _paper_states(16, seed=0) * np.array([0.2, 0.3, 0.1, 0.0])
    errs = _errors_vs_tight_reference(p, x0)
    e = [errs[n] for n in STEPS[:4]]      # 3200 steps reach the reference's own error
    r = _order_ratios(e)
    assert e[0] > 1e-7 and np.all((r > 14.5) & (r < 18.5)), (e, r)


def test_rk4_and_adaptive_agree_on_paper_preset(paper_reference):
    """Stroboscopic map P^2 of the paper preset, 16 starts over the region D.

    With backlash the error of fixed-step RK4 behaves like C h^2 (docs/model.md §8); measured
    C is 5-12 for these starts. The tolerance is 40 h^2, h = T / steps_per_period.
    """
    p, errs = paper_reference
    T = 2 * math.pi / float(p.Omega)
    for n, e in errs.items():
        assert e < 40 * (T / n) ** 2, (n, e)
    assert errs[3200] < errs[800] < errs[200]
    assert errs[400] < 5e-3


def test_rk4_order_drops_with_backlash(paper_reference):
    """Documentation of docs/model.md §8: the backlash kinks cut fixed-step RK4 to ~2nd order."""
    _, errs = paper_reference
    n = np.array(sorted(errs), float)
    e = np.array([errs[k] for k in sorted(errs)])
    order = -np.polyfit(np.log(n), np.log(e), 1)[0]
    assert 1.0 < order < 3.0, order
    # a 4th-order method would have shrunk the error 65536-fold from 200 to 3200 steps
    assert errs[3200] > 100 * errs[200] / 16**4


# ----------------------------------------------------------------------------- interface
def test_integrator_advance_equals_stroboscopic_map_and_batches():
    """The integrator's batch operation (struct of arrays) equals the public map on any
    batch shape, and each lane equals its own one-state flow."""
    p = jg.paper_params()
    x0 = _paper_states(6, seed=2).reshape(2, 3, 4)
    integ = jg.RK4(100)
    y = np.asarray(integ.advance(REDUCED, p, jnp.asarray(x0.reshape(-1, 4).T), 0.0, 2)).T.reshape(2, 3, 4)
    z = np.asarray(jg.stroboscopic_map(REDUCED, p, x0, periods=2, integrator=integ))
    assert z.shape == (2, 3, 4)
    np.testing.assert_allclose(y, z, rtol=1e-13, atol=1e-12)
    one = np.asarray(integ.flow(REDUCED, p, jnp.asarray(x0[1, 2]), 0.0, 2))
    np.testing.assert_allclose(one, z[1, 2], rtol=1e-13, atol=1e-12)


def test_sample_times_and_consistency():
    P, x_ss = duffing_linear()
    T = 2 * math.pi / 1.3
    t0 = 0.4
    ts, xs = jg.sample_trajectory(jg.DUFFING, P, x_ss(t0), periods=2, samples_per_period=8, t0=t0,
                                  integrator=jg.RK4(60))
    ts, xs = np.asarray(ts), np.asarray(xs)
    assert ts.shape == (17,) and xs.shape == (17, 2)
    np.testing.assert_allclose(ts, t0 + T * np.arange(17) / 8, rtol=1e-14)
    np.testing.assert_array_equal(xs[0], x_ss(t0))
    # steps_per_period 60 is rounded up to 64 (a multiple of 8): still accurate on the orbit
    np.testing.assert_allclose(xs, x_ss(ts), atol=1e-5)
    ts2, xs2 = jg.sample_trajectory(jg.DUFFING, P, x_ss(t0), periods=2, samples_per_period=8, t0=t0,
                                    integrator=jg.Adaptive())
    np.testing.assert_allclose(np.asarray(xs2), x_ss(ts), atol=1e-9)
    # the sample at one period equals the stroboscopic map with the same step
    y = np.asarray(jg.stroboscopic_map(jg.DUFFING, P, x_ss(t0), t0=t0, integrator=jg.RK4(64)))
    np.testing.assert_allclose(xs[8], y, rtol=1e-12, atol=1e-13)


def test_adaptive_failure_is_nan_not_a_wrong_value():
    # a very stiff oscillator (alpha = 1e10, ~3e5 oscillations) needs more than max_steps
    P = jg.DuffingParams(delta=0.2, alpha=1e10, beta=0.0, gamma=1.0, omega=1.3)
    y = np.asarray(jg.stroboscopic_map(jg.DUFFING, P, np.ones((2, 2)), periods=3, t0=1.1, integrator=jg.Adaptive()))
    assert np.all(np.isnan(y))


def test_integrator_validation():
    with pytest.raises(ValueError, match="steps_per_period"):
        jg.RK4(0)
    with pytest.raises(ValueError, match="integrator"):
        jg.stroboscopic_map(REDUCED, jg.paper_params(), np.zeros(4), integrator="rk4")


def test_an_analysis_with_the_adaptive_integrator_has_its_cycles_multipliers():
    """``analyze_global`` with ``jg.Adaptive`` (the reference integrator) gives each cycle its
    Floquet multipliers, from the jvp of its own map's forward-mode solve (the jvp of the
    reverse-mode solve that ``advance`` runs raised an error). Independent check: the forced
    Duffing oscillator's two P-1 cycles each have a complex pair of multipliers, whose
    modulus is ``exp(-delta T / 2)`` by Liouville's formula (the field's divergence is
    ``-delta``); each cycle crosses the section."""
    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (4, 4))
    r = jg.analyze_global(jg.DUFFING, p, grid, jg.Direct(integrator=jg.Adaptive(rtol=1e-9, atol=1e-9)),
                          progress=False, uncertainty=0)
    assert [a.period for a in r.attractors] == [1, 1]
    want = np.exp(-0.1 * (2 * np.pi / 1.4) / 2)
    for a in r.attractors:
        assert abs(a.multiplier - want) < 1e-7, (a.multiplier, want)
        assert len(a.section_points) > 0
