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

import dataclasses
import math
import warnings
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import progress_bar
from .._checks import split_changes, with_changes
from .._params import get_param, params_to_dict, with_param
from .._status import Status
from .._system import ForcedSystem, check_state_shape, check_system
from .._version import __version__
from ..integrate import AbstractIntegrator, resolve_integrator
from ..shooting import ShootOptions, periodic_orbit, sorted_eigvals
from ..shooting._floquet import check_period
from ._branch import BifurcationKind, BifurcationPoint, Branch, BranchSettings, BranchStatus
from ._options import CORRECTOR, ContinuationOptions

__all__ = ["continue_orbit", "switch_branch", "START_ITERATIONS"]

START_ITERATIONS = 40
"""Newton iterations at least of the solve that converges the starting orbit from ``x0``
(a point near the orbit, not on it: more than a corrector step from a predicted point needs)."""

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


class _Ctx(NamedTuple):
    """Everything fixed along one branch: the problem (system, parameters, the continued
    parameter's name, ``k``), the integrator, the phase ``t0`` and the corrector's options."""

    system: ForcedSystem
    params: Any
    name: str
    k: int
    integrator: AbstractIntegrator
    t0: Any
    shoot: ShootOptions

    def correct(self, z_guess, anchor, w, tref) -> _Step:
        f64 = lambda a: jnp.asarray(a, jnp.float64)
        # the Newton solver is a static argument: benchmarks/continuation.py swaps in a
        # hand-written reference loop to time against it in the same process
        out = _correct(_bordered_newton, self._replace(t0=f64(self.t0)), f64(z_guess), f64(anchor), f64(w),
                       f64(tref))
        return _Step(*[np.asarray(a) for a in jax.device_get(out)])


@eqx.filter_jit
def _correct(newton, ctx: _Ctx, z_guess, anchor, w, tref):
    """Bordered Newton ``F(z) = 0, w . (z - anchor) = 0`` from ``z_guess`` by ``newton``
    (:func:`_bordered_newton`, with the tolerances of ``ctx.shoot``), then the tangent,
    multipliers and test functions at the result (one compiled kernel)."""
    n = z_guess.shape[0] - 1
    eye = jnp.eye(n)
    evaluate = lambda z: _map_and_jac(ctx.system, ctx.params, ctx.name, ctx.k, ctx.t0, ctx.integrator, z)
    opts = ctx.shoot
    z, st, it, rF, J, pts = newton(evaluate, z_guess, anchor, w, opts.tol, opts.max_iter, opts.max_norm)
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
        candidates.append((BifurcationKind.PD, _T_PD))
    if fold:
        candidates.append((BifurcationKind.SN, _T_TP))
    elif changes(_T_DET):
        candidates.append((BifurcationKind.BP, _T_DET))
    if changes(_T_NS):
        candidates.append((BifurcationKind.NS, _T_NS))
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
        if kind == BifurcationKind.NS:
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
def _options(options, shoot, changes: dict) -> tuple[ContinuationOptions, ShootOptions]:
    """The continuation and corrector options with ``changes`` (fields of either) applied."""
    to_options, to_shoot = split_changes(changes, ContinuationOptions, ShootOptions)
    return (with_changes(options, ContinuationOptions, to_options),
            with_changes(CORRECTOR if shoot is None else shoot, ShootOptions, to_shoot))


def _check_stop(stop, param: str) -> float | None:
    if stop is not None and (isinstance(stop, bool) or not math.isfinite(float(stop))):
        raise ValueError(f"stop={stop} must be a finite value of {param} (or None for no target).")
    return None if stop is None else float(stop)


def _end_point(ctx: _Ctx, cur: _Step, out: _Step, settings: BranchSettings):
    """The accepted step ``cur -> out`` ended past ``stop`` or outside ``bounds``: the point
    re-converged on the target value and why the branch ends there (``(out, None)`` when
    it goes on)."""
    z, stop, bounds = cur.z, settings.stop, settings.options.bounds
    p_old, p_new = float(z[-1]), float(out.z[-1])
    if stop is not None and (p_old - stop) * (p_new - stop) <= 0 and p_new != p_old and p_old != stop:
        target, reason = stop, BranchStatus.STOP
    elif bounds is not None and not (bounds[0] <= p_new <= bounds[1]):
        target, reason = (bounds[0] if p_new < bounds[0] else bounds[1]), BranchStatus.BOUNDS
    else:
        return out, None
    zg = z + (target - p_old) / (p_new - p_old) * (out.z - z)
    zg[-1] = target
    fin = ctx.correct(zg, zg, _e_p(len(z) - 1), cur.tangent)
    return (fin if fin.status == _OK else out), reason


def _run(ctx: _Ctx, first: _Step, settings: BranchSettings, progress: bool, params_start: dict) -> Branch:
    """The continuation loop from the converged point ``first`` (tangent oriented already)."""
    opts = settings.options
    ds, (ds_min, ds_max) = float(opts.ds), opts.step_range
    steps, bifs, status, cur = [first], [], BranchStatus.MAX_STEPS, first
    cos_max = math.cos(opts.max_angle)
    bar = progress_bar(int(opts.max_steps), f"P-{ctx.k} continuation in {ctx.name}", progress, unit="step")
    try:
        while len(steps) <= opts.max_steps:
            zp = cur.z + ds * cur.tangent
            out = ctx.correct(zp, zp, cur.tangent, cur.tangent)
            ok = out.status == _OK and float(out.tangent @ cur.tangent) >= cos_max and \
                float(np.linalg.norm(out.z - zp)) <= ds
            if not ok:
                if ds <= ds_min * (1 + 1e-12):
                    status = BranchStatus.DIVERGED if out.status == _DIVERGED else BranchStatus.CORRECTOR_FAILED
                    break
                ds = max(0.5 * ds, ds_min)
                continue
            out, reason = _end_point(ctx, cur, out, settings)
            if opts.detect:
                bifs.extend(_detect(ctx, cur, out, len(steps) - 1, opts.locate_tol))
            steps.append(out)
            cur = out
            bar.update(1)
            bar.set_postfix_str(f"{ctx.name}={float(out.z[-1]):.6g} ds={ds:.2g}", refresh=False)
            if reason is not None:
                status = reason
                break
            if out.iterations <= 2:
                ds = min(1.5 * ds, ds_max)
            elif out.iterations >= 5:
                ds = max(0.7 * ds, ds_min)
    finally:
        bar.close()
    return _branch(ctx, steps, tuple(bifs), status, settings, params_start)


def _branch(ctx: _Ctx, steps: list[_Step], bifs: tuple, status: BranchStatus, settings: BranchSettings,
            params_start: dict) -> Branch:
    """The :class:`Branch` of the corrected points ``steps``."""
    Z = np.array([s.z for s in steps])
    m, n = Z.shape[0], Z.shape[1] - 1
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(Z, axis=0), axis=1))])
    lam = np.array([s.multipliers for s in steps])
    return Branch(
        param=ctx.name, values=Z[:, -1].copy(), points=np.array([s.pts for s in steps]).reshape(m, ctx.k, n),
        multipliers=lam, stable=np.all(np.abs(lam) < 1.0, axis=1),
        residuals=np.array([float(s.residual) for s in steps]), tangents=np.array([s.tangent for s in steps]),
        arclength=arc, status=status, bifurcations=bifs, period=ctx.k, system=ctx.system.name,
        state_names=tuple(ctx.system.state_names), params=params_start, settings=settings, version=__version__,
    )


def _start_orbit(system, params, x0, param: str, k: int, t0, integrator, shoot: ShootOptions):
    """The P-k orbit converged from ``x0`` at the parameter's value in ``params`` (checked):
    its point and that value."""
    p0 = get_param(params, param)  # ValueError for an unknown name
    x0 = np.asarray(x0, dtype=float)
    check_state_shape(system, x0)
    if x0.shape != (system.dim,):
        raise ValueError(f"x0 must be one state of shape ({system.dim},), got {x0.shape}.")
    check_system(system, params, x0)
    res = periodic_orbit(system, params, x0, period=k, t0=t0, integrator=integrator,
                         options=dataclasses.replace(shoot, max_iter=max(shoot.max_iter, START_ITERATIONS)))
    if int(res.status) != Status.CONVERGED:
        raise ValueError(f"Newton from x0={x0.tolist()} did not converge to a P-{k} orbit at {param}={p0:.6g} "
                         f"({Status(int(res.status)).label}, residual {float(res.residual):.2e}); "
                         "give a point nearer the orbit.")
    if int(res.min_period) < k:
        warnings.warn(f"the orbit found from x0 has minimal period {int(res.min_period)} < {k}: continuing it as a "
                      f"fixed point of P^{k} (its period doublings show up as branch points).", stacklevel=3)
    return np.asarray(res.point, dtype=float), p0


def continue_orbit(system: ForcedSystem, params, x0, *, param: str, stop: float, period: int = 1, t0: float = 0.0,
                   integrator: AbstractIntegrator | None = None, options: ContinuationOptions | None = None,
                   shoot: ShootOptions | None = None, progress: bool = True, **changes) -> Branch:
    """Follow a P-k orbit in the parameter ``param`` by pseudo-arclength continuation.

    Starts by converging the orbit at the parameter's current value in ``params`` with
    :func:`~jaxgear.periodic_orbit` (``shoot``, with at least :data:`START_ITERATIONS`
    iterations, from ``x0``), then follows the curve of fixed points of ``P^k`` in
    ``(x, p)`` until the parameter reaches ``stop`` (the last point is placed at ``stop``
    exactly), leaves ``options.bounds``, ``options.max_steps`` steps are taken, or the
    corrector fails at the smallest step (see :data:`BRANCH_STATUS`). Folds are passed
    (the parameter may turn around on the way to ``stop``). Floquet multipliers are
    computed at every point and period doublings, saddle-nodes, branch points and
    Neimark-Sacker points are detected and located (see the module docs).

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
        t0: phase of the stroboscopic section.
        integrator: any integrator object; default :func:`~jaxgear.default_integrator`.
        options: :class:`ContinuationOptions` (step ``ds`` and its bounds, ``max_steps``,
            ``max_angle``, parameter ``bounds``, ``detect``, ``locate_tol``); ``None``: the defaults.
        shoot: the corrector's :class:`~jaxgear.ShootOptions`: ``tol`` on
            ``||P^k(x) - x||`` (Newton also stops only when its next step is below
            ``tol + 1e-8 |(x, p)|``), ``max_iter`` per step (a step needing more is
            retried with half the step), ``max_norm`` (a point with ``||x|| > max_norm``
            counts as diverged); ``None``: :data:`CORRECTOR`.
        progress: show a progress bar.
        **changes: fields of ``options`` or ``shoot`` to change, e.g. ``ds=0.005, tol=1e-9``.
    Returns:
        :class:`Branch` (its ``settings`` hold both options objects).
    Raises:
        ValueError: bad arguments (unknown parameter or option, ``stop`` equal to the
            start, wrong state shape, ...) or Newton did not converge from ``x0``.
    """
    options, shoot = _options(options, shoot, changes)
    integrator = resolve_integrator(integrator)
    k = check_period(period)
    stop = _check_stop(stop, param)
    if stop is None:
        raise ValueError(f"stop=None: continue_orbit needs the value of {param} to continue towards.")
    point, p0 = _start_orbit(system, params, x0, param, k, t0, integrator, shoot)
    if stop == p0:
        raise ValueError(f"stop={stop} equals the starting value of {param}: nothing to continue.")
    ctx = _Ctx(system, params, param, k, integrator, float(t0), shoot)
    n = system.dim
    z0 = np.concatenate([point, [p0]])
    first = ctx.correct(z0, z0, _e_p(n), np.sign(stop - p0) * _e_p(n))
    if first.status != _OK:
        raise ValueError(f"the orbit found from x0 at {param}={p0:.6g} could not be refined by the corrector "
                         f"(status {int(first.status)}); try a smaller tol or another integrator.")
    settings = BranchSettings(options=options, shoot=shoot, stop=stop, t0=float(t0), integrator=integrator)
    return _run(ctx, first, settings, progress, params_to_dict(with_param(params, param, p0)))


def _pd_eigenvector(ctx: _Ctx, bifurcation: BifurcationPoint) -> tuple[_Step, np.ndarray]:
    """The P-k orbit re-converged at the PD point and the unit eigenvector of its multiplier -1."""
    n = ctx.system.dim
    z_pd = np.concatenate([np.asarray(bifurcation.point, dtype=float), [float(bifurcation.param_value)]])
    at = ctx.correct(z_pd, z_pd, _e_p(n), _e_p(n))
    if at.status != _OK:
        raise ValueError(f"the P-{ctx.k} orbit could not be re-converged at the PD point "
                         f"{ctx.name}={float(bifurcation.param_value):.8g}.")
    lam, V = np.linalg.eig(at.jac[:, :n] + np.eye(n))
    v = np.real(V[:, int(np.argmin(np.abs(lam + 1.0)))])
    v /= np.linalg.norm(v)
    return at, (-v if v[np.argmax(np.abs(v))] < 0 else v)


def switch_branch(system: ForcedSystem, params, branch: Branch, bifurcation: BifurcationPoint | int, *,
                  stop: float | None = None, amplitude: float | None = None,
                  integrator: AbstractIntegrator | None = None, options: ContinuationOptions | None = None,
                  shoot: ShootOptions | None = None, progress: bool = True, **changes) -> Branch:
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
            runs until ``options.bounds`` or ``options.max_steps``; the doubled branch may
            go either way).
        amplitude: size of the initial displacement along ``v`` (default ``options.ds``).
        integrator: any integrator object (default :func:`~jaxgear.default_integrator`;
            pass ``branch.settings.integrator`` to keep the branch's).
        options, shoot: as in :func:`continue_orbit`; ``None``: those of ``branch``
            (``branch.settings.options`` and ``branch.settings.shoot``).
        progress: show a progress bar.
        **changes: fields of ``options`` or ``shoot`` to change.
    Returns:
        the P-2k :class:`Branch`.
    """
    if isinstance(bifurcation, (int, np.integer)):
        if not 0 <= int(bifurcation) < len(branch.bifurcations):
            raise ValueError(f"bifurcation index {bifurcation} outside 0..{len(branch.bifurcations) - 1}.")
        bifurcation = branch.bifurcations[int(bifurcation)]
    if bifurcation.kind != BifurcationKind.PD:
        raise ValueError(f"switch_branch starts the doubled branch at a period doubling (kind 'PD'), "
                         f"got kind {bifurcation.kind!r}.")
    options, shoot = _options(branch.settings.options if options is None else options,
                              branch.settings.shoot if shoot is None else shoot, changes)
    param = branch.param
    integrator = resolve_integrator(integrator)
    get_param(params, param)  # ValueError for an unknown name
    stop = _check_stop(stop, param)
    h = options.ds if amplitude is None else float(amplitude)
    if not (h > 0):
        raise ValueError(f"amplitude={amplitude} must be > 0.")
    t0 = branch.settings.t0
    ctx_k = _Ctx(system, params, param, branch.period, integrator, t0, shoot)
    at, v = _pd_eigenvector(ctx_k, bifurcation)
    k2 = 2 * branch.period
    ctx = ctx_k._replace(k=k2)
    w = np.concatenate([v, [0.0]])
    z_guess = at.z + h * w
    first = ctx.correct(z_guess, z_guess, w, w)
    if first.status != _OK:
        raise ValueError(f"no P-{k2} orbit found at distance {h:g} from the PD point along its eigenvector "
                         f"(corrector status {int(first.status)}); try a smaller amplitude.")
    if np.linalg.norm(first.pts[branch.period] - first.pts[0]) <= 1e-3 * h:
        raise ValueError("the corrector went back to the P-k orbit; try another amplitude.")
    p_pd = float(bifurcation.param_value)
    settings = BranchSettings(options=options, shoot=shoot, stop=stop, t0=float(t0), integrator=integrator,
                              origin=f"PD of the P-{branch.period} branch at {param}={p_pd!r}", amplitude=h)
    return _run(ctx, first, settings, progress, params_to_dict(with_param(params, param, float(first.z[-1]))))
