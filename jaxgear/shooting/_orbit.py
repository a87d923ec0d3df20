"""Shooting: a P-k orbit as a fixed point of the k-fold stroboscopic map (paper §4.1).

For a forced system (paper eq. 6) with period ``T`` a P-k motion is a fixed point of

    G(x) = P^k(x) - x = 0,    P^k: x(t0) -> x(t0 + k T)   (full state, model document §6),

solved by an optimistix root finder with the Jacobian from ``jax.jacfwd`` through the
integrator, batched over seeds with ``vmap``; each seed returns a :class:`~jaxgear.Status`
instead of a wrong orbit. The converged point is differentiable with respect to the
parameters by the implicit function theorem (the iterations are not unrolled).
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from .._checks import is_traced
from .._status import Status
from .._system import ForcedSystem, check_state_shape, check_system
from ..integrate import AbstractIntegrator, resolve_integrator
from ._floquet import Instability, check_period, classify_multipliers, orbit_jacobians, sorted_eigvals
from ._options import ShootOptions, with_changes
from ._solve import Shooting, check_segments, solve_orbit

__all__ = ["ShootResult", "periodic_orbit", "shoot_kernel", "check_shooting", "params_concrete"]


class ShootResult(NamedTuple):
    """Per-seed result of :func:`periodic_orbit` (leading shape ``...`` = the seeds'), paper §4.1.

    States are in state units at time ``t0`` (system time unit), residuals in state
    units, multipliers dimensionless.

    Lanes that did not converge hold NaN in ``point``, ``orbit``, ``monodromy`` and
    ``multipliers``; their ``status`` says why and ``last_iterate`` where Newton stopped.
    Only ``point`` carries derivatives with respect to the parameters (implicit
    function theorem); the other fields are diagnostics. For derivatives of the
    multipliers use :func:`floquet_multipliers` at ``point``.

    The fields are plain ``jax.Array`` annotations (the result codec reads them); their
    shapes are given here.

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
        iterations: ``(...)`` solver iterations taken.
        status: ``(...)`` int, ``Status.CONVERGED`` .. ``Status.DIVERGED``.
        history: ``(..., max_iter + 1)`` the final residual at index ``iterations``, NaN
            elsewhere (optimistix does not expose its intermediate iterates).
        last_iterate: ``(..., dim)`` the solver's last iterate (for failure diagnosis;
            chain ``max_iter=1`` solves through it to follow the iteration).
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


def _floquet_result(shoot: Shooting, params, t0, x, period_tol, solved) -> ShootResult:
    """The :class:`ShootResult` of a solve: Floquet data at the converged point ``x``.

    ``solved = (status, iterations, residual, history, last_iterate)``; the orbit points and
    the Jacobians of ``P^1 .. P^k`` come from :func:`orbit_jacobians` (NaN where the solve
    did not converge)."""
    st, it, r, hist, last = solved
    k = shoot.k
    xs = jax.lax.stop_gradient(x)
    conv = st == Status.CONVERGED
    _, pts, Cs = orbit_jacobians(shoot.system, params, jnp.where(conv, xs, 0.0), t0, k, shoot.integrator)
    nan = jnp.nan
    m = _minimal_period(pts, xs, k, period_tol)
    M = jnp.take(Cs, m - 1, axis=0)
    lam = jnp.where(conv, sorted_eigvals(jnp.where(conv, M, 0.0)), nan)
    stable, kind = classify_multipliers(lam)
    return ShootResult(
        point=jnp.where(conv, x, nan), orbit=jnp.where(conv, pts, nan), min_period=jnp.where(conv, m, 0),
        monodromy=jnp.where(conv, M, nan), multipliers=lam, stable=stable & conv,
        instability=jnp.where(conv, kind, int(Instability.UNKNOWN)), residual=r, iterations=it, status=st,
        history=hist, last_iterate=last,
    )


def _shoot_one(shoot: Shooting, params, t0, x0, known, options: ShootOptions) -> ShootResult:
    """Solve from one seed ``x0 (dim,)`` and analyse the orbit (one lane of :func:`shoot_kernel`)."""
    x, st, it, r, last = solve_orbit(shoot, params, t0, x0, known, options)
    st = st.astype(jnp.int32)
    it = jnp.asarray(it, jnp.int32)
    # optimistix does not expose its iterates: the history holds the final residual only
    hist = jnp.full(options.max_iter + 1, jnp.nan).at[jnp.clip(it, 0, options.max_iter)].set(r)
    return _floquet_result(shoot, params, t0, x, options.period_tol, (st, it, r, hist, last))


@eqx.filter_jit
def shoot_kernel(shoot: Shooting, params, X, t0, known, options: ShootOptions) -> ShootResult:
    """:func:`_shoot_one` over the seeds ``X (n, dim)`` (``vmap``; one compiled shape per
    problem, options and batch size). ``known``: ``(R, dim)`` points deflated away, or ``None``."""
    return jax.vmap(lambda x0: _shoot_one(shoot, params, t0, x0, known, options))(X)


def params_concrete(params) -> bool:
    """True when no parameter leaf is a tracer (the parameters can be checked concretely)."""
    return not any(is_traced(leaf) for leaf in jax.tree_util.tree_leaves(params))


def check_shooting(system, integrator, k: int, options: ShootOptions) -> Shooting:
    """The :class:`~._solve.Shooting` problem of a P-k orbit, its segments checked against
    ``integrator`` (``ValueError`` when ``options.segments`` does not split the orbit)."""
    return Shooting(system, integrator, k, check_segments(integrator, k, options.segments))


def periodic_orbit(system: ForcedSystem, params, x0: Float[ArrayLike, "*batch dim"], *, period: int = 1, t0=0.0,
                   integrator: AbstractIntegrator | None = None, options: ShootOptions | None = None,
                   deflate: Float[ArrayLike, "r dim"] | None = None, **changes) -> ShootResult:
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
    (a custom JVP at the root; the iterations are not unrolled):
    ``dx*/dp = -(DP^k - I)^{-1} dP^k/dp``.

    Args:
        system: any :class:`~jaxgear.ForcedSystem`.
        params: its parameter pytree (not batched).
        x0: seeds, shape ``(..., dim)`` (state units, at time ``t0``).
        period: ``k`` (forcing periods per return, int >= 1).
        t0: phase of the stroboscopic section (time at which the points are taken).
        integrator: default :func:`~jaxgear.integrate.default_integrator`; the residual
            is that of this integrator's discrete map.
        options: :class:`ShootOptions` (solver, tolerances, iteration limit, segments,
            deflation operator); ``None``: the defaults.
        deflate: optional ``(R, dim)`` known orbit points (phase ``t0``) that the solver
            is deflated away from (Farrell-Birkisson-Funke operator
            ``prod (1/||x - r_i||^p + shift)``; non-finite rows are ignored).
        **changes: fields of ``options`` to change, e.g. ``tol=1e-12, max_iter=20``.
    Returns:
        :class:`ShootResult` with the leading shape of ``x0``.
    Raises:
        ValueError: wrong state shape, non-finite seeds, ``period < 1``, bad options.
    """
    k = check_period(period)
    check_state_shape(system, x0)
    options = with_changes(options, ShootOptions, changes)
    integrator = resolve_integrator(integrator)
    shoot = check_shooting(system, integrator, k, options)
    known = None if deflate is None else jnp.asarray(deflate, jnp.float64).reshape(-1, system.dim)
    if params_concrete(params):
        check_system(system, params, np.asarray(x0, dtype=float).reshape(-1, system.dim)[0], batched=False)
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    lead = x0.shape[:-1]
    res = shoot_kernel(shoot, params, x0.reshape(-1, system.dim), jnp.asarray(t0, jnp.float64), known,
                       options.shoot_options())
    return jax.tree_util.tree_map(lambda a: a.reshape(*lead, *a.shape[1:]), res)
