"""Attractors at point level: periods on the stroboscopic map, refined points, section crossings."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import SMALL_BATCH, pad_rows, power_of_two_at_least
from .._poincare import LOCATE_BISECTIONS, locate_sign_changes, one_period, stroboscopic_orbit, switching_count

__all__ = ["detect_period", "follow", "refine_orbits", "largest_multipliers", "cycle_multipliers", "cycle_multipliers_of",
           "cycle_sections_and_multipliers", "advance_states"]


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
def advance_state_rows(system, params, X, periods, integrator):
    """States ``X (n, dim)`` (rows) advanced by ``periods`` forcing periods, jitted (the
    kernel :func:`jaxgear._devices.shard_rows` shards for the stroboscopic cell map)."""
    return integrator.advance(system, params, X.T, jnp.asarray(0.0), periods).T


def advance_states(system, params, X, periods: int, integrator) -> np.ndarray:
    """States ``X (n, dim)`` at phase 0 advanced by ``periods`` forcing periods: ``(n, dim)``."""
    X = jax.device_put(np.asarray(X, np.float64))
    return np.asarray(advance_state_rows(system, params, X, int(periods), integrator))


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


LONG_CYCLE_FACTOR = 16
"""An attractor of boxes whose largest exponent is negative (a cycle longer than
``max_period``) is given its period when that is at most this many times ``max_period``."""
LONG_CYCLE_SETTLE = 200
"""Periods such a cycle's point is continued before its period is read."""


def long_cycles(system, params, starts, integrator, max_period: int, tol: float):
    """The cycles through the states ``starts`` (one per attractor of boxes that contracts:
    a cycle longer than ``max_period``): for each, ``(points (k, dim), k, residual)`` of the
    cycle after :data:`LONG_CYCLE_SETTLE` periods, its period ``k`` up to
    :data:`LONG_CYCLE_FACTOR` ``* max_period`` read as for any cycle
    (:func:`detect_period`, tolerance ``tol``), or ``None`` where none repeats."""
    if not len(starts):
        return []
    K = LONG_CYCLE_FACTOR * int(max_period)
    periods, orbits = follow(system, params, _pad_rows(np.asarray(starts, np.float64)), integrator, LONG_CYCLE_SETTLE,
                             K, tol)
    found = [i for i in range(len(starts)) if periods[i] > 0]
    refined = dict(zip(found, refine_orbits(system, params, [(orbits[i, -1], int(periods[i])) for i in found],
                                            integrator, max_period=K)))
    return [(refined[i][0], int(periods[i]), refined[i][1]) if i in refined else None for i in range(len(starts))]


def _pad_rows(X: np.ndarray, minimum: int = 8) -> np.ndarray:
    """``X (n, dim)`` padded with copies of a row to a power of two (at least ``minimum``)
    rows, so that batches of a few states share one compiled shape."""
    return pad_rows(X, power_of_two_at_least(len(X), minimum))


def refine_orbits(system, params, cycles, integrator, settle: int = 0, max_period: int | None = None):
    """Refined points of several cycles at once: for each ``(x, k)`` (a state near a P-k
    cycle), the k stroboscopic points after ``settle`` more periods and the residual
    ``|P^k(p) - p|``; points start at the one with the smallest first coordinate (a
    canonical order). Returns ``[(points (k, dim), residual)]``.

    All cycles run in one batch (one compiled computation whatever their periods;
    ``max_period`` bounds them, default the largest ``k``)."""
    if not cycles:
        return []
    X = np.stack([np.asarray(x, np.float64) for x, _ in cycles])
    ks = [int(k) for _, k in cycles]
    K = max(ks) if max_period is None else int(max_period)
    Xp = _pad_rows(X)
    if settle > 0:
        Xp = advance_states(system, params, Xp, int(settle), integrator)
    orb = np.asarray(stroboscopic_orbit(system, params, jax.device_put(Xp), n_points=2 * K, integrator=integrator))
    out = []
    for i, k in enumerate(ks):
        pts = orb[i, k - 1: 2 * k - 1]
        res = float(np.linalg.norm(orb[i, 2 * k - 1] - orb[i, k - 1]))
        start = int(np.argmin(pts[:, 0]))
        out.append((np.roll(pts, -start, axis=0), res))
    return out


FD_STEP = 1e-6
"""Relative step of the central differences of :func:`largest_multipliers` (times
``1 + max |x|``)."""


def largest_multipliers(system, params, cycles, integrator, max_period: int | None = None) -> np.ndarray:
    """The largest modulus of the Floquet multipliers of each cycle ``(points (k, dim), k)``
    (paper §4.1: asymptotically stable when it is below 1), from :func:`cycle_multipliers`
    (``inf`` where they are not finite). Returns ``(n,)``."""
    return np.array([float(np.abs(mu).max()) if np.all(np.isfinite(mu)) else np.inf
                     for mu in cycle_multipliers(system, params, cycles, integrator, max_period)])


def cycle_multipliers_of(cycles, jacobians) -> list[np.ndarray]:
    """The Floquet multipliers of each cycle (``cycles``: point arrays ``(k, dim)`` in cycle
    order; ``jacobians``: ``D P`` at every point of every cycle, in that order, from
    :func:`one_period`): the eigenvalues of the monodromy matrix ``D P(p_(k-1)) ... D P(p_0)``
    of the k-fold map (exact to round-off, even for multipliers near 0). Returns one
    complex ``(dim,)`` array per cycle (``inf`` where not finite)."""
    out, start = [], 0
    for p in cycles:
        M = np.eye(p.shape[1])
        for j in range(len(p)):
            M = jacobians[start + j] @ M
        start += len(p)
        out.append(np.linalg.eigvals(M) if np.all(np.isfinite(M)) else np.full(p.shape[1], np.inf + 0j))
    return out


def cycle_multipliers(system, params, cycles, integrator, max_period: int | None = None) -> list[np.ndarray]:
    """The Floquet multipliers of each cycle ``(points (k, dim), k)``: the eigenvalues
    ``(dim,)`` of the monodromy matrix of the k-fold stroboscopic map at the cycle's first
    point, by central differences (step :data:`FD_STEP` ``(1 + max |x|)`` per coordinate). All
    cycles run in one batch of ``2 dim`` states each, ``2 max_period`` periods long, as
    in :func:`refine_orbits` (``max_period`` bounds the periods, default the largest
    ``k``). A cycle whose perturbed states blow up gets ``inf``. Returns one complex
    ``(dim,)`` array per cycle."""
    if not cycles:
        return []
    ks = [int(k) for _, k in cycles]
    x0 = np.stack([np.asarray(p, np.float64).reshape(k, -1)[0] for (p, _), k in zip(cycles, ks)])
    n, dim = x0.shape
    h = FD_STEP * (1.0 + np.abs(x0).max(axis=1))  # (n,)
    E = np.eye(dim)[None] * h[:, None, None]  # (n, dim, dim): row j perturbs coordinate j
    X = np.concatenate([x0[:, None] + E, x0[:, None] - E], axis=1).reshape(-1, dim)  # (n 2 dim, dim)
    K = max(ks) if max_period is None else int(max_period)
    orb = np.asarray(stroboscopic_orbit(system, params, jax.device_put(_pad_rows(X)), n_points=2 * K,
                                        integrator=integrator))
    out = []
    for i, k in enumerate(ks):
        end = orb[2 * dim * i: 2 * dim * (i + 1), k - 1]  # P^k of x0 + h e_j, then of x0 - h e_j
        J = (end[:dim] - end[dim:]).T / (2.0 * h[i])  # column j: d P^k / d x_j
        out.append(np.linalg.eigvals(J) if np.all(np.isfinite(J)) else np.full(dim, np.inf + 0j))
    return out


def cycle_sections_and_multipliers(system, params, cycles, integrator, index, direction
                                   ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The section points and the Floquet multipliers of each periodic orbit (``cycles``: a
    list of stroboscopic point arrays ``(k, dim)``, ``k >= 1``, in cycle order), from one
    :func:`one_period` of every point of every cycle.

    - Section points: the crossings of Σ = {x_index = 0} over the k periods, in time order,
      ``(m, dim)`` (``direction`` > 0 keeps upward crossings, < 0 downward, 0 both; none
      where ``index`` is None or the cycle is not finite). Each step of the samples over
      which ``x_index`` changes sign is bisected to the crossing
      (:func:`~jaxgear._poincare.locate_sign_changes`, to round-off of the step's length),
      the program the gear view's contact changes use.
    - Multipliers: :func:`cycle_multipliers_of` the cycle's one-period Jacobians, complex
      ``(dim,)`` (``inf`` where not finite).
    """
    if not cycles:
        return [], []
    pts = [np.asarray(p, np.float64).reshape(len(p), system.dim) for p in cycles]
    ts, xs, J = one_period(system, params, np.concatenate(pts), integrator)
    mults = cycle_multipliers_of(pts, J)
    empty = np.zeros((0, system.dim))
    ok = np.concatenate([np.full(len(p), bool(np.all(np.isfinite(p)))) for p in pts])
    if index is None or not ok.any():
        return [empty for _ in pts], mults
    stepper, direction = integrator.crossing_stepper, int(np.sign(direction))
    g0, g1 = xs[:, :-1, index], xs[:, 1:, index]
    up, down = (g0 < 0) & (g1 >= 0), (g0 > 0) & (g1 <= 0)
    hits = (up if direction > 0 else down if direction < 0 else (up | down)) & ok[:, None]
    lane, step = np.nonzero(hits)  # by state (cycle order), then time
    found = np.zeros((0, system.dim))
    if len(lane):
        n = len(lane)
        size = power_of_two_at_least(n, SMALL_BATCH)
        lp, sp = pad_rows(lane, size), pad_rows(step, size)
        _, Z = locate_sign_changes(system, stepper, LOCATE_BISECTIONS, params, jnp.asarray(ts[sp]),
                                   jnp.asarray(xs[lp, sp]).T, jnp.asarray(ts[sp + 1] - ts[sp]),
                                   jnp.full(size, switching_count(system, params) + int(index), jnp.int32),
                                   jnp.asarray(g0[lp, sp] > 0))
        found = np.array(np.asarray(Z).T[:n])
    found[:, index] = 0.0  # on Σ by definition (the bisection leaves round-off)
    sections, start = [], 0
    for p in pts:
        sections.append(found[(lane >= start) & (lane < start + len(p))])
        start += len(p)
    return sections, mults
