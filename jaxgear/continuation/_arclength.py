"""Continuation of a periodic orbit in one parameter, with Floquet multipliers and bifurcations.

It extends the shooting of paper §4.1 along a parameter. A P-k orbit
is a zero of

    F(x, p) = P^k(x; p) - x,    F: R^dim x R -> R^dim,

where ``P`` is the stroboscopic map (full state, model document §6) and ``p`` one scalar
parameter (any field of the parameter pytree, see :func:`jaxgear._params.with_param`).
The solutions form curves in ``(x, p)``; they are followed by **pseudo-arclength
continuation** (Keller):

- the tangent ``t`` (unit, ``dim + 1``) is the null vector of the augmented Jacobian
  ``J = [D_x P^k - I, d_p P^k]``, which comes from ``jax.jacfwd`` through the
  integrator with respect to ``x`` and ``p`` together;
- predictor ``z + ds t``; corrector: ``optimistix.Newton`` on the bordered system
  ``F(z) = 0, t . (z - z_pred) = 0`` with Jacobian ``[J; t^T]`` (LU). Because the
  parameter is an unknown, folds (where ``p`` turns around) are passed. ``J`` reaches
  the solver through a custom JVP and the last one comes back as its aux, so an
  iteration integrates once and the tangent and multipliers below cost no further
  integration: the same steps as the hand-written loop it replaced, within a few per
  cent of its time (``benchmarks/continuation.py``);
- the step ``ds`` adapts: halved when the corrector fails (or the step turns the
  tangent by more than ``max_angle`` or the corrector moves far from the predictor),
  enlarged after fast convergence, kept in ``[ds_min, ds_max]``.

Along the branch the Floquet multipliers are the eigenvalues of the monodromy
``D_x P^k = J_x + I`` (already at hand) and sign changes of test functions between
consecutive points reveal bifurcations:

- period doubling ``PD``: ``det(D_x P^k + I)`` (a real multiplier through -1);
- saddle-node / fold ``SN``: the parameter component ``t_p`` of the tangent (the
  branch turns; ``det(D_x P^k - I)`` changes sign too);
- branch point ``BP``: ``det(D_x P^k - I)`` changes sign while ``t_p`` does not
  (a multiplier through +1 without a fold: pitchfork or transcritical);
- Neimark-Sacker ``NS``: ``prod_{i<j} (lambda_i lambda_j - 1)`` (the bialternate
  product; a complex pair through ``|lambda| = 1``); sign changes caused by a real
  pair with ``lambda_i lambda_j = 1`` (a neutral saddle) are discarded.

Each is located more precisely than the step by the Illinois (regula falsi) method on
the test function along the segment, every trial point re-converged on the branch.
At a period doubling :func:`switch_branch` starts the P-2k branch from the PD point
displaced along the eigenvector of the multiplier -1.

One compiled kernel (predictor + bordered Newton + tangent + multipliers + test
functions, parameters as array leaves) serves every step of a branch; the loop over
steps is Python (inherent: each step depends on the last) with a progress bar.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import progress_bar
from .._params import get_param, params_to_dict, with_param
from .._status import Status
from .._system import ForcedSystem, check_state_shape, check_system
from .._version import __version__
from ..integrate import AbstractIntegrator, resolve_integrator
from ..shooting import ShootOptions, periodic_orbit, sorted_eigvals
from ..shooting._floquet import check_period
from ._branch import BifurcationPoint, Branch, BranchSettings

__all__ = ["continue_orbit", "switch_branch"]

# Corrector outcomes (a Status).
_OK = int(Status.CONVERGED)
_NOT_CONVERGED = int(Status.NOT_CONVERGED)
_DIVERGED = int(Status.DIVERGED)
# Relative step tolerance of the corrector's Newton (see _bordered_newton): the point it
# returns is within about tol + 1e-8 |z| of the root. With 1e-8 the step test holds as soon as the
# residual test does on the branches of benchmarks/continuation.py (the same iterations
# and points as a residual test alone); with 1e-9 or less it costs one iteration more
# near folds, which the step control reads as slow convergence (48 points instead of 38
# on the Duffing branch).
_STEP_RTOL = 1e-8
# Test-function columns.
_T_PD, _T_TP, _T_DET, _T_NS = 0, 1, 2, 3


class _Step(NamedTuple):
    z: jax.Array  # (dim + 1,) corrected (x, p)
    status: jax.Array  # _OK / _NOT_CONVERGED / _DIVERGED
    iterations: jax.Array
    residual: jax.Array  # ||F|| at z
    jac: jax.Array  # (dim, dim + 1) [D_x P^k - I, d_p P^k]
    tangent: jax.Array  # (dim + 1,) unit, oriented with tref
    multipliers: jax.Array  # (dim,) complex, by decreasing modulus
    pts: jax.Array  # (k, dim)
    tests: jax.Array  # (4,) PD, t_p, det(D_x F), NS


def _map_and_jac(system, params, name, k, t0, integrator, z):
    """``F(z) = P^k(x; p) - x``, its Jacobian ``(dim, dim + 1)`` and the ``k`` points."""

    def G(zz):
        x, p = zz[:-1], zz[-1]
        prm = with_param(params, name, p)
        T = system.period(prm)

        def one(y, j):
            return integrator.flow(system, prm, y, t0 + j * T, 1), y

        xk, pts = jax.lax.scan(one, x, jnp.arange(k, dtype=jnp.float64))  # period index as a time factor
        r = xk - x
        return r, (r, pts)

    J, (F, pts) = jax.jacfwd(G, has_aux=True)(z)
    return F, J, pts


def _ns_test(lam):
    """``Re prod_{i<j} (lambda_i lambda_j - 1)`` (zero when a pair has product 1)."""
    n = lam.shape[0]
    if n < 2:
        return jnp.asarray(1.0)
    i, j = np.triu_indices(n, 1)
    return jnp.real(jnp.prod(lam[i] * lam[j] - 1.0))


def _bordered_newton(evaluate, z_guess, anchor, w, tol, max_iter, max_norm):
    """``optimistix.Newton`` on the bordered system ``F(z) = 0, w . (z - anchor) = 0``.

    ``evaluate(z)`` returns ``F (dim,)``, its Jacobian ``J (dim, dim + 1)`` and the ``k``
    points, from one ``jax.jacfwd`` through the integrator; a custom JVP hands that ``J``
    to Newton (``[J; w^T]``, solved by LU), so an iteration integrates once, and the
    last evaluation (point, ``F``, ``J``) comes back as the solver's aux: the tangent and
    the multipliers are computed from it without a further integration. The border row
    is divided by ``1 + ||anchor||`` (a scaling that leaves the Newton step unchanged).

    Termination (optimistix's Cauchy test): ``||(F, border)|| < tol`` at the evaluated
    point and the Newton step from it below ``tol + _STEP_RTOL |z|``; the evaluated point
    is returned. Returns ``(z, status, iterations, ||F||, J, pts)``, ``iterations`` the
    Newton steps taken before ``z``.
    """
    import lineax as lx  # with optimistix, imported on first use (they add to every `import jaxgear`)
    import optimistix as optx

    scale = 1.0 + jnp.linalg.norm(anchor)

    @jax.custom_jvp
    def bordered(z):
        F, J, pts = evaluate(z)
        return jnp.concatenate([F, (w @ (z - anchor) / scale)[None]]), (z, F, J, pts)

    @bordered.defjvp
    def _(primals, tangents):
        (z,), (dz,) = primals, tangents
        r, aux = bordered(z)
        dr = jnp.concatenate([aux[2] @ dz, (w @ dz / scale)[None]])
        return (r, aux), (dr, jax.tree.map(jnp.zeros_like, aux))

    solver = optx.Newton(rtol=_STEP_RTOL, atol=tol, norm=optx.two_norm, linear_solver=lx.LU())
    sol = optx.root_find(lambda z, _: bordered(z), solver, z_guess, has_aux=True, max_steps=max_iter + 1,
                         throw=False)
    z, F, J, pts = sol.aux
    rF = jnp.linalg.norm(F)
    finite = jnp.all(jnp.isfinite(z)) & jnp.isfinite(rF) & jnp.all(jnp.isfinite(J))
    conv = (sol.result == optx.RESULTS.successful) & finite & (rF <= tol)
    div = ~finite | (jnp.linalg.norm(z[:-1]) > max_norm)
    st = jnp.where(conv, _OK, jnp.where(div, _DIVERGED, _NOT_CONVERGED))
    return z, st, sol.stats["num_steps"] - 1, rF, J, pts


@eqx.filter_jit
def _correct(newton, system, params, name, k, integrator, t0, z_guess, anchor, w, tref, tol, max_iter, max_norm):
    """Bordered Newton ``F(z) = 0, w . (z - anchor) = 0`` from ``z_guess`` by ``newton``
    (:func:`_bordered_newton`), then the tangent, multipliers and test functions at the
    result (one compiled kernel)."""
    n = z_guess.shape[0] - 1
    eye = jnp.eye(n)
    evaluate = lambda z: _map_and_jac(system, params, name, k, t0, integrator, z)
    z, st, it, rF, J, pts = newton(evaluate, z_guess, anchor, w, tol, max_iter, max_norm)
    ok = st == _OK
    Js = jnp.where(ok, J, 0.0)
    _, _, Vh = jnp.linalg.svd(Js, full_matrices=True)
    t = Vh[-1]
    sgn = jnp.sign(t @ tref)
    t = t * jnp.where(sgn == 0, 1.0, sgn)
    M = Js[:, :n] + eye
    lam = sorted_eigvals(M)
    tests = jnp.stack([jnp.linalg.det(M + eye), t[-1], jnp.linalg.det(Js[:, :n]), _ns_test(lam)])
    nan = jnp.nan
    return _Step(z=z, status=st, iterations=it, residual=rF, jac=J, tangent=jnp.where(ok, t, nan),
                 multipliers=jnp.where(ok, lam, nan), pts=pts, tests=jnp.where(ok, tests, nan))


class _Ctx(NamedTuple):
    """Everything fixed along one branch (the kernel's static configuration and tolerances)."""

    system: ForcedSystem
    params: Any
    name: str
    k: int
    integrator: AbstractIntegrator
    t0: float
    tol: float
    max_iter: int
    max_norm: float

    def correct(self, z_guess, anchor, w, tref) -> _Step:
        f64 = lambda a: jnp.asarray(a, jnp.float64)
        # the Newton solver is a static argument: benchmarks/continuation.py swaps in a
        # hand-written reference loop to time against it in the same process
        out = _correct(_bordered_newton, self.system, self.params, self.name, self.k, self.integrator,
                       f64(self.t0), f64(z_guess), f64(anchor), f64(w), f64(tref), self.tol, self.max_iter, self.max_norm)
        return _Step(*[np.asarray(a) for a in jax.device_get(out)])


def _e_p(n):
    e = np.zeros(n + 1)
    e[-1] = 1.0
    return e


# --------------------------------------------------------------------------- location
def _locate(ctx: _Ctx, a: _Step, b: _Step, col: int, locate_tol: float, max_iter: int = 80):
    """Zero of test function ``col`` between branch points ``a`` and ``b`` (Illinois).

    Trial points are ``z_a + s t_a`` corrected on the hyperplane ``t_a . (z - z_a - s t_a) = 0``
    (the same parametrisation as the predictor, so it passes folds); ``s`` in
    ``[0, t_a . (z_b - z_a)]``. Returns ``(step, nonsmooth)`` (``step`` None when no
    trial point converged); ``nonsmooth`` is True when the bracket shrank below
    ``locate_tol`` while the test function stayed away from zero on both sides: it
    jumps across zero (a discontinuity-induced bifurcation, e.g. grazing of a
    backlash boundary) rather than crossing it smoothly.
    """
    za, ta = a.z, a.tangent
    s_lo, s_hi = 0.0, float(ta @ (b.z - za))
    f_lo, f_hi = float(a.tests[col]), float(b.tests[col])
    if not (s_hi > 0) or not (f_lo * f_hi < 0):
        return None, False
    scale = max(abs(f_lo), abs(f_hi))
    true_lo, true_hi = f_lo, f_hi  # actual values at the bracket ends (Illinois halves f_lo / f_hi)
    best = None
    side = 0
    s_prev = None
    for _ in range(max_iter):
        s = (s_lo * f_hi - s_hi * f_lo) / (f_hi - f_lo)
        if not (s_lo < s < s_hi):
            s = 0.5 * (s_lo + s_hi)
        zg = za + s * ta
        out = ctx.correct(zg, zg, ta, ta)
        if out.status != _OK:
            s = 0.5 * (s_lo + s_hi)  # retry at the midpoint once
            zg = za + s * ta
            out = ctx.correct(zg, zg, ta, ta)
            if out.status != _OK:
                return best, False
        f = float(out.tests[col])
        if best is None or abs(f) <= abs(float(best.tests[col])):
            best = out
        if f == 0.0:
            return best, False
        if f * f_lo > 0:
            s_lo, f_lo, true_lo = s, f, f
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            s_hi, f_hi, true_hi = s, f, f
            if side == +1:
                f_lo *= 0.5
            side = +1
        if (s_hi - s_lo) <= locate_tol:
            break
        if s_prev is not None and abs(s - s_prev) <= 0.1 * locate_tol and abs(f) <= 1e-6 * scale:
            break
        s_prev = s
    nonsmooth = min(abs(true_lo), abs(true_hi)) > 1e-3 * scale
    return best, nonsmooth


def _detect(ctx: _Ctx, a: _Step, b: _Step, index: int, locate_tol: float) -> list[BifurcationPoint]:
    """Bifurcations between consecutive branch points ``a``, ``b`` (sign changes of test functions)."""
    found = []
    ta, tb = a.tests, b.tests
    changes = lambda c: bool(np.isfinite(ta[c]) and np.isfinite(tb[c]) and ta[c] * tb[c] < 0)
    fold = changes(_T_TP)
    candidates = []
    if changes(_T_PD):
        candidates.append(("PD", _T_PD))
    if fold:
        candidates.append(("SN", _T_TP))
    elif changes(_T_DET):
        candidates.append(("BP", _T_DET))
    if changes(_T_NS):
        candidates.append(("NS", _T_NS))
    for kind, col in candidates:
        p, nonsmooth = _locate(ctx, a, b, col, locate_tol)
        if p is None:  # location failed: report the linear interpolation of the bracket
            w = ta[col] / (ta[col] - tb[col])
            z = a.z + w * (b.z - a.z)
            near = a if abs(w) < 0.5 else b
            lam, orbit = near.multipliers, a.pts + w * (b.pts - a.pts)
            point, val, tv = z[:-1], z[-1], float("nan")
        else:
            lam, point, val, tv, orbit = p.multipliers, p.z[:-1], p.z[-1], float(p.tests[col]), p.pts
        if kind == "NS":
            # a complex pair on the unit circle, not a real pair with product 1 (neutral saddle)
            near = np.abs(np.abs(lam) - 1.0) < 1e-3
            cplx = np.abs(np.imag(lam)) > 1e-6 * np.maximum(1.0, np.abs(lam))
            if not np.any(near & cplx):
                continue
        found.append(BifurcationPoint(kind=kind, param_value=float(val), point=np.array(point, dtype=float),
                                      multipliers=np.array(lam, dtype=complex), index=int(index),
                                      orbit=np.array(orbit, dtype=float), test_value=tv,
                                      nonsmooth=bool(nonsmooth)))
    return found


# --------------------------------------------------------------------------- driver
def _validate(system, params, param, stop, period, ds, max_steps, ds_min, ds_max, tol, bounds):
    k = check_period(period)
    p0 = get_param(params, param)  # ValueError for an unknown name
    if stop is not None and not math.isfinite(float(stop)):
        raise ValueError(f"stop={stop} must be a finite value of {param}.")
    if not (ds > 0 and math.isfinite(ds)):
        raise ValueError(f"ds={ds} must be a positive step (arclength in (x, {param})).")
    if isinstance(max_steps, bool) or int(max_steps) < 1:
        raise ValueError(f"max_steps={max_steps} must be an integer >= 1.")
    ds_min = ds * 1e-4 if ds_min is None else float(ds_min)
    ds_max = ds * 10.0 if ds_max is None else float(ds_max)
    if not (0 < ds_min <= ds <= ds_max):
        raise ValueError(f"need 0 < ds_min <= ds <= ds_max, got ds_min={ds_min}, ds={ds}, ds_max={ds_max}.")
    if not (tol > 0):
        raise ValueError(f"tol={tol} must be > 0.")
    if bounds is not None:
        lo, hi = (float(v) for v in bounds)
        if not lo < hi:
            raise ValueError(f"bounds={bounds} must be (low, high) with low < high.")
        bounds = (lo, hi)
    return k, p0, ds_min, ds_max, bounds


def _run(ctx: _Ctx, first: _Step, *, stop, ds, ds_min, ds_max, max_steps, bounds, max_angle, detect,
         locate_tol, progress, desc, param, settings, params_start):
    """The continuation loop from the converged point ``first`` (tangent oriented already)."""
    n = first.z.shape[0] - 1
    steps = [first]
    bifs: list[BifurcationPoint] = []
    status = "max_steps"
    cur = first
    cos_max = math.cos(max_angle)
    bar = progress_bar(int(max_steps), desc, progress, unit="step")
    try:
        while len(steps) <= max_steps:
            z, t = cur.z, cur.tangent
            zp = z + ds * t
            out = ctx.correct(zp, zp, t, t)
            ok = out.status == _OK
            if ok:
                turn = float(out.tangent @ t)
                far = float(np.linalg.norm(out.z - zp))
                ok = turn >= cos_max and far <= ds
            if not ok:
                if ds <= ds_min * (1 + 1e-12):
                    status = "diverged" if out.status == _DIVERGED else "corrector_failed"
                    break
                ds = max(0.5 * ds, ds_min)
                continue
            final = False
            p_old, p_new = float(z[-1]), float(out.z[-1])
            target = None
            if stop is not None and (p_old - stop) * (p_new - stop) <= 0 and p_new != p_old and p_old != stop:
                target, reason = float(stop), "stop"
            elif bounds is not None and not (bounds[0] <= p_new <= bounds[1]):
                target, reason = (bounds[0] if p_new < bounds[0] else bounds[1]), "bounds"
            if target is not None:
                frac = (target - p_old) / (p_new - p_old)
                zg = z + frac * (out.z - z)
                zg[-1] = target
                fin = ctx.correct(zg, zg, _e_p(n), t)
                if fin.status == _OK:
                    out = fin
                status, final = reason, True
            if detect:
                bifs.extend(_detect(ctx, cur, out, len(steps) - 1, locate_tol))
            steps.append(out)
            cur = out
            bar.update(1)
            bar.set_postfix_str(f"{param}={float(out.z[-1]):.6g} ds={ds:.2g}", refresh=False)
            if final:
                break
            if out.iterations <= 2:
                ds = min(1.5 * ds, ds_max)
            elif out.iterations >= 5:
                ds = max(0.7 * ds, ds_min)
    finally:
        bar.close()
    Z = np.array([s.z for s in steps])
    m = len(steps)
    pts = np.array([s.pts for s in steps])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(Z, axis=0), axis=1))])
    lam = np.array([s.multipliers for s in steps])
    return Branch(
        param=param, values=Z[:, -1].copy(), points=pts.reshape(m, ctx.k, n), multipliers=lam,
        stable=np.all(np.abs(lam) < 1.0, axis=1), residuals=np.array([float(s.residual) for s in steps]),
        tangents=np.array([s.tangent for s in steps]), arclength=arc, status=status, bifurcations=tuple(bifs),
        period=ctx.k, system=ctx.system.name, state_names=tuple(ctx.system.state_names),
        params=params_start, settings=settings, version=__version__,
    )


def _settings(ctx, ds, ds_min, ds_max, max_steps, stop, bounds, max_angle, locate_tol, origin: str = "start",
              amplitude: float | None = None) -> BranchSettings:
    return BranchSettings(ds=float(ds), ds_min=float(ds_min), ds_max=float(ds_max), max_steps=int(max_steps),
                          stop=None if stop is None else float(stop),
                          bounds=None if bounds is None else (float(bounds[0]), float(bounds[1])),
                          max_angle=float(max_angle), tol=float(ctx.tol), max_iter=int(ctx.max_iter),
                          max_norm=float(ctx.max_norm), locate_tol=float(locate_tol), t0=float(ctx.t0),
                          integrator=ctx.integrator, origin=origin, amplitude=None if amplitude is None else float(amplitude))


def continue_orbit(system: ForcedSystem, params, x0, *, param: str, stop: float, period: int = 1,
                   ds: float = 0.01, max_steps: int = 500, integrator: AbstractIntegrator | None = None, progress: bool = True,
                   t0: float = 0.0, ds_min: float | None = None, ds_max: float | None = None,
                   tol: float = 1e-10, max_iter: int = 10, max_norm: float = 1e6,
                   bounds: tuple[float, float] | None = None, max_angle: float = 0.5, detect: bool = True,
                   locate_tol: float = 1e-10) -> Branch:
    """Follow a P-k orbit in the parameter ``param`` by pseudo-arclength continuation.

    Starts by converging the orbit at the parameter's current value in ``params`` with
    :func:`~jaxgear.periodic_orbit` (the library's solver from ``x0``), then follows the curve
    of fixed points of ``P^k`` in ``(x, p)`` until the parameter reaches ``stop`` (the
    last point is placed at ``stop`` exactly), leaves ``bounds``, ``max_steps`` steps are
    taken, or the corrector fails at the smallest step (see :data:`BRANCH_STATUS`).
    Folds are passed (the parameter may turn around on the way to ``stop``). Floquet
    multipliers are computed at every point and period doublings, saddle-nodes, branch
    points and Neimark-Sacker points are detected and located (see the module docs).

    Args:
        system: any :class:`~jaxgear.ForcedSystem`.
        params: its parameter pytree (``GearParams``, ``DuffingParams``, ...).
        x0: ``(dim,)`` a point near the orbit at the starting parameter (phase ``t0``).
        param: the parameter to vary: a field name (for ``GearParams`` a canonical name
            of model document §4, e.g. ``"Omega"``, ``"b_sp"``), or ``"b"`` (``b_sp`` and
            ``b_rp`` together) / ``"kappa_amp"`` (both stiffness amplitudes).
            Per-planet fields are set for all planets.
        stop: the parameter value at which to end; the initial direction is towards it.
        period: ``k``, the orbit is a fixed point of ``P^k`` (forcing periods).
        ds: initial arclength step in ``(x, p)`` (state units and parameter units mixed:
            choose it for the faster-changing of the two).
        max_steps: the most continuation steps (the branch has at most ``max_steps + 1`` points).
        integrator: :class:`~jaxgear.RK4` (default) or :class:`~jaxgear.Adaptive`.
        progress: show a progress bar.
        t0: phase of the stroboscopic section.
        ds_min, ds_max: step bounds (default ``ds / 1e4`` and ``10 ds``).
        tol: corrector tolerance on ``||P^k(x) - x||`` (Newton also stops only when its
            next step is below ``tol + 1e-8 |(x, p)|``).
        max_iter: corrector Newton iterations per step (a step needing more is retried
            with half the step).
        max_norm: a point with ``||x|| > max_norm`` counts as diverged.
        bounds: optional ``(low, high)`` for the parameter; the branch ends on leaving it.
        max_angle: largest turn of the tangent per step (rad); a step turning more is
            retried with half the step (keeps the branch from jumping).
        detect: detect and locate bifurcations.
        locate_tol: arclength tolerance of the bifurcation location.
    Returns:
        :class:`Branch`.
    Raises:
        ValueError: bad arguments (unknown parameter, ``stop`` equal to the start,
            wrong state shape, ...) or Newton did not converge from ``x0``.
    """
    integrator = resolve_integrator(integrator)
    k, p0, ds_min, ds_max, bounds = _validate(system, params, param, stop, period, ds, max_steps, ds_min, ds_max,
                                              tol, bounds)
    if float(stop) == p0:
        raise ValueError(f"stop={stop} equals the starting value of {param}: nothing to continue.")
    x0 = np.asarray(x0, dtype=float)
    check_state_shape(system, x0)
    if x0.shape != (system.dim,):
        raise ValueError(f"x0 must be one state of shape ({system.dim},), got {x0.shape}.")
    check_system(system, params, x0)
    res = periodic_orbit(system, params, x0, period=k, t0=t0, integrator=integrator,
                         options=ShootOptions(tol=tol, max_norm=max_norm))
    if int(res.status) != Status.CONVERGED:
        raise ValueError(f"Newton from x0={x0.tolist()} did not converge to a P-{k} orbit at {param}={p0:.6g} "
                         f"({Status(int(res.status)).label}, residual {float(res.residual):.2e}); "
                         "give a point nearer the orbit.")
    if int(res.min_period) < k:
        warnings.warn(f"the orbit found from x0 has minimal period {int(res.min_period)} < {k}: continuing it as a "
                      f"fixed point of P^{k} (its period doublings show up as branch points).", stacklevel=2)
    ctx = _Ctx(system, params, param, k, integrator, float(t0), float(tol), int(max_iter), float(max_norm))
    n = system.dim
    z0 = np.concatenate([np.asarray(res.point, dtype=float), [p0]])
    direction = np.sign(float(stop) - p0) * _e_p(n)
    first = ctx.correct(z0, z0, _e_p(n), direction)
    if first.status != _OK:
        raise ValueError(f"the orbit found from x0 at {param}={p0:.6g} could not be refined by the corrector "
                         f"(status {int(first.status)}); try a smaller tol or another integrator.")
    settings = _settings(ctx, ds, ds_min, ds_max, max_steps, stop, bounds, max_angle, locate_tol, origin="start")
    return _run(ctx, first, stop=float(stop), ds=ds, ds_min=ds_min, ds_max=ds_max, max_steps=int(max_steps),
                bounds=bounds, max_angle=max_angle, detect=detect, locate_tol=locate_tol, progress=progress,
                desc=f"P-{k} continuation in {param}", param=param, settings=settings,
                params_start=params_to_dict(with_param(params, param, p0)))


def switch_branch(system: ForcedSystem, params, branch: Branch, bifurcation: BifurcationPoint | int, *,
                  stop: float | None = None, amplitude: float | None = None, ds: float | None = None,
                  max_steps: int = 500, integrator: AbstractIntegrator | None = None, progress: bool = True,
                  ds_min: float | None = None, ds_max: float | None = None, tol: float = 1e-10,
                  max_iter: int = 10, max_norm: float = 1e6, bounds: tuple[float, float] | None = None,
                  max_angle: float = 0.5, detect: bool = True, locate_tol: float = 1e-10) -> Branch:
    """Follow the period-doubled branch born at a period-doubling point of ``branch``.

    At a PD point of a P-k branch the P-2k orbits bifurcate in the direction of the
    eigenvector ``v`` of the multiplier -1 (for ``P^{2k}`` the PD is a pitchfork whose
    new branch is tangent to ``(v, 0)`` in ``(x, p)``). The first point is found by the
    bordered Newton from ``x_PD + amplitude v`` on the hyperplane
    ``v . (x - x_PD) = amplitude`` (the parameter free), then the P-2k branch is
    continued away from the P-k orbit as in :func:`continue_orbit` (with ``period = 2k``).
    The PD point itself is not part of the returned branch; ``settings.origin``
    records it.

    Args:
        system, params: as given to :func:`continue_orbit` for ``branch`` (``params`` is
            the base set; the parameter is set to the PD value).
        branch: the P-k :class:`Branch`.
        bifurcation: one of ``branch.bifurcations`` (kind ``"PD"``) or its index there.
        stop: end of the new branch in the parameter (optional: without it the branch
            runs until ``bounds`` or ``max_steps``; the doubled branch may go either way).
        amplitude: size of the initial displacement along ``v`` (default ``ds``).
        ds: arclength step (default ``branch.settings.ds``).
        integrator: use the one of ``branch``.
        Other arguments as in :func:`continue_orbit`.
    Returns:
        the P-2k :class:`Branch`.
    """
    if isinstance(bifurcation, (int, np.integer)):
        if not 0 <= int(bifurcation) < len(branch.bifurcations):
            raise ValueError(f"bifurcation index {bifurcation} outside 0..{len(branch.bifurcations) - 1}.")
        bifurcation = branch.bifurcations[int(bifurcation)]
    if bifurcation.kind != "PD":
        raise ValueError(f"switch_branch starts the doubled branch at a period doubling (kind 'PD'), "
                         f"got kind {bifurcation.kind!r}.")
    ds = branch.settings.ds if ds is None else float(ds)
    param = branch.param
    integrator = resolve_integrator(integrator)
    k2, p_pd, ds_min, ds_max, bounds = _validate(system, params, param, stop, 2 * branch.period, ds, max_steps,
                                                 ds_min, ds_max, tol, bounds)
    h = ds if amplitude is None else float(amplitude)
    if not (h > 0):
        raise ValueError(f"amplitude={amplitude} must be > 0.")
    t0 = branch.settings.t0
    p_pd = float(bifurcation.param_value)
    n = system.dim
    x_pd = np.asarray(bifurcation.point, dtype=float)
    # eigenvector of the multiplier -1 of P^k at the PD point (re-converged there)
    ctx_k = _Ctx(system, params, param, branch.period, integrator, t0, float(tol), int(max_iter), float(max_norm))
    z_pd = np.concatenate([x_pd, [p_pd]])
    at = ctx_k.correct(z_pd, z_pd, _e_p(n), _e_p(n))
    if at.status != _OK:
        raise ValueError(f"the P-{branch.period} orbit could not be re-converged at the PD point {param}={p_pd:.8g}.")
    M = at.jac[:, :n] + np.eye(n)
    lam, V = np.linalg.eig(M)
    i = int(np.argmin(np.abs(lam + 1.0)))
    v = np.real(V[:, i])
    v /= np.linalg.norm(v)
    if v[np.argmax(np.abs(v))] < 0:
        v = -v
    ctx = _Ctx(system, params, param, k2, integrator, t0, float(tol), int(max_iter), float(max_norm))
    w = np.concatenate([v, [0.0]])
    z_guess = at.z + h * w
    first = ctx.correct(z_guess, z_guess, w, w)
    if first.status != _OK:
        raise ValueError(f"no P-{k2} orbit found at distance {h:g} from the PD point along its eigenvector "
                         f"(corrector status {int(first.status)}); try a smaller amplitude.")
    if np.linalg.norm(first.pts[branch.period] - first.pts[0]) <= 1e-3 * h:
        raise ValueError("the corrector went back to the P-k orbit; try another amplitude.")
    settings = _settings(ctx, ds, ds_min, ds_max, max_steps, stop, bounds, max_angle, locate_tol,
                         origin=f"PD of the P-{branch.period} branch at {param}={p_pd!r}", amplitude=h)
    return _run(ctx, first, stop=None if stop is None else float(stop), ds=ds, ds_min=ds_min, ds_max=ds_max,
                max_steps=int(max_steps), bounds=bounds, max_angle=max_angle, detect=detect, locate_tol=locate_tol,
                progress=progress, desc=f"P-{k2} continuation in {param}", param=param, settings=settings,
                params_start=params_to_dict(with_param(params, param, float(first.z[-1]))))
