"""The kink-aware step three ways: compiled CPU kernel = pure-JAX steps = a reference.

The reference below is written separately from the library, lane by lane in plain
Python floats (the model of the model document §4 and §2, its switching functions
``x1 -+ b_sp``, ``X_rp -+ b_rp``, the crossing as the smallest root in ``[0, 1]`` of the
cubic Hermite interpolant of the switching function found by ``numpy.roots``, the
sub-steps on the smooth pieces, one Newton landing on the surface, a second event in
the rest of the step). All three must agree to 1e-12 on random states and parameters
of every built-in model, on states exactly on a switching surface and on steps that
cross two surfaces; and a batch in which every lane crosses in the same step (the
gather's fallback) must give the states of a batch in which one lane does.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear.integrate import KinkAwareRK4
from jaxgear.integrate._kink import DENSE_MAX, kink_step
from jaxgear.integrate._native import native_available

TOL = 1e-12
step = jax.jit(kink_step, static_argnums=(0, 5))  # compiled once per system and shape


# ----------------------------------------------------------------- the reference step
class RefStep:
    """The kink-aware step of one lane, written from its description: subclasses give the
    field's pieces, the switching functions and their rates along a field value."""

    events = 0  # events handled (for the tests' own checks)
    double = 0  # steps with two events

    @staticmethod
    def side(s):
        return 1.0 if s >= 0 else -1.0

    def own(self, t, z):
        """The field itself: the piece of the state's own sides."""
        return self.field(t, z, [self.side(s) for s in self.switching(t, z)])

    def rk4(self, t, y, h, sides, k1=None):
        """RK4 on the piece of ``sides`` (on the field itself for ``None``: the trial step)."""
        f = (lambda tt, z: self.field(tt, z, sides)) if sides is not None else self.own  # noqa: E731
        ax = lambda z, w, k: [a + w * b for a, b in zip(z, k)]  # noqa: E731
        k1 = f(t, y) if k1 is None else k1
        k2 = f(t + h / 2, ax(y, h / 2, k1))
        k3 = f(t + h / 2, ax(y, h / 2, k2))
        k4 = f(t + h, ax(y, h, k3))
        return [a + h / 6 * (b + 2 * (c + d) + e) for a, b, c, d, e in zip(y, k1, k2, k3, k4)], k1

    def crossing(self, t, h, y, y1, k1, sides):
        """(theta, index, flips) of the first crossing in the step y -> y1, or None."""
        S0, S1 = self.switching(t, y), self.switching(t + h, y1)
        crossed = [self.side(b) != sd and math.isfinite(a) and math.isfinite(b) for a, b, sd in zip(S0, S1, sides)]
        if not any(crossed):
            return None
        D0 = self.rate(t, k1)
        D1 = self.rate(t + h, self.own(t + h, y1))
        ths = []
        for i, c in enumerate(crossed):
            if not c:
                ths.append(2.0)
                continue
            s0, s1, d0, d1 = S0[i], S1[i], D0[i] * h, D1[i] * h
            # p(th) = s0 + d0 th + (3 (s1 - s0) - 2 d0 - d1) th^2 + (2 (s0 - s1) + d0 + d1) th^3
            r = np.roots([2 * (s0 - s1) + d0 + d1, 3 * (s1 - s0) - 2 * d0 - d1, d0, s0])
            r = [z.real for z in r if abs(z.imag) < 1e-9 and -1e-12 <= z.real <= 1 + 1e-12]
            ths.append(min(max(min(r), 0.0), 1.0))
        j = int(np.argmin(ths))
        flips = [th <= ths[j] + 1e-12 for th in ths]
        return ths[j], j, flips

    def event(self, t, y, h, y1, k1, sides):
        """Split the step at its first event; returns (tt, ym, hh, y2, k2, sides) or None."""
        c = self.crossing(t, h, y, y1, k1, sides)
        if c is None:
            return None
        self.events += 1
        th, j, flips = c
        h1 = th * h
        ym, _ = self.rk4(t, y, h1, sides, k1)
        F = self.field(t + h1, ym, sides)  # land: one Newton step onto the surface
        rate = self.rate(t + h1, F)[j]
        dt = -self.switching(t + h1, ym)[j] / rate if rate != 0 else 0.0
        if rate != 0 and math.isfinite(dt) and abs(dt) <= 0.25 * abs(h):
            ym = [a + b * dt for a, b in zip(ym, F)]
            h1 += dt
        sides = [-s if f else s for s, f in zip(sides, flips)]
        y2, k2 = self.rk4(t + h1, ym, h - h1, sides)
        return t + h1, ym, h - h1, y2, k2, sides

    def step(self, t, y, h):
        sides = [self.side(s) for s in self.switching(t, y)]
        y1, k1 = self.rk4(t, y, h, None)  # the trial: plain RK4 of the field
        e = self.event(t, y, h, y1, k1, sides)
        if e is None:
            return y1
        tt, ym, hh, y2, k2, sides = e
        e2 = self.event(tt, ym, hh, y2, k2, sides)
        if e2 is None:
            return y2
        self.double += 1
        return e2[3]

    def advance(self, y, t0, h, steps):
        y = list(map(float, y))
        for i in range(steps):
            y = self.step(t0 + i * h, y, h)
        return np.array(y)



class Ref(RefStep):
    """One lane of the reduced (``planets=None``) or N-planet model, sine mesh stiffness."""

    def __init__(self, p, planets=None):
        g = lambda name: float(np.ravel(np.asarray(getattr(p, name)))[0])  # noqa: E731
        self.q = {k: g(k) for k in ("mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean",
                                    "kappa_rp_amp", "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp",
                                    "beta_rp", "gamma_sr", "b_sp", "b_rp", "c_sp", "c_rp", "f_D", "f_L", "Omega")}
        self.N = int(p.N)
        self.planets = planets

    def terms(self, t):
        q, W = self.q, self.q["Omega"]
        ksp = q["kappa_sp_mean"] + q["kappa_sp_amp"] * math.sin(W * t + q["phi_sp"])
        krp = q["kappa_rp_mean"] + q["kappa_rp_amp"] * math.sin(W * t + q["phi_rp"])
        a, b = W * t + q["beta_sp"], W * t + q["beta_rp"] + q["gamma_sr"]
        E = q["e_sp_amp"] * math.sin(a) + q["e_rp_amp"] * math.sin(b)
        dE = q["e_sp_amp"] * W * math.cos(a) + q["e_rp_amp"] * W * math.cos(b)
        dde_sp = -q["e_sp_amp"] * W * W * math.sin(a)
        return ksp, krp, E, dE, dde_sp

    @staticmethod
    def dead(X, b, hi, lo):
        return X - b if hi > 0 else (X + b if lo < 0 else 0.0)

    def gaps(self, x):
        """Sun-planet deflections and the carrier coordinate, velocities."""
        if self.planets is None:
            return [x[0]], [x[1]], x[2], x[3]
        n = self.planets
        return list(x[0:2 * n:2]), list(x[1:2 * n:2]), x[2 * n], x[2 * n + 1]

    def field(self, t, x, sides):
        """The smooth piece on ``sides`` (the field itself where ``sides`` are the state's own)."""
        q = self.q
        ksp, krp, E, dE, dde = self.terms(t)
        X, V, Xc, Vc = self.gaps(x)
        m = len(X)
        gsp = [ksp * self.dead(X[i], q["b_sp"], sides[i], sides[m + i]) + q["c_sp"] * V[i] for i in range(m)]
        grp = [krp * self.dead(Xc - X[i] - E, q["b_rp"], sides[2 * m + i], sides[3 * m + i])
               + q["c_rp"] * (Vc - V[i] - dE) for i in range(m)]
        load1 = q["mu_s"] * q["f_D"] + q["mu_c"] * q["f_L"] - dde
        load2 = q["mu_s"] * q["f_D"] + 2.0 * q["mu_c"] * q["f_L"]
        if self.planets is None:  # identical planets (model document §4)
            N, mu_s, mu_p, mu_c = self.N, q["mu_s"], q["mu_p"], q["mu_c"]
            return [x[1], -(N + mu_p) * gsp[0] + (mu_p - N * mu_c) * grp[0] + load1, x[3],
                    -N * (mu_s + 2 * mu_c) * gsp[0] - 2 * N * mu_c * grp[0] + load2]
        Ssp, Srp = sum(gsp), sum(grp)  # model document §2 in dimensionless form
        out = []
        for i in range(m):
            out += [V[i], load1 - (q["mu_s"] + q["mu_c"]) * Ssp - q["mu_c"] * Srp - q["mu_p"] * (gsp[i] - grp[i])]
        return out + [Vc, load2 - (q["mu_s"] + 2 * q["mu_c"]) * Ssp - 2 * q["mu_c"] * Srp]

    def switching(self, t, x):
        q = self.q
        E = self.terms(t)[2]
        X, _, Xc, _ = self.gaps(x)
        Xr = [Xc - a - E for a in X]
        return ([a - q["b_sp"] for a in X] + [a + q["b_sp"] for a in X] + [a - q["b_rp"] for a in Xr]
                + [a + q["b_rp"] for a in Xr])

    def rate(self, t, f):
        """ds/dt along the field values ``f``."""
        dE = self.terms(t)[3]
        X, _, Xc, _ = self.gaps(f)
        r = [Xc - a - dE for a in X]
        return X + X + r + r


# ----------------------------------------------------------------- cases
def random_params(rng):
    p = jg.paper_params()
    return p.replace(
        Omega=rng.uniform(0.5, 1.6), b_sp=rng.choice([0.0, rng.uniform(0.2, 4.0)]), b_rp=rng.uniform(0.0, 4.0),
        kappa_sp_amp=rng.uniform(0.0, 0.4), kappa_rp_amp=rng.uniform(0.0, 0.4), phi_sp=rng.uniform(0, 2 * math.pi),
        phi_rp=rng.uniform(0, 2 * math.pi), e_sp_amp=rng.uniform(0.0, 0.8), e_rp_amp=rng.uniform(0.0, 0.8),
        beta_sp=rng.uniform(0, 2 * math.pi), gamma_sr=rng.uniform(0, 2 * math.pi), c_sp=rng.uniform(0.01, 0.2),
        c_rp=rng.uniform(0.01, 0.2), f_D=rng.uniform(0.0, 1.0))


def reduced_states(rng, n, p, t0):
    """Random states, the first ones exactly on a switching surface (x1 = +-b_sp; X_rp = b_rp
    as exactly as the time terms allow), and lanes fast enough to cross both meshes' gaps."""
    Y = np.stack([rng.uniform(-12, 12, n), rng.uniform(-10, 20, n), rng.uniform(-10, 30, n), rng.uniform(-8, 8, n)])
    Y[0, 0], Y[0, 1] = float(p.b_sp), -float(p.b_sp)  # lanes 0 and 1 on x1 = +-b_sp
    E0 = Ref(p).terms(t0)[2]
    Y[2, 2] = Y[0, 2] + E0 + float(p.b_rp)
    Y[1, 3:8] = rng.uniform(12.0, 24.0, 5) * rng.choice([-1.0, 1.0], 5)  # many crossings per period
    Y[3, 3:8] = -Y[1, 3:8]
    return Y


def rel_diff(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b) / (1.0 + np.abs(b))))


STEPS = 60


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_reduced_model_one_step_pure_jax_equals_reference(seed):
    """Single steps from random states and times, fast lanes included (several crossings
    in one step): the step itself, without any amplification over many steps."""
    rng = np.random.default_rng(seed)
    p = random_params(rng)
    h = 2 * math.pi / float(p.Omega) / STEPS
    ref = Ref(p)
    for t in rng.uniform(0, 10, 10):
        Y = reduced_states(rng, 12, p, float(t))
        out = np.asarray(step(jg.REDUCED, p, float(t), jnp.asarray(Y), h))
        want = np.stack([ref.step(float(t), list(Y[:, j]), h) for j in range(Y.shape[1])], axis=1)
        assert rel_diff(out, want) < TOL
    assert ref.events > 15 and ref.double >= 1  # the cases hold crossings, and steps with two


@pytest.mark.parametrize("seed", [0, 1])
def test_reduced_model_kernel_equals_pure_jax_equals_reference_over_a_period(seed):
    rng = np.random.default_rng(seed)
    p = random_params(rng)
    t0 = float(rng.uniform(0, 10))
    Y = reduced_states(rng, 12, p, t0)
    jax_Y = np.asarray(KinkAwareRK4(STEPS, native=False).advance(jg.REDUCED, p, jnp.asarray(Y), t0, 1))
    ref = Ref(p)
    h = 2 * math.pi / float(p.Omega) / STEPS
    ref_Y = np.stack([ref.advance(Y[:, j], t0, h, STEPS) for j in range(Y.shape[1])], axis=1)
    assert ref.events > 20
    assert rel_diff(jax_Y, ref_Y) < TOL
    if native_available():
        nat_Y = np.asarray(KinkAwareRK4(STEPS).advance(jg.REDUCED, p, jnp.asarray(Y), t0, 1))
        assert rel_diff(nat_Y, ref_Y) < TOL
        assert rel_diff(nat_Y, jax_Y) < TOL


def test_states_on_a_switching_surface_with_zero_backlash():
    """b = 0: both sides of a backlash coincide and every crossing crosses two surfaces."""
    rng = np.random.default_rng(7)
    p = random_params(rng).replace(b_sp=0.0, b_rp=0.0)
    Y = reduced_states(rng, 8, p, 0.0)
    Y[0, 0] = 0.0
    ref = Ref(p)
    h = 2 * math.pi / float(p.Omega) / STEPS
    ref_Y = np.stack([ref.advance(Y[:, j], 0.0, h, STEPS) for j in range(Y.shape[1])], axis=1)
    jax_Y = np.asarray(KinkAwareRK4(STEPS, native=False).advance(jg.REDUCED, p, jnp.asarray(Y), 0.0, 1))
    assert ref.events > 10
    assert rel_diff(jax_Y, ref_Y) < TOL
    if native_available():
        nat_Y = np.asarray(KinkAwareRK4(STEPS).advance(jg.REDUCED, p, jnp.asarray(Y), 0.0, 1))
        assert rel_diff(nat_Y, ref_Y) < TOL


def test_nplanet_model_pure_jax_equals_reference():
    """The N-planet model (no compiled kernel) with planets in different states."""
    rng = np.random.default_rng(3)
    p = random_params(rng)
    N = int(p.N)
    system = jg.nplanet_system(N)
    n = 4
    Y = np.zeros((2 * N + 2, n))
    Y[0:2 * N:2] = rng.uniform(-8, 8, (N, n))
    Y[1:2 * N:2] = rng.uniform(-15, 15, (N, n))
    Y[2 * N] = rng.uniform(-10, 30, n)
    Y[2 * N + 1] = rng.uniform(-8, 8, n)
    Y[0, 0] = float(p.b_sp)  # on a surface
    ref = Ref(p, planets=N)
    steps = 40
    h = 2 * math.pi / float(p.Omega) / steps
    ref_Y = np.stack([ref.advance(Y[:, j], 0.5, h, steps) for j in range(n)], axis=1)
    jax_Y = np.asarray(KinkAwareRK4(steps, native=False).advance(system, p, jnp.asarray(Y), 0.5, 1))
    assert ref.events > 10
    assert rel_diff(jax_Y, ref_Y) < TOL


# ----------------------------------------------------------------- the gathered lanes
@pytest.mark.parametrize("n", [DENSE_MAX + 8, pytest.param(4 * DENSE_MAX, marks=pytest.mark.slow)])
def test_every_lane_crossing_gives_the_states_of_one_lane_crossing(n):
    """Batches larger than ``DENSE_MAX`` gather the lanes with an event in chunks, as many
    as needed: a step in which every lane crosses, one lane, or a tenth of them must give
    lane 0 the same state, the reference's; the quiet lanes the plain step."""
    p = jg.paper_params()
    h = float(2 * math.pi / p.Omega / 200)
    b = float(p.b_sp)
    y0 = np.array([b - 0.01, 3.0, 2.0, 0.0])  # crosses x1 = b_sp within the step
    quiet = np.array([0.0, 0.0, 0.5, 0.0])  # deep in both gaps, slow: no crossing
    all_cross = np.repeat(y0[:, None], n, axis=1)
    all_cross[1] += np.linspace(0.0, 1.0, n)  # different lanes, all crossing
    one_cross = np.repeat(quiet[:, None], n, axis=1)
    one_cross[:, 0] = y0
    some = one_cross.copy()
    some[:, : n // 10] = all_cross[:, : n // 10]
    t = 0.7
    outs = [np.asarray(step(jg.REDUCED, p, t, jnp.asarray(Y), h)) for Y in (all_cross, one_cross, some)]
    ref = Ref(p)
    want = np.array(ref.step(t, list(y0), h))
    assert ref.events == 1
    for out in outs:
        assert rel_diff(out[:, 0], want) < TOL
    assert rel_diff(outs[0][:, : n // 10], outs[2][:, : n // 10]) < TOL
    plain = Ref(p).rk4(t, list(quiet), h, None)[0]
    assert rel_diff(outs[1][:, 1:], np.repeat(np.array(plain)[:, None], n - 1, axis=1)) < TOL


def test_gathered_lanes_with_two_events_equal_the_reference():
    """Every lane of a large batch with one or two events (fast lanes through both gaps),
    in another order than the reference's: each lane as the reference steps it alone."""
    rng = np.random.default_rng(11)
    p = random_params(rng)
    h = 2 * math.pi / float(p.Omega) / STEPS
    t = float(rng.uniform(0, 10))
    base = reduced_states(rng, 12, p, t)
    n = DENSE_MAX + 8
    source = rng.integers(0, 12, n)
    source[5:5 + 12 * 12:12] = np.arange(12)  # every kind of lane, scattered
    out = np.asarray(step(jg.REDUCED, p, t, jnp.asarray(base[:, source]), h))
    ref = Ref(p)
    want = np.stack([ref.step(t, list(base[:, j]), h) for j in range(12)], axis=1)
    assert ref.events >= 3 and ref.double >= 1
    assert rel_diff(out, want[:, source]) < TOL


# ----------------------------------------------------------------- other systems
class SpurRef(RefStep):
    """The single spur pair with backlash (``jaxgear.SPUR_PAIR``'s field) with its two
    switching functions ``x -+ b``."""

    def __init__(self, q):
        self.q = {k: float(getattr(q, k)) for k in ("zeta", "kappa", "b", "f_m", "e_amp", "Omega")}

    def field(self, t, x, sides):
        q = self.q
        k = 1.0 + q["kappa"] * math.sin(q["Omega"] * t)
        d = x[0] - q["b"] if sides[0] > 0 else (x[0] + q["b"] if sides[1] < 0 else 0.0)
        return [x[1], q["f_m"] + q["e_amp"] * q["Omega"] ** 2 * math.sin(q["Omega"] * t) - 2 * q["zeta"] * x[1] - k * d]

    def switching(self, t, x):
        return [x[0] - self.q["b"], x[0] + self.q["b"]]

    def rate(self, t, f):
        return [f[0], f[0]]


def _spur_pieces(t, x, q, sides):
    k = 1.0 + q.kappa * jnp.sin(q.Omega * t)
    d = jnp.where(sides[0] > 0, x[0] - q.b, jnp.where(sides[1] < 0, x[0] + q.b, 0.0))
    return jnp.stack([x[1], q.f_m + q.e_amp * q.Omega**2 * jnp.sin(q.Omega * t) - 2.0 * q.zeta * x[1] - k * d])


SPUR_WITH_SURFACES = jg.ForcedSystem(
    vector_field=jg.SPUR_PAIR.vector_field, period=jg.SPUR_PAIR.period, state_names=("x", "v"),
    section_index=1, name="spur-pair-surfaces",
    switching=lambda t, x, q: jnp.stack([x[0] - q.b, x[0] + q.b]), piece_field=_spur_pieces)


def test_user_system_with_switching_functions_equals_reference():
    """A user system (the spur pair with its backlash surfaces declared) over a period:
    the pure-JAX step as the reference, through contact, gap and back contact."""
    q = jg.SpurPairParams(b=0.5, kappa=0.3, e_amp=0.4, Omega=1.3)
    rng = np.random.default_rng(5)
    Y = np.stack([rng.uniform(-3, 3, 10), rng.uniform(-4, 4, 10)])
    Y[0, 0] = 0.5  # on a surface
    steps = 50
    h = 2 * math.pi / 1.3 / steps
    ref = SpurRef(q)
    want = np.stack([ref.advance(Y[:, j], 0.2, h, steps) for j in range(Y.shape[1])], axis=1)
    out = np.asarray(KinkAwareRK4(steps).advance(SPUR_WITH_SURFACES, q, jnp.asarray(Y), 0.2, 1))
    assert ref.events > 10
    assert rel_diff(out, want) < TOL


@pytest.mark.parametrize("system, params", [(jg.DUFFING, jg.DuffingParams(beta=0.5, gamma=3.0)),
                                            (jg.SPUR_PAIR, jg.SpurPairParams(b=0.5))])
def test_systems_without_switching_functions_take_plain_rk4_steps(system, params):
    """Without declared surfaces the kink-aware integrator is classical RK4 (written here)."""
    assert system.switching is None
    y = np.array([1.5, -0.5])
    steps = 40
    h = float(system.period(params)) / steps
    f = lambda t, z: np.asarray(system.vector_field(t, jnp.asarray(z), params))  # noqa: E731
    z = y.copy()
    for i in range(steps):
        t = 0.3 + i * h
        k1 = f(t, z)
        k2 = f(t + h / 2, z + h / 2 * k1)
        k3 = f(t + h / 2, z + h / 2 * k2)
        k4 = f(t + h, z + h * k3)
        z = z + h / 6 * (k1 + 2 * (k2 + k3) + k4)
    out = np.asarray(KinkAwareRK4(steps, native=False).advance(system, params, jnp.asarray(y[:, None]), 0.3, 1))
    assert rel_diff(out[:, 0], z) < TOL


@pytest.mark.slow  # compiles both derivatives of the gathered step (~35 s on the loaded 2 cores)
def test_gathered_lanes_are_differentiated_as_the_whole_batch_select():
    """Derivatives through the gathered path (forward and reverse mode) are those of the
    same lanes stepped in a small batch (the select path), lane by lane."""
    rng = np.random.default_rng(11)
    p = random_params(rng)
    h = 2 * math.pi / float(p.Omega) / STEPS
    t = float(rng.uniform(0, 10))
    base = jnp.asarray(reduced_states(rng, 12, p, t))
    n = DENSE_MAX + 8
    source = np.arange(n) % 12
    direction = jnp.asarray(rng.normal(size=(4, 12)))
    _, small = jax.jvp(lambda Y: step(jg.REDUCED, p, t, Y, h), (base,), (direction,))
    _, big = jax.jvp(lambda Y: step(jg.REDUCED, p, t, Y, h), (base[:, source],), (direction[:, source],))
    assert rel_diff(big, np.asarray(small)[:, source]) < TOL
    weights = jnp.asarray(rng.normal(size=(4, 12)))
    g_small = jax.grad(lambda Y: jnp.sum(weights * step(jg.REDUCED, p, t, Y, h)))(base)
    g_big = jax.grad(lambda Y: jnp.sum(weights[:, source] * step(jg.REDUCED, p, t, Y, h)))(base[:, source])
    assert rel_diff(g_big, np.asarray(g_small)[:, source]) < TOL
    assert float(jnp.max(jnp.abs(g_small - weights))) > 1e-3  # the step is not the identity


def test_gathered_lanes_with_time_breaks_equal_the_small_batch():
    """The rectangular mesh-stiffness wave jumps at known times (time breaks): a large
    batch's gathered lanes split there as the same lanes in a small batch do, over steps
    that hold a break and crossings (a lane with a break and no crossing is split too)."""
    rng = np.random.default_rng(13)
    p = jg.paper_params().replace(kappa_sp_amp=0.02, kappa_rp_amp=0.02, mesh_shape="rectangular")
    breaks = np.asarray(jg.REDUCED.time_breaks(p))
    T = 2 * math.pi / float(p.Omega)
    h = T / STEPS
    base = jnp.asarray(reduced_states(rng, 12, p, 0.0))
    source = np.arange(DENSE_MAX + 8) % 12
    # a break 0.3 and 0.6 of a step after the step's start, and a step without one
    for t in (float(breaks[0]) * T - 0.3 * h, float(breaks[1]) * T - 0.6 * h, 0.37):
        small = np.asarray(step(jg.REDUCED, p, t, base, h))
        big = np.asarray(step(jg.REDUCED, p, t, base[:, source], h))
        assert rel_diff(big, small[:, source]) < TOL
