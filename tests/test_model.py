"""Gear models (docs/model.md §2-§4): equations, symmetry, linear limits, JAX transforms.

References: Newton's equations of docs/model.md §2 written in the tests in the physical
coordinates u_s, u_pi, u_c (before elimination), hand-solved linear equilibria and the
closed-form forced response of the linear limit (docs/model.md §4 written out by hand).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import REDUCED, nplanet_system, nplanet_vector_field, reduced_to_nplanet, reduced_vector_field

S3 = nplanet_system(3)


def _rand_states(n, seed=0):
    """States spread over the paper's region D (docs/model.md §5), x4 in [-5, 5]."""
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(-25, 25, n), rng.uniform(-10, 20, n), rng.uniform(-10, 50, n),
                     rng.uniform(-5, 5, n)], -1)


# ----------------------------------------------------------------------------- references
def f_dead(X, b):
    """Paper eq. (3), written out: X - b above b, X + b below -b, 0 inside."""
    X, b = np.broadcast_arrays(np.asarray(X, float), np.asarray(b, float))
    out = np.zeros_like(X)
    out[X > b] = (X - b)[X > b]
    out[X < -b] = (X + b)[X < -b]
    return out


def newton_nplanet(t, x, p):
    """N-planet accelerations from Newton's equations in u_s, u_pi, u_c (docs/model.md §2).

    The rigid-body rotation is free: put u_c = 0 and rebuild u_s, u_pi from the mesh
    deflections, apply the mesh forces of eq. (3), and form X_spi'' = u_s'' - u_pi'' -
    u_c'' - e_spi'' and X_sc'' = u_s'' - 2 u_c''. Dimensionless: u_h'' = mu_h * force.
    """
    N = p.N
    P = lambda name: np.broadcast_to(np.asarray(getattr(p, name), float), (N,))
    W = float(p.Omega)
    X, V = np.asarray(x[0:2 * N:2]), np.asarray(x[1:2 * N:2])
    Xsc, Vsc = x[2 * N], x[2 * N + 1]
    a_sp, a_rp = W * t + P("beta_sp"), W * t + P("beta_rp") + P("gamma_sr")
    e_sp, de_sp, dde_sp = P("e_sp_amp") * np.sin(a_sp), P("e_sp_amp") * W * np.cos(a_sp), -P("e_sp_amp") * W**2 * np.sin(a_sp)
    e_rp, de_rp = P("e_rp_amp") * np.sin(a_rp), P("e_rp_amp") * W * np.cos(a_rp)
    k_sp = P("kappa_sp_mean") + P("kappa_sp_amp") * np.sin(W * t + P("phi_sp"))
    k_rp = P("kappa_rp_mean") + P("kappa_rp_amp") * np.sin(W * t + P("phi_rp"))
    # coordinates (u_c = 0, u_c' = 0): X_sc = u_s - 2 u_c, X_spi = u_s - u_pi - u_c - e_spi
    u_c, du_c = 0.0, 0.0
    u_s, du_s = Xsc + 2 * u_c, Vsc + 2 * du_c
    u_p, du_p = u_s - X - u_c - e_sp, du_s - V - du_c - de_sp
    # ring-planet deflection X_rpi = u_pi - u_c - e_rpi (paper eq. 4, ring fixed)
    X_rp, V_rp = u_p - u_c - e_rp, du_p - du_c - de_rp
    F_sp = k_sp * f_dead(X, P("b_sp")) + P("c_sp") * V
    F_rp = k_rp * f_dead(X_rp, P("b_rp")) + P("c_rp") * V_rp
    dd_us = float(p.mu_s) * (float(p.f_D) - F_sp.sum())
    dd_up = P("mu_p") * (F_sp - F_rp)
    dd_uc = float(p.mu_c) * ((F_sp + F_rp).sum() - float(p.f_L))
    dd_X = dd_us - dd_up - dd_uc - dde_sp
    dd_Xsc = dd_us - 2 * dd_uc
    out = np.empty(2 * N + 2)
    out[0:2 * N:2], out[1:2 * N:2] = V, dd_X
    out[2 * N], out[2 * N + 1] = Vsc, dd_Xsc
    return out


def linear_matrices(p):
    """Reduced model, linear limit (b = 0, constant stiffness), from docs/model.md §4 by hand.

    With q = (x1, x3): q'' + C q' + K q = F0 + forcing(t), where
    x1'' = -(N + mu_p) g_sp + A g_rp + ..., x3'' = -B g_sp - D g_rp + ...,
    A = mu_p - N mu_c, B = N (mu_s + 2 mu_c), D = 2 N mu_c,
    g_sp = k_sp x1 + c_sp x1', g_rp = k_rp (x3 - x1 - e) + c_rp (x3' - x1' - e').
    """
    N = p.N
    mus, mup, muc = float(p.mu_s), float(p.mu_p), float(p.mu_c)
    ksp, krp, csp, crp = float(p.kappa_sp_mean), float(p.kappa_rp_mean), float(p.c_sp), float(p.c_rp)
    A, B, D = mup - N * muc, N * (mus + 2 * muc), 2 * N * muc
    K = np.array([[(N + mup) * ksp + A * krp, -A * krp], [B * ksp - D * krp, D * krp]])
    C = np.array([[(N + mup) * csp + A * crp, -A * crp], [B * csp - D * crp, D * crp]])
    F0 = np.array([mus * float(p.f_D) + muc * float(p.f_L), mus * float(p.f_D) + 2 * muc * float(p.f_L)])
    return K, C, F0, (A, B, D)


def linear_steady_state(p):
    """Closed-form periodic response of the linear limit: ``x(t)`` for an array of times.

    Errors e_sp = Im(E_sp e^{i W t}), e_rp = Im(E_rp e^{i W t}); they force x1 through
    -e_sp'' and both rows through the ring mesh (k_rp e + c_rp e'). The complex
    amplitude is Q = (K - W^2 I + i W C)^{-1} F.
    """
    K, C, F0, (A, B, D) = linear_matrices(p)
    W = float(p.Omega)
    krp, crp = float(p.kappa_rp_mean), float(p.c_rp)
    E_sp = float(p.e_sp_amp) * np.exp(1j * float(p.beta_sp))
    E_rp = float(p.e_rp_amp) * np.exp(1j * (float(p.beta_rp) + float(p.gamma_sr)))
    E = E_sp + E_rp
    F = np.array([-A * (krp + 1j * W * crp) * E + W**2 * E_sp, D * (krp + 1j * W * crp) * E])
    Q = np.linalg.solve(K - W**2 * np.eye(2) + 1j * W * C, F)
    q_static = np.linalg.solve(K, F0)

    def x_of_t(t):
        z = np.exp(1j * W * np.asarray(t, float))[..., None]
        q = q_static + np.imag(Q * z)
        dq = np.imag(1j * W * Q * z)
        return np.stack([q[..., 0], dq[..., 0], q[..., 1], dq[..., 1]], -1)

    return x_of_t


def linear_params(**kw):
    base = dict(b_sp=0.0, b_rp=0.0, kappa_sp_amp=0.0, kappa_rp_amp=0.0, e_sp_amp=0.0, e_rp_amp=0.0)
    base.update(kw)
    return jg.paper_params(**base)


def _vfield(field):
    """The field on a batch of (time, state) pairs, one compiled call."""
    return jax.jit(jax.vmap(field, in_axes=(0, 0, None)))


# ----------------------------------------------------------------------------- equations
def test_backlash_function():
    X = np.array([-9.0, -5.0, -4.999, -1.0, 0.0, 3.0, 5.0, 5.5, 12.0])
    np.testing.assert_array_equal(np.asarray(jg.backlash(jnp.asarray(X), 5.0)), [-4.0, 0, 0, 0, 0, 0, 0, 0.5, 7.0])
    np.testing.assert_array_equal(np.asarray(jg.backlash(jnp.asarray(X), 0.0)), X)
    np.testing.assert_allclose(np.asarray(jg.backlash(jnp.asarray(X), 2.5)), f_dead(X, 2.5), rtol=0, atol=0)


@pytest.mark.parametrize("uniform", [True, False])
def test_nplanet_field_equals_newton_equations(uniform):
    p = jg.paper_params(beta_sp=0.3, beta_rp=-0.2, gamma_sr=0.5, phi_sp=0.4, phi_rp=1.1, b_sp=2.0, b_rp=3.0)
    if not uniform:
        p = p.replace(mu_p=[0.3, 0.38, 0.45], phi_sp=[0.0, 2.1, 4.2], b_rp=[1.0, 3.0, 5.0],
                      kappa_sp_amp=[0.1, 0.3, 0.2], e_rp_amp=[0.5, 1.0, 1.5], c_sp=[0.05, 0.08, 0.1],
                      gamma_sr=[0.0, 0.3, 0.6])
    rng = np.random.default_rng(3)
    ts = rng.uniform(0, 20, 20)
    xs = rng.normal(0, 6, (20, 8)) + np.array([2, 0, 2, 0, 2, 0, 5, 0])
    got = np.asarray(_vfield(nplanet_vector_field)(jnp.asarray(ts), jnp.asarray(xs), p))
    for t, x, g in zip(ts, xs, got):
        np.testing.assert_allclose(g, newton_nplanet(t, x, p), rtol=1e-12, atol=1e-12)


def test_reduced_field_equals_nplanet_field_on_symmetric_states():
    p = jg.paper_params(beta_sp=0.3, beta_rp=-0.2, gamma_sr=0.5, phi_sp=0.4, phi_rp=1.1)
    rng = np.random.default_rng(4)
    for N in (1, 3, 5):
        pN = p.replace(N=N)
        xs, ts = jnp.asarray(_rand_states(20, seed=N)), jnp.asarray(rng.uniform(0, 30, 20))
        fr = np.asarray(_vfield(reduced_vector_field)(ts, xs, pN))
        fn = np.asarray(_vfield(nplanet_vector_field)(ts, reduced_to_nplanet(xs, N), pN))
        # every planet sees the reduced field, the carrier pair is x3, x4
        for i in range(N):
            np.testing.assert_allclose(fn[:, 2 * i:2 * i + 2], fr[:, 0:2], rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(fn[:, 2 * N:], fr[:, 2:4], rtol=1e-13, atol=1e-12)


def test_reduced_to_nplanet_layout_and_systems():
    x = jnp.arange(8.0).reshape(2, 4)
    y = reduced_to_nplanet(x, 3)
    np.testing.assert_array_equal(np.asarray(y), [[0, 1, 0, 1, 0, 1, 2, 3], [4, 5, 4, 5, 4, 5, 6, 7]])
    assert S3.dim == 8 and S3.section_index == 7 and S3.state_names[-2:] == ("X_sc", "V_sc")
    assert REDUCED.dim == 4 and REDUCED.section_index == 3
    with pytest.raises(ValueError, match="N=0"):
        nplanet_system(0)
    np.testing.assert_allclose(float(REDUCED.period(jg.paper_params())), 2 * math.pi / 0.87, rtol=1e-15)


# ----------------------------------------------------------------------------- symmetry
@pytest.fixture(scope="module")
def symmetric_orbits():
    p = jg.paper_params()
    x0 = _rand_states(4, seed=1)
    n = 40
    o_r = np.asarray(jg.stroboscopic_orbit(REDUCED, p, x0, n_points=n))
    o_n = np.asarray(jg.stroboscopic_orbit(S3, p, reduced_to_nplanet(x0, 3), n_points=n))
    return o_r, o_n


def test_nplanet_identical_planets_equal_reduced_model(symmetric_orbits):
    o_r, o_n = symmetric_orbits
    scale = np.abs(o_r).max()
    assert scale > 5  # non-trivial motion, with contact loss (b = 5)
    diff = np.abs(o_n[..., [0, 1, 6, 7]] - o_r).max(axis=(0, 2))  # per period
    assert diff[0] < 1e-12 * scale           # one period: round-off
    assert diff[:5].max() < 1e-11 * scale
    assert diff.max() < 1e-7 * scale          # 40 periods: round-off amplified, still tiny


def test_nplanet_identical_planets_stay_symmetric(symmetric_orbits):
    _, o_n = symmetric_orbits
    for i in (1, 2):
        np.testing.assert_array_equal(o_n[..., 2 * i:2 * i + 2], o_n[..., 0:2])


def test_nplanet_per_planet_phases_break_symmetry():
    # sequentially phased meshes (phi_sp = 0, 2pi/3, 4pi/3): planets no longer move alike
    p = jg.paper_params(phi_sp=[0.0, 2 * math.pi / 3, 4 * math.pi / 3])
    x0 = reduced_to_nplanet(_rand_states(4, seed=1), 3)
    o = np.asarray(jg.stroboscopic_orbit(S3, p, x0, n_points=40))
    spread = np.abs(o[..., 2:4] - o[..., 0:2]).max(axis=(1, 2))
    assert np.all(spread > 0.5)


# ----------------------------------------------------------------------------- linear limits
@pytest.mark.parametrize("f_L_factor", [2.0, 0.0, 1.3])
def test_static_equilibrium_linear_limit(f_L_factor):
    """b = 0, constant stiffness, no errors: the static equilibrium by hand (docs/model.md §4)."""
    f_D = 2.0
    f_L = f_L_factor * f_D
    p = linear_params(f_D=f_D, f_L=f_L, c_sp=1.0, c_rp=1.2)
    N, mus, mup, muc = p.N, float(p.mu_s), float(p.mu_p), float(p.mu_c)
    ksp, krp = float(p.kappa_sp_mean), float(p.kappa_rp_mean)
    # x2' = x4' = 0:
    #   (N + mu_p) g_sp - (mu_p - N mu_c) g_rp = mu_s f_D + mu_c f_L
    #   N (mu_s + 2 mu_c) g_sp + 2 N mu_c g_rp = mu_s f_D + 2 mu_c f_L
    a11, a12, r1 = N + mup, -(mup - N * muc), mus * f_D + muc * f_L
    a21, a22, r2 = N * (mus + 2 * muc), 2 * N * muc, mus * f_D + 2 * muc * f_L
    det = a11 * a22 - a12 * a21
    g_sp = (r1 * a22 - a12 * r2) / det
    g_rp = (a11 * r2 - a21 * r1) / det
    if f_L_factor == 2.0:  # torque balance: both mean mesh forces are f_D / N (docs/model.md §7)
        assert abs(g_sp - f_D / N) < 1e-13 and abs(g_rp - f_D / N) < 1e-13
    x1 = g_sp / ksp                 # g_sp = k_sp x1
    x3 = x1 + g_rp / krp            # g_rp = k_rp (x3 - x1)
    x_eq = np.array([x1, 0.0, x3, 0.0])
    # the field vanishes there at every time
    for t in (0.0, 1.3, 5.0):
        np.testing.assert_allclose(np.asarray(reduced_vector_field(t, jnp.asarray(x_eq), p)), 0.0, atol=1e-13)
    # and a damped motion from rest at the origin settles onto it (slowest decay ~e^-1.8 per period)
    x_end = np.asarray(jg.stroboscopic_map(REDUCED, p, np.zeros(4), periods=25))
    np.testing.assert_allclose(x_end, x_eq, atol=1e-10)
    # the N-planet model has the same equilibrium
    fN = np.asarray(nplanet_vector_field(0.7, reduced_to_nplanet(jnp.asarray(x_eq), N), p))
    np.testing.assert_allclose(fN, 0.0, atol=1e-13)


def test_static_equilibrium_is_not_trivially_satisfied():
    # the equilibrium of one load is not one of another load (the test above can fail)
    p = linear_params(f_D=2.0, f_L=4.0)
    x_wrong = np.array([2.0 / 3 * 1.01, 0.0, 2.0 / 3 + 2.0 / (3 * float(p.kappa_rp_mean)), 0.0])
    assert np.abs(np.asarray(reduced_vector_field(0.0, jnp.asarray(x_wrong), p))).max() > 1e-3


def test_linear_forced_response_closed_form():
    """Harmonic errors only (b = 0, constant stiffness): the periodic response in closed form."""
    p = linear_params(e_sp_amp=1.0, e_rp_amp=0.6, beta_sp=0.3, beta_rp=-0.4, gamma_sr=0.7)
    x_ss = linear_steady_state(p)
    # the response is really forced by both errors (not just the static part)
    amp = np.ptp(x_ss(np.linspace(0, 2 * np.pi / 0.87, 50)), axis=0)
    assert amp[0] > 0.2 and amp[2] > 1.0
    # start on the closed-form orbit at t0 and follow it: the model stays on it
    t0 = 0.37
    ts, xs = jg.sample_trajectory(REDUCED, p, x_ss(t0), periods=2, samples_per_period=20, t0=t0,
                                  integrator=jg.RK4(400))
    np.testing.assert_allclose(np.asarray(xs), x_ss(np.asarray(ts)), atol=2e-8)
    # from rest, heavy damping: converges to the same orbit (stroboscopic map at t0 = 0)
    ph = p.replace(c_sp=1.0, c_rp=1.2)
    x_end = np.asarray(jg.stroboscopic_map(REDUCED, ph, np.zeros(4), periods=25, integrator=jg.RK4(400)))
    np.testing.assert_allclose(x_end, linear_steady_state(ph)(0.0), atol=1e-7)


def test_linear_forced_response_fails_with_wrong_phase():
    # the same comparison with gamma_sr ignored in the reference is far off (the test can fail)
    p = linear_params(e_sp_amp=1.0, e_rp_amp=0.6, gamma_sr=1.5)
    wrong = linear_steady_state(p.replace(gamma_sr=0.0))
    ts, xs = jg.sample_trajectory(REDUCED, p, wrong(0.0), periods=2, samples_per_period=20, integrator=jg.RK4(400))
    assert np.abs(np.asarray(xs) - wrong(np.asarray(ts))).max() > 1e-2


# ----------------------------------------------------------------------------- JAX transforms
def test_jacfwd_reduced_linear_limit_equals_system_matrix():
    p = linear_params(e_sp_amp=1.0, e_rp_amp=0.6, beta_sp=0.3)
    K, C, _, _ = linear_matrices(p)
    J_hand = np.zeros((4, 4))
    J_hand[0, 1] = J_hand[2, 3] = 1.0
    J_hand[1, [0, 2]], J_hand[1, [1, 3]] = -K[0], -C[0]
    J_hand[3, [0, 2]], J_hand[3, [1, 3]] = -K[1], -C[1]
    jac = jax.jit(jax.jacfwd(reduced_vector_field, argnums=1))
    for t, x in zip((0.0, 2.2, 5.1), _rand_states(3, seed=7)):
        np.testing.assert_allclose(np.asarray(jac(t, jnp.asarray(x), p)), J_hand, rtol=1e-13, atol=1e-14)


def test_jacfwd_nplanet_equals_finite_differences():
    p = jg.paper_params(mu_p=[0.3, 0.38, 0.45], phi_sp=[0.0, 2.1, 4.2])
    jac = jax.jit(jax.jacfwd(nplanet_vector_field, argnums=1))
    rng = np.random.default_rng(5)
    x = rng.normal(0, 8, 8)
    t = 1.7
    J = np.asarray(jac(t, jnp.asarray(x), p))
    eps = 1e-6
    J_fd = np.stack([(newton_nplanet(t, x + eps * e, p) - newton_nplanet(t, x - eps * e, p)) / (2 * eps)
                     for e in np.eye(8)], axis=1)
    np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("system, field", [(REDUCED, reduced_vector_field), (S3, nplanet_vector_field)])
def test_jit_and_vmap_agree_with_eager_loop(system, field):
    p = jg.paper_params(beta_sp=0.3)
    X = _rand_states(6, seed=8)
    if system is S3:
        X = np.asarray(reduced_to_nplanet(X, 3)) + np.random.default_rng(0).normal(0, 0.5, (6, 8))
    ts = np.linspace(0, 7, 6)
    loop = np.stack([np.asarray(field(t, jnp.asarray(x), p)) for t, x in zip(ts, X)])
    vm = np.asarray(jax.jit(jax.vmap(field, in_axes=(0, 0, None)))(jnp.asarray(ts), jnp.asarray(X), p))
    np.testing.assert_allclose(vm, loop, rtol=1e-14, atol=1e-13)
    # vmap over parameters (a pytree with a batched leaf)
    Om = jnp.array([0.8, 0.87, 0.95])
    pv = jax.vmap(lambda w: field(1.0, jnp.asarray(X[0]), eqx.tree_at(lambda q: q.Omega, p, w)))(Om)
    for k, w in enumerate(np.asarray(Om)):
        np.testing.assert_allclose(np.asarray(pv[k]), np.asarray(field(1.0, jnp.asarray(X[0]), p.replace(Omega=float(w)))),
                                   rtol=1e-14, atol=1e-13)


# ----------------------------------------------------------------------------- the rectangular stiffness wave
@pytest.mark.parametrize("eps", [1.2, 1.5, 1.96])
def test_rectangular_wave_first_harmonic_is_the_sine(eps):
    """Paper §2.1: the sine stiffness is the first harmonic of the rectangular wave that
    alternates between one and two tooth pairs, in double contact a share eps - 1 of the
    mesh period; the wave has zero mean and two levels."""
    from jaxgear._model import stiffness_wave

    n = 1 << 14
    angle = 2 * math.pi * (np.arange(n) + 0.5) / n + 0.3
    w = np.asarray(stiffness_wave(jnp.asarray(angle), eps, "rectangular"))
    levels = np.unique(np.round(w, 12))
    assert len(levels) == 2
    assert abs(np.mean(np.isclose(w, levels.max())) - (eps - 1)) < 2.0 / n  # duty cycle = eps - 1
    assert abs(w.mean()) < 1e-3  # zero mean (up to the sampling of the two jumps)
    a1 = 2 * np.mean(w * np.sin(angle))
    b1 = 2 * np.mean(w * np.cos(angle))
    assert abs(a1 - 1.0) < 2e-3 and abs(b1) < 2e-3  # first harmonic = sin(angle)
    np.testing.assert_allclose(np.asarray(stiffness_wave(jnp.asarray(angle), eps, "sine")), np.sin(angle))


def test_rectangular_wave_jumps_at_the_declared_time_breaks():
    p = jg.paper_params().replace(mesh_shape="rectangular", kappa_sp_amp=0.05, kappa_rp_amp=0.01,
                                  contact_ratio_sp=1.4, contact_ratio_rp=1.7, phi_sp=0.4, phi_rp=1.1)
    T = float(p.period)
    breaks = np.sort(np.asarray(REDUCED.time_breaks(p))) * T
    assert breaks.size == 4
    k = lambda t: np.asarray(jg._model.mesh_excitation(t, p)[:2])  # noqa: E731
    for tb in breaks:  # a jump at every break ...
        assert np.abs(k(tb + 1e-9) - k(tb - 1e-9)).max() > 1e-3
    for a, b in zip(breaks, np.roll(breaks, -1) + np.r_[0, 0, 0, T]):  # ... and none between them
        ts = np.linspace(a + 1e-9, b - 1e-9, 50)
        ks = np.stack([k(t) for t in ts])
        assert np.ptp(ks, axis=0).max() < 1e-12
    # closed form (paper §2.1): double contact, a fraction d = contact_ratio - 1 of the mesh
    # period, is centred where the sine peaks (Omega t + phi = pi / 2), so each mesh jumps at
    # Omega t + phi = pi / 2 -+ pi d
    Om = float(p.Omega)
    expected = sorted(((math.pi / 2 + s * math.pi * (cr - 1) - phi) / Om) % T
                      for cr, phi in ((1.4, 0.4), (1.7, 1.1)) for s in (-1, 1))
    np.testing.assert_allclose(breaks, expected, rtol=0, atol=1e-12 * T)


def test_gear_set_contact_ratios_from_the_involute_geometry():
    # a textbook value: two 20-tooth standard spur gears, 20 degrees: 1.557
    base = dict(pressure_angle_deg=20.0, module=2e-3, addendum_coef=1.0)
    a = jg.GearSet(z_s=20, z_p=20, z_r=60, **base)
    assert abs(a.derived()["contact_ratio_sp"] - 1.557) < 1e-3
    # a ring with many teeth meshes like a rack: (sqrt(ra_p^2 - rb_p^2) - r_p sin a + ha m / sin a) / p_b
    zp, m, al = 20, 2e-3, math.radians(20.0)
    rp, rb = m * zp / 2, m * zp / 2 * math.cos(al)
    rack = (math.sqrt((rp + m) ** 2 - rb ** 2) - rp * math.sin(al) + m / math.sin(al)) / (math.pi * m * math.cos(al))
    gap = [abs(jg.GearSet(z_s=z, z_p=20, z_r=z + 40, **base).derived()["contact_ratio_rp"] - rack)
           for z in (2000, 20000)]
    assert gap[1] < 5e-4 and 8 < gap[0] / gap[1] < 12, gap  # O(1 / z_r) towards the rack
    # given values win; the dimensionless set carries them and the shape
    c = a.replace(contact_ratio_sp=1.3, mesh_shape="rectangular", k_sp_amp=0.05e9, k_rp_amp=0.05e9)
    p = c.to_params()
    assert float(p.contact_ratio_sp) == 1.3 and p.mesh_shape == "rectangular"
    with pytest.raises(ValueError, match="contact_ratio_sp"):
        a.replace(contact_ratio_sp=2.5)
