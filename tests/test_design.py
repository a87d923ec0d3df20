"""Differentiable periodic response and design (jaxgear._design), checked against central
finite differences of re-converged orbits, closed-form optima of a linear system, the
Mathieu stability boundary and a Duffing fold located by independent shooting."""

import json
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import jaxgear as jg
from jaxgear._params import set_fields as _set_params

# A point near the stable P-4 of the paper preset (stroboscopic map, phase 0).
P4_SEED = np.array([5.8575, -0.6064, 12.1892, -0.9570])


@pytest.fixture(scope="module")
def paper_p4():
    p = jg.paper_params()
    r = jg.periodic_orbit(jg.REDUCED, p, P4_SEED, period=4)
    assert int(r.status) == 0 and int(r.min_period) == 4 and bool(r.stable)
    return p, np.asarray(r.point)


# --------------------------------------------------------------------------- gradients
@pytest.mark.slow
def test_implicit_gradients_of_gear_orbit_scalars_match_finite_differences(paper_p4):
    """d/dp of the RMS and peak-to-peak dynamic mesh forces, the dynamic transmission error and
    the largest Floquet multiplier of the paper's P-4, for four parameters, against central
    differences of orbits re-converged by Newton: relative error < 1e-5 (measured ~1e-8)."""
    p, x4 = paper_p4
    names = ["c_sp", "phi_rp", "gamma_sr", "kappa_sp_amp"]

    def scalars(v):
        q = _set_params(p, names, [v[i] for i in range(len(names))])
        res = jg.periodic_orbit(jg.REDUCED, q, x4, period=4)
        o = jg.sample_orbit(jg.REDUCED, q, res.point, period=4)
        return jnp.stack([jg.mesh_force_rms(q, o, "both"), jg.mesh_force_ptp(q, o, "both"),
                          jg.transmission_error_rms(q, o), jg.max_multiplier(q, o)])

    v0 = jnp.array([float(getattr(p, n)) for n in names])
    f = jax.jit(scalars)
    J = np.asarray(jax.jit(jax.jacrev(scalars))(v0))  # reverse mode: one pass per scalar
    h = 1e-5
    fd = np.stack([(np.asarray(f(v0.at[i].add(h))) - np.asarray(f(v0.at[i].add(-h)))) / (2 * h)
                   for i in range(len(names))], axis=1)
    assert np.all(np.isfinite(J)) and np.all(np.abs(J[:, [0, 3]]) > 1e-3)  # c_sp, kappa_sp_amp matter
    rel = np.abs(J - fd) / np.maximum(np.abs(fd), 1e-3 * np.abs(fd).max(axis=1, keepdims=True))
    assert rel.max() < 1e-5, rel


@pytest.mark.slow
def test_gradient_does_not_unroll_newton():
    """The gradient is that of the root, not of Newton's path: the same from a far seed
    (many iterations) as from the converged point (none), and available at all in reverse
    mode, which JAX refuses for an unrolled while_loop."""
    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)

    def amp(gamma, seed):
        q = p.__class__(delta=0.1, alpha=1.0, beta=1.0, gamma=gamma, omega=1.4)
        r = jg.periodic_orbit(jg.DUFFING, q, seed)
        return jg.rms(jg.sample_orbit(jg.DUFFING, q, r.point).states[:, 0]), r.iterations

    far = jnp.array([1.6, 0.3])
    vg = jax.jit(jax.value_and_grad(amp, has_aux=True))
    (_, it_far), g_far = vg(0.3, far)
    point = jg.periodic_orbit(jg.DUFFING, p, far).point
    (_, it_at), g_at = vg(0.3, point)
    assert int(it_far) >= 4 and int(it_at) == 0
    assert abs(float(g_far) - float(g_at)) <= 1e-10 * abs(float(g_at))
    # a Newton loop cannot be reverse-differentiated: differentiating through one raises
    def unrolled(gamma):
        q = p.__class__(delta=0.1, alpha=1.0, beta=1.0, gamma=gamma, omega=1.4)
        G = lambda z: jg.RK4().flow(jg.DUFFING, q, z, 0.0, 1) - z
        step = lambda c: (c[0] + 1, c[1] - jnp.linalg.solve(jax.jacfwd(G)(c[1]), G(c[1])))
        return jnp.sum(jax.lax.while_loop(lambda c: c[0] < 40, step, (0, far))[1])

    with pytest.raises(ValueError, match="while_loop"):
        jax.grad(unrolled)(0.3)


# --------------------------------------------------------------------------- known optimum
class TwoSource(NamedTuple):
    psi: float  # phase of the second source [rad]
    a2: float  # amplitude of the second source
    c: float  # damping


W, K1, K2, A1 = 0.8, 1.0, 0.5, 1.0


def _two_source_field(t, x, p):
    x1, v1, x2, v2 = x[0], x[1], x[2], x[3]
    return jnp.stack([v1, -p.c * v1 - (K1 + K2) * x1 + K2 * x2 + A1 * jnp.cos(W * t),
                      v2, -p.c * v2 - K2 * (x2 - x1) + p.a2 * jnp.cos(W * t + p.psi)])


TWO_SOURCE = jg.ForcedSystem(_two_source_field, lambda p: 2 * jnp.pi / W, ("x1", "v1", "x2", "v2"),
                             name="two-source")


def _closed_form(c):
    """Receptances H = K(w)^-1 of the 2-DOF chain; x1 = Re((H11 A1 + H12 a2 e^{i psi}) e^{iwt})."""
    K = np.array([[K1 + K2 - W * W + 1j * W * c, -K2], [-K2, K2 - W * W + 1j * W * c]])
    return np.linalg.inv(K)


def test_design_reaches_closed_form_optimum_and_respects_bounds(tmp_path):
    """RMS of x1 of a 2-DOF linear chain forced on both masses, over the relative phase psi:
    |X1| = |H11 A1 + H12 a2 e^{i psi}| is smallest at psi* = arg(-H11 A1 / (H12 a2))."""
    H = _closed_form(0.1)
    p = TwoSource(psi=0.0, a2=0.7, c=0.1)
    psi_star = float(np.angle(-H[0, 0] * A1 / (H[0, 1] * p.a2)))
    rms_min = abs(abs(H[0, 0]) * A1 - abs(H[0, 1]) * p.a2) / np.sqrt(2)
    traces = []

    def obj(q, o):
        traces.append(1)  # a Python side effect: runs only while the step is traced
        return jg.rms(o.states[:, 0])

    r = jg.design(TWO_SOURCE, p, np.zeros(4), obj, free={"psi": (-np.pi, np.pi)}, steps=300, progress=False)
    n_traces = len(traces)
    assert r.status == "converged", r.table()
    assert abs(r.params.psi - psi_star) < 1e-4
    assert abs(r.objective - rms_min) < 1e-6 * rms_min  # RK4 at 200 steps/period: ~1e-7
    assert np.all(np.diff(r.history["objective"][:4]) < 0)  # it goes downhill from the start
    # psi* outside the bounds: the design ends exactly on the nearer bound (the objective
    # grows monotonically away from psi* on (psi*, psi* + pi))
    lo, hi = psi_star + 0.3, psi_star + 1.2
    rb = jg.design(TWO_SOURCE, p._replace(psi=psi_star + 1.0), np.zeros(4), obj, free={"psi": (lo, hi)},
                   steps=100, progress=False)
    hist = rb.history["psi"]
    assert len(traces) == n_traces  # another start and other bounds (data) compiled nothing new
    assert np.all((hist >= lo) & (hist <= hi))
    assert rb.params.psi == lo and rb.status == "converged"
    # history, table, saved result
    assert set(rb.history) >= {"objective", "psi", "max_multiplier", "grad_norm"}
    assert all(len(v) == rb.n_steps + 1 for v in rb.history.values())
    text = rb.table()
    assert "psi" in text and "(at bound)" in text
    path = rb.save(tmp_path / "design.nc")
    # a user's parameter type is rebuilt from the class the user names, never imported from the file
    assert jg.load(path).params == rb.params._asdict()
    back = jg.load(path, params_type=TwoSource)
    assert back.params == rb.params and isinstance(back.params, TwoSource)
    for key in rb.history:
        np.testing.assert_array_equal(back.history[key], rb.history[key])
    np.testing.assert_array_equal(back.orbit.points, rb.orbit.points)
    np.testing.assert_array_equal(back.orbit.multipliers, rb.orbit.multipliers)
    assert (back.free, back.status, back.settings, back.initial_params) == (rb.free, rb.status, rb.settings,
                                                                             rb.initial_params)
    # the settings are the options object and typed fields; the start is the parameter pytree
    assert back.settings.options == jg.DesignOptions(steps=100) and back.settings.period == 1
    assert back.settings.optimizer == "adam, lr 0.05 cosine decay" and back.settings.integrator == rb.settings.integrator
    assert isinstance(back.initial_params, TwoSource) and back.initial_params == p._replace(psi=psi_star + 1.0)
    import xarray as xr

    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["jaxgear_type"] == "DesignResult" and ds.attrs["system"] == "two-source"
        assert json.loads(ds.attrs["free"]) == {"psi": list(rb.free["psi"])}
        np.testing.assert_array_equal(ds["history__psi"].values, rb.history["psi"])
        assert list(ds["state"].values) == ["x1", "v1", "x2", "v2"]


@pytest.mark.slow
def test_design_of_two_parameters_reaches_the_closed_form_on_a_bound():
    """Two parameters: psi interior, a2 bounded above the cancelling amplitude |H11 A1 / H12|
    = 0.32: a2 ends on its lower bound, psi at psi*(a2) (independent of a2), the RMS at its
    closed form there."""
    H = _closed_form(0.1)
    p = TwoSource(psi=0.0, a2=0.7, c=0.1)
    psi_star = float(np.angle(-H[0, 0] * A1 / (H[0, 1] * p.a2)))
    obj = lambda q, o: jg.rms(o.states[:, 0])
    assert abs(H[0, 0] * A1 / H[0, 1]) < 0.4
    r2 = jg.design(TWO_SOURCE, p, np.zeros(4), obj, free={"psi": (-np.pi, np.pi), "a2": (0.4, 0.9)}, steps=300,
                   progress=False)
    assert r2.params.a2 == 0.4 and abs(r2.params.psi - psi_star) < 1e-4
    rms_04 = abs(abs(H[0, 0]) * A1 - abs(H[0, 1]) * 0.4) / np.sqrt(2)
    assert abs(r2.objective - rms_04) < 1e-6 * rms_04
    assert set(r2.history) >= {"objective", "psi", "a2", "max_multiplier", "grad_norm"}
    assert "a2" in r2.table() and "(at bound)" in r2.table()


# --------------------------------------------------------------------------- tracking limits
def _minus_largest_multiplier(q, o):
    """An objective whose minimum lies where the largest multiplier is largest (one function
    object: the designs of the spur pair below share one compiled step)."""
    return -jg.max_multiplier(q, o)


def test_design_stops_at_the_stability_boundary():
    """Damped Mathieu (spur pair without backlash or forcing) at Omega = 2: pushing kappa up to
    make the trivial orbit's multiplier large with require_stable stops just inside the
    first parametric tongue, whose edge is located here by bisection on the multipliers."""
    p = jg.SpurPairParams(zeta=0.01, kappa=0.01, b=0.0, f_m=0.0, e_amp=0.0, Omega=2.0)
    r = jg.design(jg.SPUR_PAIR, p, np.zeros(2), _minus_largest_multiplier, free={"kappa": (0.0, 0.2)},
                  steps=100, require_stable=True, progress=False)
    assert r.status == "lost stability" and r.orbit.stable

    def mod(kappa):
        q = jg.SpurPairParams(zeta=0.01, kappa=kappa, b=0.0, f_m=0.0, e_amp=0.0, Omega=2.0)
        return float(jnp.max(jnp.abs(jg.floquet_multipliers(jg.SPUR_PAIR, q, jnp.zeros(2)))))

    lo, hi = 0.0, 0.2
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mod(mid) < 1.0 else (lo, mid)
    assert abs(lo - 4 * 0.01) < 2e-3  # first-order theory: kappa_c = 4 zeta
    assert lo - 1e-3 < r.params.kappa < lo
    assert 0.98 < r.orbit.max_multiplier < 1.0


@pytest.mark.slow
def test_design_stops_at_a_fold():
    """Hardening Duffing, small-amplitude orbit, maximise its amplitude over omega: it grows
    toward lower omega until the orbit dies in a fold (jump-up). The design stops there;
    independent shooting finds the small orbit at the final omega and none 0.005 below."""
    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)
    r = jg.design(jg.DUFFING, p, np.array([-0.3353, 0.0763]), lambda q, o: -jg.rms(o.states[:, 0]),
                  free={"omega": (1.0, 2.0)}, steps=100, progress=False)
    assert r.status == "newton failed" and "fold" in r.message
    w = float(r.params.omega)
    assert 1.0 < w < 1.4 and r.improvement > 0.3  # the amplitude grew (objective is -RMS)
    seeds = jg.seeds_in_box(40, [-2, -2], [2, 2], seed=1)

    def small_orbits(omega):
        q = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=omega)
        # a trust-region solver: plain Newton steps overshoot the saddle this close to the fold
        dogleg = optx.Dogleg(rtol=1e-10, atol=1e-12)
        return [o for o in jg.find_periodic_orbits(jg.DUFFING, q, seeds, solver=dogleg).orbits
                if o.points[0, 0] < 0]

    assert len(small_orbits(w)) == 2  # the stable small orbit and the saddle, about to merge
    assert len(small_orbits(w - 0.005)) == 0


# --------------------------------------------------------------------------- input checks
def test_design_input_errors():
    p, x4 = jg.paper_params(), P4_SEED  # refused before any orbit is sought
    obj = lambda q, o: jg.mesh_force_rms(q, o)
    bad = [
        (dict(free={"nope": (0, 1)}), "not a field"),
        (dict(free={"N": (1, 5)}), "static"),
        (dict(free={"c_sp": (0.1, 0.05)}), "high > low"),
        (dict(free={"c_sp": (0.1, 0.2)}), "outside its bounds"),
        (dict(free={"c_sp": 0.1}), "pair"),
        (dict(free={}), "non-empty"),
        (dict(free={"c_sp": (0.0, 0.2)}, period=0), "period"),
    ]
    for kw, match in bad:
        with pytest.raises(ValueError, match=match):
            jg.design(jg.REDUCED, p, x4, obj, **{"period": 4, "steps": 1, "progress": False, **kw})
    with pytest.raises(ValueError, match="no P-1 orbit"):  # free flight: no orbit at the seed
        q = jg.SpurPairParams(zeta=0.0, kappa=0.0, b=100.0, f_m=0.0, e_amp=0.0, Omega=1.0)
        jg.design(jg.SPUR_PAIR, q, np.array([0.0, 0.5]), _minus_largest_multiplier, free={"kappa": (0.0, 0.2)},
                  steps=1, progress=False)
    with pytest.raises(ValueError, match="mesh forces"):
        q = jg.DuffingParams()
        jg.mesh_forces(q, (jnp.zeros(3), jnp.zeros((3, 2))))


@pytest.mark.slow
def test_design_upper_bound_is_exact_and_can_be_left():
    # the 2-DOF chain's response falls with damping here: c ends exactly on its upper bound;
    # started on that bound with the phase far from psi*, psi still moves to psi*
    H = _closed_form(0.3)
    psi_star = float(np.angle(-H[0, 0] * A1 / (H[0, 1] * 0.7)))
    obj = lambda q, o: jg.rms(o.states[:, 0])
    r = jg.design(TWO_SOURCE, TwoSource(psi=0.0, a2=0.7, c=0.3), np.zeros(4), obj,
                  free={"psi": (-np.pi, np.pi), "c": (0.05, 0.3)}, steps=300, progress=False)
    assert float(r.params.c) == 0.3 and abs(float(r.params.psi) - psi_star) < 1e-4
    # the objective pulls c off a lower bound it started on
    r = jg.design(TWO_SOURCE, TwoSource(psi=psi_star, a2=0.7, c=0.05), np.zeros(4), obj,
                  free={"c": (0.05, 0.3)}, steps=5, progress=False)
    assert np.all(np.diff(r.history["c"]) > 0)


def test_mesh_forces_of_identical_planets_are_those_of_the_reduced_model():
    """On the symmetric subspace (every planet moving as the reduced model's one) each
    planet's mesh forces and transmission errors are the reduced model's (model document
    §4); a state of another dimension is refused."""
    p = jg.paper_params(N=3)
    rng = np.random.default_rng(3)
    ts = jnp.asarray(rng.uniform(0, 2 * np.pi / p.Omega, 7))
    xs = jnp.asarray(rng.normal(0, 3, (7, 4)))
    xn = jnp.asarray(jg.reduced_to_nplanet(xs, 3))
    red, npl = jg.mesh_forces(p, (ts, xs)), jg.mesh_forces(p, (ts, xn))
    for a, b in ((red.sp, npl.sp), (red.rp, npl.rp)):
        assert np.shape(b) == (7, 3) and np.ptp(np.abs(a)) > 0
        np.testing.assert_allclose(np.asarray(b), np.repeat(np.asarray(a)[:, None], 3, axis=1), rtol=1e-13, atol=1e-13)
    for mesh in ("sp", "rp"):
        a, b = jg.transmission_error(p, (ts, xs), mesh), jg.transmission_error(p, (ts, xn), mesh)
        np.testing.assert_allclose(np.asarray(b), np.repeat(np.asarray(a)[:, None], 3, axis=1), rtol=1e-13, atol=1e-13)
    with pytest.raises(ValueError, match="neither the reduced"):
        jg.mesh_forces(p, (ts, jnp.zeros((7, 6))))
