"""Shooting, Floquet multipliers and verification (jaxgear._shooting), checked against
closed forms (forced linear oscillator), perturbation theory (Mathieu tongue),
finite differences and Liouville's formula."""

import io
import json
from contextlib import redirect_stdout
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from scipy.optimize import brentq

import jaxgear as jg
from jaxgear import Instability, Status

FLIP, STABLE = Instability.FLIP, Instability.STABLE
SHOOT_CONVERGED, SHOOT_SINGULAR = Status.CONVERGED, Status.SINGULAR

# Hardening Duffing with three P-1 orbits (checked by shooting from a box of seeds;
# harmonic balance gives amplitudes 0.34, 0.95, 1.24): two stable, one saddle between.
BISTABLE = dict(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)
NEWTON = optx.Newton(rtol=1e-10, atol=1e-12)


def duffing(**kw):
    return jg.DuffingParams(**{**BISTABLE, **kw})


# --------------------------------------------------------------------------- linear limit
def test_linear_oscillator_matches_closed_form():
    # x'' + d x' + a x = g cos(w t): steady state x = Re(g H e^{iwt}), H = 1/(a - w^2 + i d w)
    p = duffing(beta=0.0, gamma=1.0, omega=1.3)
    r = jg.periodic_orbit(jg.DUFFING, p, jnp.array([2.0, -3.0]), period=1)
    assert int(r.status) == SHOOT_CONVERGED and float(r.residual) <= 1e-10
    H = 1.0 / (1.0 - 1.3**2 + 1j * 0.1 * 1.3)
    exact = np.array([(1.0 * H).real, (1j * 1.3 * 1.0 * H).real])
    np.testing.assert_allclose(np.asarray(r.point), exact, atol=1e-7)
    # Floquet multipliers = exp(lambda_i T), lambda_i eigenvalues of [[0, 1], [-a, -d]]
    T = 2 * np.pi / 1.3
    lam = np.exp(np.linalg.eigvals(np.array([[0.0, 1.0], [-1.0, -0.1]])) * T)
    got = np.asarray(r.multipliers)
    np.testing.assert_allclose(np.sort_complex(got), np.sort_complex(lam), atol=1e-7)
    assert bool(r.stable) and int(r.min_period) == 1 and int(r.instability) == STABLE


@pytest.mark.slow
def test_linear_oscillator_with_adaptive_integrator():
    # the same closed form with diffrax (Tsit5): the residual is that of the adaptive map
    p = duffing(beta=0.0, gamma=1.0, omega=1.3)
    integ = jg.Adaptive(rtol=1e-12, atol=1e-12, max_steps=4096)
    r = jg.periodic_orbit(jg.DUFFING, p, jnp.array([2.0, -3.0]), integrator=integ)
    assert int(r.status) == SHOOT_CONVERGED and float(r.residual) <= 1e-10
    H = 1.0 / (1.0 - 1.3**2 + 1j * 0.1 * 1.3)
    np.testing.assert_allclose(np.asarray(r.point), [H.real, (1j * 1.3 * H).real], atol=1e-10)


# --------------------------------------------------------------------------- Mathieu tongue
def _max_modulus(Omega, kappa, zeta):
    p = jg.SpurPairParams(zeta=zeta, kappa=kappa, b=0.0, f_m=0.0, e_amp=0.0, Omega=Omega)
    return float(jnp.max(jnp.abs(jg.floquet_multipliers(jg.SPUR_PAIR, p, jnp.zeros(2)))))


def _bisect_edge(lo, hi, kappa, zeta, threshold):
    f = lambda W: _max_modulus(W, kappa, zeta) - 1.0 - threshold
    f_lo = f(lo)
    assert f_lo * f(hi) < 0
    for _ in range(36):
        mid = 0.5 * (lo + hi)
        if (f(mid) > 0) == (f_lo > 0):
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_mathieu_first_parametric_tongue():
    # x'' + 2 zeta x' + (1 + kappa sin(Omega t)) x = 0 (spur pair, b = f_m = e_amp = 0).
    # In s = Omega t: x'' + (delta + eps cos s) x = 0 with delta = 1/Omega^2, eps = kappa/Omega^2
    # (sin vs cos is a time shift). Undamped transition curves from delta = 1/4 (Rand,
    # Lecture notes on nonlinear vibrations; Nayfeh & Mook): delta = 1/4 +- eps/2 - eps^2/8 + O(eps^3),
    # i.e. Omega = 2 -+ kappa/2 to first order.
    kappa = 0.1
    lo = _bisect_edge(1.8, 2.0, kappa, 0.0, 1e-9)
    hi = _bisect_edge(2.0, 2.3, kappa, 0.0, 1e-9)
    lo2 = brentq(lambda W: W * W / 4 + kappa / 2 - kappa**2 / (8 * W * W) - 1, 1.5, 2.0)
    hi2 = brentq(lambda W: W * W / 4 - kappa / 2 - kappa**2 / (8 * W * W) - 1, 2.0, 2.5)
    assert abs(lo - lo2) < kappa**3 and abs(hi - hi2) < kappa**3
    # Damped (Landau & Lifshitz §27): growth rate (1/2) sqrt((kappa/2)^2 - (Omega-2)^2) > zeta,
    # so the tongue is |Omega - 2| < (1/2) sqrt(kappa^2 - 16 zeta^2) to first order in kappa.
    zeta = 0.01
    lo_d = _bisect_edge(1.8, 2.0, kappa, zeta, 0.0)
    hi_d = _bisect_edge(2.0, 2.3, kappa, zeta, 0.0)
    w = 0.5 * np.sqrt(kappa**2 - 16 * zeta**2)
    assert abs(lo_d - (2 - w)) < 0.5 * kappa**2 and abs(hi_d - (2 + w)) < 0.5 * kappa**2
    assert lo < lo_d < hi_d < hi  # damping narrows the tongue
    # inside the tongue the trivial orbit loses stability by a flip (response at Omega/2)
    p = jg.SpurPairParams(zeta=zeta, kappa=kappa, b=0.0, f_m=0.0, e_amp=0.0, Omega=2.0)
    r = jg.periodic_orbit(jg.SPUR_PAIR, p, jnp.zeros(2))
    assert int(r.status) == SHOOT_CONVERGED and not bool(r.stable) and int(r.instability) == FLIP
    assert float(jnp.real(r.multipliers[0])) < -1.0


# --------------------------------------------------------------------------- Jacobian, Newton
def test_autodiff_jacobian_matches_central_difference():
    cases = [(jg.DUFFING, duffing(), np.array([0.4, -0.7]), 2),
             (jg.REDUCED, jg.paper_params(), np.array([5.4, -0.2, 8.3, -0.8]), 1)]
    for system, p, x, k in cases:
        J = np.asarray(jg.monodromy(system, p, x, period=k))
        h = 1e-6
        E = np.eye(system.dim) * h
        fd = (np.asarray(jg.stroboscopic_map(system, p, x + E, periods=k))
              - np.asarray(jg.stroboscopic_map(system, p, x - E, periods=k))).T / (2 * h)
        np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-6 * np.abs(J).max())


def test_newton_converges_quadratically():
    # one optimistix Newton step per call, chained through the last iterate; the residual
    # ||P(x) - x|| of each iterate measured here by the stroboscopic map
    p = duffing()
    x = jnp.array([0.7, 1.3])
    h = []
    for _ in range(12):
        h.append(float(jnp.linalg.norm(jg.stroboscopic_map(jg.DUFFING, p, x) - x)))
        r = jg.periodic_orbit(jg.DUFFING, p, x, solver=NEWTON, max_iter=1)
        x = r.last_iterate
        if int(r.status) == SHOOT_CONVERGED:
            break
    assert int(r.status) == SHOOT_CONVERGED and float(r.residual) <= 1e-10
    h.append(float(jnp.linalg.norm(jg.stroboscopic_map(jg.DUFFING, p, x) - x)))
    h = np.asarray(h)
    pairs = [(a, b) for a, b in zip(h[:-1], h[1:]) if a < 1e-2 and b > 1e-13]  # above round-off
    assert len(pairs) >= 2
    for a, b in pairs:
        assert b <= 20.0 * a * a, (a, b)  # r_{n+1} <= C r_n^2 (linear convergence would fail)


# --------------------------------------------------------------------------- orbits, verification
def test_bistable_duffing_three_orbits_saddle_left_stable_kept():
    p = duffing()
    seeds = jg.seeds_in_box(40, [-2.0, -2.0], [2.0, 2.0], seed=1)
    search = jg.find_periodic_orbits(jg.DUFFING, p, seeds, period=1)
    assert len(search.orbits) == 3 and all(o.period == 1 for o in search.orbits)
    assert sum(search.status_counts.values()) == 40
    T = 2 * np.pi / 1.4
    for o in search.orbits:
        assert o.residual <= 1e-10
        # Liouville: det of the monodromy = exp(-delta T)
        assert abs(np.prod(o.multipliers).real - np.exp(-0.1 * T)) < 1e-7
    stable = [o for o in search.orbits if o.stable]
    saddle = [o for o in search.orbits if not o.stable]
    assert len(stable) == 2 and len(saddle) == 1
    assert saddle[0].instability == "fold" and np.max(np.abs(saddle[0].multipliers).real) > 1
    amp = lambda o: np.linalg.norm(o.points[0])
    assert amp(stable[0]) < amp(saddle[0]) < amp(stable[1]) or amp(stable[1]) < amp(saddle[0]) < amp(stable[0])
    for o in stable:
        chk = jg.verify_orbit(jg.DUFFING, p, o, periods=150)
        assert chk.kept and np.all(chk.left_at == -1) and np.max(chk.distance) < 1e-5
    chk = jg.verify_orbit(jg.DUFFING, p, saddle[0], periods=150)
    assert not chk.kept and np.all(chk.left_at > 0) and not chk.diverged.any()
    # it ends on one of the stable orbits
    ends = chk.final_points[:, -1]
    d = np.min([np.linalg.norm(ends - o.points[0], axis=1) for o in stable], axis=0)
    assert np.all(d < 1e-4)


def test_minimal_period_and_dedup_via_seeds_from_result():
    p = duffing()
    stable = jg.periodic_orbit(jg.DUFFING, p, jnp.array([[-0.3, 0.1], [1.0, 1.1]]))
    a, b = np.asarray(stable.point)
    b1 = np.asarray(jg.stroboscopic_map(jg.DUFFING, p, b))
    # stand-in cell-mapping result: approximate points, one P-1 attractor reported as P-2
    fake = SimpleNamespace(attractors=[
        SimpleNamespace(points=(a + 0.01)[None], period=1),
        SimpleNamespace(points=np.stack([b + 0.01, b1 - 0.01]), period=2),
        SimpleNamespace(points=np.zeros((0, 2)), period=0),  # non-periodic: skipped
    ])
    groups = jg.seeds_from_result(fake)
    assert sorted(groups) == [1, 2] and groups[1].shape == (1, 2) and groups[2].shape == (2, 2)
    search = jg.find_periodic_orbits(jg.DUFFING, p, groups)
    assert len(search.orbits) == 2  # the P-2 request found the large P-1 twice: reported once
    assert all(o.period == 1 and o.stable for o in search.orbits)
    assert np.asarray(search.shots[2].min_period).tolist() == [1, 1]
    big = max(search.orbits, key=lambda o: np.linalg.norm(o.points[0]))
    np.testing.assert_allclose(big.points[0], b, atol=1e-8)
    assert big.n_seeds == 2
    with pytest.raises(ValueError, match="needs an object with .attractors"):
        jg.seeds_from_result(object())


@pytest.fixture(scope="module")
def paper_p4():
    p = jg.paper_params()
    x0 = jg.seeds_in_box(1, [-5, -3, 0, -2], [5, 3, 10, 2], seed=7)[0]
    x = jg.stroboscopic_map(jg.REDUCED, p, x0, periods=600)
    pts = np.asarray(jg.stroboscopic_orbit(jg.REDUCED, p, x, n_points=8))
    assert np.max(np.abs(pts[4:] - pts[:4])) < 1e-6  # the motion settled on a P-4 orbit
    assert np.min(np.linalg.norm(pts[1:4] - pts[0], axis=1)) > 1e-2  # not P-1 or P-2
    return p, pts[:4]


@pytest.mark.slow
def test_paper_preset_stable_p4(paper_p4):
    p, pts = paper_p4
    rng = np.random.default_rng(0)
    seeds = pts + 0.05 * rng.standard_normal(pts.shape)
    r = jg.periodic_orbit(jg.REDUCED, p, seeds, period=4)
    assert np.all(np.asarray(r.status) == SHOOT_CONVERGED)
    assert np.all(np.asarray(r.residual) <= 1e-10)
    assert np.all(np.asarray(r.iterations) >= 2)  # it had work to do
    assert np.all(np.asarray(r.min_period) == 4) and np.all(np.asarray(r.stable))
    # each seed converged to the point it was near (a cyclic shift of the same orbit)
    np.testing.assert_allclose(np.asarray(r.point), pts, atol=1e-6)
    # asking for P-8 reports the same orbit with minimal period 4, once
    search = jg.find_periodic_orbits(jg.REDUCED, p, seeds[:2], period=(4, 8))
    assert len(search.orbits) == 1 and search.orbits[0].period == 4 and search.orbits[0].n_seeds == 4


@pytest.mark.slow
def test_cli_shoot_json(paper_p4, monkeypatch):
    from jaxgear.cli import main

    p, pts = paper_p4
    argv = ["shoot", "--period", "4", "--json"] + sum((["--from", ",".join(map(str, x))] for x in pts[:2]), [])
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(argv) == 0
    out = json.loads(buf.getvalue())
    assert out["params"] == p.to_dict()
    assert len(out["orbits"]) == 1 and out["orbits"][0]["period"] == 4 and out["orbits"][0]["stable"]
    # --seeds-from: any loader returning an object with .attractors and .params
    fake = SimpleNamespace(params=p.to_dict(), attractors=[SimpleNamespace(points=pts + 0.01, period=4)])
    monkeypatch.setattr("jaxgear._io.load", lambda path, expected=None: fake)
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["shoot", "--seeds-from", "whatever.nc"]) == 0
    text = buf.getvalue()
    assert "P-4, stable" in text and "4 converged" in text
    assert main(["shoot", "--period", "0", "--from", "1,2,3,4"]) == 2
    assert main(["shoot", "--from", "1,2,3"]) == 2


# --------------------------------------------------------------------------- gradients
def test_implicit_gradient_matches_finite_difference_of_reconverged_orbits():
    x0 = jnp.array([1.0, 1.1])  # the large-amplitude stable orbit

    def amplitude(gamma):
        r = jg.periodic_orbit(jg.DUFFING, duffing(gamma=gamma), x0)
        return jnp.sum(r.point**2)

    g = float(jax.grad(amplitude)(0.3))
    h = 1e-5
    fd = (float(amplitude(0.3 + h)) - float(amplitude(0.3 - h))) / (2 * h)
    assert np.isfinite(g) and abs(g) > 0.1
    assert abs(g - fd) <= 1e-6 * abs(fd)


# --------------------------------------------------------------------------- input checks
def test_bad_input_rejected():
    p = duffing()
    with pytest.raises(ValueError, match="shape"):
        jg.periodic_orbit(jg.DUFFING, p, jnp.zeros(3))
    with pytest.raises(ValueError, match="period"):
        jg.periodic_orbit(jg.DUFFING, p, jnp.zeros(2), period=0)
    with pytest.raises(ValueError, match="period"):
        jg.periodic_orbit(jg.DUFFING, p, jnp.zeros(2), period=1.5)
    with pytest.raises(ValueError, match="NaN or infinite"):
        jg.periodic_orbit(jg.DUFFING, p, jnp.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="shape"):
        jg.find_periodic_orbits(jg.DUFFING, p, np.zeros((3, 4)))
    with pytest.raises(ValueError, match="high > low"):
        jg.seeds_in_box(5, [0, 0], [1, -1])
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        jg.verify_orbit(jg.DUFFING, p, np.zeros((1, 3)))


def test_failures_are_reported_as_data():
    # free flight (no stiffness in reach): DP - I is singular, reported per seed, no orbit
    p = jg.SpurPairParams(zeta=0.0, kappa=0.0, b=100.0, f_m=0.0, e_amp=0.0, Omega=1.0)
    r = jg.periodic_orbit(jg.SPUR_PAIR, p, jnp.array([[0.0, 0.5], [1.0, 0.0]]))
    st = np.asarray(r.status)
    assert st[0] == SHOOT_SINGULAR and np.all(np.isnan(np.asarray(r.point[0])))
    assert st[1] in (SHOOT_CONVERGED, SHOOT_SINGULAR)  # at rest: a fixed point of P


def test_gradient_through_singular_seeds_is_finite():
    # implicit derivatives exist only at a converged, regular root: where DP - I is
    # singular the seed carries a zero derivative, so a batch's gradient stays finite
    def total(f_m):
        p = jg.SpurPairParams(zeta=0.0, kappa=0.0, b=100.0, f_m=f_m, e_amp=0.0, Omega=1.0)
        r = jg.periodic_orbit(jg.SPUR_PAIR, p, jnp.array([[0.0, 0.5], [1.0, 0.0]]))
        return jnp.sum(jnp.where(jnp.isfinite(r.point), r.point, 0.0)), r.status

    (_, st), g = jax.value_and_grad(total, has_aux=True)(0.0)
    assert np.asarray(st)[0] == SHOOT_SINGULAR
    assert np.isfinite(float(g))


# --------------------------------------------------------------------------- figure
def test_plot_orbit_figure():
    from matplotlib.figure import Figure

    from jaxgear.plotting import plot_orbit

    p = duffing()
    o = jg.find_periodic_orbits(jg.DUFFING, p, np.array([[1.0, 1.1]])).orbits[0]
    fig = plot_orbit(jg.DUFFING, p, o, coords=(0, 1), samples_per_period=50)
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    ax = fig.axes[0]
    line = ax.lines[0].get_xydata()
    assert np.linalg.norm(line[0] - o.points[0]) < 1e-12 and np.linalg.norm(line[-1] - o.points[0]) < 1e-4
    fig3 = plot_orbit(jg.REDUCED, jg.paper_params(), np.array([[5.4, -0.2, 8.3, -0.8]]), coords=(0, 1, 2),
                      samples_per_period=20)
    assert fig3.axes[0].name == "3d"
    with pytest.raises(ValueError, match="coords must be 2 or 3 indices"):
        plot_orbit(jg.DUFFING, p, o, coords=(0, 5))


# --------------------------------------------------------------------------- batches, files
@pytest.mark.slow
def test_find_periodic_orbits_independent_of_chunk_size():
    p = duffing()
    seeds = np.concatenate([jg.seeds_in_box(7, [-1.5, -1.5], [1.5, 1.5], seed=3), [[40.0, -40.0], [1.0, 1.1]]])
    runs = [jg.find_periodic_orbits(jg.DUFFING, p, seeds, period=1, chunk_size=c, max_iter=15, progress=False,
                                    trajectory_samples=0) for c in (2, 4, 64)]
    ref = runs[0]
    assert len(ref.orbits) >= 2 and 5 <= ref.status_counts["converged"] < 9  # some lanes fail
    for other in runs[1:]:
        assert other.status_counts == ref.status_counts
        for k in (1,):
            a, b = ref.shots[k], other.shots[k]
            for name in ("status", "iterations", "min_period", "stable", "instability"):
                np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
            conv = a.status == SHOOT_CONVERGED
            for name in ("point", "orbit", "monodromy", "multipliers", "residual", "last_iterate"):
                # the same lanes to round-off (XLA may order a batched sum differently for another
                # batch size; a lane that wanders without converging amplifies that, so converged lanes)
                np.testing.assert_allclose(getattr(a, name)[conv], getattr(b, name)[conv], rtol=1e-12, atol=1e-12,
                                           err_msg=name)
        assert [(o.period, o.stable, o.n_seeds) for o in other.orbits] == [(o.period, o.stable, o.n_seeds)
                                                                          for o in ref.orbits]
        for o, q in zip(ref.orbits, other.orbits):
            np.testing.assert_allclose(q.points, o.points, rtol=0, atol=1e-12)


def test_find_periodic_orbits_checks_input_on_entry():
    with pytest.raises(ValueError, match="period must be positive"):  # check_system: T = 2 pi / omega
        jg.find_periodic_orbits(jg.DUFFING, duffing(omega=0.0), np.zeros((2, 2)), progress=False)
    with pytest.raises(ValueError, match="chunk_size"):
        jg.find_periodic_orbits(jg.DUFFING, duffing(), np.zeros((2, 2)), chunk_size=0, progress=False)
    with pytest.raises(ValueError, match="shape"):
        jg.find_periodic_orbits(jg.DUFFING, duffing(), np.zeros((0, 2)), progress=False)
    with pytest.raises(ValueError, match="NaN or infinite"):
        jg.find_periodic_orbits(jg.DUFFING, duffing(), np.array([[np.inf, 0.0]]), progress=False)


def test_find_periodic_orbits_stores_settings_and_trajectories():
    p = duffing()
    s = jg.find_periodic_orbits(jg.DUFFING, p, np.array([[1.0, 1.1]]), progress=False, trajectory_samples=40)
    o = s.orbits[0]
    assert s.params == {"delta": 0.1, "alpha": 1.0, "beta": 1.0, "gamma": 0.3, "omega": 1.4}
    assert s.system == "duffing" and s.state_names == ("x", "v")
    assert s.settings.options == jg.SearchOptions(trajectory_samples=40) and s.settings.periods == (1,)
    assert o.trajectory.shape == (41, 2) and o.samples_per_period == 40
    # the stored trajectory is the flow: it starts at the orbit point and closes after one period
    # (40 samples of 5 RK4 steps: the 200 steps of the map the orbit is a fixed point of)
    np.testing.assert_array_equal(o.trajectory[0], o.points[0])
    assert np.linalg.norm(o.trajectory[-1] - o.points[0]) < 1e-10
    ts, xs = jg.sample_trajectory(jg.DUFFING, p, o.points[0], periods=1, samples_per_period=40)
    np.testing.assert_allclose(o.trajectory, np.asarray(xs), rtol=0, atol=1e-13)


@pytest.mark.slow
def test_search_settings_are_typed_and_load_as_saved(tmp_path):
    """The settings of a search are its options object (a solver and a search integrator
    of the user's included), the periods, t0 and the integrator; the file gives them back
    equal, field by field."""
    import optimistix as optx

    opts = jg.SearchOptions(solver=optx.Dogleg(rtol=1e-9, atol=1e-11), search_integrator=jg.RK4(100),
                            max_iter=25, trajectory_samples=0)
    s = jg.find_periodic_orbits(jg.DUFFING, duffing(), np.array([[1.0, 1.1]]), period=[1, 2], t0=0.25,
                                integrator=jg.RK4(200), options=opts, progress=False)
    assert s.settings == jg.SearchSettings(options=opts, periods=(1, 2), t0=0.25, integrator=jg.RK4(200))
    back = jg.load(s.save(tmp_path / "s.nc"))
    assert back.settings == s.settings and back.settings.search_integrator == jg.RK4(100)
    assert back.summary()["settings"] == s.summary()["settings"]
    assert s.summary()["settings"]["solver"]["type"] == "Dogleg" and s.summary()["settings"]["periods"] == [1, 2]


@pytest.mark.slow
def test_cli_shoot_out_writes_orbits_json_and_figures(tmp_path):
    from jaxgear.cli import main

    x = ",".join(repr(v) for v in [5.5791, -0.6199, 10.6749, -0.2539])  # near the paper's unstable P-1
    with redirect_stdout(io.StringIO()) as buf:
        assert main(["shoot", "--from", x, "--period", "1", "--out", str(tmp_path / "a"), "--quiet"]) == 0
    assert "wrote orbits.nc, orbits.json, orbit_1_P-1.png, multipliers.png" in buf.getvalue()
    s = jg.load(tmp_path / "a" / "orbits.nc")
    assert isinstance(s, jg.OrbitSearch) and [o.instability for o in s.orbits] == ["flip"]
    js = json.loads((tmp_path / "a" / "orbits.json").read_text())
    assert js["params"] == jg.paper_params().to_dict() and js["orbits"][0]["period"] == 1
    np.testing.assert_array_equal(js["orbits"][0]["points"], s.orbits[0].points)
    assert (tmp_path / "a" / "orbit_1_P-1.png").stat().st_size > 1000
    with redirect_stdout(io.StringIO()):
        assert main(["shoot", "--from", x, "--period", "1", "--out", str(tmp_path / "b"), "--no-figures",
                     "--quiet"]) == 0
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["orbits.json", "orbits.nc"]


# --------------------------------------------------------------------------- optimistix solvers, deflation, segments
def test_deflation_ignores_padding_rows_and_their_derivative():
    """The deflation table is padded with NaN rows: they leave the factor 1 / ||x - r||^p +
    shift of the real rows alone and add no derivative, also at x = 0 (where a padding row
    once gave 1 / 0 inside the unused branch and a NaN gradient)."""
    from jaxgear.shooting._solve import deflation

    r = jnp.array([[1.0, 2.0], [jnp.nan, jnp.nan]])
    for x in (jnp.zeros(2), jnp.array([0.5, -1.0])):
        d = float(np.linalg.norm(np.asarray(x) - [1.0, 2.0]))
        assert float(deflation(x, r, 2.0, 1.0)) == pytest.approx(1.0 / d**2 + 1.0, rel=1e-14)
        g = np.asarray(jax.grad(lambda y: deflation(y, r, 2.0, 1.0))(x))
        np.testing.assert_allclose(g, -2.0 * (np.asarray(x) - [1.0, 2.0]) / d**4, rtol=1e-12)


def test_deflation_finds_the_saddle_plain_newton_misses():
    # random seeds around the small stable orbit: plain Newton returns it from every seed;
    # the deflated round pushes the same seeds off it, onto the saddle (and the large orbit)
    p = duffing()
    seeds = jg.seeds_in_box(8, [-0.6, -0.2], [-0.1, 0.3], seed=0)
    kw = dict(integrator=jg.RK4(100), max_iter=20, progress=False, trajectory_samples=0, solver=NEWTON)
    plain = jg.find_periodic_orbits(jg.DUFFING, p, seeds, **kw)
    assert [o.stable for o in plain.orbits] == [True] and plain.orbits[0].n_seeds == 8
    defl = jg.find_periodic_orbits(jg.DUFFING, p, seeds, deflation_rounds=1, **kw)
    saddles = [o for o in defl.orbits if not o.stable]
    assert len(saddles) == 1 and saddles[0].instability == "fold" and saddles[0].residual <= 1e-10
    np.testing.assert_allclose(saddles[0].points[0], [-0.8471, 0.6365], atol=1e-3)  # the saddle (harmonic balance 0.95)
    c = defl.convergence_of(1)
    assert c.runs == 16 and c.first_round == 8 and c.converged > 8
    # plain Newton from the same seeds with the known orbit deflated finds no stable small orbit again
    small = plain.orbits[0].points
    r = jg.periodic_orbit(jg.DUFFING, p, seeds, integrator=jg.RK4(100), max_iter=20, deflate=small, solver=NEWTON)
    conv = np.asarray(r.status) == SHOOT_CONVERGED
    assert conv.any() and np.all(np.linalg.norm(np.asarray(r.point)[conv] - small[0], axis=1) > 0.1)


def test_multiple_shooting_converges_from_more_seeds():
    # seeds far out in the phase plane (the hardening spring makes single-period flows from
    # them wild): five segments per period converge from more of the same seeds
    p = duffing()
    seeds = jg.seeds_in_box(32, [-4.0, -4.0], [4.0, 4.0], seed=2)
    frac = {}
    for M in (1, 5):
        r = jg.periodic_orbit(jg.DUFFING, p, seeds, segments=M, integrator=jg.RK4(100), max_iter=20, solver=NEWTON)
        st = np.asarray(r.status)
        frac[M] = float(np.mean(st == SHOOT_CONVERGED))
        assert np.all(np.asarray(r.residual)[st == SHOOT_CONVERGED] <= 1e-10)
    assert frac[1] <= 8 / 32 and frac[5] >= 10 / 32, frac


@pytest.mark.slow
def test_implicit_gradient_through_optimistix_solvers_and_segments():
    x0 = jnp.array([1.0, 1.1])

    def amplitude(gamma, solver, M):
        r = jg.periodic_orbit(jg.DUFFING, duffing(gamma=gamma), x0, solver=solver, segments=M, integrator=jg.RK4(100))
        return jnp.sum(r.point**2)

    h = 1e-5
    for solver, M in ((optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12), 1), (NEWTON, 4)):
        g = float(jax.grad(amplitude)(0.3, solver, M))
        fd = (float(amplitude(0.3 + h, solver, M)) - float(amplitude(0.3 - h, solver, M))) / (2 * h)
        assert np.isfinite(g) and abs(g) > 0.1 and abs(g - fd) <= 1e-6 * abs(fd), (solver, M, g, fd)


def test_solver_options_rejected():
    p = duffing()
    with pytest.raises(ValueError, match="solver"):
        jg.periodic_orbit(jg.DUFFING, p, jnp.zeros(2), solver="bisection")
    with pytest.raises(ValueError, match="segments"):
        jg.periodic_orbit(jg.DUFFING, p, jnp.zeros(2), segments=3)  # 200 steps: 3 does not divide
    with pytest.raises(ValueError, match="damped-newton"):  # names are the command line's only
        jg.periodic_orbit(jg.DUFFING, p, jnp.zeros(2), solver="damped-newton", segments=2)


def test_bad_solver_object_refused_with_a_clear_message():
    p = duffing()
    bad = [(optx.Newton, "is a class"),  # not an instance
           ("dogleg", "command line only"),  # a name, not an object
           (optx.BFGS(rtol=1e-8, atol=1e-8), "optimistix solver instance"),  # a minimiser
           (optx.Bisection(rtol=1e-8, atol=1e-8), "scalar equations"),
           (lambda f, x: x, "optimistix solver instance")]
    for solver, match in bad:
        with pytest.raises(ValueError, match=match) as err:
            jg.ShootOptions(solver=solver)
        assert str(err.value).startswith("solver=")
        with pytest.raises(ValueError, match=match):
            jg.find_periodic_orbits(jg.DUFFING, p, np.zeros((1, 2)), solver=solver, progress=False)
    with pytest.raises(ValueError, match="unknown option 'solvr'"):
        jg.periodic_orbit(jg.DUFFING, p, jnp.zeros(2), solvr=NEWTON)
    with pytest.raises(ValueError, match="SearchOptions"):
        jg.find_periodic_orbits(jg.DUFFING, p, np.zeros((1, 2)), options={"transient": 40}, progress=False)


# --------------------------------------------------------------------------- jaxgear shoot --periods
def _cli_json(argv):
    from jaxgear.cli import main

    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(argv) == 0
    return json.loads(buf.getvalue())


def _assert_periodic_by_reintegration(out, integrator):
    """Every reported orbit returns to its points after its minimal period (and not before)."""
    p = jg.GearParams.from_dict(out["params"]).uniform()
    for o in out["orbits"]:
        pts, m = np.asarray(o["points"]), int(o["period"])
        back = np.asarray(jg.stroboscopic_map(jg.REDUCED, p, pts, periods=m, integrator=integrator))
        assert np.max(np.abs(back - pts)) < 1e-7 * (1 + np.max(np.abs(pts))), o
        if m > 1:  # minimal: fewer periods do not close the orbit
            one = np.asarray(jg.stroboscopic_map(jg.REDUCED, p, pts[:1], periods=1, integrator=integrator))
            assert np.linalg.norm(one - pts[:1]) > 1e-3


SHOOT_ARGV = ["--random", "8", "--steps-per-period", "100", "--verify", "50", "--json"]
"""A small search over the paper's region D, from 8 random seeds at a coarse step (100
steps per period): the transient brings the seeds near the attractor, the solver on P^k
from there reaches the unstable orbits."""


def test_cli_period_and_periods_make_one_and_the_same_search_call(monkeypatch):
    # --period K and --periods K-K reach find_periodic_orbits with the same seeds, periods,
    # integrator and options (one search path); the search itself runs in the slow test below
    import jaxgear.shooting as shooting
    from jaxgear.cli import main

    calls = []

    class Stop(Exception):
        pass

    def spy(system, params, seeds, *, period, integrator, options, progress):
        calls.append((system, params, np.asarray(seeds), list(period), integrator, options))
        raise Stop

    monkeypatch.setattr(shooting, "find_periodic_orbits", spy)
    for form in (["--period", "3"], ["--periods", "3-3"]):
        with pytest.raises(Stop):
            main(["shoot", *form, *SHOOT_ARGV])
    (sys1, p1, x1, k1, i1, o1), (sys2, p2, x2, k2, i2, o2) = calls
    assert sys1 is sys2 and p1 == p2 and k1 == k2 == [3] and i1 == i2 and o1 == o2
    np.testing.assert_array_equal(x1, x2)
    assert o1.transient > 0 and x1.shape == (8, 4)  # random seeds get the transient (--period once ran without)


@pytest.fixture(scope="module")
def shoot_period_1():
    """``jaxgear shoot --period 1`` on :data:`SHOOT_ARGV` (its JSON), run once for the two
    slow tests below."""
    return _cli_json(["shoot", "--period", "1"] + SHOOT_ARGV)


@pytest.fixture(scope="module")
def shoot_periods_1_2():
    """``jaxgear shoot --periods 1-2`` on :data:`SHOOT_ARGV` (its JSON), run once for the two
    slow tests below."""
    return _cli_json(["shoot", "--periods", "1-2"] + SHOOT_ARGV)


@pytest.mark.slow
def test_cli_shoot_one_period_is_the_periods_search_of_that_period(shoot_period_1, shoot_periods_1_2):
    # one search: --period 1 converges from the same seeds to the same P-1, the unstable (flip)
    # orbit of region D, as the P^1 part of --periods 1-2 (--period once ran without the
    # transient, with another solver, and converged from none of them). That --period K and
    # --periods K-K make the same call is checked without running it by
    # test_cli_period_and_periods_make_one_and_the_same_search_call.
    one, out = shoot_period_1, shoot_periods_1_2
    _assert_periodic_by_reintegration(one, jg.default_integrator(100))
    assert one["settings"]["periods_tried"] == [1] and one["convergence"]["1"] == out["convergence"]["1"]
    assert one["settings"]["search"] == dict(out["settings"]["search"], periods=[1])
    assert one["convergence"]["1"]["runs"] == 8 and one["convergence"]["1"]["converged"] >= 1
    assert len(one["orbits"]) == 1
    p1 = one["orbits"][0]
    assert p1["period"] == 1 and not p1["stable"] and p1["instability"] == "flip" and p1["multipliers"][0][0] < -1
    np.testing.assert_allclose(next(o for o in out["orbits"] if o["period"] == 1)["points"], p1["points"], atol=1e-9)
    assert len(one["checks"]) == 1 and all(v["consistent"] for v in one["checks"].values())


@pytest.mark.slow
def test_cli_shoot_periods_search_finds_the_unstable_p1_and_p2(shoot_periods_1_2):
    # P^1 and P^2 searched together reach the unstable P-1 (flip) and the P-2 born from it
    out = shoot_periods_1_2
    assert out["settings"]["periods_tried"] == [1, 2]
    _assert_periodic_by_reintegration(out, jg.default_integrator(100))
    periods = sorted(o["period"] for o in out["orbits"])
    assert 1 in periods and 2 in periods, periods
    p1 = next(o for o in out["orbits"] if o["period"] == 1)
    assert not p1["stable"] and p1["instability"] == "flip" and p1["multipliers"][0][0] < -1
    c = out["convergence"]
    assert c["1"]["runs"] == 8 and c["1"]["converged"] >= 1 and c["2"]["converged"] >= 1
    # each orbit checked by direct integration, consistent with its multipliers
    assert len(out["checks"]) == len(out["orbits"]) and all(v["consistent"] for v in out["checks"].values())


@pytest.mark.slow
def test_cli_shoot_periods_1_8_on_region_d_finds_the_four_orbits():
    # the done-when search (64 random seeds over region D, every period 1..8) on 32 seeds:
    # the same orbits (22 to 26 seeds converge at periods 1, 2, 4 and 8), in half the time
    out = _cli_json(["shoot", "--periods", "1-8", "--random", "32", "--json"])
    _assert_periodic_by_reintegration(out, jg.default_integrator())
    kinds = {(o["period"], o["stable"]) for o in out["orbits"]}
    assert {(1, False), (2, False), (4, True), (8, True)} <= kinds, kinds
    runs = sum(c["runs"] for c in out["convergence"].values())
    conv = sum(c["converged"] for c in out["convergence"].values())
    assert conv / runs >= 0.15, (conv, runs)
    p1 = next(o for o in out["orbits"] if o["period"] == 1)
    assert p1["instability"] == "flip" and p1["multipliers"][0][0] < -1
