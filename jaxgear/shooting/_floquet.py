"""Floquet multipliers of periodic orbits: monodromy matrices by ``jax.jacfwd``, stability.

A P-k orbit is asymptotically stable when every eigenvalue of the monodromy matrix
``D P^k`` at a point of the orbit lies inside the unit circle (paper §4.1 judges the
shooting results by them); the multiplier of largest modulus says how an unstable
orbit loses stability.
"""

from __future__ import annotations

import enum

import equinox as eqx
import jax
import jax.numpy as jnp

from .._checks import check_int
from .._system import ForcedSystem, check_state_shape
from ..integrate import AbstractIntegrator, resolve_integrator

__all__ = ["Instability", "classify_multipliers", "sorted_eigvals", "monodromy", "floquet_multipliers",
           "check_period", "orbit_jacobians"]


class Instability(enum.IntEnum):
    """Stability of a periodic orbit, from its multiplier of largest modulus.

    ``UNKNOWN`` (-1, not converged), ``STABLE`` (0, all inside the unit circle),
    ``FOLD`` (1, real > 1: saddle-node type), ``FLIP`` (2, real < -1: period doubling),
    ``NEIMARK_SACKER`` (3, a complex pair outside the unit circle).
    """

    UNKNOWN = -1
    STABLE = 0
    FOLD = 1
    FLIP = 2
    NEIMARK_SACKER = 3

    @property
    def label(self) -> str:
        """``"stable"``, ``"fold"``, ``"flip"``, ``"neimark-sacker"`` or ``"unknown"``."""
        return self.name.lower().replace("_", "-")


def check_period(period) -> int:
    """``period`` (the k of a P-k orbit) as an int >= 1."""
    return check_int(period, "period", 1)


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
    kind = jnp.where(stable, int(Instability.STABLE),
                     jnp.where(real, jnp.where(jnp.real(top) > 0, int(Instability.FOLD), int(Instability.FLIP)),
                               int(Instability.NEIMARK_SACKER)))
    return stable, kind


def sorted_eigvals(M):
    """Eigenvalues of ``M (..., dim, dim)`` by decreasing modulus (complex)."""
    lam = jnp.linalg.eigvals(M)
    order = jnp.argsort(-jnp.abs(lam), axis=-1)
    return jnp.take_along_axis(lam, order, axis=-1)


def orbit_jacobians(system, params, x, t0, k, integrator):
    """Points and Jacobians along ``k`` periods from ``x (dim,)`` at ``t0``.

    Returns ``x_k = P^k(x)``, the points ``pts = (x, P(x), ..., P^{k-1}(x))`` of shape
    ``(k, dim)`` and ``Cs`` of shape ``(k, dim, dim)`` with ``Cs[j] = D P^{j+1}(x)``
    (products of one-period Jacobians from ``jax.jacfwd``; ``Cs[k-1]`` is ``DP^k``, the
    monodromy matrix of a P-k orbit through ``x``).
    """
    T = system.period(params)

    def one_period(z, i):
        def step(w):
            y = integrator.flow(system, params, w, t0 + i * T, 1)
            return y, y

        J, y = jax.jacfwd(step, has_aux=True)(z)
        return y, (z, J)

    xk, (pts, Js) = jax.lax.scan(one_period, x, jnp.arange(k, dtype=jnp.float64))

    def accumulate(C, J):
        C = J @ C
        return C, C

    _, Cs = jax.lax.scan(accumulate, jnp.eye(x.shape[0]), Js)
    return xk, pts, Cs


@eqx.filter_jit
def _monodromy_kernel(system, params, X, t0, k, integrator):
    return jax.vmap(lambda x: jax.jacfwd(lambda z: integrator.flow(system, params, z, t0, k))(x))(X)


def monodromy(system: ForcedSystem, params, x, *, period: int = 1, t0=0.0,
              integrator: AbstractIntegrator | None = None):
    """Jacobian ``D P^k(x)`` of the k-fold stroboscopic map, ``(..., dim, dim)``, by ``jax.jacfwd``.

    At a point of a P-k orbit this is the monodromy matrix; its eigenvalues are the
    Floquet multipliers (see :func:`floquet_multipliers`; paper §4.1 judges the
    stability of the shooting results by them). ``x``: states ``(..., dim)`` at time
    ``t0`` (system time unit); ``M[..., i, j] = d x_i(t0 + kT) / d x_j(t0)``
    (dimensionless when all coordinates share a unit; otherwise in their ratio).
    The derivative is through the integrator's discrete map (no finite differences).
    """
    k = check_period(period)
    check_state_shape(system, x)
    integrator = resolve_integrator(integrator)
    x = jnp.asarray(x, jnp.float64)
    lead = x.shape[:-1]
    M = _monodromy_kernel(system, params, x.reshape(-1, system.dim), jnp.asarray(t0, jnp.float64), k, integrator)
    return M.reshape(*lead, system.dim, system.dim)


def floquet_multipliers(system: ForcedSystem, params, x, *, period: int = 1, t0=0.0,
                        integrator: AbstractIntegrator | None = None):
    """Floquet multipliers (eigenvalues of :func:`monodromy`), ``(..., dim)`` complex, by decreasing modulus.

    ``x`` (shape ``(..., dim)``, at time ``t0``) should be a point of a P-k orbit (e.g.
    ``x = 0`` for the trivial orbit of a parametrically excited system); a periodic
    orbit is asymptotically stable when all ``|lambda| < 1`` (paper §4.1). Multipliers
    are dimensionless; differentiable w.r.t. ``params`` (``jax.grad`` of a modulus gives
    the sensitivity of the stability margin).
    """
    return sorted_eigvals(monodromy(system, params, x, period=period, t0=t0, integrator=integrator))

