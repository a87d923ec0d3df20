"""The paper's check of an orbit by direct integration from perturbed starts (§4.1)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._poincare import stroboscopic_orbit
from .._system import ForcedSystem, check_state_shape
from ..integrate import AbstractIntegrator
from ._options import VerifyOptions, with_changes

__all__ = ["OrbitCheck", "verify_orbit"]


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


def verify_orbit(system: ForcedSystem, params, orbit, *, t0=0.0, integrator: AbstractIntegrator | None = None,
                 options: VerifyOptions | None = None, **changes) -> OrbitCheck:
    """Check an orbit by direct integration from perturbed starts (paper §4.1).

    Starts at ``points[0] + perturbation * (1 + ||points[0]||) * u`` for ``n_trials``
    random unit vectors ``u`` at phase ``t0``, integrates ``periods`` forcing periods
    (one batched call) and measures the distance of each stroboscopic point to the
    nearest point of the orbit. An asymptotically stable orbit keeps the motion, an
    unstable one is left (the perturbation grows like ``|lambda_max|^n``).

    Args:
        system, params: the :class:`~jaxgear.ForcedSystem` and its parameters.
        orbit: a :class:`PeriodicOrbit`, or its points ``(m, dim)`` at phase ``t0``.
        t0: phase of the orbit's points (system time unit).
        integrator: any integrator object; default :func:`~jaxgear.default_integrator`.
        options: :class:`VerifyOptions` (``periods``, ``perturbation``, ``n_trials``,
            ``leave_tol``, ``n_final``, ``seed``); ``None``: the defaults.
        **changes: fields of ``options`` to change, e.g. ``periods=100``.
    Returns:
        :class:`OrbitCheck` (``distance`` of shape ``(n_trials, periods)``,
        ``final_points`` ``(n_trials, n_final, dim)``).
    """
    opts = with_changes(options, VerifyOptions, changes)
    pts = np.asarray(getattr(orbit, "points", orbit), dtype=float)
    if pts.ndim == 1:
        pts = pts[None]
    check_state_shape(system, pts)
    u = np.array(jax.random.normal(jax.random.PRNGKey(opts.seed), (opts.n_trials, system.dim), jnp.float64))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    x0 = pts[0] + opts.perturbation * (1.0 + np.linalg.norm(pts[0])) * u
    traj = np.asarray(stroboscopic_orbit(system, params, x0, n_points=opts.periods, t0=t0, integrator=integrator))
    dist = np.min(np.linalg.norm(traj[:, :, None, :] - pts[None, None], axis=-1), axis=-1)
    dist = np.where(np.isfinite(dist), dist, np.inf)
    out = dist > opts.leave_tol
    left_at = np.where(out.any(axis=1), np.argmax(out, axis=1) + 1, -1)
    diverged = ~np.all(np.isfinite(traj), axis=(1, 2))
    return OrbitCheck(kept=bool(np.all(left_at < 0)), left_at=left_at, distance=dist,
                      final_points=traj[:, -opts.n_final:], diverged=diverged)
