"""Shooting: a P-k orbit as a fixed point of the k-fold stroboscopic map (paper §4.1).

For a forced system (paper eq. 6) with period ``T`` a P-k motion is a fixed point of

    G(x) = P^k(x) - x = 0,    P^k: x(t0) -> x(t0 + k T)   (full state, model document §6),

solved by Newton's method with the Jacobian from ``jax.jacfwd`` through the integrator,
batched over seeds with ``vmap``; each seed returns a :class:`~jaxgear.Status` instead of
a wrong orbit. The converged point is differentiable with respect to the parameters by
the implicit function theorem (Newton is not unrolled).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_int, check_number, is_traced
from .._status import Status
from .._system import ForcedSystem, check_state_shape, check_system
from ..integrate import AbstractIntegrator, resolve_integrator
from ._floquet import Instability, check_period, classify_multipliers, sorted_eigvals
from ._newton import damped_newton, orbit_jacobians
from ._solve import SOLVERS, Shooting, check_segments, solve_orbit

__all__ = ["ShootResult", "periodic_orbit", "default_solver", "shoot_kernel", "check_newton_options", "check_solver_options",
           "params_concrete"]


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
        status: ``(...)`` int, ``Status.CONVERGED`` .. ``Status.DIVERGED``.
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


def _minimal_period(pts, x, k, period_tol):
    """Smallest divisor ``j`` of ``k`` with ``||P^j(x) - x|| <= period_tol (1 + ||x||)``, else ``k``."""
    scale = 1.0 + jnp.linalg.norm(x)
    m = jnp.asarray(k)
    for j in sorted((d for d in range(1, k) if k % d == 0), reverse=True):
        m = jnp.where(jnp.linalg.norm(pts[j] - x) <= period_tol * scale, j, m)
    return m


def _floquet_result(system, params, x, t0, k, integrator, period_tol, r, it, st, hist):
    """The :class:`ShootResult` of a solve: Floquet data at the converged point ``x``."""
    xs = jax.lax.stop_gradient(x)
    conv = st == Status.CONVERGED
    _, pts, Cs = orbit_jacobians(system, params, jnp.where(conv, xs, 0.0), t0, k, integrator)
    return _result_at(x, pts, Cs, k, period_tol, r, it, st, hist)


def _result_at(x, pts, Cs, k, period_tol, r, it, st, hist):
    """The :class:`ShootResult` at ``x`` from its orbit points ``pts`` and the Jacobians
    ``Cs`` of ``P^1 .. P^k`` there (NaN where the solve did not converge)."""
    xs = jax.lax.stop_gradient(x)
    conv = st == Status.CONVERGED
    nan = jnp.nan
    m = _minimal_period(pts, xs, k, period_tol)
    M = jnp.take(Cs, m - 1, axis=0)
    lam = jnp.where(conv, sorted_eigvals(jnp.where(conv, M, 0.0)), nan)
    stable, kind = classify_multipliers(lam)
    return ShootResult(
        point=jnp.where(conv, x, nan), orbit=jnp.where(conv, pts, nan), min_period=jnp.where(conv, m, 0),
        monodromy=jnp.where(conv, M, nan), multipliers=lam, stable=stable & conv,
        instability=jnp.where(conv, kind, int(Instability.UNKNOWN)), residual=r, iterations=it, status=st,
        history=hist, last_iterate=xs,
    )


def _shoot_damped(system, params, x0, t0, k, integrator, tol, max_iter, max_norm, period_tol):
    """The hand-written damped Newton (solver ``"damped-newton"``, single shooting)."""
    flow_k = lambda x: integrator.flow(system, params, x, t0, k)
    G = lambda x: flow_k(x) - x
    evaluate = lambda x: orbit_jacobians(system, params, x, t0, k, integrator)

    def solve(f, guess):  # f is G; Newton uses the same map through evaluate/flow_k
        x, (r, it, st, hist, pts, Cs) = damped_newton(evaluate, flow_k, guess, k, tol, max_iter, max_norm)
        # integer aux outputs break custom_root's JVP rule (jax 0.10): carry them as floats
        return x, (r, it.astype(jnp.float64), st.astype(jnp.float64), hist, pts, Cs)

    def tangent_solve(g, y):
        return jnp.linalg.solve(jax.jacfwd(g)(y), y)

    x, (r, it, st, hist, pts, Cs) = jax.lax.custom_root(G, x0, solve, tangent_solve, has_aux=True)
    return _result_at(x, pts, Cs, k, period_tol, r, it.astype(jnp.int32), st.astype(jnp.int32), hist)


def _shoot_one(system, params, x0, t0, k, integrator, tol, max_iter, max_norm, period_tol, solver="damped-newton",
               segments=1, known=None, power=2.0, shift=1.0):
    if solver == "damped-newton":
        return _shoot_damped(system, params, x0, t0, k, integrator, tol, max_iter, max_norm, period_tol)
    shoot = Shooting(system, integrator, k, segments)
    x, st, it, r = solve_orbit(shoot, params, t0, x0, known, solver=solver, tol=tol, max_iter=max_iter,
                               max_norm=max_norm, power=power, shift=shift)
    st = st.astype(jnp.int32)
    it = jnp.asarray(it, jnp.int32)
    # optimistix does not expose its iterates: the history holds the final residual only
    hist = jnp.full(max_iter + 1, jnp.nan).at[jnp.clip(it, 0, max_iter)].set(r)
    return _floquet_result(system, params, x, t0, k, integrator, period_tol, r, it, st, hist)


@eqx.filter_jit
def shoot_kernel(system, params, X, t0, k, integrator, tol, max_iter, max_norm, period_tol, solver="damped-newton",
                 segments=1, known=None, power=2.0, shift=1.0):
    one = lambda x0: _shoot_one(system, params, x0, t0, k, integrator, tol, max_iter, max_norm, period_tol,
                                solver, segments, known, power, shift)
    return jax.vmap(one)(X)


def params_concrete(params) -> bool:
    """True when no parameter leaf is a tracer (the parameters can be checked concretely)."""
    return not any(is_traced(leaf) for leaf in jax.tree_util.tree_leaves(params))


def check_newton_options(tol, max_iter, period_tol, max_norm=1e6) -> None:
    """Raise ``ValueError`` naming the first bad Newton option."""
    check_number(tol, "tol", 0, strict_min=True)
    check_int(max_iter, "max_iter", 1)
    check_number(period_tol, "period_tol", 0, strict_min=True)
    check_number(max_norm, "max_norm", 0, strict_min=True)


def default_solver(segments: int = 1, deflating: bool = False) -> str:
    """The solver used when none is given: the damped Newton for single shooting without
    deflation (as often converged as the best optimistix solver and the fastest in
    ``benchmarks/shooting.py``), the optimistix Newton otherwise."""
    return "newton" if int(segments) > 1 or deflating else "damped-newton"


def check_solver_options(solver, segments, integrator, k, deflating=False, power=2.0, shift=1.0) -> int:
    """Raise ``ValueError`` for an unknown solver, bad segments or deflation settings; return ``M``."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}.")
    M = check_segments(integrator, k, segments)
    if solver == "damped-newton" and (M != 1 or deflating):
        raise ValueError("the damped-newton solver does single shooting without deflation: "
                         "use segments=1 and no deflation, or an optimistix solver.")
    check_number(power, "deflation_power", 1, strict_min=True)
    check_number(shift, "deflation_shift", 0)
    return M


def periodic_orbit(system: ForcedSystem, params, x0, *, period: int = 1, t0=0.0,
                   integrator: AbstractIntegrator | None = None, tol: float = 1e-10, max_iter: int = 40,
                   max_norm: float = 1e6, period_tol: float = 1e-6, solver: str | None = None, segments: int = 1,
                   deflate=None, deflation_power: float = 2.0, deflation_shift: float = 1.0) -> ShootResult:
    """Shooting: a P-k orbit as a fixed point of ``P^k`` by Newton-type solvers (paper §4.1, [15]).

    Solves ``G(x) = P^k(x) - x = 0`` in the full state from each seed in ``x0`` (single
    shooting, ``segments=1``) or its multiple-shooting form with ``segments`` segments
    (continuity of the segment flows, :mod:`jaxgear.shooting._solve`), with Jacobians
    from ``jax.jacfwd`` through the integrator, by an optimistix solver under ``vmap``
    (``throw=False``: each seed ends with its own status). One ``jit``; a batch of
    hundreds of seeds is one call. Then the Floquet analysis at each converged point
    (see :class:`ShootResult`).

    The converged ``point`` is differentiable with respect to ``params``
    (``jax.grad``, ``jax.jacfwd``) by the implicit function theorem
    (``optimistix.ImplicitAdjoint``; the iterations are not unrolled):
    ``dx*/dp = -(DP^k - I)^{-1} dP^k/dp``.

    Args:
        system: any :class:`~jaxgear.ForcedSystem`.
        params: its parameter pytree (not batched).
        x0: seeds, shape ``(..., dim)``.
        period: ``k`` (forcing periods per return, int >= 1).
        t0: phase of the stroboscopic section (time at which the points are taken).
        integrator: default :func:`~jaxgear.integrate.default_integrator`; the residual
            is that of this integrator's discrete map.
        tol: convergence on ``||P^k(x) - x||`` (Euclidean, state units).
        max_iter: Newton iteration limit.
        max_norm: an iterate with ``||x|| > max_norm`` is reported as diverged.
        period_tol: ``P^j(x*) = x*`` for a divisor ``j`` of ``k`` when
            ``||P^j(x*) - x*|| <= period_tol * (1 + ||x*||)``.
        solver: ``None`` (default: :func:`default_solver`), ``"damped-newton"`` (the
            hand-written Newton with Armijo backtracking, single shooting; as often converged as the best optimistix
            solver and the fastest in ``benchmarks/shooting.py``, and it alone records
            every iteration in ``history``), or ``"newton"``, ``"dogleg"``,
            ``"levenberg-marquardt"`` (optimistix; needed for ``segments > 1`` and
            ``deflate``).
        segments: ``M``, segments of the multiple shooting (1: single shooting).
        deflate: optional ``(R, dim)`` known orbit points (phase ``t0``) that the solver
            is deflated away from (Farrell-Birkisson-Funke operator
            ``prod (1/||x - r_i||^p + shift)``; non-finite rows are ignored).
        deflation_power, deflation_shift: ``p`` and ``shift`` of that operator.
    Returns:
        :class:`ShootResult` with the leading shape of ``x0``.
    Raises:
        ValueError: wrong state shape, non-finite seeds, ``period < 1``, bad options.
    """
    k = check_period(period)
    check_state_shape(system, x0)
    check_newton_options(tol, max_iter, period_tol, max_norm)
    integrator = resolve_integrator(integrator)
    known = None if deflate is None else jnp.asarray(deflate, jnp.float64).reshape(-1, system.dim)
    solver = default_solver(segments, known is not None) if solver is None else solver
    M = check_solver_options(solver, segments, integrator, k, known is not None, deflation_power, deflation_shift)
    if params_concrete(params):
        check_system(system, params, np.asarray(x0, dtype=float).reshape(-1, system.dim)[0], batched=False)
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    lead = x0.shape[:-1]
    X = x0.reshape(-1, system.dim)
    res = shoot_kernel(system, params, X, jnp.asarray(t0, jnp.float64), k, integrator, float(tol),
                        int(max_iter), float(max_norm), float(period_tol), solver, M, known, float(deflation_power),
                        float(deflation_shift))
    return jax.tree_util.tree_map(lambda a: a.reshape(*lead, *a.shape[1:]), res)

