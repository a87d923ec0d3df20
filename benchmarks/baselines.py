"""Reference implementations of the paper-grid stroboscopic map, for the benchmark only.

Each computes the same thing as ``jaxgear.stroboscopic_map(jaxgear.REDUCED, params, X,
periods=1)``: the reduced 2-DOF gear model of MODEL.md §4 (paper §4.1) advanced over
whole forcing periods ``T = 2 pi / Omega`` from ``t0``, in float64.

- :func:`numba_blocked` — the strongest hand-written CPU style of
  ``/work/shared/reference/BENCHMARK_NOTES.md``: struct-of-arrays, blocks of cells kept
  in cache for all time steps, time-only coefficients tabulated once per stage time and
  shared by all cells, the inner loop over the cells of a block vectorisable
  (``fastmath``, branch-free backlash), blocks spread over the cores with ``prange``.
- :func:`numba_naive` — a straightforward ``prange`` loop, one cell at a time, with
  ``sin``/``cos`` recomputed at every stage (a weak baseline).
- :func:`scipy_loop` — ``scipy.integrate.solve_ivp`` (RK45) in a Python loop.
- :func:`diffrax_vmap` — an adaptive diffrax solve (Tsit5) vmapped over the cells.

The numba kernels use the same RK4 steps (``steps_per_period`` fixed steps, stage times
``t0 + i h``, ``+ h/2``, ``+ h``) as jaxgear, so they agree with it to round-off.
Only identical planets (scalar per-mesh parameters) are supported.
"""

from __future__ import annotations

import math

import numpy as np

# Order of the scalar constants passed to the numba kernels.
_CONST_NAMES = ("N", "mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean",
                "kappa_rp_amp", "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp",
                "gamma_sr", "b_sp", "b_rp", "c_sp", "c_rp", "f_D", "f_L", "Omega")


def constants(params) -> np.ndarray:
    """The scalar parameters of a uniform :class:`jaxgear.GearParams` as a float64 vector."""
    d = params.to_dict()
    out = []
    for name in _CONST_NAMES:
        a = np.asarray(d[name], dtype=np.float64)
        if a.ndim > 0:
            if not np.all(a == a.ravel()[0]):
                raise ValueError(f"baselines need identical planets; {name}={a} varies per planet.")
            a = a.ravel()[0]
        out.append(float(a))
    return np.array(out)


def stage_table(c: np.ndarray, t0: float, n_steps: int, h: float) -> np.ndarray:
    """Time-only coefficients at every RK4 stage time: ``(n_steps, 3, 5)``.

    Stage ``s`` of step ``i`` is at ``t0 + i h + (0, h/2, h)[s]`` (the same float
    expressions as jaxgear's kernel). Columns: ``k_sp, k_rp, e_sp + e_rp,
    e_sp' + e_rp', load1 = mu_s f_D + mu_c f_L - e_sp''``.
    """
    (N, mu_s, mu_p, mu_c, ksm, ksa, krm, kra, phi_sp, phi_rp, esa, era,
     beta_sp, beta_rp, gamma_sr, b_sp, b_rp, c_sp, c_rp, f_D, f_L, W) = c
    i = np.arange(n_steps, dtype=np.float64)
    t = t0 + i * h
    ts = np.stack([t, t + 0.5 * h, t + h], axis=1)
    a_sp = W * ts + beta_sp
    a_rp = W * ts + beta_rp + gamma_sr
    tab = np.empty((n_steps, 3, 5))
    tab[..., 0] = ksm + ksa * np.sin(W * ts + phi_sp)
    tab[..., 1] = krm + kra * np.sin(W * ts + phi_rp)
    tab[..., 2] = esa * np.sin(a_sp) + era * np.sin(a_rp)
    tab[..., 3] = esa * W * np.cos(a_sp) + era * W * np.cos(a_rp)
    tab[..., 4] = (mu_s * f_D + mu_c * f_L) - (-esa * W * W * np.sin(a_sp))
    return tab


# --------------------------------------------------------------------------- numba
_KERNELS = {}


def _build_kernels():
    if _KERNELS:
        return _KERNELS
    import numba
    from numba import njit, prange

    @njit(inline="always", fastmath=True)
    def _bl(x, b):
        # dead zone, branch-free so the cell loop vectorises
        return max(x - b, 0.0) + min(x + b, 0.0)

    @njit(parallel=True, fastmath=True, cache=False)
    def blocked(Y, tab, c, h, block):
        """RK4 over all steps, block by block; Y (4, n) is updated in place."""
        N, mu_s, mu_p, mu_c = c[0], c[1], c[2], c[3]
        b_sp, b_rp, c_sp, c_rp, f_D, f_L = c[15], c[16], c[17], c[18], c[19], c[20]
        a_sp = -(N + mu_p)
        a_rp = mu_p - N * mu_c
        d_sp = -N * (mu_s + 2.0 * mu_c)
        d_rp = -2.0 * N * mu_c
        load2 = mu_s * f_D + 2.0 * mu_c * f_L
        n = Y.shape[1]
        n_steps = tab.shape[0]
        nb = (n + block - 1) // block
        h2 = 0.5 * h
        h6 = h / 6.0
        for bi in prange(nb):
            lo = bi * block
            m = min(block, n - lo)
            x1 = np.empty(block)
            x2 = np.empty(block)
            x3 = np.empty(block)
            x4 = np.empty(block)
            for j in range(m):
                x1[j] = Y[0, lo + j]
                x2[j] = Y[1, lo + j]
                x3[j] = Y[2, lo + j]
                x4[j] = Y[3, lo + j]
            for i in range(n_steps):
                k0s, k0r, E0, dE0, L0 = tab[i, 0, 0], tab[i, 0, 1], tab[i, 0, 2], tab[i, 0, 3], tab[i, 0, 4]
                k1s, k1r, E1, dE1, L1 = tab[i, 1, 0], tab[i, 1, 1], tab[i, 1, 2], tab[i, 1, 3], tab[i, 1, 4]
                k2s, k2r, E2, dE2, L2 = tab[i, 2, 0], tab[i, 2, 1], tab[i, 2, 2], tab[i, 2, 3], tab[i, 2, 4]
                for j in range(m):
                    y1 = x1[j]
                    y2 = x2[j]
                    y3 = x3[j]
                    y4 = x4[j]
                    # stage 1 at t
                    gs = k0s * _bl(y1, b_sp) + c_sp * y2
                    gr = k0r * _bl(y3 - y1 - E0, b_rp) + c_rp * (y4 - y2 - dE0)
                    p1 = y2
                    v1 = a_sp * gs + a_rp * gr + L0
                    q1 = y4
                    w1 = d_sp * gs + d_rp * gr + load2
                    # stage 2 at t + h/2
                    z1 = y1 + h2 * p1
                    z2 = y2 + h2 * v1
                    z3 = y3 + h2 * q1
                    z4 = y4 + h2 * w1
                    gs = k1s * _bl(z1, b_sp) + c_sp * z2
                    gr = k1r * _bl(z3 - z1 - E1, b_rp) + c_rp * (z4 - z2 - dE1)
                    p2 = z2
                    v2 = a_sp * gs + a_rp * gr + L1
                    q2 = z4
                    w2 = d_sp * gs + d_rp * gr + load2
                    # stage 3 at t + h/2
                    z1 = y1 + h2 * p2
                    z2 = y2 + h2 * v2
                    z3 = y3 + h2 * q2
                    z4 = y4 + h2 * w2
                    gs = k1s * _bl(z1, b_sp) + c_sp * z2
                    gr = k1r * _bl(z3 - z1 - E1, b_rp) + c_rp * (z4 - z2 - dE1)
                    p3 = z2
                    v3 = a_sp * gs + a_rp * gr + L1
                    q3 = z4
                    w3 = d_sp * gs + d_rp * gr + load2
                    # stage 4 at t + h
                    z1 = y1 + h * p3
                    z2 = y2 + h * v3
                    z3 = y3 + h * q3
                    z4 = y4 + h * w3
                    gs = k2s * _bl(z1, b_sp) + c_sp * z2
                    gr = k2r * _bl(z3 - z1 - E2, b_rp) + c_rp * (z4 - z2 - dE2)
                    p4 = z2
                    v4 = a_sp * gs + a_rp * gr + L2
                    q4 = z4
                    w4 = d_sp * gs + d_rp * gr + load2
                    x1[j] = y1 + h6 * (p1 + 2.0 * (p2 + p3) + p4)
                    x2[j] = y2 + h6 * (v1 + 2.0 * (v2 + v3) + v4)
                    x3[j] = y3 + h6 * (q1 + 2.0 * (q2 + q3) + q4)
                    x4[j] = y4 + h6 * (w1 + 2.0 * (w2 + w3) + w4)
            for j in range(m):
                Y[0, lo + j] = x1[j]
                Y[1, lo + j] = x2[j]
                Y[2, lo + j] = x3[j]
                Y[3, lo + j] = x4[j]

    @njit(inline="always")
    def _field(t, y1, y2, y3, y4, c):
        N, mu_s, mu_p, mu_c = c[0], c[1], c[2], c[3]
        ksm, ksa, krm, kra, phi_sp, phi_rp = c[4], c[5], c[6], c[7], c[8], c[9]
        esa, era, beta_sp, beta_rp, gamma_sr = c[10], c[11], c[12], c[13], c[14]
        b_sp, b_rp, c_sp, c_rp, f_D, f_L, W = c[15], c[16], c[17], c[18], c[19], c[20], c[21]
        k_sp = ksm + ksa * math.sin(W * t + phi_sp)
        k_rp = krm + kra * math.sin(W * t + phi_rp)
        a_sp = W * t + beta_sp
        a_rp = W * t + beta_rp + gamma_sr
        s_sp = math.sin(a_sp)
        e = esa * s_sp + era * math.sin(a_rp)
        de = esa * W * math.cos(a_sp) + era * W * math.cos(a_rp)
        X_rp = y3 - y1 - e
        if y1 > b_sp:
            f1 = y1 - b_sp
        elif y1 < -b_sp:
            f1 = y1 + b_sp
        else:
            f1 = 0.0
        if X_rp > b_rp:
            f2 = X_rp - b_rp
        elif X_rp < -b_rp:
            f2 = X_rp + b_rp
        else:
            f2 = 0.0
        gs = k_sp * f1 + c_sp * y2
        gr = k_rp * f2 + c_rp * (y4 - y2 - de)
        dx2 = -(N + mu_p) * gs + (mu_p - N * mu_c) * gr + mu_s * f_D + mu_c * f_L + esa * W * W * s_sp
        dx4 = -N * (mu_s + 2.0 * mu_c) * gs - 2.0 * N * mu_c * gr + mu_s * f_D + 2.0 * mu_c * f_L
        return y2, dx2, y4, dx4

    @njit(parallel=True)
    def naive(Y, c, t0, h, n_steps):
        """One cell at a time, sin/cos recomputed at every stage; Y (4, n) in place."""
        n = Y.shape[1]
        h2 = 0.5 * h
        for j in prange(n):
            y1, y2, y3, y4 = Y[0, j], Y[1, j], Y[2, j], Y[3, j]
            for i in range(n_steps):
                t = t0 + i * h
                a1, a2, a3, a4 = _field(t, y1, y2, y3, y4, c)
                b1, b2, b3, b4 = _field(t + h2, y1 + h2 * a1, y2 + h2 * a2, y3 + h2 * a3, y4 + h2 * a4, c)
                c1, c2, c3, c4 = _field(t + h2, y1 + h2 * b1, y2 + h2 * b2, y3 + h2 * b3, y4 + h2 * b4, c)
                d1, d2, d3, d4 = _field(t + h, y1 + h * c1, y2 + h * c2, y3 + h * c3, y4 + h * c4, c)
                y1 = y1 + (h / 6.0) * (a1 + 2.0 * (b1 + c1) + d1)
                y2 = y2 + (h / 6.0) * (a2 + 2.0 * (b2 + c2) + d2)
                y3 = y3 + (h / 6.0) * (a3 + 2.0 * (b3 + c3) + d3)
                y4 = y4 + (h / 6.0) * (a4 + 2.0 * (b4 + c4) + d4)
            Y[0, j], Y[1, j], Y[2, j], Y[3, j] = y1, y2, y3, y4

    _KERNELS.update(blocked=blocked, naive=naive, numba_version=numba.__version__,
                    threads=numba.get_num_threads())
    return _KERNELS


def numba_blocked(params, X, *, periods=1, t0=0.0, steps_per_period=200, block=512):
    """Blocked, tabulated, vectorised numba RK4: ``X (n, 4) -> (n, 4)``."""
    k = _build_kernels()
    c = constants(params)
    T = 2.0 * math.pi / c[21]
    h = T / steps_per_period
    n_steps = steps_per_period * int(periods)
    tab = stage_table(c, float(t0), n_steps, h)
    Y = np.ascontiguousarray(np.asarray(X, dtype=np.float64).T)
    k["blocked"](Y, tab, c, h, int(block))
    return Y.T


def numba_naive(params, X, *, periods=1, t0=0.0, steps_per_period=200):
    """Per-cell numba ``prange`` RK4, sin/cos at every stage: ``X (n, 4) -> (n, 4)``."""
    k = _build_kernels()
    c = constants(params)
    h = 2.0 * math.pi / c[21] / steps_per_period
    Y = np.ascontiguousarray(np.asarray(X, dtype=np.float64).T)
    k["naive"](Y, c, float(t0), h, steps_per_period * int(periods))
    return Y.T


# --------------------------------------------------------------------------- scipy
def _numpy_field(c):
    (N, mu_s, mu_p, mu_c, ksm, ksa, krm, kra, phi_sp, phi_rp, esa, era,
     beta_sp, beta_rp, gamma_sr, b_sp, b_rp, c_sp, c_rp, f_D, f_L, W) = (float(v) for v in c)

    def bl(x, b):
        return x - b if x > b else (x + b if x < -b else 0.0)

    def f(t, y):
        y1, y2, y3, y4 = y
        k_sp = ksm + ksa * math.sin(W * t + phi_sp)
        k_rp = krm + kra * math.sin(W * t + phi_rp)
        a_sp = W * t + beta_sp
        a_rp = W * t + beta_rp + gamma_sr
        s_sp = math.sin(a_sp)
        e = esa * s_sp + era * math.sin(a_rp)
        de = esa * W * math.cos(a_sp) + era * W * math.cos(a_rp)
        gs = k_sp * bl(y1, b_sp) + c_sp * y2
        gr = k_rp * bl(y3 - y1 - e, b_rp) + c_rp * (y4 - y2 - de)
        dx2 = -(N + mu_p) * gs + (mu_p - N * mu_c) * gr + mu_s * f_D + mu_c * f_L + esa * W * W * s_sp
        dx4 = -N * (mu_s + 2.0 * mu_c) * gs - 2.0 * N * mu_c * gr + mu_s * f_D + 2.0 * mu_c * f_L
        return np.array([y2, dx2, y4, dx4])

    return f


def scipy_loop(params, X, *, periods=1, t0=0.0, rtol=1e-8, atol=1e-8):
    """``solve_ivp`` (RK45) one cell at a time in a Python loop: ``X (n, 4) -> (n, 4)``."""
    from scipy.integrate import solve_ivp

    c = constants(params)
    f = _numpy_field(c)
    t1 = t0 + periods * 2.0 * math.pi / c[21]
    out = np.empty_like(np.asarray(X, dtype=np.float64))
    for j, x in enumerate(np.asarray(X, dtype=np.float64)):
        sol = solve_ivp(f, (t0, t1), x, method="RK45", rtol=rtol, atol=atol)
        out[j] = sol.y[:, -1] if sol.success else np.nan
    return out


# --------------------------------------------------------------------------- diffrax
def make_diffrax_vmap(rtol=1e-8, atol=1e-8, max_steps=100_000):
    """A jitted ``(params, X (n, 4), t0, periods) -> (n, 4)``: Tsit5 + PID, vmapped over cells.

    Written directly against diffrax (not jaxgear's integrators), as a generic JAX
    basin tool would: one ``diffeqsolve`` per state, ``jax.vmap`` over the states.
    """
    import diffrax
    import jax
    import jax.numpy as jnp

    import jaxgear

    term = diffrax.ODETerm(lambda t, y, p: jaxgear.reduced_vector_field(t, y, p))
    solver = diffrax.Tsit5()
    ctrl = diffrax.PIDController(rtol=rtol, atol=atol)

    def one(p, x, t0, t1):
        sol = diffrax.diffeqsolve(term, solver, t0, t1, dt0=(t1 - t0) / 200, y0=x, args=p,
                                  saveat=diffrax.SaveAt(t1=True), stepsize_controller=ctrl,
                                  max_steps=max_steps, throw=False)
        return sol.ys[-1], sol.stats["num_steps"]

    @jax.jit
    def run(p, X, t0, periods):
        t1 = t0 + periods * 2.0 * jnp.pi / p.Omega
        return jax.vmap(one, in_axes=(None, 0, None, None))(p, X, t0, t1)

    return run
