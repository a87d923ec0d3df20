"""Lyapunov exponents of the stroboscopic map and attractor types (jaxgear._lyapunov).

References, none from the code under test: closed forms (a linear oscillator; the sum of
the two exponents of a planar system with constant divergence), scipy DOP853 twin
trajectories with renormalisation every period (a chaotic Duffing oscillator), scipy
variational equations (a piecewise-linear oscillator with backlash kinks), averaging
theory and a scipy rotation-number check (a quasi-periodic van der Pol oscillator),
and the Floquet multipliers of the shooting module (the paper preset's P-4).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxgear
from jaxgear._examples import DUFFING, VAN_DER_POL, DuffingParams, VanDerPolParams
from jaxgear._lyapunov import (
    AttractorType,
    LyapunovSpectrum,
    birkhoff_weights,
    classify_attractor,
    kaplan_yorke,
    lyapunov_spectrum,
)

# one setting for the default tests of the two-dimensional systems: one compilation each
PERIODS, STRETCHES = 400, 4

UEDA = dict(delta=0.05, gamma=7.5)  # x'' + 0.05 x' + x^3 = 7.5 cos t (Ueda's chaotic attractor)


def _ueda_field(t, y):
    return [y[1], UEDA["gamma"] * np.cos(t) - UEDA["delta"] * y[1] - y[0] ** 3]


def _ueda_period(y):
    return solve_ivp(_ueda_field, (0.0, 2 * np.pi), y, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]


@pytest.fixture(scope="module")
def ueda_start():
    """A state on the Ueda attractor (scipy, after 30 periods from (2.5, 0))."""
    y = np.array([2.5, 0.0])
    for _ in range(30):
        y = _ueda_period(y)
    return y


def _twin_exponents(y, n, d0=1e-8):
    """scipy reference: twin trajectories, the twin renormalised to distance d0 along the
    separation after every period; the log growth of each period, (n,)."""
    z = y + d0 * np.array([1.0, 0.0])
    logs = []
    for _ in range(n):
        y, z = _ueda_period(y), _ueda_period(z)
        dist = np.linalg.norm(z - y)
        logs.append(np.log(dist / d0))
        z = y + (z - y) * (d0 / dist)
    return np.array(logs)


def test_linear_oscillator_closed_form():
    # x'' + delta x' + alpha x = gamma cos(omega t): the stroboscopic map is affine with
    # multipliers exp(s_i T), s_i the roots of s^2 + delta s + alpha: exponents per unit
    # time Re s_i (underdamped: both -delta/2; overdamped: -delta/2 +- sqrt(delta^2/4 - alpha))
    x0 = jnp.array([[0.3, -0.2], [1.0, 2.0]])
    for delta, alpha in [(0.2, 1.0), (3.0, 1.0)]:
        p = DuffingParams(delta=delta, alpha=alpha, beta=0.0, gamma=1.0, omega=1.3)
        disc = np.sqrt(complex(delta**2 / 4 - alpha))
        want = np.sort(np.real([-delta / 2 + disc, -delta / 2 - disc]))[::-1]
        s = lyapunov_spectrum(DUFFING, p, x0, periods=PERIODS, transient=0, stretches=STRETCHES, chunk_size=1)
        assert s.exponents.shape == (2, 2) and s.stretch_exponents.shape == (2, STRETCHES, 2)
        np.testing.assert_allclose(s.per_time, np.broadcast_to(want, (2, 2)), atol=1e-6, rtol=0)
        np.testing.assert_allclose(s.exponents, s.per_time * 2 * np.pi / 1.3, rtol=1e-12)
        assert np.all(np.asarray(s.status) == int(jaxgear.Status.CONVERGED))
        assert list(classify_attractor(s)) == [int(AttractorType.PERIODIC)] * 2
        np.testing.assert_array_equal(s.kaplan_yorke, [0.0, 0.0])  # a point of the map


def _spur_system():
    """The single spur pair with backlash, declared with its kinks |x| = b so that the
    kink-aware integrator stops on them."""
    from jaxgear._examples import SPUR_PAIR

    return jaxgear.ForcedSystem(vector_field=SPUR_PAIR.vector_field, period=SPUR_PAIR.period,
                                state_names=("x", "v"), name="spur-pair-kinks",
                                switching=lambda t, x, p: jnp.stack([x[0] - p.b, x[0] + p.b]))


SPUR = dict(zeta=0.05, kappa=0.2, b=0.5, f_m=0.1, e_amp=0.5, Omega=0.7)


def _spur_reference(y):
    """scipy: the stable P-1 orbit of the spur pair through its kinks and its Floquet
    multipliers from the variational equations (Jacobian of the piecewise-linear field:
    stiffness k(t) in contact |x| > b, 0 in the gap; the field is continuous, so the
    saltation matrix at the kinks is the identity)."""
    p, T = SPUR, 2 * np.pi / SPUR["Omega"]

    def f(t, z):
        x, v = z[0], z[1]
        bl = x - p["b"] if x >= p["b"] else (x + p["b"] if x <= -p["b"] else 0.0)
        kt = (1.0 + p["kappa"] * np.sin(p["Omega"] * t)) * (1.0 if abs(x) >= p["b"] else 0.0)
        J = np.array([[0.0, 1.0], [-kt, -2 * p["zeta"]]])
        Phi = z[2:].reshape(2, 2)
        acc = p["f_m"] + p["e_amp"] * p["Omega"] ** 2 * np.sin(p["Omega"] * t) - 2 * p["zeta"] * v \
            - (1.0 + p["kappa"] * np.sin(p["Omega"] * t)) * bl
        return np.concatenate([[v, acc], (J @ Phi).ravel()])

    def state(t, y):
        return f(t, np.concatenate([y, np.zeros(4)]))[:2]

    # multipliers ~0.64: 70 periods reach the orbit to ~1e-13
    y = solve_ivp(state, (0.0, 70 * T), y, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]
    out = solve_ivp(f, (0.0, T), np.concatenate([y, np.eye(2).ravel()]), method="DOP853", rtol=1e-12, atol=1e-13,
                    dense_output=True)
    M = out.y[2:, -1].reshape(2, 2)
    xs = out.sol(np.linspace(0.0, T, 400))[0]
    return y, np.linalg.eigvals(M), xs


def test_periodic_orbit_through_kinks_matches_floquet_multipliers():
    seed = np.array([-0.8, 1.0])
    y, mu, xs = _spur_reference(seed)
    assert xs.min() < -SPUR["b"] and xs.max() > SPUR["b"]  # the orbit crosses both kinks, twice each
    s = lyapunov_spectrum(_spur_system(), jaxgear.SpurPairParams(**SPUR), jnp.asarray(seed), periods=PERIODS,
                          transient=60, stretches=STRETCHES)
    want = np.sort(np.log(np.abs(mu)))[::-1]  # a P-1 orbit: lambda_i = ln|mu_i| / 1
    np.testing.assert_allclose(s.exponents, want, atol=1e-6, rtol=0)
    np.testing.assert_allclose(s.final_state, y, atol=1e-6)
    assert classify_attractor(s, 1) is AttractorType.PERIODIC
    assert classify_attractor(s) is AttractorType.PERIODIC  # negative beyond its error


def test_chaotic_duffing_matches_scipy_twin_trajectories(ueda_start):
    # Over 25 periods the RK4(1000) and DOP853 trajectories stay within 1e-3 of each
    # other, so both estimate the same finite-time exponent from the same start and
    # initial direction (the first unit vector): the plain average over the segment.
    n = 25
    ref = _twin_exponents(ueda_start.copy(), n).mean()
    p = DuffingParams(delta=UEDA["delta"], alpha=0.0, beta=1.0, gamma=UEDA["gamma"], omega=1.0)
    # a second start far out blows up: its lane is DIVERGED, the first is not touched
    x0 = jnp.asarray(np.stack([ueda_start, [1e30, 0.0]]))
    both = lyapunov_spectrum(DUFFING, p, x0, periods=n, transient=0, stretches=5, weighted=False,
                             integrator=jaxgear.RK4(1000))
    assert list(np.asarray(both.status)) == [int(jaxgear.Status.CONVERGED), int(jaxgear.Status.DIVERGED)]
    assert np.all(np.isnan(np.asarray(both.exponents[1])))
    assert list(classify_attractor(both)) == [int(AttractorType.CHAOTIC), int(AttractorType.UNKNOWN)]
    s = jax.tree.map(lambda a: a[0], both)
    lam = np.asarray(s.exponents)
    assert abs(lam[0] / ref - 1) < 0.05
    assert abs(lam[0] - ref) <= 3 * float(s.errors[0])
    # the divergence of the field is -delta: every period contracts areas by exp(-delta T)
    np.testing.assert_allclose(lam.sum(), -UEDA["delta"] * 2 * np.pi, atol=1e-9)
    np.testing.assert_allclose(s.per_time, lam / (2 * np.pi), rtol=1e-12)
    assert lam[0] > 0
    ky = 1 + lam[0] / abs(lam[1])
    np.testing.assert_allclose(s.kaplan_yorke, ky, rtol=1e-12)


def _twin_chains(starts, transient, n, d0=1e-8):
    """scipy reference for many independent chains at once (one vectorised DOP853 system):
    after ``transient`` periods, twin trajectories renormalised every period; the plain
    average of the log growth per chain, ``(chains,)``."""
    m = len(starts)

    def f(t, y):
        x, v = y[0::2], y[1::2]
        out = np.empty_like(y)
        out[0::2] = v
        out[1::2] = UEDA["gamma"] * np.cos(t) - UEDA["delta"] * v - x**3
        return out

    def period(y):
        return solve_ivp(f, (0.0, 2 * np.pi), y, method="DOP853", rtol=1e-11, atol=1e-11).y[:, -1]

    y = np.asarray(starts, float).ravel()
    for _ in range(transient):
        y = period(y)
    y = y.reshape(m, 2)
    z = y + d0 * np.array([1.0, 0.0])
    total = np.zeros(m)
    for _ in range(n):
        out = period(np.concatenate([y, z], axis=0).ravel()).reshape(2 * m, 2)
        y, z = out[:m], out[m:]
        dist = np.linalg.norm(z - y, axis=1)
        total += np.log(dist / d0)
        z = y + (z - y) * (d0 / dist)[:, None]
    return total / n


@pytest.mark.slow
def test_chaotic_duffing_long_runs_match_scipy(ueda_start):
    # 64 independent chains of 250 periods from starts spread over the attractor (the
    # trajectories of the two integrators part after ~30 periods, so the estimates are
    # independent samples of the same exponent): the means agree within 5 %, and the
    # errors jaxgear reports agree with the spread between its chains
    rng = np.random.default_rng(0)
    pts = [ueda_start]
    for _ in range(63 * 5):
        pts.append(_ueda_period(pts[-1]))
    starts = np.array(pts[::5]) + 1e-3 * rng.standard_normal((64, 2))
    n, transient = 250, 30
    ref = _twin_chains(starts, transient, n)
    ref_mean, ref_err = ref.mean(), ref.std(ddof=1) / np.sqrt(len(ref))
    p = DuffingParams(delta=UEDA["delta"], alpha=0.0, beta=1.0, gamma=UEDA["gamma"], omega=1.0)
    s = lyapunov_spectrum(DUFFING, p, jnp.asarray(starts), periods=n, transient=transient, stretches=5,
                          weighted=False)
    lam, err = np.asarray(s.exponents)[:, 0], np.asarray(s.errors)[:, 0]
    mean, mean_err = lam.mean(), np.sqrt(np.sum(err**2)) / len(lam)
    assert abs(mean / ref_mean - 1) < 0.05
    assert abs(mean - ref_mean) <= 3 * np.hypot(mean_err, ref_err)
    spread = lam.std(ddof=1) / np.sqrt(len(lam))  # the error of the mean from the chains themselves
    assert 0.5 < mean_err / spread < 2.0
    assert list(classify_attractor(s)).count(int(AttractorType.CHAOTIC)) >= 60
    assert np.all((1.0 < np.asarray(s.kaplan_yorke)) & (np.asarray(s.kaplan_yorke) < 2.0))


def test_unlocked_van_der_pol_is_quasi_periodic():
    p = VanDerPolParams(mu=0.1, F=0.05, omega=(1 + 5**0.5) / 2)
    T = 2 * np.pi / float(p.omega)
    # scipy: the section points after a transient lie on a closed curve around the origin
    # and never repeat: rotation number far from every p/q with q <= 20, no P-q return
    def f(t, y):
        return [y[1], 0.1 * (1 - y[0] ** 2) * y[1] - y[0] + 0.05 * np.cos(float(p.omega) * t)]

    n = 400
    sol = solve_ivp(f, (0.0, (200 + n) * T), [2.0, 0.0], method="DOP853", rtol=1e-10, atol=1e-10,
                    t_eval=T * np.arange(200, 200 + n + 1))
    pts = sol.y.T
    ang = np.unwrap(np.arctan2(pts[:, 1], pts[:, 0]))
    rho = -(ang[-1] - ang[0]) / (2 * np.pi * n) % 1.0  # clockwise rotation per period, in turns
    q = np.arange(1, 21)
    assert np.min(np.abs(rho * q - np.round(rho * q)) / q) > 1e-3
    for k in range(1, 21):
        assert np.min(np.linalg.norm(pts[k:] - pts[:-k], axis=1)) > 1e-3
    s = lyapunov_spectrum(VAN_DER_POL, p, jnp.array([2.0, 0.0]), periods=PERIODS, transient=200,
                          stretches=STRETCHES)
    lam, err = np.asarray(s.exponents), np.asarray(s.errors)
    assert abs(lam[0]) <= max(3 * err[0], 1e-7)
    assert lam[1] < -3 * err[1]
    # averaging: the limit cycle's transverse exponent is -mu per unit time (to O(mu^2))
    np.testing.assert_allclose(float(s.per_time[1]), -0.1, rtol=0.02)
    assert classify_attractor(s) is AttractorType.QUASI_PERIODIC
    assert classify_attractor(s, 3) is AttractorType.PERIODIC  # a period given wins
    # D_KY = 1 + lambda_1/|lambda_2| (a curve) when lambda_1 >= 0, else 0
    assert float(s.kaplan_yorke) == (pytest.approx(1.0, abs=1e-6) if lam[0] >= 0 else 0.0)


@pytest.mark.slow
def test_paper_p4_exponents_equal_floquet_multipliers():
    params = jaxgear.paper_params()
    r = jaxgear.periodic_orbit(jaxgear.REDUCED, params, jnp.array([5.36, -0.19, 8.28, -0.84]), period=4)
    assert int(r.status) == 0 and bool(r.stable)
    want = np.sort(np.log(np.abs(np.asarray(r.multipliers))))[::-1] / 4
    s = lyapunov_spectrum(jaxgear.REDUCED, params, r.point, n_exponents=4, periods=2400, transient=8, stretches=2)
    np.testing.assert_allclose(s.exponents, want, atol=1e-6, rtol=0)
    assert classify_attractor(s, 4) is AttractorType.PERIODIC


def test_kaplan_yorke_definition():
    # D = j + (l_1 + ... + l_j) / |l_(j+1)|, j the largest index with a non-negative partial sum
    two = [([0.5, -1.0], 1.5), ([-0.1, -0.2], 0.0), ([0.0, -0.5], 1.0), ([0.1, 0.05], np.nan),
           ([np.nan, -1.0], np.nan)]
    three = [([0.3, 0.1, -0.8], 2.5), ([0.3, -0.2, -0.4], 2.25), ([0.2, -0.5, -0.6], 1.4)]
    for cases in (two, three):
        got = kaplan_yorke(jnp.array([lam for lam, _ in cases]))
        np.testing.assert_allclose(got, [want for _, want in cases], rtol=1e-14)


def test_birkhoff_weights_super_converge_on_a_rotation():
    # the weighted average of cos(2 pi (x0 + n a)) over a golden-mean rotation is 0 to
    # round-off within a few hundred points; the plain average only to ~1/n
    a = (5**0.5 - 1) / 2
    n = 400
    g = np.cos(2 * np.pi * (0.1 + a * np.arange(n)))
    assert abs(birkhoff_weights(n) @ g) < 1e-10
    assert abs(g.mean()) > 1e-4
    np.testing.assert_allclose(birkhoff_weights(n).sum(), 1.0, rtol=1e-14)


def test_classify_from_constructed_spectra():
    def spec(l1, e1, status=0):
        z = jnp.array([[l1, -1.0]])
        e = jnp.array([[e1, 0.01]])
        return LyapunovSpectrum(exponents=z, per_time=z, errors=e, errors_per_time=e,
                                stretch_exponents=jnp.zeros((1, 2, 2)), kaplan_yorke=jnp.zeros(1),
                                final_state=jnp.zeros((1, 2)), status=jnp.array([status], jnp.int32),
                                periods=2, transient=0, weighted=False)

    assert list(classify_attractor(spec(0.2, 0.01))) == [AttractorType.CHAOTIC]
    assert list(classify_attractor(spec(0.02, 0.01))) == [AttractorType.QUASI_PERIODIC]
    assert list(classify_attractor(spec(-0.2, 0.01))) == [AttractorType.PERIODIC]
    assert list(classify_attractor(spec(0.2, 0.01, status=3))) == [AttractorType.UNKNOWN]
    assert list(classify_attractor(spec(0.2, 0.01), np.array([2]))) == [AttractorType.PERIODIC]
    assert list(classify_attractor(spec(5e-7, 1e-9))) == [AttractorType.QUASI_PERIODIC]  # below zero_tol
    # beyond 3 errors but within 1e-4 of the contraction (-1): a torus's finite-time bias, zero
    assert list(classify_attractor(spec(5e-5, 1e-7))) == [AttractorType.QUASI_PERIODIC]
    assert "zero within" in jaxgear.type_reason(AttractorType.QUASI_PERIODIC, [5e-5, -1.0], [1e-7, 0.01])
    assert list(classify_attractor(spec(2e-4, 1e-7))) == [AttractorType.CHAOTIC]


def test_a_zero_exponent_is_a_torus_only_on_a_closed_curve_else_undetermined():
    """Zero largest exponent: quasi-periodic when the second contracts beyond its errors (a
    closed curve of the map), undetermined when the second is zero too (never guessed);
    the reason names the numbers the test compared. Chaotic and contracting are unchanged."""
    def spec(l1, e1, l2, e2):
        z, e = jnp.array([[l1, l2]]), jnp.array([[e1, e2]])
        return LyapunovSpectrum(exponents=z, per_time=z, errors=e, errors_per_time=e,
                                stretch_exponents=jnp.zeros((1, 2, 2)), kaplan_yorke=jnp.zeros(1),
                                final_state=jnp.zeros((1, 2)), status=jnp.array([0], jnp.int32),
                                periods=2, transient=0, weighted=False)

    cases = [((0.001, 0.001, -0.3, 0.01), AttractorType.QUASI_PERIODIC, "a closed curve"),
             ((0.001, 0.001, -0.002, 0.001), AttractorType.UNDETERMINED, "both zero within 3 errors"),
             ((0.4, 0.005, -0.002, 0.001), AttractorType.CHAOTIC, "positive beyond 3 errors"),
             ((-0.1, 0.001, -0.2, 0.001), AttractorType.PERIODIC, "no period found")]
    for (l1, e1, l2, e2), want, words in cases:
        (got,) = classify_attractor(spec(l1, e1, l2, e2))
        assert got == want, (l1, l2, got)
        reason = jaxgear.type_reason(got, [l1, l2], [e1, e2])
        assert words in reason and f"{l1:+.4g}" in reason, reason
    assert jaxgear.type_reason(AttractorType.PERIODIC, [-0.1, -0.2], [0, 0], period=4).startswith("a P-4 cycle")
    a = jaxgear.Attractor(id=0, period=0, points=np.zeros((3, 2)), section_points=np.zeros((0, 2)),
                          kind=int(AttractorType.UNDETERMINED), exponents=np.array([0.001, -0.002]),
                          exponent_errors=np.array([0.001, 0.001]))
    assert a.label == "undetermined" and "not decided" in a.type_reason and a.summary()["type"] == "undetermined"


def test_bad_options_are_refused():
    p = DuffingParams()
    x = jnp.zeros(2)
    with pytest.raises(ValueError, match="n_exponents=3"):
        lyapunov_spectrum(DUFFING, p, x, n_exponents=3)
    with pytest.raises(ValueError, match="periods=101 must be a multiple of stretches=10"):
        lyapunov_spectrum(DUFFING, p, x, periods=101)
    with pytest.raises(ValueError, match="stretches=1"):
        lyapunov_spectrum(DUFFING, p, x, stretches=1)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        lyapunov_spectrum(DUFFING, p, jnp.zeros(3))
    with pytest.raises(ValueError, match="period="):
        classify_attractor(_dummy(), 1.5)


def _dummy():
    z = jnp.zeros(2)
    return LyapunovSpectrum(exponents=z, per_time=z, errors=z, errors_per_time=z, stretch_exponents=jnp.zeros((2, 2)),
                            kaplan_yorke=jnp.zeros(()), final_state=z, status=jnp.zeros((), jnp.int32), periods=2,
                            transient=0, weighted=False)


@pytest.mark.slow
def test_weakly_chaotic_gear_attractor_is_never_called_a_torus():
    """At b = 16/11 the reduced gear model's chaotic attractor has lambda_1 of only about
    0.14 per period: 200 periods in 4 stretches from some of its points give an estimate
    within three errors of zero (about one start in five calls it quasi-periodic). The
    global analysis measures such a zero again over :data:`LYAPUNOV_RECHECK` times as
    many periods before it believes it: from 40 points of the attractor (a stroboscopic
    orbit written apart from the analysis), every one is chaotic."""
    from jaxgear.analysis._global import attractor_exponents

    p = jaxgear.with_param(jaxgear.paper_params(), "b", 16 / 11)
    orbit = np.asarray(jaxgear.stroboscopic_orbit(jaxgear.REDUCED, p, np.array([16 / 11 + 0.3, 0.0, 0.0, 0.0]),
                                                   n_points=500 + 40 * 37))
    starts = orbit[500::37][:40]
    short = lyapunov_spectrum(jaxgear.REDUCED, p, starts, periods=200, stretches=4, transient=0)
    assert np.any(np.asarray(classify_attractor(short)) == int(AttractorType.QUASI_PERIODIC))  # the trap is real
    kinds, spectra = attractor_exponents(jaxgear.REDUCED, p, [(x[None], 0) for x in starts],
                                         jaxgear.integrate.default_integrator(), [None] * len(starts))
    assert np.all(kinds == int(AttractorType.CHAOTIC)), kinds
    assert all(lam[0] > 3 * err[0] > 0 for lam, err, _ in spectra)


def _ueda_cloud(start, n: int = 128, every: int = 3) -> np.ndarray:
    """``n`` points of the Ueda attractor, ``every`` periods apart (scipy)."""
    pts = [np.asarray(start, float)]
    for _ in range(n * every - 1):
        pts.append(_ueda_period(pts[-1]))
    return np.array(pts[::every])


def test_ensemble_exponents_pool_independent_starts(ueda_start):
    """An attractor without a period gets exponents averaged over starts spread over its
    cloud: the printed error is the spread between them (an ensemble of lanes, several
    times smaller than one start's error from its stretches), the phase-space
    contraction per period holds for the pooled exponents, and the pooled value lies
    within three of its errors of the mean of many independent single starts."""
    from jaxgear.analysis._global import LYAPUNOV_LANES, attractor_exponents

    p = DuffingParams(delta=UEDA["delta"], alpha=0.0, beta=1.0, gamma=UEDA["gamma"], omega=1.0)
    cloud = _ueda_cloud(ueda_start, n=LYAPUNOV_LANES)
    integrator = jaxgear.RK4(120)
    kinds, [(lam, err, _)] = attractor_exponents(DUFFING, p, [(cloud, 0)], integrator, [None])
    assert kinds[0] == int(AttractorType.CHAOTIC)
    single = lyapunov_spectrum(DUFFING, p, cloud[:1], periods=200, transient=0, stretches=4, integrator=integrator)
    assert err[0] < float(single.errors[0, 0]) / 2.5  # 32 starts: about sqrt(32 / 4) times smaller
    assert err[0] <= 0.03 * lam[0]  # (Ueda's attractor stretches unevenly: 2-3 % from 32 starts of 200 periods)
    np.testing.assert_allclose(lam.sum(), -UEDA["delta"] * 2 * np.pi, rtol=1e-3)  # (to RK4(120)'s accuracy)
    others = lyapunov_spectrum(DUFFING, p, _ueda_cloud(cloud[-1], n=64, every=2), periods=400, transient=0,
                               stretches=4, integrator=integrator)
    ref = np.asarray(others.exponents)[:, 0]
    assert abs(lam[0] - ref.mean()) <= 3 * np.hypot(err[0], ref.std(ddof=1) / np.sqrt(len(ref)))


@pytest.mark.slow
def test_ensemble_exponent_of_ueda_matches_scipy_within_its_error(ueda_start):
    """The pooled largest exponent of the Ueda attractor against independent scipy twin
    trajectories (64 chains of 250 periods): within 3 combined errors, a printed error of
    at most 3 %."""
    from jaxgear.analysis._global import attractor_exponents

    p = DuffingParams(delta=UEDA["delta"], alpha=0.0, beta=1.0, gamma=UEDA["gamma"], omega=1.0)
    cloud = _ueda_cloud(ueda_start)
    kinds, [(lam, err, _)] = attractor_exponents(DUFFING, p, [(cloud, 0)], jaxgear.integrate.default_integrator(),
                                                 [None])
    ref = _twin_chains(cloud[1::2][:64], 0, 250)
    ref_mean, ref_err = ref.mean(), ref.std(ddof=1) / np.sqrt(len(ref))
    assert kinds[0] == int(AttractorType.CHAOTIC) and err[0] <= 0.03 * lam[0]
    assert abs(lam[0] - ref_mean) <= 3 * np.hypot(err[0], ref_err)
