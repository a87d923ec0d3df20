"""The kink-aware integrator against event-located references (model document §8).

References that do not come from jaxgear's steps: scipy's DOP853 at rtol 1e-13,
restarted at every crossing of a switching surface (located by scipy's event finder)
and at every known time break, each smooth piece integrated with its own field; its
monodromy matrix from the variational equations integrated piece by piece (fields
that only kink: the saltation matrix is the identity) or by central differences of
the whole reference flow (fields that jump). The Liouville formula gives the
monodromy determinant of the gear models in closed form.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxgear as jg
from jaxgear.integrate import KinkAwareRK4

RTOL = 1e-13


# ----------------------------------------------------------------------------- an event-located reference
def reference_flow(field, switching, x0, t0, t1, breaks=(), variational=None):
    """Integrate ``x' = field(t, x, sides)`` from ``t0`` to ``t1`` with scipy's DOP853,
    each smooth piece with the field of its own region ``sides`` (the signs of the
    switching functions), restarting at every crossing and at every time in ``breaks``.

    ``variational(t, x, sides) -> df/dx`` also integrates the monodromy matrix (valid for
    fields that are continuous across the surfaces). Returns ``x(t1)`` (and the matrix).
    """
    x = np.asarray(x0, float)
    n = x.size
    sides = np.where(switching(t0, x) >= 0, 1.0, -1.0)
    Phi = np.eye(n)
    cuts = sorted(b for b in breaks if t0 < b < t1) + [t1]
    t = t0
    for stop in cuts:
        while t < stop:
            mid = 0.5 * (t + stop)

            def rhs(tt, z, sides=sides, mid=mid):
                y = z[:n]
                dy = field(tt, y, sides, mid)
                if variational is None:
                    return dy
                J = variational(tt, y, sides, mid)
                return np.concatenate([dy, (J @ z[n:].reshape(n, n)).ravel()])

            events = []
            for i in range(sides.size):
                ev = (lambda tt, z, i=i: switching(tt, z[:n])[i])
                ev.terminal = True
                ev.direction = -sides[i]  # leaving the current side only
                events.append(ev)
            z0 = x if variational is None else np.concatenate([x, Phi.ravel()])
            sol = solve_ivp(rhs, (t, stop), z0, method="DOP853", rtol=RTOL, atol=RTOL, events=events)
            assert sol.success, sol.message
            z = sol.y[:, -1]
            x = z[:n]
            if variational is not None:
                Phi = z[n:].reshape(n, n)
            t = sol.t[-1]
            if sol.status == 1:  # an event: flip the side of the surface crossed
                fired = [i for i, te in enumerate(sol.t_events) if te.size]
                sides = sides.copy()
                sides[fired[0]] = -sides[fired[0]]
    return (x, Phi) if variational is not None else x


def central_difference_jacobian(flow, x0, delta=1e-5):
    x0 = np.asarray(x0, float)
    cols = []
    for j in range(x0.size):
        e = np.zeros_like(x0)
        e[j] = delta * (1.0 + abs(x0[j]))
        cols.append((flow(x0 + e) - flow(x0 - e)) / (2.0 * e[j]))
    return np.stack(cols, axis=1)


def sorted_eigs(M):
    w = np.linalg.eigvals(M)
    return w[np.lexsort((w.imag, w.real))]


# ----------------------------------------------------------------------------- a dead-zone oscillator
# x'' + 2 zeta x' + k dz(x) = F cos(w t), dz(x) = x - b (x > b), 0 (|x| <= b), x + b (x < -b):
# a field that kinks at x = +-b (continuous, its derivative jumps).
ZETA, K, B, F, W = 0.06, 4.0, 0.5, 2.0, 1.3


def _dz_jax(x, b):
    return jnp.where(x > b, x - b, jnp.where(x < -b, x + b, 0.0))


def _dz_piece(x, b, sides):
    """The dead zone's piece on ``sides`` (the signs of ``x - b``, ``x + b``), extended."""
    return jnp.where(sides[0] > 0, x - b, jnp.where(sides[1] < 0, x + b, 0.0))


DEAD_ZONE = jg.ForcedSystem(
    vector_field=lambda t, x, p: jnp.stack([x[1], p["F"] * jnp.cos(W * t) - 2 * ZETA * x[1] - K * _dz_jax(x[0], B)]),
    period=lambda p: 2 * math.pi / W,
    state_names=("x", "v"),
    switching=lambda t, x, p: jnp.stack([x[0] - B, x[0] + B]),
    piece_field=lambda t, x, p, sd: jnp.stack([x[1], p["F"] * jnp.cos(W * t) - 2 * ZETA * x[1] - K * _dz_piece(x[0], B, sd)]),
    name="dead-zone",
)
DZ_PARAMS = {"F": jnp.asarray(F)}


def _dz_field(t, x, sides, mid):
    dz = x[0] - B if sides[0] > 0 else (x[0] + B if sides[1] < 0 else 0.0)
    return np.array([x[1], F * np.cos(W * t) - 2 * ZETA * x[1] - K * dz])


def _dz_jac(t, x, sides, mid):
    k = K if (sides[0] > 0 or sides[1] < 0) else 0.0
    return np.array([[0.0, 1.0], [-k, -2 * ZETA]])


def _dz_switching(t, x):
    return np.array([x[0] - B, x[0] + B])


T_DZ = 2 * math.pi / W


def test_dead_zone_states_fourth_order_multipliers_at_least_third():
    x0 = np.array([1.7, -0.4])
    ref_x, ref_M = reference_flow(_dz_field, _dz_switching, x0, 0.0, 2 * T_DZ, variational=_dz_jac)
    ref_mu = sorted_eigs(ref_M)
    # the orbit crosses both surfaces: a real test of the splits
    ts = np.linspace(0, 2 * T_DZ, 2001)
    xs = solve_ivp(lambda t, z: _dz_field(t, z, np.where(_dz_switching(t, z) >= 0, 1.0, -1.0), 0), (0, 2 * T_DZ),
                   x0, t_eval=ts, rtol=1e-10, atol=1e-10).y[0]
    assert (xs > B).any() and (xs < -B).any() and (np.abs(xs) < B).any()

    state_err, mu_err = [], []
    for n in (40, 80, 160, 320):
        integ = KinkAwareRK4(n, native=False)
        flow = jax.jit(lambda x, integ=integ: integ.flow(DEAD_ZONE, DZ_PARAMS, x, 0.0, 2))
        y = np.asarray(flow(jnp.asarray(x0)))
        M = np.asarray(jax.jacfwd(flow)(jnp.asarray(x0)))
        state_err.append(np.abs(y - ref_x).max())
        mu_err.append(np.abs(sorted_eigs(M) - ref_mu).max())
    s = np.asarray(state_err)
    m = np.asarray(mu_err)
    assert s[-1] > 1e-11 and m[-1] > 1e-11, (s, m)  # still above the reference's own error
    s_ratio, m_ratio = s[:-1] / s[1:], m[:-1] / m[1:]
    print("state errors", s, "ratios", s_ratio, "multiplier errors", m, "ratios", m_ratio)
    assert np.all((s_ratio > 12) & (s_ratio < 22)), s_ratio  # about 16 = 2^4 per halving
    assert np.all(m_ratio >= 8), m_ratio  # third order or better


def test_plain_rk4_is_only_second_order_on_the_same_problem():
    """The check above can fail: without the splits the same steps lose their order."""
    x0 = np.array([1.7, -0.4])
    ref_x = reference_flow(_dz_field, _dz_switching, x0, 0.0, 2 * T_DZ)
    errs = [np.abs(np.asarray(jg.RK4(n).flow(DEAD_ZONE, DZ_PARAMS, jnp.asarray(x0), 0.0, 2)) - ref_x).max()
            for n in (50, 100, 200, 400)]
    r = np.asarray(errs[:-1]) / np.asarray(errs[1:])
    assert np.median(r) < 8, r


# ----------------------------------------------------------------------------- fields that jump
# contact damping: c_c x' acts only while |x| > b, so the acceleration jumps at x = +-b
C_CONTACT = 0.8


def _contact_field_jax(t, x, p):
    contact = (x[0] > B) | (x[0] < -B)
    acc = p["F"] * jnp.cos(W * t) - 2 * ZETA * x[1] - K * _dz_jax(x[0], B) - jnp.where(contact, C_CONTACT * x[1], 0.0)
    return jnp.stack([x[1], acc])


def _contact_piece_jax(t, x, p, sd):
    contact = (sd[0] > 0) | (sd[1] < 0)
    acc = (p["F"] * jnp.cos(W * t) - 2 * ZETA * x[1] - K * _dz_piece(x[0], B, sd)
           - jnp.where(contact, C_CONTACT * x[1], 0.0))
    return jnp.stack([x[1], acc])


CONTACT_DAMPED = jg.ForcedSystem(
    vector_field=_contact_field_jax,
    piece_field=_contact_piece_jax,
    period=lambda p: 2 * math.pi / W,
    state_names=("x", "v"),
    switching=lambda t, x, p: jnp.stack([x[0] - B, x[0] + B]),
    field_jumps=True,
    name="contact-damped",
)


def _contact_field(t, x, sides, mid):
    contact = sides[0] > 0 or sides[1] < 0
    dz = x[0] - B if sides[0] > 0 else (x[0] + B if sides[1] < 0 else 0.0)
    return np.array([x[1], F * np.cos(W * t) - 2 * ZETA * x[1] - K * dz - (C_CONTACT * x[1] if contact else 0.0)])


def test_jumping_field_monodromy_includes_the_saltation():
    x0 = np.array([1.7, -0.4])
    integ = KinkAwareRK4(800, native=False)
    flow = jax.jit(lambda x: integ.flow(CONTACT_DAMPED, DZ_PARAMS, x, 0.0, 1))
    ref = lambda x: reference_flow(_contact_field, _dz_switching, x, 0.0, T_DZ)  # noqa: E731
    np.testing.assert_allclose(np.asarray(flow(jnp.asarray(x0))), ref(x0), atol=1e-9)
    M_ref = central_difference_jacobian(ref, x0)
    M = np.asarray(jax.jacfwd(flow)(jnp.asarray(x0)))
    np.testing.assert_allclose(M, M_ref, atol=1e-6)
    # the saltation is not negligible here: the field's own variational matrix (no
    # saltation, the reference's pieces glued without it) misses by far more
    _, M_glued = reference_flow(
        _contact_field, _dz_switching, x0, 0.0, T_DZ,
        variational=lambda t, x, s, m: np.array(
            [[0.0, 1.0], [-(K if (s[0] > 0 or s[1] < 0) else 0.0), -2 * ZETA - (C_CONTACT if (s[0] > 0 or s[1] < 0) else 0.0)]]))
    assert np.abs(M_glued - M_ref).max() > 1e-3


# a stiffness that jumps at known times (a rectangular wave): k(t) = K (1 + a sq(w t))
A_SQ = 0.4
SQ_BREAKS = (0.15, 0.65)  # phases of the jumps


def _sq(phase):
    return jnp.where((phase >= SQ_BREAKS[0]) & (phase < SQ_BREAKS[1]), 1.0, -1.0)


SQUARE_STIFFNESS = jg.ForcedSystem(
    vector_field=lambda t, x, p: jnp.stack([
        x[1], p["F"] * jnp.cos(W * t) - 2 * ZETA * x[1]
        - K * (1 + A_SQ * _sq(jnp.mod(t / (2 * math.pi / W), 1.0))) * _dz_jax(x[0], B)]),
    period=lambda p: 2 * math.pi / W,
    state_names=("x", "v"),
    switching=lambda t, x, p: jnp.stack([x[0] - B, x[0] + B]),
    time_breaks=lambda p: jnp.asarray(SQ_BREAKS),
    name="square-stiffness",
)


def _sq_field(t, x, sides, mid):
    phase = (mid / T_DZ) % 1.0
    k = K * (1 + A_SQ * (1.0 if SQ_BREAKS[0] <= phase < SQ_BREAKS[1] else -1.0))
    dz = x[0] - B if sides[0] > 0 else (x[0] + B if sides[1] < 0 else 0.0)
    return np.array([x[1], F * np.cos(W * t) - 2 * ZETA * x[1] - k * dz])


def test_known_time_jumps_land_on_step_boundaries():
    x0 = np.array([1.7, -0.4])
    breaks = [T_DZ * (per + b) for per in range(2) for b in SQ_BREAKS]
    ref = lambda x: reference_flow(_sq_field, _dz_switching, x, 0.0, T_DZ, breaks=breaks)  # noqa: E731
    errs = []
    for n in (100, 200, 400):
        integ = KinkAwareRK4(n, native=False)
        errs.append(np.abs(np.asarray(integ.flow(SQUARE_STIFFNESS, DZ_PARAMS, jnp.asarray(x0), 0.0, 1)) - ref(x0)).max())
    r = np.asarray(errs[:-1]) / np.asarray(errs[1:])
    assert np.all(r > 12), (errs, r)  # fourth order although the field jumps mid-step
    integ = KinkAwareRK4(800, native=False)
    flow = jax.jit(lambda x: integ.flow(SQUARE_STIFFNESS, DZ_PARAMS, x, 0.0, 1))
    np.testing.assert_allclose(np.asarray(jax.jacfwd(flow)(jnp.asarray(x0))), central_difference_jacobian(ref, x0),
                               atol=1e-6)


# ----------------------------------------------------------------------------- the paper preset
def _reduced_numpy(p):
    """The reduced model of model document §4 written out again in numpy, piece by piece:
    ``(field(t, x, sides, mid), switching(t, x))`` for :func:`reference_flow`."""
    q = {k: float(np.ravel(np.asarray(getattr(p, k)))[0]) for k in (
        "mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp", "phi_sp",
        "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr", "b_sp", "b_rp", "c_sp", "c_rp",
        "f_D", "f_L", "Omega")}
    N = float(p.N)
    W = q["Omega"]

    def errors(t):
        a, r = W * t + q["beta_sp"], W * t + q["beta_rp"] + q["gamma_sr"]
        e = q["e_sp_amp"] * math.sin(a) + q["e_rp_amp"] * math.sin(r)
        de = q["e_sp_amp"] * W * math.cos(a) + q["e_rp_amp"] * W * math.cos(r)
        dde_sp = -q["e_sp_amp"] * W * W * math.sin(a)
        return e, de, dde_sp

    def piece(X, b, hi, lo):
        return X - b if hi > 0 else (X + b if lo < 0 else 0.0)

    def field(t, x, sides, mid):
        e, de, dde_sp = errors(t)
        k_sp = q["kappa_sp_mean"] + q["kappa_sp_amp"] * math.sin(W * t + q["phi_sp"])
        k_rp = q["kappa_rp_mean"] + q["kappa_rp_amp"] * math.sin(W * t + q["phi_rp"])
        X_rp, V_rp = x[2] - x[0] - e, x[3] - x[1] - de
        g_sp = k_sp * piece(x[0], q["b_sp"], sides[0], sides[1]) + q["c_sp"] * x[1]
        g_rp = k_rp * piece(X_rp, q["b_rp"], sides[2], sides[3]) + q["c_rp"] * V_rp
        a2 = (-(N + q["mu_p"]) * g_sp + (q["mu_p"] - N * q["mu_c"]) * g_rp + q["mu_s"] * q["f_D"]
              + q["mu_c"] * q["f_L"] - dde_sp)
        a4 = (-N * (q["mu_s"] + 2 * q["mu_c"]) * g_sp - 2 * N * q["mu_c"] * g_rp + q["mu_s"] * q["f_D"]
              + 2 * q["mu_c"] * q["f_L"])
        return np.array([x[1], a2, x[3], a4])

    def switching(t, x):
        X_rp = x[2] - x[0] - errors(t)[0]
        return np.array([x[0] - q["b_sp"], x[0] + q["b_sp"], X_rp - q["b_rp"], X_rp + q["b_rp"]])

    return field, switching


def test_paper_preset_states_fourth_order_against_event_located_reference():
    p = jg.paper_params()
    T = 2 * math.pi / float(p.Omega)
    field, switching = _reduced_numpy(p)
    rng = np.random.default_rng(3)
    X0 = np.stack([rng.uniform(-25, 25, 6), rng.uniform(-10, 20, 6), rng.uniform(-10, 50, 6), np.zeros(6)], -1)
    ref = np.stack([reference_flow(field, switching, x, 0.0, T) for x in X0])
    errs = []
    for n in (100, 200, 400, 800):
        Y = jg.KinkAwareRK4(n).advance(jg.REDUCED, p, jnp.asarray(X0.T), 0.0, 1)
        errs.append(np.abs(np.asarray(Y).T - ref).max())
    r = np.asarray(errs[:-1]) / np.asarray(errs[1:])
    assert errs[-1] > 1e-11, errs
    assert np.all((r > 12) & (r < 22)), (errs, r)


# seeds near the preset's P-1 (unstable) and P-4 (stable) orbits; Newton finds them exactly
P1_SEED = np.array([5.579, -0.620, 10.675, -0.254])
P4_SEED = np.array([5.361, -0.190, 8.280, -0.837])


def _orbits(p, seeds, n):
    """The orbits through ``seeds`` as fixed points of ``P^4`` (one batched shooting call:
    one compilation per step count), their points and multipliers (sorted)."""
    r = jg.periodic_orbit(jg.REDUCED, p, seeds, period=4, integrator=jg.KinkAwareRK4(n), tol=1e-12)
    assert np.all(np.asarray(r.status) == int(jg.Status.CONVERGED)), r.status
    mu = np.asarray(r.multipliers)
    return np.asarray(r.point), np.stack([m[np.lexsort((m.imag, -np.abs(m)))] for m in mu]), np.asarray(r.min_period)


@pytest.mark.slow
def test_paper_preset_orbits_converged_at_the_default_steps():
    """Model document §8: halving the default step moves the P-1 and P-4 points and the
    multipliers of ``P^4`` there by less than 1e-6, and the moves shrink at fourth order."""
    p = jg.paper_params()
    n0 = jg.default_integrator().steps_per_period
    seeds = np.stack([P1_SEED, P4_SEED])
    runs = []
    for m in (n0, 2 * n0, 4 * n0):
        runs.append(_orbits(p, seeds, m))
        np.testing.assert_array_equal(runs[-1][2], [1, 4])
        seeds = runs[-1][0]
    for i, k in enumerate((1, 4)):
        dx = [np.abs(a[0][i] - b[0][i]).max() for a, b in zip(runs, runs[1:])]
        dmu = [np.abs(a[1][i] - b[1][i]).max() for a, b in zip(runs, runs[1:])]
        assert dx[0] <= 1e-6 and dmu[0] <= 1e-6, (k, dx, dmu)
        assert 12 < dx[0] / dx[1] < 22 and 12 < dmu[0] / dmu[1] < 22, (k, dx, dmu)


@pytest.mark.parametrize("steps", [pytest.param((200, 400, 800, 3200), marks=pytest.mark.slow, id="ladder"),
                                   pytest.param((200, 400), id="order")])
def test_paper_preset_monodromy_determinant_is_the_liouville_value(steps):
    """det DP^k(x) = exp(trace(df/dx) k T) at any state (Liouville): the trace of the
    reduced field is the constant -(N + mu_p) c_sp - (mu_p - N mu_c) c_rp - 2 N mu_c c_rp,
    and the backlash only kinks (every saltation matrix has determinant 1). The deviation
    falls at fourth order in the step (``order``), to 1e-10 at 3,200 steps (``ladder``)."""
    p = jg.paper_params()
    N, mu_p, mu_c, c_sp, c_rp = (float(np.ravel(np.asarray(v))[0]) for v in (p.N, p.mu_p, p.mu_c, p.c_sp, p.c_rp))
    trace = -(N + mu_p) * c_sp - (mu_p - N * mu_c) * c_rp - 2 * N * mu_c * c_rp
    T = 2 * math.pi / float(p.Omega)
    k = 2
    liouville = math.exp(trace * k * T)
    X = np.stack([P1_SEED, P4_SEED, np.array([-20.0, 5.0, 30.0, 0.0])])
    dev = []
    for n in steps:
        M = np.asarray(jg.monodromy(jg.REDUCED, p, X, period=k, integrator=jg.KinkAwareRK4(n)))
        dev.append(np.abs(np.linalg.det(M) / liouville - 1.0))
    dev = np.asarray(dev)  # (n, state)
    assert np.all((dev[0] / dev[1] > 12) & (dev[0] / dev[1] < 22)), dev
    assert len(steps) == 2 or np.all(dev[-1] <= 1e-10), dev


# ----------------------------------------------------------------------------- typed options
def test_native_option_is_a_bool_and_saved_settings_of_either_form_are_read():
    from jaxgear.integrate import integrator_from_dict

    assert KinkAwareRK4(50).native is True
    for d, native in (({"type": "KinkAwareRK4", "steps_per_period": 50, "backend": "jax"}, False),
                      ({"type": "KinkAwareRK4", "steps_per_period": 50, "backend": "auto"}, True),
                      ({"type": "KinkAwareRK4", "steps_per_period": 50}, True),
                      (KinkAwareRK4(50, max_splits=3, native=False).to_dict(), False)):
        integ = integrator_from_dict(d)
        assert integ.native is native and integ.steps_per_period == 50, d
    assert integrator_from_dict(KinkAwareRK4(50, max_splits=3, native=False).to_dict()).max_splits == 3
    with pytest.raises(ValueError, match="native"):
        KinkAwareRK4(50, native="jax")
    with pytest.raises(ValueError, match="backend"):
        integrator_from_dict({"type": "KinkAwareRK4", "backend": "gpu"})


def test_a_system_names_its_compiled_kernel_with_the_typed_marker():
    from jaxgear._system import ForcedSystem, NativeKernel

    assert jg.REDUCED.native is NativeKernel.REDUCED
    with pytest.raises(ValueError, match="native"):
        ForcedSystem(vector_field=lambda t, x, p: x, period=lambda p: 1.0, state_names=("x",), native="reduced")
