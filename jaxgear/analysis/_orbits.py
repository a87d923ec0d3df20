"""Attractors at point level: periods on the stroboscopic map, refined points, section crossings."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._poincare import sample_trajectory, section_map, stroboscopic_orbit
from .._status import Status

__all__ = ["detect_period", "follow", "refine_orbit", "section_points", "advance_states"]


def detect_period(orbit: np.ndarray, max_period: int, tol: float) -> np.ndarray:
    """Minimal period of each stroboscopic sequence ``orbit (..., K, dim)`` (the P-k of paper §4).

    The smallest ``k <= max_period`` with ``|x_j - x_(j-k)| <= tol (1 + |x_j|)`` for the
    last ``k + 1`` points ``j`` (so a whole cycle and one more step repeat); ``0`` if
    none, ``-1`` if the sequence is not finite. Needs ``K >= 2 max_period + 1``.
    ``tol`` is relative (dimensionless); returns an int array of shape ``(...)``.
    """
    orbit = np.asarray(orbit)
    K = orbit.shape[-2]
    if K < 2 * max_period + 1:
        raise ValueError(f"detect_period needs at least {2 * max_period + 1} points, got {K}.")
    lead = orbit.shape[:-2]
    out = np.zeros(lead, dtype=np.int64)
    done = np.zeros(lead, dtype=bool)
    with np.errstate(invalid="ignore", over="ignore"):
        scale = 1.0 + np.linalg.norm(orbit[..., -1, :], axis=-1)
        for k in range(1, max_period + 1):
            idx = np.arange(K - k - 1, K)
            d = np.linalg.norm(orbit[..., idx, :] - orbit[..., idx - k, :], axis=-1).max(axis=-1)
            hit = (d <= tol * scale) & ~done
            out[hit] = k
            done |= hit
    out[~np.all(np.isfinite(orbit), axis=(-1, -2))] = -1
    return out


@eqx.filter_jit
def _advance_rows(system, params, X, periods, integrator):
    return integrator.advance(system, params, X.T, jnp.asarray(0.0), periods).T


def advance_states(system, params, X, periods: int, integrator) -> np.ndarray:
    """States ``X (n, dim)`` at phase 0 advanced by ``periods`` forcing periods: ``(n, dim)``."""
    return np.asarray(_advance_rows(system, params, jnp.asarray(X), int(periods), integrator))


def follow(system, params, X: np.ndarray, integrator, settle: int, max_period: int, tol: float):
    """Integrate states ``X (n, dim)`` ``settle`` periods, then record ``2 max_period + 2``
    stroboscopic points; returns (periods (n,), recorded points (n, K, dim))."""
    Xs = np.array(advance_states(system, params, X, settle, integrator) if settle > 0 else X, dtype=float)
    # a state that blew up while settling is escaped (period -1: the sink), like a
    # sequence that blows up while it is recorded
    blown = ~np.all(np.isfinite(Xs), axis=-1)
    Xs[blown] = 0.0
    orbit = np.array(stroboscopic_orbit(system, params, Xs, n_points=2 * max_period + 2, integrator=integrator))
    orbit[blown] = np.nan
    return detect_period(orbit, max_period, tol), orbit


def refine_orbit(system, params, x: np.ndarray, k: int, integrator, settle: int = 0) -> tuple[np.ndarray, float]:
    """The k stroboscopic points from ``x`` (after ``settle`` more periods, rounded to a
    multiple of k) and the residual ``|P^k(p) - p|``; points start at the one with the
    smallest first coordinate (a canonical order)."""
    if settle > 0:
        x = advance_states(system, params, np.asarray(x)[None], int(-(-settle // k) * k), integrator)[0]
    orb = np.asarray(stroboscopic_orbit(system, params, jnp.asarray(x), n_points=2 * k, integrator=integrator))
    pts = orb[k - 1: 2 * k - 1]
    res = float(np.max(np.linalg.norm(orb[2 * k - 1] - orb[k - 1])))
    start = int(np.argmin(pts[:, 0]))
    return np.roll(pts, -start, axis=0), res


def section_points(system, params, points: np.ndarray, integrator, index, direction, samples=200) -> np.ndarray:
    """Crossings of Σ = {x_index = 0} over the k periods of a periodic orbit (k = len(points))."""
    if index is None or len(points) == 0 or not np.all(np.isfinite(points)):
        return np.zeros((0, system.dim))
    k = len(points)
    ts, xs = sample_trajectory(system, params, jnp.asarray(points[0]), periods=k, samples_per_period=samples,
                               integrator=integrator)
    ts, xs = np.asarray(ts), np.asarray(xs)
    g = xs[:, index]
    if direction > 0:
        hits = np.nonzero((g[:-1] < 0) & (g[1:] >= 0))[0]
    elif direction < 0:
        hits = np.nonzero((g[:-1] > 0) & (g[1:] <= 0))[0]
    else:
        hits = np.nonzero(np.sign(g[:-1]) * np.sign(g[1:]) < 0)[0]
    out = []
    for i in hits:
        h = section_map(system, params, xs[i], periods=0, t0=ts[i], index=index, direction=direction,
                        max_extra_periods=2.0 / samples, integrator=integrator)
        if int(h.status) == Status.CONVERGED:
            out.append(np.asarray(h.state))
    return np.asarray(out).reshape(-1, system.dim)
