"""Continuation of periodic orbits (issue 5, point 3), checked against theory and scipy.

References that do not come from jaxgear:
- the damped Mathieu equation's first-tongue boundary from perturbation theory and the
  exact flip condition det(M + I) = 0 from a high-accuracy scipy monodromy;
- the one-harmonic balance of the hardening Duffing oscillator (fold points, P-2
  amplitude of the parametric Duffing) and the closed-form linear response;
- direct integration (stroboscopic map) for the period of the doubled branch.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import count_compilations
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import jaxgear as jg
from jaxgear import continue_orbit, switch_branch
from jaxgear import load as load_branch
from jaxgear.continuation import CORRECTOR

ZETA, EPS, BETA = 0.005, 0.1, 1.0


def _f64(x):
    return jnp.asarray(x, dtype=jnp.float64)


# --------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def mathieu():
    """Trivial P-1 orbit x = 0 of the parametric Duffing oscillator continued in Omega."""
    p = jg.ParamDuffingParams(zeta=ZETA, epsilon=EPS, beta=BETA, Omega=1.85)
    br = continue_orbit(jg.PARAM_DUFFING, p, np.zeros(2), param="Omega", stop=2.15,
                        options=jg.ContinuationOptions(ds=0.02, ds_max=0.05), progress=False)
    return p, br


@pytest.fixture(scope="module")
def doubled(mathieu):
    p, br = mathieu
    pd = [b for b in br.bifurcations if b.kind == "PD"]
    return switch_branch(jg.PARAM_DUFFING, p, br, pd[0], stop=2.15, progress=False)  # the options of br


DUFF = dict(delta=0.01, alpha=1.0, beta=1.0, gamma=0.003)


@pytest.fixture(scope="module")
def duffing_folds():
    """Hardening Duffing continued in omega through its resonance (two folds)."""
    p = jg.DuffingParams(omega=0.9, **DUFF)
    return p, continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.15, ds=0.01, ds_max=0.05,
                             progress=False)


# --------------------------------------------------------------------------- references
def mathieu_flip(omega):
    """det(M + I) of the damped Mathieu equation x'' + 2 zeta x' + (1 + eps cos(Omega t)) x = 0
    (the linearisation at x = 0), monodromy by DOP853 at rtol 1e-13."""
    T = 2 * np.pi / omega

    def f(t, y):
        k = 1 + EPS * np.cos(omega * t)
        return [y[1], -2 * ZETA * y[1] - k * y[0], y[3], -2 * ZETA * y[3] - k * y[2]]

    s = solve_ivp(f, (0, T), [1.0, 0.0, 0.0, 1.0], method="DOP853", rtol=1e-13, atol=1e-14)
    M = s.y[:, -1].reshape(2, 2).T
    return M


def duffing_hb_folds(delta, alpha, beta, gamma):
    """Fold frequencies of [(alpha - w^2 + 3/4 beta A^2)^2 + (delta w)^2] A^2 = gamma^2 (numpy):
    the local extrema of w(A) on the upper (+) root w^2 = u(A) of the quadratic in u."""
    A = np.linspace(1e-3, 1.0, 4_000_001)
    c = alpha + 0.75 * beta * A**2
    disc = (2 * c - delta**2) ** 2 - 4 * (c**2 - gamma**2 / A**2)
    folds = []
    for sgn in (1.0, -1.0):
        u = 0.5 * ((2 * c - delta**2) + sgn * np.sqrt(np.where(disc >= 0, disc, np.nan)))
        w = np.sqrt(np.where(u > 0, u, np.nan))
        dw = np.diff(w)
        i = np.flatnonzero(np.sign(dw[:-1]) * np.sign(dw[1:]) < 0) + 1
        folds += [float(w[j]) for j in i]
    return sorted(folds)


# --------------------------------------------------------------------------- period doubling
def test_mathieu_pd_points_match_first_order_perturbation_theory(mathieu):
    # Harmonic balance x = a cos(Omega t/2) + b sin(Omega t/2) on the damped Mathieu equation
    # gives the first-tongue edges (1 - Omega^2/4)^2 = (eps^2 - 4 zeta^2 Omega^2)/4, i.e.
    # Omega_pm = 2 sqrt(1 +- sqrt(eps^2 - 16 zeta^2)/2) to first order in eps. In Mathieu form
    # (delta = 1/Omega^2, e = eps/Omega^2 ~ 0.025) the neglected term is e^2/8 in delta,
    # i.e. ~3e-4 in Omega: compare within 1e-3.
    _, br = mathieu
    pds = sorted(b.param_value for b in br.bifurcations if b.kind == "PD")
    assert len(pds) == 2
    S = np.sqrt(EPS**2 - 16 * ZETA**2)
    theory = [2 * np.sqrt(1 - S / 2), 2 * np.sqrt(1 + S / 2)]
    err = np.abs(np.array(pds) - theory)
    assert np.max(err) < 1e-3
    # the error is the theory's O(eps^2): halving eps and zeta divides it by ~4
    q = jg.ParamDuffingParams(zeta=ZETA / 2, epsilon=EPS / 2, beta=BETA, Omega=1.85)
    half = continue_orbit(jg.PARAM_DUFFING, q, np.zeros(2), param="Omega", stop=2.15, ds=0.02, ds_max=0.05,
                          progress=False)
    pds2 = sorted(b.param_value for b in half.bifurcations if b.kind == "PD")
    S2 = S / 2
    err2 = np.abs(np.array(pds2) - [2 * np.sqrt(1 - S2 / 2), 2 * np.sqrt(1 + S2 / 2)])
    assert np.all((3.0 < err / err2) & (err / err2 < 5.0))


def test_mathieu_pd_points_match_exact_flip_condition(mathieu):
    _, br = mathieu
    pds = sorted((b for b in br.bifurcations if b.kind == "PD"), key=lambda b: b.param_value)
    flip = lambda w: np.linalg.det(mathieu_flip(w) + np.eye(2))
    exact = [brentq(flip, 1.9, 2.0, xtol=1e-14), brentq(flip, 2.0, 2.1, xtol=1e-14)]
    for b, w in zip(pds, exact):
        assert abs(b.param_value - w) < 1e-6
        assert not b.nonsmooth
        assert np.min(np.abs(b.multipliers + 1.0)) < 1e-6  # a multiplier at -1
        assert np.allclose(b.point, 0.0, atol=1e-12)
    # the trivial orbit is unstable exactly between the two PD points (the tongue)
    inside = (br.values > pds[0].param_value) & (br.values < pds[1].param_value)
    assert inside.any() and (~inside).any()
    np.testing.assert_array_equal(br.stable, ~inside)
    # multipliers along the branch agree with the scipy monodromy
    for i in (0, len(br) // 2, len(br) - 1):
        lam = np.sort_complex(np.linalg.eigvals(mathieu_flip(br.values[i])))
        np.testing.assert_allclose(np.sort_complex(br.multipliers[i]), lam, atol=1e-6)


def test_doubled_branch_is_a_growing_p2(mathieu, doubled):
    p, br = mathieu
    d = doubled
    pd = min((b for b in br.bifurcations if b.kind == "PD"), key=lambda b: b.param_value)
    assert d.period == 2 and d.status == "stop" and d.values[-1] == 2.15
    assert len(d) >= 5 and abs(d.values[0] - pd.param_value) < 0.01
    # genuine P-2 by direct integration: P(x) is far from x, P^2(x) returns to x
    for i in (1, len(d) // 2, len(d) - 1):
        q = jg.ParamDuffingParams(zeta=ZETA, epsilon=EPS, beta=BETA, Omega=d.values[i])
        x = d.points[i, 0]
        amp = np.linalg.norm(x)
        assert np.linalg.norm(np.asarray(jg.stroboscopic_map(jg.PARAM_DUFFING, q, x)) - x) > amp
        np.testing.assert_allclose(np.asarray(jg.stroboscopic_map(jg.PARAM_DUFFING, q, x, periods=2)), x,
                                   atol=1e-9)
        np.testing.assert_allclose(d.points[i, 1], np.asarray(jg.stroboscopic_map(jg.PARAM_DUFFING, q, x)),
                                   atol=1e-9)
    # amplitude of x = A cos(Omega t/2 - psi) grows away from the PD point ...
    A = np.hypot(d.points[:, 0, 0], d.points[:, 0, 1] / (d.values / 2))
    assert np.all(np.diff(A) > 0) and np.all(np.diff(d.values) > 0)
    # ... as the one-harmonic balance (1 - W^2/4 + 3/4 beta A^2)^2 + zeta^2 W^2 = eps^2/4 says, on its
    # branch born at the lower tongue edge (stable, supercritical); HB's PD is off by ~3e-4, so
    # compare away from it: within 3 % for Omega >= 1.97
    W = d.values
    A_hb = np.sqrt(4 / (3 * BETA) * (W**2 / 4 - 1 + np.sqrt(EPS**2 / 4 - ZETA**2 * W**2)))
    far = W >= 1.97
    assert far.sum() >= 3
    assert np.max(np.abs(A[far] / A_hb[far] - 1)) < 0.03
    assert np.all(d.stable)


# --------------------------------------------------------------------------- folds
def test_duffing_folds_passed_and_located(duffing_folds):
    _, br = duffing_folds
    assert br.status == "stop" and br.values[-1] == 1.15
    sn = [b for b in br.bifurcations if b.kind == "SN"]
    assert len(sn) == 2 and len(br.bifurcations) == 2
    # the parameter turns around: it first rises to the upper fold, falls to the lower one, rises again
    dw = np.diff(br.values)
    assert (dw < 0).sum() >= 3
    i1, i2 = sn[0].index, sn[1].index
    assert np.all(dw[:i1] > 0) and np.all(dw[i1 + 1:i2] < 0) and np.all(dw[i2 + 1:] > 0)
    # fold frequencies vs one-harmonic balance; its error is ~ (3/256) beta^2 A^4 ~ 1e-4 at the
    # largest amplitude A ~ 0.29 (upper fold), smaller at the lower fold: compare within 2e-4
    hb = duffing_hb_folds(**DUFF)
    got = sorted(b.param_value for b in sn)
    assert len(hb) == 2
    assert np.max(np.abs(np.array(got) - hb)) < 2e-4
    for b in sn:
        assert np.min(np.abs(b.multipliers - 1.0)) < 1e-6  # a real multiplier at +1
        assert not b.nonsmooth


def test_duffing_middle_branch_unstable(duffing_folds):
    _, br = duffing_folds
    i1, i2 = (b.index for b in br.bifurcations)
    middle = np.zeros(len(br), bool)
    middle[i1 + 1:i2 + 1] = True
    np.testing.assert_array_equal(br.stable, ~middle)
    lam = br.multipliers[middle]
    top = lam[np.arange(len(lam)), np.argmax(np.abs(lam), axis=1)]
    assert np.all(np.abs(top.imag) < 1e-9) and np.all(top.real > 1.0)  # a real multiplier > 1 (saddle)
    # Liouville: the product of the multipliers is exp(-delta T) everywhere (independent of the orbit)
    T = 2 * np.pi / br.values
    np.testing.assert_allclose(np.prod(br.multipliers, axis=1).real, np.exp(-DUFF["delta"] * T), rtol=1e-7)


def test_linear_limit_matches_closed_form():
    delta, alpha, gamma = 0.1, 1.0, 0.1
    p = jg.DuffingParams(delta=delta, alpha=alpha, beta=0.0, gamma=gamma, omega=0.5)
    with count_compilations("_correct") as compiled:
        br = continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.5, ds=0.02, progress=False)
    # one compiled corrector for the whole branch (params are array leaves; 0 if the Duffing kernel is cached)
    assert len(compiled) <= 1
    assert br.status == "stop" and br.values[0] == 0.5 and br.values[-1] == 1.5
    assert len(br) >= 10 and not br.bifurcations and np.all(br.stable)
    w = br.values
    H = gamma / (alpha - w**2 + 1j * delta * w)  # x(t) = Re(H e^{i w t})
    # tolerance: the O(h^4) error of RK4 with h = T/200, amplified near resonance (Q = 10)
    np.testing.assert_allclose(br.points[:, 0, 0], H.real, atol=1e-6)
    np.testing.assert_allclose(br.points[:, 0, 1], -w * H.imag, atol=1e-6)
    A = np.hypot(br.points[:, 0, 0], br.points[:, 0, 1] / w)
    np.testing.assert_allclose(A, gamma / np.sqrt((alpha - w**2) ** 2 + (delta * w) ** 2), rtol=1e-5)


def test_no_recompilation_for_new_parameter_values(duffing_folds):
    p, _ = duffing_folds
    with count_compilations("_correct") as compiled:
        br = continue_orbit(jg.DUFFING, p.__class__(omega=1.2, delta=0.05, alpha=1.0, beta=0.5, gamma=0.01),
                            np.zeros(2), param="omega", stop=1.25, ds=0.02, progress=False)
    assert len(br) >= 3
    assert compiled == []


# --------------------------------------------------------------------------- results
def _assert_same_branch(a, b):
    for f in ("values", "points", "multipliers", "stable", "residuals", "tangents", "arclength"):
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        np.testing.assert_array_equal(x, y, err_msg=f)
    for f in ("param", "status", "period", "system", "state_names", "params", "settings", "version"):
        assert getattr(a, f) == getattr(b, f), f
    assert len(a.bifurcations) == len(b.bifurcations)
    for p, q in zip(a.bifurcations, b.bifurcations):
        assert (p.kind, p.param_value, p.index, p.test_value, p.nonsmooth) == (
            q.kind, q.param_value, q.index, q.test_value, q.nonsmooth)
        for f in ("point", "multipliers", "orbit"):
            np.testing.assert_array_equal(getattr(p, f), getattr(q, f))


def test_save_load_round_trip_and_plot(tmp_path, duffing_folds, doubled):
    import xarray as xr

    _, br = duffing_folds
    for i, b in enumerate((br, doubled)):
        path = b.save(tmp_path / f"branch{i}.nc")
        c = load_branch(path)
        _assert_same_branch(b, c)
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            assert ds.attrs["jaxgear_type"] == "Branch" and ds.attrs["system"] == b.system
            assert b.param in ds.coords and list(ds["state"].values) == list(b.state_names)
    assert "SN" in br.table() and "P-1 branch of duffing" in br.table()
    assert br.summary()["bifurcations"][0]["kind"] == "SN"

    from jaxgear.plotting import plot_branch

    c = load_branch(tmp_path / "branch0.nc")
    fig = plot_branch(c, "x", multipliers=True)
    ax, ax2 = fig.axes
    styles = {ln.get_linestyle() for ln in ax.get_lines()}
    assert styles == {"-", "--"}  # stable and unstable parts
    assert len(ax.collections) == 2  # one marker per bifurcation
    assert sorted(t.get_text() for t in ax.texts) == ["SN", "SN"]
    assert len(ax2.get_lines()) == 2  # max |lambda| and the line |lambda| = 1
    # drawing into given axes, a P-2 branch (two curves per run) and the norm measure
    fig2 = plot_branch(doubled, "norm")
    plot_branch(doubled, 0, ax=fig2.axes[0], color="k")
    assert len(fig2.axes) == 1 and len(fig2.axes[0].get_lines()) >= 2


# --------------------------------------------------------------------------- errors, helpers
def test_bad_input_is_rejected(duffing_folds, mathieu):
    p, br = duffing_folds
    with pytest.raises(ValueError, match="unknown parameter 'omg'.*omega"):
        continue_orbit(jg.DUFFING, p, np.zeros(2), param="omg", stop=1.0, progress=False)
    with pytest.raises(ValueError, match="equals the starting value"):
        continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=0.9, progress=False)
    with pytest.raises(ValueError, match="shape"):
        continue_orbit(jg.DUFFING, p, np.zeros(3), param="omega", stop=1.0, progress=False)
    with pytest.raises(ValueError, match="ds="):
        continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.0, ds=-1, progress=False)
    with pytest.raises(ValueError, match="period"):
        continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.0, period=0, progress=False)
    with pytest.raises(ValueError, match="period doubling"):
        switch_branch(jg.DUFFING, p, br, 0, stop=1.0, progress=False)
    with pytest.raises(ValueError, match="unknown option 'step'.*ds.*max_iter"):
        continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.0, step=0.1, progress=False)
    for bad, match in ((dict(ds=0.1, ds_max=0.05), "ds_min <= ds <= ds_max"), (dict(bounds=(2.0, 1.0)), "bounds="),
                       (dict(max_steps=0), "max_steps=0"), (dict(max_angle=4.0), "max_angle"),
                       (dict(locate_tol=0.0), "locate_tol")):
        with pytest.raises(ValueError, match=match):
            jg.ContinuationOptions(**bad)


def test_typed_options_are_the_branch_settings(mathieu, doubled):
    """The options object and the same fields given as keywords follow the same branch; the
    branch records both options objects, and the doubled branch inherits those of its parent."""
    p, br = mathieu
    assert br.settings.options == jg.ContinuationOptions(ds=0.02, ds_max=0.05)
    assert br.settings.shoot == CORRECTOR and br.settings.shoot.max_iter == 10
    assert (br.settings.stop, br.settings.origin, br.settings.amplitude) == (2.15, "start", None)
    assert doubled.settings.options == br.settings.options and doubled.settings.amplitude == 0.02
    assert doubled.settings.origin.startswith("PD of the P-1 branch")
    opts = jg.ContinuationOptions(ds=0.05, max_steps=2)
    shoot = jg.ShootOptions(tol=1e-9, max_iter=8)
    a = continue_orbit(jg.PARAM_DUFFING, p, np.zeros(2), param="Omega", stop=2.15, options=opts, shoot=shoot,
                       progress=False)
    b = continue_orbit(jg.PARAM_DUFFING, p, np.zeros(2), param="Omega", stop=2.15, ds=0.05, max_steps=2, tol=1e-9,
                       max_iter=8, progress=False)
    assert a.settings == b.settings and (a.settings.options, a.settings.shoot) == (opts, shoot)
    np.testing.assert_array_equal(a.values, b.values)
    assert len(a) == 3 and a.status == "max_steps"


def test_with_param_and_get_param():
    gp = jg.paper_params()
    q = jg.with_param(gp, "b", 0.7)
    assert float(q.b_sp) == float(q.b_rp) == 0.7 == jg.get_param(q, "b")
    assert jg.get_param(q, "b_sp") == 0.7 and float(q.b_rp) == 0.7
    # per-planet arrays are set for every planet
    per = gp.replace(kappa_sp_amp=[0.1] * gp.N)
    r = jg.with_param(per, "kappa_sp_amp", 0.2)
    np.testing.assert_array_equal(np.asarray(r.kappa_sp_amp), [0.2] * gp.N)
    # traceable: derivative through with_param inside jit equals the field's
    f = jax.jit(jax.grad(lambda v: jnp.sum(jg.with_param(gp, "kappa_amp", v).kappa_rp_amp)))
    assert float(f(0.1)) == 1.0
    # other pytrees: eqx.Module, NamedTuple, dict
    assert jg.get_param(jg.with_param(jg.DuffingParams(), "omega", 1.3), "omega") == 1.3
    from typing import NamedTuple

    class P(NamedTuple):
        a: float
        b: float

    assert jg.with_param(P(1.0, 2.0), "b", 3.0).b == 3.0
    assert jg.get_param({"a": 1.0, "c": 2.0}, "c") == 2.0
    assert "kappa_amp" in jg.param_names(gp) and "b" in jg.param_names(jg.SpurPairParams())
    with pytest.raises(ValueError, match="unknown parameter 'nope'.*Omega"):
        jg.with_param(gp, "nope", 1.0)
    with pytest.raises(ValueError, match="b_sp"):
        jg.with_param(gp, "b", -1.0)  # validated again (backlash >= 0)
    with pytest.raises(ValueError, match="differ"):
        jg.get_param(gp.replace(b_sp=0.5, b_rp=0.6), "b")


# --------------------------------------------------------------------------- Neimark-Sacker
class _VdPParams(eqx.Module):
    mu: Any = eqx.field(converter=_f64, default=0.2)
    F: Any = eqx.field(converter=_f64, default=1.0)
    omega: Any = eqx.field(converter=_f64, default=1.3)


def _vdp_field(t, x, p):
    return jnp.stack([x[1], p.mu * (1 - x[0] ** 2) * x[1] - x[0] + p.F * jnp.cos(p.omega * t)])


VDP = jg.ForcedSystem(vector_field=_vdp_field, period=lambda p: 2 * jnp.pi / p.omega, state_names=("x", "v"),
                      name="forced-van-der-pol")


def test_neimark_sacker_of_forced_van_der_pol():
    # x'' - mu (1 - x^2) x' + x = F cos(omega t), detuned (omega = 1.3): the entrained P-1
    # response loses stability as F decreases, by a complex pair leaving the unit circle
    # (quasi-periodic drift); the located point is checked with a scipy variational solve.
    p = _VdPParams(mu=0.2, F=1.0, omega=1.3)
    x0 = np.asarray(jg.stroboscopic_map(VDP, p, np.zeros(2), periods=200))
    br = continue_orbit(VDP, p, x0, param="F", stop=0.8, ds=0.02, ds_max=0.05, progress=False)
    ns = [b for b in br.bifurcations if b.kind == "NS"]
    assert len(ns) == 1 and len(br.bifurcations) == 1
    b = ns[0]
    i = b.index
    assert br.stable[i] and not br.stable[i + 1] and np.all(~br.stable[i + 1:])
    assert br.values[i + 1] < b.param_value < br.values[i]
    lam = b.multipliers
    assert abs(lam[0].imag) > 0.1 and abs(abs(lam[0]) - 1.0) < 1e-8 and np.isclose(lam[1], np.conj(lam[0]))

    mu, F, w = 0.2, b.param_value, 1.3

    def f(t, y):
        x, v = y[0], y[1]
        J = np.array([[0.0, 1.0], [-2 * mu * x * v - 1.0, mu * (1 - x * x)]])
        Phi = J @ y[2:].reshape(2, 2)
        return np.concatenate([[v, mu * (1 - x * x) * v - x + F * np.cos(w * t)], Phi.ravel()])

    s = solve_ivp(f, (0, 2 * np.pi / w), np.concatenate([b.point, np.eye(2).ravel()]), method="DOP853",
                  rtol=1e-12, atol=1e-13)
    assert np.linalg.norm(s.y[:2, -1] - b.point) < 1e-6  # a periodic orbit of the exact flow
    lam_ref = np.linalg.eigvals(s.y[2:, -1].reshape(2, 2))
    assert np.max(np.abs(np.abs(lam_ref) - 1.0)) < 1e-5  # on the unit circle: NS placed to ~1e-5 in F
    assert np.min(np.abs(lam_ref.imag)) > 0.1


def test_branch_end_statuses():
    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.0, gamma=0.1, omega=0.5)
    br = continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.5, ds=0.01, max_steps=3, progress=False)
    assert br.status == "max_steps" and len(br) == 4
    br = continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.5, ds=0.05, bounds=(0.3, 0.7),
                        progress=False)
    assert br.status == "bounds" and br.values[-1] == 0.7
    # going down towards stop
    br = continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=0.4, ds=0.05, progress=False)
    assert br.status == "stop" and br.values[-1] == 0.4 and np.all(np.diff(br.values) < 0)


# --------------------------------------------------------------------------- gear model
@pytest.mark.slow
def test_paper_p4_continuation_in_omega():
    # the paper preset's stable P-4 (README) continued in Omega: it loses stability through a
    # multiplier jumping over -1 (the backlash makes the map only piecewise smooth): flagged nonsmooth
    p = jg.paper_params()
    x0 = np.array([5.3608, -0.1903, 8.2803, -0.8374])
    br = continue_orbit(jg.REDUCED, p, x0, param="Omega", stop=0.9, period=4, ds=0.01, progress=False)
    assert br.status == "stop" and br.stable[0] and not br.stable[-1]
    pd = [b for b in br.bifurcations if b.kind == "PD"]
    assert pd and 0.885 < pd[0].param_value < 0.895
    i = pd[0].index
    assert br.multipliers[i + 1][np.argmax(np.abs(br.multipliers[i + 1]))].real < -1
    # every point is a P-4 orbit of the map (direct integration)
    for j in (0, len(br) - 1):
        q = p.replace(Omega=float(br.values[j]))
        x4 = np.asarray(jg.stroboscopic_map(jg.REDUCED, q, br.points[j, 0], periods=4))
        assert np.linalg.norm(x4 - br.points[j, 0]) < 1e-8


@pytest.mark.slow
def test_adaptive_integrator_linear_limit():
    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.0, gamma=0.1, omega=0.5)
    br = continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.5, ds=0.05, progress=False,
                        integrator=jg.Adaptive(rtol=1e-11, atol=1e-12))
    w = br.values
    H = 0.1 / (1 - w**2 + 0.1j * w)
    np.testing.assert_allclose(br.points[:, 0, 0], H.real, atol=1e-8)
    np.testing.assert_allclose(br.points[:, 0, 1], -w * H.imag, atol=1e-8)
