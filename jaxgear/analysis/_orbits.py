"""Attractors at point level: periods on the stroboscopic map, refined points, section crossings."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import pad_rows, power_of_two_at_least
from .._poincare import stroboscopic_orbit
from ..integrate import batch_field

__all__ = ["detect_period", "follow", "refine_orbits", "largest_multipliers", "cycle_multipliers", "exact_cycle_multipliers", "section_points_of",
           "advance_states"]


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


@functools.partial(jax.jit, static_argnames=("system", "integrator"))
def _period_jacobians(system, params, X, integrator):
    """``D P(x)`` of the one-period stroboscopic map at each state of ``X (n, dim)``:
    ``(n, dim, dim)``, by forward-mode autodiff through the integrator (the kink-aware
    step's derivatives come from its pure-JAX steps: exact at the backlash kinks).

    One ``jax.jvp`` of the batched map: lane ``i dim + j`` starts at ``X[i]`` with the
    tangent ``e_j`` (the lanes of a batch are independent), so the step's derivative is
    traced once, without the two ``vmap`` s of ``vmap(jacfwd(.))`` that turn its
    conditionals into selects (a third of the trace and compile time, equal to round-off)."""
    n, dim = X.shape
    Y = jnp.repeat(X, dim, axis=0).T  # (dim, n dim)
    T = jnp.tile(jnp.eye(dim, dtype=X.dtype), (1, n))  # (dim, n dim): lane i dim + j moves along e_j

    def period(Y):
        return integrator.advance(system, params, Y, jnp.asarray(0.0), 1)

    _, dY = jax.jvp(period, (Y,), (T,))
    return dY.T.reshape(n, dim, dim).transpose(0, 2, 1)  # [i, :, j] = d P(X[i]) / d x_j


def exact_cycle_multipliers(system, params, cycles, integrator) -> list[np.ndarray]:
    """The Floquet multipliers of each cycle ``(points (k, dim) in cycle order, k)``: the
    eigenvalues of the monodromy matrix ``D P(p_(k-1)) ... D P(p_0)`` of the k-fold map, the
    product of the one-period Jacobians at its points (autodiff, one batch for every point
    of every cycle: exact to round-off, even for multipliers near 0). Returns one complex
    ``(dim,)`` array per cycle (``inf`` where not finite)."""
    if not cycles:
        return []
    pts = [np.asarray(p, np.float64).reshape(int(k), -1) for p, k in cycles]
    X = np.concatenate(pts)
    J = np.asarray(_period_jacobians(system, params, jax.device_put(_pad_rows(X)), integrator))[: len(X)]
    out, start = [], 0
    for p in pts:
        M = np.eye(p.shape[1])
        for j in range(len(p)):
            M = J[start + j] @ M
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


@functools.partial(jax.jit, static_argnames=("system", "stepper", "index", "direction"))
def _crossings(system, params, X, stepper, index: int, direction: int):
    """One forcing period from each state ``X (n, dim)`` at phase 0 with the fixed-step
    ``stepper``, and at every step the crossing of ``x_index = 0`` inside it: whether the
    step crosses (in ``direction``) ``(steps, n)`` and the state landed on the crossing
    ``(steps, dim, n)``, by Newton's method on the length of a step from the step's start.

    One call site of the step serves both the full step (iteration 0) and the Newton
    iterations, so the step is traced once."""
    n_steps = int(stepper.steps_per_period)
    h = system.period(params) / n_steps
    lanes = X.shape[0]

    def one_step(Y, i):
        t = jnp.full((lanes,), i * h, dtype=jnp.float64)
        g0 = Y[index]

        def iterate(j, c):
            dt, _, full = c
            Z = stepper.step(system, params, t, Y, dt)
            full = jnp.where(j == 0, Z, full)
            F = batch_field(system, params, t + dt, Z)
            g1 = full[index]
            secant = h * g0 / jnp.where(g0 == g1, 1.0, g0 - g1)
            newton = dt - Z[index] / jnp.where(F[index] == 0, 1.0, F[index])
            return jnp.clip(jnp.where(j == 0, secant, newton), 0.0, h), Z, full

        _, Z, full = jax.lax.fori_loop(0, 9, iterate, (jnp.full((lanes,), h), Y, Y))
        g1 = full[index]
        up, down = (g0 < 0) & (g1 >= 0), (g0 > 0) & (g1 <= 0)
        hit = up if direction > 0 else down if direction < 0 else (up | down)
        return full, (hit, Z)

    _, (hits, Zs) = jax.lax.scan(one_step, X.T, jnp.arange(n_steps, dtype=jnp.float64))
    return hits, Zs


SECTION_ROWS = 32
"""States integrated together by :func:`section_points_of` (at least; more in powers of
two): one compiled shape for every result with up to 32 cycle points."""


def section_points_of(system, params, cycles, integrator, index, direction) -> list[np.ndarray]:
    """Crossings of Σ = {x_index = 0} over the k periods of each periodic orbit (``cycles``:
    a list of stroboscopic point arrays ``(k, dim)`` in cycle order), in time order:
    ``[(m, dim)]``. ``direction`` > 0 keeps upward crossings, < 0 downward, 0 both.

    Every point of every cycle is integrated one period in one batch with the
    integrator's fixed-step stepper; a step that crosses Σ is redone with its length
    found by Newton's method so that it ends on Σ (to round-off)."""
    empty = np.zeros((0, system.dim))
    if index is None:
        return [empty for _ in cycles]
    ok = [len(p) > 0 and bool(np.all(np.isfinite(p))) for p in cycles]
    rows = [np.asarray(p, np.float64) for p, good in zip(cycles, ok) if good]
    if not rows:
        return [empty for _ in cycles]
    X = np.concatenate(rows)
    Xp = _pad_rows(X, SECTION_ROWS)
    stepper, direction = integrator.crossing_stepper, int(np.sign(direction))
    hits, Zs = _crossings(system, params, jax.device_put(Xp), stepper=stepper, index=int(index), direction=direction)
    hits, Zs = np.asarray(hits)[:, : len(X)], np.asarray(Zs)[:, :, : len(X)]
    lane, step = np.nonzero(hits.T)  # by state (cycle order), then time
    found = Zs[step, :, lane]
    found = np.array(found).reshape(-1, system.dim)
    found[:, index] = 0.0  # on Σ by definition (Newton leaves round-off)
    out, start = [], 0
    for p, good in zip(cycles, ok):
        if not good:
            out.append(empty)
            continue
        k = len(p)
        out.append(found[(lane >= start) & (lane < start + k)])
        start += k
    return out
