"""Reference implementations of the paper-grid stroboscopic map, for the benchmark only.

Each computes the same thing as ``jaxgear.stroboscopic_map(jaxgear.REDUCED, params, X,
periods=1)``: the reduced 2-DOF gear model of docs/model.md §4 (paper §4.1) advanced over
whole forcing periods ``T = 2 pi / Omega`` from ``t0``, in float64.

- :func:`numba_blocked` — the strongest hand-written CPU style of
  the benchmark notes: struct-of-arrays, blocks of cells kept
  in cache for all time steps, time-only coefficients tabulated once per stage time and
  shared by all cells, the inner loop over the cells of a block vectorisable
  (``fastmath``, branch-free backlash), blocks spread over the cores with ``prange``.
- :func:`numba_blocked_kink` — the same style for the *kink-aware* RK4 of jaxgear's
  default integrator (``jaxgear.KinkAwareRK4``): the vectorised trial step of
  :func:`numba_blocked`, a per-lane sign test of the four switching functions, and for
  the few lanes whose step crosses a backlash kink the split of the compiled CPU kernel
  (``jaxgear/integrate/native/gear_kernel.cc``) step for step: Hermite crossing,
  sub-step to it, rest of the step, up to ``max_splits`` events per step. It is the
  baseline of that kernel's algorithm, with the crossing lanes split one by one (the
  kernel gathers them per block and splits them eight at a time).
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


# --------------------------------------------------------------------------- numba, kink-aware
# The kink-aware RK4 of jaxgear.KinkAwareRK4 for the reduced model (sine stiffness), as the
# compiled CPU kernel computes it (jaxgear/integrate/native/gear_kernel.cc), in the style of
# ``blocked``. Per step and block of lanes:
#   1. the trial RK4 step of every lane (vectorised, tabulated time terms), with the sign
#      test of the switching functions s = x1 -+ b_sp, X_rp -+ b_rp at both ends;
#   2. each lane whose step changes a sign: the earliest crossing on the cubic Hermite
#      interpolant of s (values and rates at both ends; safeguarded Newton with early stop),
#      an RK4 sub-step to it, that surface's side flipped, an RK4 step over the rest, and the
#      same once more for a further event (up to ``max_splits`` events). Time terms inside
#      the step come from the step start's tabulated sines and cosines by angle addition
#      (the kernel's ``Clock``/``terms_at``); the terms at a time met twice (a sub-step's end
#      is the next one's start; the step's own start and end are in the table) are reused,
#      which is what the kernel's per-lane ``TermCache`` does.
# The first stage k1 of a split lane's trial step is recomputed there (one field evaluation
# for a few per cent of the lanes), as the kernel does; the values are the same. The split code takes scalars and tuples only: an
# array argument costs numba two atomic reference-count updates per call, which would
# dominate the few hundred flops of a split.
# fastmath: every flag but ``nnan``/``ninf`` (they would drop the finiteness test of the
# switching functions) and ``reassoc`` (not needed to vectorise the lane loop: it has no
# reduction), so the rounding is the kernel's up to FMA contraction.
KINK_FASTMATH = frozenset({"nsz", "arcp", "contract", "afn"})
_KINK_KERNELS = {}
_HERMITE_ITERS = 12
_EPS = 2.220446049250313e-16
_SIMULTANEOUS = 1e-12  # crossings this close (fraction of a step) are one event, as in jaxgear


def _build_kink_kernels(fastmath=KINK_FASTMATH):
    key = fastmath if isinstance(fastmath, bool) else frozenset(fastmath)
    if key in _KINK_KERNELS:
        return _KINK_KERNELS[key]
    from numba import njit, prange

    fm = fastmath if isinstance(fastmath, bool) else set(fastmath)

    @njit(inline="always", fastmath=fm)
    def _bl(x, b):
        return x - b if x >= b else (x + b if x <= -b else 0.0)

    @njit(inline="always", fastmath=fm)
    def _side(s):
        return 1.0 if s >= 0.0 else -1.0

    @njit(inline="always", fastmath=fm)
    def _sgn(v):
        return 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)

    @njit(inline="always", fastmath=fm)
    def _field(q, y, kc):
        # q = (k_sp, k_rp, E, E', load1); kc = (a2sp, a2rp, a4sp, a4rp, load2, b_sp, b_rp, c_sp, c_rp)
        X = y[2] - y[0] - q[2]
        V = y[3] - y[1] - q[3]
        gs = q[0] * _bl(y[0], kc[5]) + kc[7] * y[1]
        gr = q[1] * _bl(X, kc[6]) + kc[8] * V
        return (y[1], kc[0] * gs + kc[1] * gr + q[4], y[3], kc[2] * gs + kc[3] * gr + kc[4])

    @njit(inline="always", fastmath=fm)
    def _axpy(y, w, k):
        return (y[0] + w * k[0], y[1] + w * k[1], y[2] + w * k[2], y[3] + w * k[3])

    @njit(inline="always", fastmath=fm)
    def _small_sincos(x):
        if abs(x) > 0.2:
            return math.sin(x), math.cos(x)
        x2 = x * x
        s = x * (1.0 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880
                                                                                      + x2 * (-1.0 / 39916800))))))
        c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (1.0 / 40320 + x2 * (-1.0 / 3628800
                                                                                             + x2 * (1.0 / 479001600))))))
        return s, c

    @njit(inline="always", fastmath=fm)
    def _terms_at(tc, ck, t):
        # time terms at t from the step start's clock ck = (t_start, sin x 4, cos x 4) of the
        # angles Omega t + (phi_sp, phi_rp, beta_sp, beta_rp + gamma_sr), by angle addition;
        # tc = (Omega, ksm, ksa, krm, kra, esa, era, mu_s f_D + mu_c f_L)
        W = tc[0]
        sx, cx = _small_sincos(W * (t - ck[0]))
        S0 = ck[1] * cx + ck[5] * sx
        S1 = ck[2] * cx + ck[6] * sx
        S2 = ck[3] * cx + ck[7] * sx
        S3 = ck[4] * cx + ck[8] * sx
        C2 = ck[7] * cx - ck[3] * sx
        C3 = ck[8] * cx - ck[4] * sx
        e_sp = tc[5] * S2
        de_sp = tc[5] * W * C2
        dde_sp = -tc[5] * W * W * S2
        return (tc[1] + tc[2] * S0, tc[3] + tc[4] * S1, e_sp + tc[6] * S3, de_sp + tc[6] * W * C3,
                tc[7] - dde_sp)

    @njit(inline="always", fastmath=fm)
    def _terms(tc, ck, h, qa, qb, t):
        # the step's own start ck[0] and end ck[0] + h are tabulated (qa, qb)
        if t == ck[0]:
            return qa
        if t == ck[0] + h:
            return qb
        return _terms_at(tc, ck, t)

    @njit(inline="always", fastmath=fm)
    def _blp(x, b, hi, lo):
        # the branch of the backlash on the sides (hi, lo) of x = b and x = -b, extended
        return x - b if hi > 0 else (x + b if lo < 0 else 0.0)

    @njit(inline="always", fastmath=fm)
    def _field_piece(q, y, kc, sd):
        # the field's smooth piece on the sides sd of the four switching surfaces
        X = y[2] - y[0] - q[2]
        V = y[3] - y[1] - q[3]
        gs = q[0] * _blp(y[0], kc[5], sd[0], sd[1]) + kc[7] * y[1]
        gr = q[1] * _blp(X, kc[6], sd[2], sd[3]) + kc[8] * V
        return (y[1], kc[0] * gs + kc[1] * gr + q[4], y[3], kc[2] * gs + kc[3] * gr + kc[4])

    @njit(inline="always", fastmath=fm)
    def _rk4_lane(kc, tc, ck, H, qa, qb, t, y, h, k1, sd):
        """One RK4 step of one lane from t on the piece sd (first stage k1): (y_new, terms at t + h)."""
        h2 = 0.5 * h
        qm = _terms(tc, ck, H, qa, qb, t + h2)
        b = _field_piece(qm, _axpy(y, h2, k1), kc, sd)
        c = _field_piece(qm, _axpy(y, h2, b), kc, sd)
        q4 = _terms(tc, ck, H, qa, qb, t + h)
        d = _field_piece(q4, _axpy(y, h, c), kc, sd)
        h6 = h / 6.0
        out = (y[0] + h6 * (k1[0] + 2.0 * (b[0] + c[0]) + d[0]), y[1] + h6 * (k1[1] + 2.0 * (b[1] + c[1]) + d[1]),
               y[2] + h6 * (k1[2] + 2.0 * (b[2] + c[2]) + d[2]), y[3] + h6 * (k1[3] + 2.0 * (b[3] + c[3]) + d[3]))
        return out, q4

    @njit(inline="always", fastmath=fm)
    def _switching(kc, E, y):
        X = y[2] - y[0] - E
        return (y[0] - kc[5], y[0] + kc[5], X - kc[6], X + kc[6])

    @njit(inline="always", fastmath=fm)
    def _hp(th, s0, s1, d0, d1):
        t2 = th * th
        t3 = t2 * th
        return (2 * t3 - 3 * t2 + 1) * s0 + (t3 - 2 * t2 + th) * d0 + (-2 * t3 + 3 * t2) * s1 + (t3 - t2) * d1

    @njit(inline="always", fastmath=fm)
    def _hdp(th, s0, s1, d0, d1):
        t2 = th * th
        return (6 * t2 - 6 * th) * s0 + (3 * t2 - 4 * th + 1) * d0 + (-6 * t2 + 6 * th) * s1 + (3 * t2 - 2 * th) * d1

    @njit(fastmath=fm)
    def _hermite_root(s0, s1, d0, d1):
        # root in (0, 1) of the cubic Hermite interpolant, s0 s1 < 0: safeguarded Newton from
        # the secant point, stopped when the correction is at round-off
        denom = s0 - s1
        th = s0 / denom if denom != 0 else 0.5
        if th < 0.0:  # noqa: PLR1730  (std::max/std::min of the kernel: a NaN stays NaN)
            th = 0.0
        if 1.0 < th:  # noqa: PLR1730
            th = 1.0
        lo, hi = 0.0, 1.0
        sg0 = _sgn(s0)
        for _ in range(_HERMITE_ITERS):
            v = _hp(th, s0, s1, d0, d1)
            if _sgn(v) == sg0:
                lo = th
            else:
                hi = th
            d = _hdp(th, s0, s1, d0, d1)
            nt = th - v / (d if d != 0 else 1.0)
            done = v == 0 or (d != 0 and abs(nt - th) <= 4.0 * _EPS)
            if not (nt > lo and nt < hi and d != 0):
                nt = 0.5 * (lo + hi)
            if done:
                break
            th = nt
        d = _hdp(th, s0, s1, d0, d1)
        return th - _hp(th, s0, s1, d0, d1) / (d if d != 0 else 1.0)

    @njit(inline="always", fastmath=fm)
    def _crosses(s0, s1, side):
        return _side(s1) != side and math.isfinite(s1) and math.isfinite(s0)

    @njit(inline="always", fastmath=fm)
    def _root(s0, s1, side, d0, d1, h):
        if not _crosses(s0, s1, side):
            return 2.0
        th = _hermite_root(s0, s1, d0 * h, d1 * h)
        if th < 0.0:  # noqa: PLR1730  (std::max/std::min of the kernel: a NaN stays NaN)
            th = 0.0
        if 1.0 < th:  # noqa: PLR1730
            th = 1.0
        return th

    @njit(fastmath=fm)
    def _first_crossing(kc, qs, qe, h, y1, k1, S0, S1, sd):
        """(theta, which, flips) of the earliest crossing in a step (terms qs, qe at its ends);
        which = -1 for none; flips: the functions crossed at that same instant."""
        none = (False, False, False, False)
        if not (_crosses(S0[0], S1[0], sd[0]) or _crosses(S0[1], S1[1], sd[1])
                or _crosses(S0[2], S1[2], sd[2]) or _crosses(S0[3], S1[3], sd[3])):
            return 1.0, -1, none
        F1 = _field(qe, y1, kc)
        Dx0, Dx1 = k1[0], F1[0]
        DX0, DX1 = k1[2] - k1[0] - qs[3], F1[2] - F1[0] - qe[3]
        t0 = _root(S0[0], S1[0], sd[0], Dx0, Dx1, h)
        t1 = _root(S0[1], S1[1], sd[1], Dx0, Dx1, h)
        t2 = _root(S0[2], S1[2], sd[2], DX0, DX1, h)
        t3 = _root(S0[3], S1[3], sd[3], DX0, DX1, h)
        th_s, j = t0, 0
        if t1 < th_s:
            th_s, j = t1, 1
        if t2 < th_s:
            th_s, j = t2, 2
        if t3 < th_s:
            th_s, j = t3, 3
        if 1.0 < th_s:  # no crossing (the sine shape has no time breaks)
            return 1.0, -1, none
        lim = th_s + _SIMULTANEOUS
        return th_s, j, (t0 <= lim, t1 <= lim, t2 <= lim, t3 <= lim)

    @njit(inline="always", fastmath=fm)
    def _flip(sd, fl):
        return (-sd[0] if fl[0] else sd[0], -sd[1] if fl[1] else sd[1],
                -sd[2] if fl[2] else sd[2], -sd[3] if fl[3] else sd[3])

    @njit(inline="always", fastmath=fm)
    def _land(kc, tc, ck, H, qa, qb, t, Ym, h1, hh, which, sd):
        """Put the end of the sub-step to a crossing on the crossed surface: one Newton
        correction along the piece being left (as jaxgear's kernel does)."""
        if which < 0:
            return Ym, h1
        q = _terms(tc, ck, H, qa, qb, t + h1)
        F = _field_piece(q, Ym, kc, sd)
        S = _switching(kc, q[2], Ym)
        rate = F[0] if which < 2 else F[2] - F[0] - q[3]
        dt = -S[which] / (rate if rate != 0 else 1.0)
        if not (rate != 0 and math.isfinite(dt) and abs(dt) <= 0.25 * abs(hh)):
            return Ym, h1
        return _axpy(Ym, dt, F), h1 + dt

    @njit(fastmath=fm)
    def _split_lane(kc, tc, ck, h, qa, qb, y, y1, k1, max_splits):
        """A lane whose trial step (y -> y1, first stage k1) changes a sign: sub-step to the
        crossing on the lane's piece, land on the surface, flip, the rest on the new piece;
        again for a further event, up to max_splits events."""
        t = ck[0]
        S0 = _switching(kc, qa[2], y)
        S1 = _switching(kc, qb[2], y1)
        sd = (_side(S0[0]), _side(S0[1]), _side(S0[2]), _side(S0[3]))
        th, which, fl = _first_crossing(kc, qa, qb, h, y1, k1, S0, S1, sd)
        tt, hh, Y, K1 = t, h, y, k1
        for it in range(max_splits):
            h1 = th * hh
            Ym, _ = _rk4_lane(kc, tc, ck, h, qa, qb, tt, Y, h1, K1, sd)
            Ym, h1 = _land(kc, tc, ck, h, qa, qb, tt, Ym, h1, hh, which, sd)
            sd = _flip(sd, fl)
            tt = tt + h1
            hh = hh - h1
            Qm = _terms(tc, ck, h, qa, qb, tt)
            K1 = _field_piece(Qm, Ym, kc, sd)
            Y1, Qe = _rk4_lane(kc, tc, ck, h, qa, qb, tt, Ym, hh, K1, sd)
            if it == max_splits - 1:
                return Y1
            S1 = _switching(kc, Qe[2], Y1)
            S0 = _switching(kc, Qm[2], Ym)
            th2, which2, fl2 = _first_crossing(kc, Qm, Qe, hh, Y1, K1, S0, S1, sd)
            more = th2 < 1.0
            if it == max_splits - 2:
                if not more:
                    return Y1
                h2 = th2 * hh
                fin, _ = _rk4_lane(kc, tc, ck, h, qa, qb, tt, Ym, h2, K1, sd)
                fin, h2 = _land(kc, tc, ck, h, qa, qb, tt, fin, h2, hh, which2, sd)
                sd = _flip(sd, fl2)
                Qf = _terms(tc, ck, h, qa, qb, tt + h2)
                out, _ = _rk4_lane(kc, tc, ck, h, qa, qb, tt + h2, fin, hh - h2, _field_piece(Qf, fin, kc, sd), sd)
                return out
            Y = Ym
            th = th2 if more else 1.0
            which = which2 if more else -1
            fl = fl2
        return Y1

    @njit(parallel=True, fastmath=fm)
    def blocked_kink(Y, tab, clock, kc, tc, h, periods, block, max_splits):
        """Kink-aware RK4 over ``periods`` periods of ``tab.shape[0]`` steps, block by block;
        Y (4, n) is updated in place. ``clock[i] = (t_i, sin x 4, cos x 4)`` at step i's start."""
        a2sp, a2rp, a4sp, a4rp, load2, b_sp, b_rp, c_sp, c_rp = kc
        n = Y.shape[1]
        steps = tab.shape[0]
        nb = (n + block - 1) // block
        h2 = 0.5 * h
        h6 = h / 6.0
        for bi in prange(nb):
            lo = bi * block
            m = min(block, n - lo)
            # two state buffers (start, end of the step), used alternately
            xs = np.empty((2, 4, block))
            need = np.zeros(block, np.uint8)
            for j in range(m):
                for r in range(4):
                    xs[0, r, j] = Y[r, lo + j]
            cur = 0
            for _ in range(periods):
                for i in range(steps):
                    x1, x2, x3, x4 = xs[cur, 0], xs[cur, 1], xs[cur, 2], xs[cur, 3]
                    n1, n2, n3, n4 = xs[1 - cur, 0], xs[1 - cur, 1], xs[1 - cur, 2], xs[1 - cur, 3]
                    k0s, k0r, E0, dE0, L0 = tab[i, 0, 0], tab[i, 0, 1], tab[i, 0, 2], tab[i, 0, 3], tab[i, 0, 4]
                    k1s, k1r, E1, dE1, L1 = tab[i, 1, 0], tab[i, 1, 1], tab[i, 1, 2], tab[i, 1, 3], tab[i, 1, 4]
                    k2s, k2r, E2, dE2, L2 = tab[i, 2, 0], tab[i, 2, 1], tab[i, 2, 2], tab[i, 2, 3], tab[i, 2, 4]
                    # 1. the trial step, vectorised over the block, and the sign test
                    for j in range(m):
                        y1 = x1[j]
                        y2 = x2[j]
                        y3 = x3[j]
                        y4 = x4[j]
                        X0 = y3 - y1 - E0
                        gs = k0s * (max(y1 - b_sp, 0.0) + min(y1 + b_sp, 0.0)) + c_sp * y2
                        gr = k0r * (max(X0 - b_rp, 0.0) + min(X0 + b_rp, 0.0)) + c_rp * (y4 - y2 - dE0)
                        p1 = y2
                        v1 = a2sp * gs + a2rp * gr + L0
                        q1 = y4
                        w1 = a4sp * gs + a4rp * gr + load2
                        z1 = y1 + h2 * p1
                        z2 = y2 + h2 * v1
                        z3 = y3 + h2 * q1
                        z4 = y4 + h2 * w1
                        X = z3 - z1 - E1
                        gs = k1s * (max(z1 - b_sp, 0.0) + min(z1 + b_sp, 0.0)) + c_sp * z2
                        gr = k1r * (max(X - b_rp, 0.0) + min(X + b_rp, 0.0)) + c_rp * (z4 - z2 - dE1)
                        p2 = z2
                        v2 = a2sp * gs + a2rp * gr + L1
                        q2 = z4
                        w2 = a4sp * gs + a4rp * gr + load2
                        z1 = y1 + h2 * p2
                        z2 = y2 + h2 * v2
                        z3 = y3 + h2 * q2
                        z4 = y4 + h2 * w2
                        X = z3 - z1 - E1
                        gs = k1s * (max(z1 - b_sp, 0.0) + min(z1 + b_sp, 0.0)) + c_sp * z2
                        gr = k1r * (max(X - b_rp, 0.0) + min(X + b_rp, 0.0)) + c_rp * (z4 - z2 - dE1)
                        p3 = z2
                        v3 = a2sp * gs + a2rp * gr + L1
                        q3 = z4
                        w3 = a4sp * gs + a4rp * gr + load2
                        z1 = y1 + h * p3
                        z2 = y2 + h * v3
                        z3 = y3 + h * q3
                        z4 = y4 + h * w3
                        X = z3 - z1 - E2
                        gs = k2s * (max(z1 - b_sp, 0.0) + min(z1 + b_sp, 0.0)) + c_sp * z2
                        gr = k2r * (max(X - b_rp, 0.0) + min(X + b_rp, 0.0)) + c_rp * (z4 - z2 - dE2)
                        p4 = z2
                        v4 = a2sp * gs + a2rp * gr + L2
                        q4 = z4
                        w4 = a4sp * gs + a4rp * gr + load2
                        # the kernel's accumulation order: ((k1 + 2 k2) + 2 k3) + k4
                        o1 = y1 + h6 * (((p1 + 2.0 * p2) + 2.0 * p3) + p4)
                        o2 = y2 + h6 * (((v1 + 2.0 * v2) + 2.0 * v3) + v4)
                        o3 = y3 + h6 * (((q1 + 2.0 * q2) + 2.0 * q3) + q4)
                        o4 = y4 + h6 * (((w1 + 2.0 * w2) + 2.0 * w3) + w4)
                        n1[j] = o1
                        n2[j] = o2
                        n3[j] = o3
                        n4[j] = o4
                        X1 = o3 - o1 - E2
                        fin = (o1 - o1 == 0.0) & (X1 - X1 == 0.0) & (y1 - y1 == 0.0) & (X0 - X0 == 0.0)
                        cr = (((y1 - b_sp >= 0.0) != (o1 - b_sp >= 0.0)) | ((y1 + b_sp >= 0.0) != (o1 + b_sp >= 0.0))
                              | ((X0 - b_rp >= 0.0) != (X1 - b_rp >= 0.0)) | ((X0 + b_rp >= 0.0) != (X1 + b_rp >= 0.0)))
                        need[j] = cr & fin
                    # 2. the few lanes with a crossing: split one by one
                    ck = (clock[i, 0], clock[i, 1], clock[i, 2], clock[i, 3], clock[i, 4],
                          clock[i, 5], clock[i, 6], clock[i, 7], clock[i, 8])
                    qa = (k0s, k0r, E0, dE0, L0)
                    qb = (k2s, k2r, E2, dE2, L2)
                    for j in range(m):
                        if need[j] == 0:
                            continue
                        y = (x1[j], x2[j], x3[j], x4[j])
                        o = _split_lane(kc, tc, ck, h, qa, qb, y, (n1[j], n2[j], n3[j], n4[j]), _field(qa, y, kc),
                                        max_splits)
                        n1[j] = o[0]
                        n2[j] = o[1]
                        n3[j] = o[2]
                        n4[j] = o[3]
                    cur = 1 - cur
            for j in range(m):
                for r in range(4):
                    Y[r, lo + j] = xs[cur, r, j]

    _KINK_KERNELS[key] = blocked_kink
    return blocked_kink


def kink_tables(c: np.ndarray, t0: float, steps: int, h: float):
    """What :func:`numba_blocked_kink` tabulates once per call: the stage terms of one period
    ``(steps, 3, 5)`` (:func:`stage_table`) and the clock of every step start
    ``t = t0 + i h``, ``(steps, 9)``: ``t`` and the sines and cosines of the four phase
    angles ``Omega t + phi_sp``, ``Omega t + phi_rp``, ``Omega t + beta_sp``,
    ``Omega t + beta_rp + gamma_sr``."""
    W = c[21]
    t = t0 + np.arange(steps, dtype=np.float64) * h
    ang = np.stack([W * t + c[8], W * t + c[9], W * t + c[12], W * t + c[13] + c[14]], axis=1)
    clock = np.concatenate([t[:, None], np.sin(ang), np.cos(ang)], axis=1)
    return stage_table(c, t0, steps, h), np.ascontiguousarray(clock)


def kink_constants(c: np.ndarray):
    """The state-independent coefficients ``kc`` and the time-term constants ``tc`` of
    :func:`numba_blocked_kink` (the compiled kernel's ``Coef`` and ``terms``)."""
    N, mu_s, mu_p, mu_c = (float(v) for v in c[:4])
    ksm, ksa, krm, kra = (float(v) for v in c[4:8])
    esa, era = float(c[10]), float(c[11])
    b_sp, b_rp, c_sp, c_rp, f_D, f_L, W = (float(v) for v in c[15:22])
    kc = (-(N + mu_p), mu_p - N * mu_c, -N * (mu_s + 2.0 * mu_c), -2.0 * N * mu_c, mu_s * f_D + 2.0 * mu_c * f_L,
          b_sp, b_rp, c_sp, c_rp)
    tc = (W, ksm, ksa, krm, kra, esa, era, mu_s * f_D + mu_c * f_L)
    return kc, tc


def numba_blocked_kink(params, X, *, periods=1, t0=0.0, steps_per_period=200, block=512, max_splits=2):
    """Blocked, tabulated, vectorised numba *kink-aware* RK4: ``X (n, 4) -> (n, 4)``.

    The same map as ``jaxgear.stroboscopic_map(jaxgear.REDUCED, params, X, periods=periods,
    integrator=jaxgear.KinkAwareRK4(steps_per_period, max_splits=max_splits))`` for the
    sine mesh stiffness and identical planets (see the section comment above).
    """
    if getattr(params, "mesh_shape", "sine") != "sine":
        raise ValueError("numba_blocked_kink supports the sine mesh stiffness only.")
    if not 1 <= int(max_splits) <= 3:
        raise ValueError(f"max_splits={max_splits} must be 1, 2 or 3.")
    kern = _build_kink_kernels()
    c = constants(params)
    h = 2.0 * math.pi / c[21] / steps_per_period
    tab, clock = kink_tables(c, float(t0), int(steps_per_period), h)
    kc, tc = kink_constants(c)
    Y = np.ascontiguousarray(np.asarray(X, dtype=np.float64).T)
    kern(Y, tab, clock, kc, tc, h, int(periods), int(block), int(max_splits))
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
