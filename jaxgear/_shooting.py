"""Shooting: periodic orbits of the stroboscopic map, Floquet multipliers, verification.

The paper (§4.1, ref. [15]) locates periodic motions with the shooting method and
checks them by direct integration. For a forced system (paper eq. 6) with period ``T``
a P-k motion is a fixed point of the k-fold stroboscopic map,

    G(x) = P^k(x) - x = 0,    P^k: x(t0) -> x(t0 + k T)   (full state, MODEL.md §6),

solved here by a damped Newton method whose Jacobian ``DP^k - I`` comes from
``jax.jacfwd`` through the integrator (no finite differences). Around it:

- :func:`periodic_orbit` — Newton from one seed or a batch of seeds (one ``jit``,
  ``vmap`` over seeds), each lane returning a status code (converged / not converged /
  singular Jacobian / diverged), the residual, the iterations and the residual history
  instead of a wrong orbit. The converged point is differentiable with respect to the
  parameters by the implicit function theorem (``lax.custom_root``; Newton is not
  unrolled).
- Floquet analysis at the converged point: the monodromy matrix of the minimal period
  ``m`` (the product of the one-period Jacobians along the orbit), its multipliers,
  stability (all ``|lambda| < 1``) and the kind of instability of the largest
  multiplier: fold (real ``lambda > 1``), flip (real ``lambda < -1``, period doubling)
  or Neimark-Sacker (complex pair ``|lambda| > 1``). A P-2 found when asking for P-4
  is reported with minimal period 2.
- :func:`find_periodic_orbits` — many seeds (user points, a random box, a cell-mapping
  result via :func:`seeds_from_result`), several ``k``, and the converged orbits
  deduplicated (cyclic shifts and multiples of the period reported once).
- :func:`verify_orbit` — the paper's check by direct integration: start on the orbit
  with a small perturbation, integrate many periods, report whether the motion stays.

Times are in the system's unit; states have shape ``(..., dim)``.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Any, Mapping, NamedTuple, Sequence

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._integrate import RK4, Adaptive, Integrator, advance_batch
from ._poincare import sample_trajectory, stroboscopic_orbit
from ._system import ForcedSystem, check_state_shape, check_system

__all__ = [
    "ShootResult",
    "PeriodicOrbit",
    "OrbitSearch",
    "OrbitCheck",
    "periodic_orbit",
    "find_periodic_orbits",
    "load_orbits",
    "monodromy",
    "floquet_multipliers",
    "classify_multipliers",
    "seeds_from_result",
    "seeds_in_box",
    "verify_orbit",
    "SHOOT_CONVERGED",
    "SHOOT_NOT_CONVERGED",
    "SHOOT_SINGULAR",
    "SHOOT_DIVERGED",
    "SHOOT_STATUS_NAMES",
    "STABLE",
    "FOLD",
    "FLIP",
    "NEIMARK_SACKER",
    "INSTABILITY_NAMES",
]

# Per-seed status codes of the Newton iteration.
SHOOT_CONVERGED = 0
SHOOT_NOT_CONVERGED = 1  # iteration limit reached or the line search stalled
SHOOT_SINGULAR = 2  # DP^k - I numerically singular (cond > 1e13)
SHOOT_DIVERGED = 3  # the flow blew up at the seed, or the iterate left ||x|| <= max_norm
_RUNNING = -1
SHOOT_STATUS_NAMES = {
    SHOOT_CONVERGED: "converged",
    SHOOT_NOT_CONVERGED: "not converged",
    SHOOT_SINGULAR: "singular Jacobian",
    SHOOT_DIVERGED: "diverged",
}

# Stability / kind of instability of a periodic orbit (largest |multiplier|).
UNKNOWN = -1
STABLE = 0
FOLD = 1  # real multiplier > 1 (saddle-node / fold type)
FLIP = 2  # real multiplier < -1 (period doubling)
NEIMARK_SACKER = 3  # complex pair outside the unit circle
INSTABILITY_NAMES = {UNKNOWN: "unknown", STABLE: "stable", FOLD: "fold", FLIP: "flip",
                     NEIMARK_SACKER: "neimark-sacker"}


# --------------------------------------------------------------------------- flows
def _flow(system: ForcedSystem, params, x, t0, periods: int, integrator: Integrator):
    """``P^periods`` for one state ``x`` of shape ``(dim,)``, differentiable both ways.

    RK4 runs the foundation kernel (fixed loop length: forward and reverse mode work);
    :class:`Adaptive` runs diffrax with ``DirectAdjoint`` (supports ``jacfwd`` for the
    monodromy and reverse mode for implicit gradients). A failed adaptive solve is NaN.
    """
    if isinstance(integrator, RK4):
        return advance_batch(system, params, x[:, None], t0, periods, integrator)[:, 0]
    if isinstance(integrator, Adaptive):
        T = system.period(params)
        term = diffrax.ODETerm(lambda t, y, a: system.vector_field(t, y, a))
        sol = diffrax.diffeqsolve(
            term, integrator.solver, t0, t0 + periods * T, dt0=T / 64, y0=x, args=params,
            stepsize_controller=diffrax.PIDController(rtol=integrator.rtol, atol=integrator.atol),
            max_steps=integrator.max_steps, adjoint=diffrax.DirectAdjoint(), throw=False,
        )
        ok = sol.result == diffrax.RESULTS.successful
        return jnp.where(ok, sol.ys[-1], jnp.nan)
    raise TypeError(f"unknown integrator {integrator!r}; use jaxgear.RK4 or jaxgear.Adaptive.")


def _value_and_jac(fun, x):
    """``(fun(x), jacfwd(fun)(x))`` with one primal evaluation."""

    def both(z):
        y = fun(z)
        return y, y

    J, y = jax.jacfwd(both, has_aux=True)(x)
    return y, J


# --------------------------------------------------------------------------- Newton
def _orbit_jacobians(system, params, x, t0, k, integrator):
    """Points and Jacobians along ``k`` periods from ``x`` at ``t0``.

    Returns ``x_k = P^k(x)``, the points ``pts = (x, P(x), ..., P^{k-1}(x))`` of shape
    ``(k, dim)`` and ``Cs`` of shape ``(k, dim, dim)`` with ``Cs[j] = D P^{j+1}(x)``
    (products of one-period Jacobians from ``jax.jacfwd``; ``Cs[k-1]`` is ``DP^k``).
    """
    T = system.period(params)

    def one_period(z, i):
        y, J = _value_and_jac(lambda w: _flow(system, params, w, t0 + i * T, 1, integrator), z)
        return y, (z, J)

    xk, (pts, Js) = jax.lax.scan(one_period, x, jnp.arange(k))

    def accumulate(C, J):
        C = J @ C
        return C, C

    _, Cs = jax.lax.scan(accumulate, jnp.eye(x.shape[0]), Js)
    return xk, pts, Cs


def _damped_newton(evaluate, flow_k, x0, k, tol, max_iter, max_norm, max_backtracks=10, stall=10):
    """Damped Newton on ``G(x) = P^k(x) - x = 0`` with Armijo backtracking on ``||G||``.

    ``evaluate(x) -> (P^k(x), pts, Cs)`` (see :func:`_orbit_jacobians`), ``flow_k(x) ->
    P^k(x)``. The step is the Newton step ``dx = -(DP^k - I)^{-1} G`` times ``a``, from
    ``a = 1`` shortened (quadratic-model backtracking, factor 0.1-0.5, at most
    ``max_backtracks`` times) until ``||G(x + a dx)|| <= (1 - 1e-4 a) ||G(x)||``.
    Every pass of the loop evaluates ``G`` and its Jacobian at the current iterate and stops there when ``||G|| <= tol``
    (converged: the points and Jacobians of that last evaluation are the Floquet data),
    when ``DP^k - I`` is singular (cond > 1e13), when the flow is not finite or the
    iterate left ``||x|| <= max_norm`` (diverged), or when the line search finds no
    decrease (a local minimum of ``||G||``), the residual did not halve over the last
    ``stall`` steps, or ``max_iter`` steps were taken (not converged).

    Returns ``x, (residual, iterations, status, history, pts, Cs)``; ``history[j]`` is
    the residual after ``j`` Newton steps.
    """
    dim = x0.shape[0]
    eye = jnp.eye(dim)
    pts0 = jnp.zeros((k, dim))
    Cs0 = jnp.zeros((k, dim, dim))
    hist0 = jnp.full(max_iter + 1, jnp.nan)

    def cond(c):
        return c[3] == _RUNNING

    def body(c):
        it, x, _, st_in, hist, _, _ = c
        xk, pts, Cs = evaluate(x)
        g = xk - x
        A = Cs[-1] - eye
        r = jnp.linalg.norm(g)
        hist = hist.at[it].set(r)
        finite = jnp.isfinite(r) & jnp.all(jnp.isfinite(A))
        A_safe = jnp.where(finite, A, eye)
        s = jnp.linalg.svd(A_safe, compute_uv=False)
        singular = ~(s[-1] > 1e-13 * s[0])
        dx = jnp.linalg.solve(jnp.where(singular, eye, A_safe), -jnp.where(finite, g, 0.0))

        def ok(a, rn):
            return jnp.isfinite(rn) & (rn <= (1.0 - 1e-4 * a) * r)

        def ls_cond(lc):
            a, _, rn, j = lc
            return ~done_here & ~ok(a, rn) & (j < max_backtracks)

        def ls_body(lc):
            a, _, rn, j = lc
            # minimiser of the quadratic model of ||G(x + a dx)||^2 through phi(0) = r^2,
            # phi'(0) = -2 r^2 and phi(a) = rn^2, kept in [a/10, a/2]; first pass a = 1
            q = r * r * a * a / (rn * rn - r * r + 2.0 * r * r * a)
            a_new = jnp.where(j == 0, 1.0,
                              jnp.where(jnp.isfinite(q), jnp.clip(q, 0.1 * a, 0.5 * a), 0.1 * a))
            xn = x + a_new * dx
            return a_new, xn, jnp.linalg.norm(flow_k(xn) - xn), j + 1

        # stalled: the residual did not halve over the last `stall` steps (wandering far
        # from any orbit; a Newton iterate that approaches one converges fast)
        stalled = (it >= stall) & (r > 0.5 * hist[jnp.maximum(it - stall, 0)])
        # under vmap the body also runs for finished lanes (st_in set): no line search there
        done_here = (st_in != _RUNNING) | (r <= tol) | ~finite | singular | (it >= max_iter) | stalled
        # the line search runs only for lanes that take a step
        ls0 = (jnp.asarray(1.0), x, jnp.asarray(jnp.inf), jnp.asarray(0))
        a, xn, rn, _ = jax.lax.while_loop(ls_cond, ls_body, ls0)
        accept = ~done_here & ok(a, rn)
        st = jnp.where(
            r <= tol, SHOOT_CONVERGED,
            jnp.where(~finite, SHOOT_DIVERGED,
                      jnp.where(singular, SHOOT_SINGULAR,
                                jnp.where((it >= max_iter) | stalled | ~accept, SHOOT_NOT_CONVERGED,
                                          jnp.where(jnp.linalg.norm(xn) > max_norm, SHOOT_DIVERGED,
                                                    _RUNNING)))))
        x_new = jnp.where(accept, xn, x)
        return it + accept.astype(it.dtype), x_new, r, st, hist, pts, Cs

    init = (jnp.asarray(0), x0, jnp.asarray(jnp.inf), jnp.asarray(_RUNNING), hist0, pts0, Cs0)
    it, x, r, st, hist, pts, Cs = jax.lax.while_loop(cond, body, init)
    return x, (r, it, st, hist, pts, Cs)


# --------------------------------------------------------------------------- results
class ShootResult(NamedTuple):
    """Per-seed result of :func:`periodic_orbit` (leading shape ``...`` = the seeds'), paper §4.1.

    States are in state units at time ``t0`` (system time unit), residuals in state
    units, multipliers dimensionless.

    Lanes that did not converge hold NaN in ``point``, ``orbit``, ``monodromy`` and
    ``multipliers``; their ``status`` says why and ``last_iterate`` where Newton stopped.
    Only ``point`` carries derivatives with respect to the parameters (implicit
    function theorem); the other fields are diagnostics. For derivatives of the
    multipliers use :func:`floquet_multipliers` at ``point``.

    Attributes:
        point: ``(..., dim)`` fixed point ``x*`` of ``P^k`` at time ``t0``
            (differentiable w.r.t. the parameters by the implicit function theorem).
        orbit: ``(..., k, dim)`` stroboscopic points ``x*, P(x*), ..., P^{k-1}(x*)``.
        min_period: ``(...)`` int, the smallest divisor ``m`` of ``k`` with
            ``P^m(x*) = x*`` (within ``period_tol``); ``k`` if none, 0 if not converged.
        monodromy: ``(..., dim, dim)`` Jacobian of ``P^m`` at ``x*`` (``m`` = min_period).
        multipliers: ``(..., dim)`` complex Floquet multipliers of ``P^m``, by
            decreasing modulus.
        stable: ``(...)`` bool, all ``|multiplier| < 1`` (False if not converged).
        instability: ``(...)`` int, ``STABLE``, ``FOLD``, ``FLIP``, ``NEIMARK_SACKER``
            (kind of the largest multiplier) or ``UNKNOWN`` (-1, not converged).
        residual: ``(...)`` ``||P^k(x) - x||`` at the last iterate.
        iterations: ``(...)`` Newton iterations taken.
        status: ``(...)`` int, ``SHOOT_CONVERGED`` .. ``SHOOT_DIVERGED``.
        history: ``(..., max_iter + 1)`` residual after ``j`` Newton steps (NaN after the end).
        last_iterate: ``(..., dim)`` the last Newton iterate (for failure diagnosis).
    """

    point: jax.Array
    orbit: jax.Array
    min_period: jax.Array
    monodromy: jax.Array
    multipliers: jax.Array
    stable: jax.Array
    instability: jax.Array
    residual: jax.Array
    iterations: jax.Array
    status: jax.Array
    history: jax.Array
    last_iterate: jax.Array


def classify_multipliers(multipliers, real_tol: float = 1e-8):
    """Stability and kind of instability from Floquet multipliers ``(..., dim)``.

    Returns ``(stable, kind)``: ``stable`` is ``all |lambda| < 1``; ``kind`` is
    ``STABLE``, or for the multiplier of largest modulus (when it is outside the unit
    circle) ``FOLD`` (real, > 1), ``FLIP`` (real, < -1) or ``NEIMARK_SACKER`` (complex).
    A multiplier counts as real when ``|Im| <= real_tol * max(1, |lambda|)``.
    """
    lam = jnp.asarray(multipliers)
    mod = jnp.abs(lam)
    stable = jnp.all(mod < 1.0, axis=-1)
    top = jnp.take_along_axis(lam, jnp.argmax(mod, axis=-1)[..., None], axis=-1)[..., 0]
    real = jnp.abs(jnp.imag(top)) <= real_tol * jnp.maximum(1.0, jnp.abs(top))
    kind = jnp.where(stable, STABLE,
                     jnp.where(real, jnp.where(jnp.real(top) > 0, FOLD, FLIP), NEIMARK_SACKER))
    return stable, kind


def _sorted_eigvals(M):
    lam = jnp.linalg.eigvals(M)
    order = jnp.argsort(-jnp.abs(lam), axis=-1)
    return jnp.take_along_axis(lam, order, axis=-1)


def _minimal_period(pts, x, k, period_tol):
    """Smallest divisor ``j`` of ``k`` with ``||P^j(x) - x|| <= period_tol (1 + ||x||)``, else ``k``."""
    scale = 1.0 + jnp.linalg.norm(x)
    m = jnp.asarray(k)
    for j in sorted((d for d in range(1, k) if k % d == 0), reverse=True):
        m = jnp.where(jnp.linalg.norm(pts[j] - x) <= period_tol * scale, j, m)
    return m


def _shoot_one(system, params, x0, t0, k, integrator, tol, max_iter, max_norm, period_tol):
    flow_k = lambda x: _flow(system, params, x, t0, k, integrator)
    G = lambda x: flow_k(x) - x
    evaluate = lambda x: _orbit_jacobians(system, params, x, t0, k, integrator)

    def solve(f, guess):  # f is G; Newton uses the same map through evaluate/flow_k
        x, (r, it, st, hist, pts, Cs) = _damped_newton(evaluate, flow_k, guess, k, tol, max_iter, max_norm)
        # integer aux outputs break custom_root's JVP rule (jax 0.10): carry them as floats
        return x, (r, it.astype(jnp.float64), st.astype(jnp.float64), hist, pts, Cs)

    def tangent_solve(g, y):
        return jnp.linalg.solve(jax.jacfwd(g)(y), y)

    x, (r, it, st, hist, pts, Cs) = jax.lax.custom_root(G, x0, solve, tangent_solve, has_aux=True)
    it = it.astype(jnp.int32)
    st = st.astype(jnp.int32)
    conv = st == SHOOT_CONVERGED
    nan = jnp.nan
    m = _minimal_period(pts, x, k, period_tol)
    M = jnp.take(Cs, m - 1, axis=0)
    lam = jnp.where(conv, _sorted_eigvals(jnp.where(conv, M, 0.0)), nan)
    stable, kind = classify_multipliers(lam)
    return ShootResult(
        point=jnp.where(conv, x, nan), orbit=jnp.where(conv, pts, nan), min_period=jnp.where(conv, m, 0),
        monodromy=jnp.where(conv, M, nan), multipliers=lam, stable=stable & conv,
        instability=jnp.where(conv, kind, UNKNOWN), residual=r, iterations=it, status=st, history=hist,
        last_iterate=jax.lax.stop_gradient(x),
    )


@eqx.filter_jit
def _shoot_kernel(system, params, X, t0, k, integrator, tol, max_iter, max_norm, period_tol):
    one = lambda x0: _shoot_one(system, params, x0, t0, k, integrator, tol, max_iter, max_norm, period_tol)
    return jax.vmap(one)(X)


def _params_concrete(params) -> bool:
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(params))


def _check_period(period) -> int:
    if isinstance(period, bool) or not isinstance(period, (int, np.integer)) or int(period) < 1:
        raise ValueError(f"period={period!r} must be an integer >= 1 (the k of a P-k orbit, in forcing periods).")
    return int(period)


def periodic_orbit(system: ForcedSystem, params, x0, *, period: int = 1, t0=0.0,
                   integrator: Integrator = RK4(), tol: float = 1e-10, max_iter: int = 40,
                   max_norm: float = 1e6, period_tol: float = 1e-6) -> ShootResult:
    """Shooting: a P-k orbit as a fixed point of ``P^k`` by damped Newton (paper §4.1, [15]).

    Solves ``G(x) = P^k(x) - x = 0`` in the full state from each seed in ``x0``, with the
    Jacobian ``DP^k - I`` from ``jax.jacfwd`` through the integrator and Armijo
    backtracking. One ``jit``; seeds are ``vmap``-ed (a batch of hundreds is one call).
    Then the Floquet analysis at each converged point (see :class:`ShootResult`).

    The converged ``point`` is differentiable with respect to ``params``
    (``jax.grad``, ``jax.jacfwd``) by the implicit function theorem
    (``lax.custom_root``, Newton is not unrolled): ``dx*/dp = -(DP^k - I)^{-1} dP^k/dp``.

    Args:
        system: any :class:`~jaxgear.ForcedSystem`.
        params: its parameter pytree (not batched).
        x0: seeds, shape ``(..., dim)``.
        period: ``k`` (forcing periods per return, int >= 1).
        t0: phase of the stroboscopic section (time at which the points are taken).
        integrator: :class:`~jaxgear.RK4` (default, 200 steps per period) or
            :class:`~jaxgear.Adaptive`; the residual is that of this discrete map.
        tol: convergence on ``||P^k(x) - x||`` (Euclidean, state units).
        max_iter: Newton iteration limit.
        max_norm: an iterate with ``||x|| > max_norm`` is reported as diverged.
        period_tol: ``P^j(x*) = x*`` for a divisor ``j`` of ``k`` when
            ``||P^j(x*) - x*|| <= period_tol * (1 + ||x*||)``.
    Returns:
        :class:`ShootResult` with the leading shape of ``x0``.
    Raises:
        ValueError: wrong state shape, non-finite seeds, ``period < 1``, bad options.
    """
    k = _check_period(period)
    check_state_shape(system, x0)
    _check_newton_options(tol, max_iter, period_tol)
    if _params_concrete(params):
        check_system(system, params, np.asarray(x0, dtype=float).reshape(-1, system.dim)[0], batched=False)
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    lead = x0.shape[:-1]
    X = x0.reshape(-1, system.dim)
    res = _shoot_kernel(system, params, X, jnp.asarray(t0, jnp.float64), k, integrator, float(tol),
                        int(max_iter), float(max_norm), float(period_tol))
    return jax.tree_util.tree_map(lambda a: a.reshape(*lead, *a.shape[1:]), res)


# --------------------------------------------------------------------------- Floquet
@eqx.filter_jit
def _monodromy_kernel(system, params, X, t0, k, integrator):
    return jax.vmap(lambda x: jax.jacfwd(lambda z: _flow(system, params, z, t0, k, integrator))(x))(X)


def monodromy(system: ForcedSystem, params, x, *, period: int = 1, t0=0.0, integrator: Integrator = RK4()):
    """Jacobian ``D P^k(x)`` of the k-fold stroboscopic map, ``(..., dim, dim)``, by ``jax.jacfwd``.

    At a point of a P-k orbit this is the monodromy matrix; its eigenvalues are the
    Floquet multipliers (see :func:`floquet_multipliers`; paper §4.1 judges the
    stability of the shooting results by them). ``x``: states ``(..., dim)`` at time
    ``t0`` (system time unit); ``M[..., i, j] = d x_i(t0 + kT) / d x_j(t0)``
    (dimensionless when all coordinates share a unit; otherwise in their ratio).
    The derivative is through the integrator's discrete map (no finite differences).
    """
    k = _check_period(period)
    check_state_shape(system, x)
    x = jnp.asarray(x, jnp.float64)
    lead = x.shape[:-1]
    M = _monodromy_kernel(system, params, x.reshape(-1, system.dim), jnp.asarray(t0, jnp.float64), k, integrator)
    return M.reshape(*lead, system.dim, system.dim)


def floquet_multipliers(system: ForcedSystem, params, x, *, period: int = 1, t0=0.0,
                        integrator: Integrator = RK4()):
    """Floquet multipliers (eigenvalues of :func:`monodromy`), ``(..., dim)`` complex, by decreasing modulus.

    ``x`` (shape ``(..., dim)``, at time ``t0``) should be a point of a P-k orbit (e.g.
    ``x = 0`` for the trivial orbit of a parametrically excited system); a periodic
    orbit is asymptotically stable when all ``|lambda| < 1`` (paper §4.1). Multipliers
    are dimensionless; differentiable w.r.t. ``params`` (``jax.grad`` of a modulus gives
    the sensitivity of the stability margin).
    """
    return _sorted_eigvals(monodromy(system, params, x, period=period, t0=t0, integrator=integrator))


# --------------------------------------------------------------------------- seeds
def seeds_from_result(result) -> dict[int, np.ndarray]:
    """Shooting seeds from a cell-mapping (or any) result: ``{k: (n_k, dim) points}``.

    ``result`` is any object with ``.attractors``, a sequence of objects with ``.points``
    (array ``(k, dim)`` of stroboscopic points) and ``.period`` (int ``k``). Every point
    of a P-k attractor becomes a seed for ``P^k`` (cell centres are approximate, so each
    point is one more chance for Newton). Attractors of the same period are grouped;
    non-periodic attractors (period 0) and non-finite points are skipped. This is the
    paper's sequence (§4): the global analysis locates the attractors, shooting
    (§4.1) makes them exact. Points in state units at the result's phase (phase 0).
    """
    attractors = getattr(result, "attractors", None)
    if attractors is None:
        raise ValueError("seeds_from_result needs an object with .attractors (a sequence of objects "
                         "with .points (k, dim) and .period).")
    groups: dict[int, list[np.ndarray]] = {}
    dim = None
    for i, a in enumerate(attractors):
        if int(a.period) < 1:
            continue  # non-periodic attractor (period 0): nothing to shoot for
        k = int(a.period)
        pts = np.atleast_2d(np.asarray(a.points, dtype=float))
        if pts.ndim != 2:
            raise ValueError(f"attractor {i}: .points must have shape (k, dim), got {pts.shape}.")
        if dim is not None and pts.shape[1] != dim:
            raise ValueError(f"attractor {i}: state dimension {pts.shape[1]} differs from {dim}.")
        dim = pts.shape[1]
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts):
            groups.setdefault(k, []).append(pts)
    return {k: np.concatenate(v, axis=0) for k, v in sorted(groups.items())}


def seeds_in_box(n: int, low, high, *, seed: int = 0) -> np.ndarray:
    """``n`` seeds uniformly distributed in the box ``low <= x <= high``: ``(n, dim)``.

    ``low``, ``high``: ``(dim,)`` bounds in state units (e.g. the paper's region D,
    eq. 10, extended by a range of ``x4``); ``seed`` fixes the random draw (JAX PRNG),
    so the same call gives the same seeds. Seeds for :func:`find_periodic_orbits`.
    """
    low = np.asarray(low, dtype=float)
    high = np.asarray(high, dtype=float)
    if low.shape != high.shape or low.ndim != 1:
        raise ValueError(f"box bounds must be two 1-D arrays of equal length, got {low.shape} and {high.shape}.")
    if not np.all(high > low):
        raise ValueError(f"box bounds need high > low in every coordinate, got low={low}, high={high}.")
    if int(n) < 1:
        raise ValueError(f"n={n} seeds: must be >= 1.")
    u = jax.random.uniform(jax.random.PRNGKey(int(seed)), (int(n), low.size), dtype=jnp.float64)
    return np.asarray(low + (high - low) * np.asarray(u))


# --------------------------------------------------------------------------- search
@dataclasses.dataclass(frozen=True)
class PeriodicOrbit:
    """One periodic orbit of the stroboscopic map (deduplicated), paper §4.1.

    Attributes:
        points: ``(m, dim)`` stroboscopic points ``x*, P(x*), ..., P^{m-1}(x*)`` (state
            units) at times ``t0 + j T``, rotated so that the point with the smallest
            first coordinate comes first.
        period: minimal period ``m`` (forcing periods).
        multipliers: ``(dim,)`` complex Floquet multipliers of ``P^m``, by decreasing modulus.
        stable: all ``|multiplier| < 1``.
        instability: ``"stable"``, ``"fold"``, ``"flip"`` or ``"neimark-sacker"``.
        residual: ``||P^k(x*) - x*||`` of the best converged seed (state units).
        n_seeds: how many seeds converged to this orbit.
        t0: phase of the stroboscopic section (time of ``points[0]``, system time unit).
        trajectory: ``(m * s + 1, dim)`` the orbit sampled ``s`` times per forcing period
            from ``points[0]`` at ``t0`` over its ``m`` periods (for figures drawn without
            integrating, e.g. from a loaded result), or ``None``.
    """

    points: np.ndarray
    period: int
    multipliers: np.ndarray
    stable: bool
    instability: str
    residual: float
    n_seeds: int
    t0: float = 0.0
    trajectory: np.ndarray | None = None

    @property
    def max_multiplier(self) -> float:
        """Largest Floquet multiplier modulus."""
        return float(np.max(np.abs(self.multipliers)))

    @property
    def samples_per_period(self) -> int:
        """Samples per forcing period of :attr:`trajectory` (0 when there is none)."""
        if self.trajectory is None:
            return 0
        return (len(self.trajectory) - 1) // int(self.period)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (without the sampled trajectory)."""
        return {
            "period": int(self.period), "points": np.asarray(self.points).tolist(),
            "multipliers_abs": np.abs(self.multipliers).tolist(),
            "multipliers": [[float(z.real), float(z.imag)] for z in np.asarray(self.multipliers)],
            "stable": bool(self.stable), "instability": self.instability,
            "residual": float(self.residual), "n_seeds": int(self.n_seeds), "t0": float(self.t0),
        }


@dataclasses.dataclass(frozen=True)
class OrbitSearch:
    """Result of :func:`find_periodic_orbits` (paper §4.1): the distinct orbits and every shot.

    Saves to netCDF with :meth:`save` (reload with :func:`load_orbits` or
    :func:`jaxgear.load`; open with ``xarray.open_dataset``).

    Attributes:
        orbits: distinct orbits found, sorted by period then first coordinate.
        shots: ``{k: ShootResult}`` the per-seed results for each ``k`` tried (numpy
            arrays, leading dimension the seeds).
        status_counts: number of seeds per Newton status name, over all ``k``.
        seeds: ``{k: (n_k, dim)}`` the seeds shot for each ``k``.
        system: the system's name; state_names: its coordinate names;
        section_index: its default section coordinate (or ``None``).
        params: the full parameter set as a dict (canonical names for the gear models).
        settings: the options of the search (tolerances, integrator, ``t0``, ...), JSON-able.
        version: jaxgear version; runtime_s: wall time of the search (s).
    """

    orbits: tuple[PeriodicOrbit, ...]
    shots: dict[int, ShootResult]
    status_counts: dict[str, int]
    seeds: dict[int, np.ndarray] = dataclasses.field(default_factory=dict)
    system: str = ""
    state_names: tuple[str, ...] = ()
    section_index: int | None = None
    params: dict = dataclasses.field(default_factory=dict)
    settings: dict = dataclasses.field(default_factory=dict)
    version: str = ""
    runtime_s: float = float("nan")

    @property
    def n_seeds(self) -> int:
        """Seed runs over all ``k``."""
        return int(sum(np.asarray(r.status).size for r in self.shots.values()))

    def table(self) -> str:
        """Printable table: one row per orbit (period, stability, max |multiplier|, first point)."""
        from ._params import format_table

        names = self.state_names or tuple(f"x{i + 1}" for i in range(self._dim()))
        rows = [(i, f"P-{o.period}", "stable" if o.stable else f"unstable ({o.instability})",
                 f"{o.max_multiplier:.4f}", "[" + ", ".join(f"{v:.4f}" for v in o.points[0]) + "]",
                 f"{o.residual:.1e}", o.n_seeds) for i, o in enumerate(self.orbits)]
        head = ("orbit", "period", "stability", "max |multiplier|", "point (" + ", ".join(names) + ")",
                "residual", "seeds")
        return format_table(rows, head)

    def _dim(self) -> int:
        for o in self.orbits:
            return int(np.shape(o.points)[-1])
        for X in self.seeds.values():
            return int(np.shape(X)[-1])
        return len(self.state_names)

    def summary(self) -> dict[str, Any]:
        """Everything but the per-seed arrays and trajectories, JSON-able."""
        return dict(
            jaxgear_type="OrbitSearch", system=self.system, state_names=list(self.state_names),
            params=self.params, settings=self.settings, n_seeds=self.n_seeds,
            status_counts=dict(self.status_counts), orbits=[o.to_dict() for o in self.orbits],
            runtime_s=self.runtime_s, version=self.version,
        )

    # ---------------------------------------------------------------- I/O
    def to_xarray(self):
        """The search as an ``xarray.Dataset``.

        Orbits along dimension ``orbit`` (``points (orbit, point, state)``, NaN-padded to
        the longest period; ``multipliers_real/imag (orbit, multiplier)``; ``trajectory
        (orbit, sample, state)``), the shots of each ``k`` as ``shot_k{k}_<field>`` over
        ``seed_k{k}``; coordinate ``state`` holds the state names; parameters, settings
        and status counts as JSON attributes, scalar parameters also as ``param_<name>``.
        """
        import xarray as xr

        dim = self._dim()
        names = list(self.state_names) or [f"x{i + 1}" for i in range(dim)]
        O = self.orbits
        mmax = max([len(o.points) for o in O] + [1])
        smax = max([0 if o.trajectory is None else len(o.trajectory) for o in O] + [1])
        pts = np.full((len(O), mmax, dim), np.nan)
        traj = np.full((len(O), smax, dim), np.nan)
        for i, o in enumerate(O):
            pts[i, : len(o.points)] = o.points
            if o.trajectory is not None:
                traj[i, : len(o.trajectory)] = o.trajectory
        lam = np.array([np.asarray(o.multipliers, dtype=complex) for o in O]).reshape(len(O), dim)
        su = {"units": "state units (lengths in b_c, velocities in b_c omega_n for the gear models)"}
        data = {
            "period": ("orbit", np.array([o.period for o in O], dtype=np.int64),
                       {"description": "minimal period m (forcing periods)"}),
            "points": (("orbit", "point", "state"), pts,
                       {"description": "stroboscopic points x*, P(x*), ..., P^(m-1)(x*) at t0 + jT", **su}),
            "multipliers_real": (("orbit", "multiplier"), lam.real.copy(), {"description": "Floquet multipliers"}),
            "multipliers_imag": (("orbit", "multiplier"), lam.imag.copy(), {"description": "Floquet multipliers"}),
            "multipliers_abs": (("orbit", "multiplier"), np.abs(lam), {"description": "|Floquet multiplier|"}),
            "stable": ("orbit", np.array([o.stable for o in O], dtype=bool)),
            "instability": ("orbit", np.array([o.instability for o in O], dtype=object),
                            {"description": "stable, fold, flip or neimark-sacker"}),
            "residual": ("orbit", np.array([o.residual for o in O], dtype=float), {"description": "||P^k(x) - x||"}),
            "n_seeds": ("orbit", np.array([o.n_seeds for o in O], dtype=np.int64)),
            "t0": ("orbit", np.array([o.t0 for o in O], dtype=float), {"units": "system time unit"}),
            "trajectory_length": ("orbit", np.array([0 if o.trajectory is None else len(o.trajectory) for o in O],
                                                    dtype=np.int64)),
            "trajectory": (("orbit", "sample", "state"), traj,
                           {"description": "the orbit sampled over its m periods from points[0] at t0", **su}),
        }
        for k, res in sorted(self.shots.items()):
            s, kd, hd = f"seed_k{k}", f"step_k{k}", f"newton_step_k{k}"
            seeds = np.asarray(self.seeds.get(k, np.full((np.asarray(res.status).size, dim), np.nan)), dtype=float)
            lamk = np.asarray(res.multipliers)
            fields = {
                "seeds": ((s, "state"), seeds), "point": ((s, "state"), res.point),
                "orbit": ((s, kd, "state"), res.orbit), "min_period": (s, res.min_period),
                "monodromy": ((s, "state", "state_from"), res.monodromy),
                "multipliers_real": ((s, "multiplier"), lamk.real.copy()),
                "multipliers_imag": ((s, "multiplier"), lamk.imag.copy()),
                "stable": (s, res.stable), "instability": (s, res.instability), "residual": (s, res.residual),
                "iterations": (s, res.iterations), "status": (s, res.status), "history": ((s, hd), res.history),
                "last_iterate": ((s, "state"), res.last_iterate),
            }
            for f, (dims, arr) in fields.items():
                data[f"shot_k{k}_{f}"] = (dims, np.asarray(arr))
        coords = {"state": ("state", names), "state_from": ("state_from", names)}
        attrs = dict(
            jaxgear_type="OrbitSearch", title="jaxgear periodic orbits (shooting)", system=self.system,
            state_names=json.dumps(list(self.state_names)), section_index=json.dumps(self.section_index),
            params=json.dumps(self.params), settings=json.dumps(self.settings),
            status_counts=json.dumps(self.status_counts), shot_periods=json.dumps(sorted(int(k) for k in self.shots)),
            version=self.version, runtime_s=float(self.runtime_s),
            status_codes=json.dumps({str(c): n for c, n in SHOOT_STATUS_NAMES.items()}),
            instability_codes=json.dumps({str(c): n for c, n in INSTABILITY_NAMES.items()}),
            units="state units of the system; time in the system's unit (dimensionless for the gear models, "
                  "MODEL.md §3)",
        )
        for name, v in self.params.items():
            if np.ndim(v) == 0:
                attrs[f"param_{name}"] = v
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path: str | Path) -> Path:
        """Write the search to a netCDF file (atomically); reload with :func:`load_orbits`."""
        from ._io import _write_netcdf

        return _write_netcdf(self.to_xarray(), path)

    def write_summary(self, path: str | Path) -> Path:
        """Write :meth:`summary` as JSON."""
        from ._io import _write_json

        return _write_json(self.summary(), path)


def _complex(re: np.ndarray, im: np.ndarray) -> np.ndarray:
    z = np.empty(re.shape, dtype=np.complex128)
    z.real = re
    z.imag = im
    return z


def load_orbits(path: str | Path) -> OrbitSearch:
    """Load an :class:`OrbitSearch` saved with :meth:`OrbitSearch.save` (exact round trip:
    arrays bit-for-bit with their dtypes, metadata equal)."""
    from ._io import _check_type, _read_netcdf

    ds = _read_netcdf(path)
    _check_type(ds, "OrbitSearch", path)
    if ds.attrs.get("jaxgear_type") != "OrbitSearch":
        raise ValueError(f"{path} is not an OrbitSearch file (no attrs['jaxgear_type'] = 'OrbitSearch').")
    v = lambda name: ds[name].values
    orbits = []
    for i in range(ds.sizes.get("orbit", 0)):
        m = int(v("period")[i])
        n_traj = int(v("trajectory_length")[i])
        orbits.append(PeriodicOrbit(
            points=v("points")[i, :m], period=m,
            multipliers=_complex(v("multipliers_real")[i], v("multipliers_imag")[i]),
            stable=bool(v("stable")[i]), instability=str(v("instability")[i]), residual=float(v("residual")[i]),
            n_seeds=int(v("n_seeds")[i]), t0=float(v("t0")[i]),
            trajectory=v("trajectory")[i, :n_traj] if n_traj else None,
        ))
    shots, seeds = {}, {}
    for k in json.loads(ds.attrs["shot_periods"]):
        g = lambda f: v(f"shot_k{k}_{f}")
        shots[k] = ShootResult(
            point=g("point"), orbit=g("orbit"), min_period=g("min_period"), monodromy=g("monodromy"),
            multipliers=_complex(g("multipliers_real"), g("multipliers_imag")), stable=g("stable"),
            instability=g("instability"), residual=g("residual"), iterations=g("iterations"), status=g("status"),
            history=g("history"), last_iterate=g("last_iterate"),
        )
        seeds[k] = g("seeds")
    return OrbitSearch(
        orbits=tuple(orbits), shots=shots, status_counts=json.loads(ds.attrs["status_counts"]), seeds=seeds,
        system=str(ds.attrs["system"]), state_names=tuple(json.loads(ds.attrs["state_names"])),
        section_index=json.loads(ds.attrs["section_index"]), params=json.loads(ds.attrs["params"]),
        settings=json.loads(ds.attrs["settings"]), version=str(ds.attrs["version"]),
        runtime_s=float(ds.attrs["runtime_s"]),
    )


def _same_orbit(a: PeriodicOrbit, b: PeriodicOrbit, tol: float) -> bool:
    if a.period != b.period:
        return False
    d = np.linalg.norm(np.asarray(b.points) - np.asarray(a.points)[0], axis=1)
    return bool(np.min(d) <= tol * (1.0 + np.linalg.norm(a.points[0])))


def _orbits_from_shots(res: ShootResult, dedup_tol: float, t0: float = 0.0) -> list[PeriodicOrbit]:
    st = np.asarray(res.status).reshape(-1)
    conv = np.flatnonzero(st == SHOOT_CONVERGED)
    if conv.size == 0:
        return []
    k = res.orbit.shape[-2]
    dim = res.orbit.shape[-1]
    orbit = np.asarray(res.orbit).reshape(-1, k, dim)[conv]
    mper = np.asarray(res.min_period).reshape(-1)[conv]
    lam = np.asarray(res.multipliers).reshape(-1, dim)[conv]
    stab = np.asarray(res.stable).reshape(-1)[conv]
    kind = np.asarray(res.instability).reshape(-1)[conv]
    resid = np.asarray(res.residual).reshape(-1)[conv]
    # canonical point of each lane: the orbit point with the smallest first coordinate
    ic = np.argmin(orbit[..., 0], axis=1)
    canon = orbit[np.arange(len(conv)), ic]
    d = np.linalg.norm(canon[:, None, :] - canon[None, :, :], axis=-1)
    scale = 1.0 + np.linalg.norm(canon, axis=-1)
    same = (d <= dedup_tol * scale[:, None]) & (mper[:, None] == mper[None, :])
    label = np.argmax(same, axis=1)  # first lane equal to each lane
    out = []
    for rep in np.unique(label):  # a handful of distinct orbits
        members = np.flatnonzero(label == rep)
        best = members[np.argmin(resid[members])]
        m = int(mper[best])
        pts = orbit[best, :m]
        pts = np.roll(pts, -int(np.argmin(pts[:, 0])), axis=0)
        out.append(PeriodicOrbit(points=pts, period=m, multipliers=lam[best],
                                 stable=bool(stab[best]), instability=INSTABILITY_NAMES[int(kind[best])],
                                 residual=float(resid[best]), n_seeds=int(members.size), t0=float(t0)))
    return out


def _merge_orbits(orbits: Sequence[PeriodicOrbit], dedup_tol: float) -> list[PeriodicOrbit]:
    merged: list[PeriodicOrbit] = []
    for o in orbits:
        for i, q in enumerate(merged):
            if _same_orbit(o, q, dedup_tol):
                keep = o if o.residual < q.residual else q
                merged[i] = dataclasses.replace(keep, n_seeds=o.n_seeds + q.n_seeds)
                break
        else:
            merged.append(o)
    merged.sort(key=lambda o: (o.period, float(o.points[0, 0])))
    return merged


def _with_trajectories(system, params, orbits: list[PeriodicOrbit], samples: int, integrator) -> list[PeriodicOrbit]:
    """Attach to each orbit its trajectory over its ``m`` periods (one batched integration)."""
    if not orbits or samples < 1:
        return orbits
    by_t0: dict[float, list[int]] = {}
    for i, o in enumerate(orbits):
        by_t0.setdefault(float(o.t0), []).append(i)
    out = list(orbits)
    for t0, idx in by_t0.items():
        mmax = max(orbits[i].period for i in idx)
        starts = np.stack([orbits[i].points[0] for i in idx])
        _, states = sample_trajectory(system, params, starts, periods=mmax, samples_per_period=samples, t0=t0,
                                      integrator=integrator)
        states = np.asarray(states)
        for j, i in enumerate(idx):
            out[i] = dataclasses.replace(orbits[i], trajectory=states[j, : orbits[i].period * samples + 1])
    return out


def _check_newton_options(tol, max_iter, period_tol) -> None:
    if not (tol > 0):
        raise ValueError(f"tol={tol} must be > 0.")
    if int(max_iter) < 1:
        raise ValueError(f"max_iter={max_iter} must be >= 1.")
    if not (period_tol > 0):
        raise ValueError(f"period_tol={period_tol} must be > 0.")


def find_periodic_orbits(system: ForcedSystem, params, seeds, *, period: int | Sequence[int] = 1, t0=0.0,
                         integrator: Integrator = RK4(), tol: float = 1e-10, max_iter: int = 40,
                         max_norm: float = 1e6, period_tol: float = 1e-6, dedup_tol: float = 1e-6,
                         chunk_size: int = 256, progress: bool = True,
                         trajectory_samples: int = 200) -> OrbitSearch:
    """Shoot from many seeds and return the distinct periodic orbits (paper §4.1, ref. [15]).

    For every ``k`` and every seed, damped Newton on ``G(x) = P^k(x) - x = 0`` (the
    k-fold stroboscopic map of paper eq. 6, full state) with the Jacobian from
    ``jax.jacfwd`` (see :func:`periodic_orbit`); then the Floquet multipliers of each
    converged orbit (its minimal period ``m``), and the converged seeds deduplicated
    into distinct orbits. Seeds are processed in chunks of ``chunk_size`` (one compiled
    shape per ``k``, ``vmap`` over the chunk): memory is bounded by the chunk, and the
    result does not depend on ``chunk_size``. The system and parameters are checked
    once on entry (:func:`~jaxgear.check_system`).

    Args:
        system: a :class:`~jaxgear.ForcedSystem` of state dimension ``dim``.
        params: its parameter pytree (not batched), e.g. :func:`jaxgear.paper_params`.
        seeds: ``(n, dim)`` array of states at phase ``t0`` (state units; shot for
            every ``k`` in ``period``), or a mapping ``{k: (n_k, dim)}`` such as
            :func:`seeds_from_result` returns.
        period: ``k`` or a sequence of ``k`` (forcing periods; ignored when ``seeds``
            is a mapping).
        t0: phase of the stroboscopic section (system time unit; the gear models use
            dimensionless time ``omega_n t``).
        integrator: :class:`~jaxgear.RK4` (default 200 steps per period) or
            :class:`~jaxgear.Adaptive`.
        tol: convergence on ``||P^k(x) - x||`` (Euclidean, state units).
        max_iter, max_norm, period_tol: as in :func:`periodic_orbit`.
        dedup_tol: two converged seeds give the same orbit when a point of one lies
            within ``dedup_tol * (1 + ||x||)`` of a point of the other (any cyclic
            shift); an orbit found with several multiples of its period is reported
            once, with its minimal period.
        chunk_size: seeds per batch (>= 1).
        progress: show a progress bar (tqdm, with time left); ``False`` silences it.
        trajectory_samples: samples per forcing period of each orbit's stored
            trajectory (:attr:`PeriodicOrbit.trajectory`, used by
            :func:`jaxgear.plotting.plot_orbit` without integrating); 0 stores none.
    Returns:
        :class:`OrbitSearch`: ``orbits`` (distinct, sorted by period), ``shots``
        ``{k: ShootResult}`` with leading shape ``(n_k,)``, ``status_counts``, the
        seeds, the parameter set and the settings.
    Raises:
        ValueError: seeds not of shape ``(n, dim)`` or not finite, ``k < 1``, bad
            options, or a system/parameter set that fails :func:`~jaxgear.check_system`.
    """
    from . import __version__
    from ._cellmap import _chunks, _pad, _progress, _pytree_dict

    start = time.perf_counter()
    if isinstance(seeds, Mapping):
        groups = {_check_period(k): np.asarray(v, dtype=float) for k, v in seeds.items()}
    else:
        ks = [period] if isinstance(period, (int, np.integer)) else list(period)
        if not ks:
            raise ValueError("period must name at least one k >= 1.")
        groups = {_check_period(k): np.asarray(seeds, dtype=float) for k in ks}
    if not groups:
        raise ValueError("no seeds: give an (n, dim) array or a non-empty mapping {k: (n_k, dim)}.")
    for k, X in groups.items():
        if X.ndim != 2 or X.shape[1] != system.dim or len(X) == 0:
            raise ValueError(f"seeds for period {k} must have shape (n, {system.dim}) with n >= 1 "
                             f"({', '.join(system.state_names)}), got {X.shape}.")
        check_state_shape(system, X)
    _check_newton_options(tol, max_iter, period_tol)
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size={chunk_size} must be >= 1.")
    if int(trajectory_samples) < 0:
        raise ValueError(f"trajectory_samples={trajectory_samples} must be >= 0.")
    first = next(iter(groups.values()))[0]
    check_system(system, params, first)

    t0_arr = jnp.asarray(t0, jnp.float64)
    shots: dict[int, ShootResult] = {}
    found: list[PeriodicOrbit] = []
    counts = {name: 0 for name in SHOOT_STATUS_NAMES.values()}
    bar = _progress(sum(len(X) for X in groups.values()), "shooting", progress, unit="seed")
    try:
        for k, X in sorted(groups.items()):  # one jit per distinct k (and chunk shape)
            size = min(int(chunk_size), len(X))
            parts = []
            for a, b in _chunks(len(X), size):
                res = _shoot_kernel(system, params, jnp.asarray(_pad(X[a:b], size)), t0_arr, k, integrator,
                                    float(tol), int(max_iter), float(max_norm), float(period_tol))
                parts.append([np.asarray(f)[: b - a] for f in res])
                bar.update(b - a)
            res = ShootResult(*[np.concatenate(f, axis=0) for f in zip(*parts)])
            shots[k] = res
            for code, name in SHOOT_STATUS_NAMES.items():
                counts[name] += int(np.sum(res.status == code))
            found.extend(_orbits_from_shots(res, dedup_tol, float(t0)))
    finally:
        bar.close()
    orbits = _with_trajectories(system, params, _merge_orbits(found, dedup_tol), int(trajectory_samples), integrator)
    settings: dict[str, Any] = dict(
        periods=sorted(groups), t0=float(t0), integrator=type(integrator).__name__,
        steps_per_period=getattr(integrator, "steps_per_period", None), rtol=getattr(integrator, "rtol", None),
        atol=getattr(integrator, "atol", None), tol=float(tol), max_iter=int(max_iter), max_norm=float(max_norm),
        period_tol=float(period_tol), dedup_tol=float(dedup_tol), chunk_size=int(chunk_size),
        trajectory_samples=int(trajectory_samples),
    )
    params_dict = _pytree_dict(params)
    return OrbitSearch(orbits=tuple(orbits), shots=shots, status_counts=counts, seeds=groups, system=system.name,
                       state_names=tuple(system.state_names), section_index=system.section_index,
                       params=params_dict, settings=settings, version=__version__,
                       runtime_s=time.perf_counter() - start)


# --------------------------------------------------------------------------- verification
class OrbitCheck(NamedTuple):
    """Result of :func:`verify_orbit` (the paper's check by direct integration, §4.1).

    Distances and points in state units; periods counted in forcing periods.

    Attributes:
        kept: True when every perturbed start stayed within ``leave_tol`` of the orbit
            over the whole integration.
        left_at: ``(n_trials,)`` first period at which the distance exceeded
            ``leave_tol`` (-1 if never).
        distance: ``(n_trials, periods)`` distance of ``P^n(x0 + e)`` to the nearest
            orbit point, ``n = 1..periods`` (``inf`` after a blow-up).
        final_points: ``(n_trials, n_final, dim)`` the last stroboscopic points of each
            trial (NaN if the motion blew up), to match against attractors.
        diverged: ``(n_trials,)`` the integration blew up.
    """

    kept: bool
    left_at: np.ndarray
    distance: np.ndarray
    final_points: np.ndarray
    diverged: np.ndarray


def verify_orbit(system: ForcedSystem, params, orbit, *, periods: int = 300, perturbation: float = 1e-6,
                 n_trials: int = 4, leave_tol: float = 1e-3, n_final: int = 8, seed: int = 0, t0=0.0,
                 integrator: Integrator = RK4()) -> OrbitCheck:
    """Check an orbit by direct integration from perturbed starts (paper §4.1).

    Starts at ``points[0] + perturbation * (1 + ||points[0]||) * u`` for ``n_trials``
    random unit vectors ``u`` at phase ``t0``, integrates ``periods`` forcing periods
    (one batched call) and measures the distance of each stroboscopic point to the
    nearest point of the orbit. An asymptotically stable orbit keeps the motion, an
    unstable one is left (the perturbation grows like ``|lambda_max|^n``).

    Args:
        orbit: a :class:`PeriodicOrbit`, or its points ``(m, dim)`` at phase ``t0``.
        periods: forcing periods integrated per trial.
        perturbation: relative size of the initial perturbation (dimensionless).
        leave_tol: distance (state units) above which the motion has left the orbit.
        n_final: number of final stroboscopic points returned per trial.
        t0: phase of the orbit's points (system time unit).
    Returns:
        :class:`OrbitCheck` (``distance`` of shape ``(n_trials, periods)``,
        ``final_points`` ``(n_trials, n_final, dim)``).
    """
    pts = np.asarray(getattr(orbit, "points", orbit), dtype=float)
    if pts.ndim == 1:
        pts = pts[None]
    check_state_shape(system, pts)
    if int(periods) < 1 or int(n_trials) < 1 or not (1 <= int(n_final) <= int(periods)):
        raise ValueError("need periods >= 1, n_trials >= 1 and 1 <= n_final <= periods.")
    if not (perturbation >= 0 and leave_tol > 0):
        raise ValueError("perturbation must be >= 0 and leave_tol > 0.")
    u = np.array(jax.random.normal(jax.random.PRNGKey(int(seed)), (int(n_trials), system.dim), jnp.float64))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    x0 = pts[0] + perturbation * (1.0 + np.linalg.norm(pts[0])) * u
    traj = np.asarray(stroboscopic_orbit(system, params, x0, n_points=int(periods), t0=t0, integrator=integrator))
    dist = np.min(np.linalg.norm(traj[:, :, None, :] - pts[None, None], axis=-1), axis=-1)
    dist = np.where(np.isfinite(dist), dist, np.inf)
    out = dist > leave_tol
    left_at = np.where(out.any(axis=1), np.argmax(out, axis=1) + 1, -1)
    diverged = ~np.all(np.isfinite(traj), axis=(1, 2))
    return OrbitCheck(kept=bool(np.all(left_at < 0)), left_at=left_at, distance=dist,
                      final_points=traj[:, -int(n_final):], diverged=diverged)
