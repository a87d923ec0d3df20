"""Poincaré maps of a forced system (paper §3, eq. 7-9).

- :func:`stroboscopic_map` — the exact Poincaré map of a forced system,
  ``x(t0) -> x(t0 + periods*T)`` on the full state (MODEL.md §6);
- :func:`stroboscopic_orbit` — the sequence ``P(x), P^2(x), ..., P^n(x)``;
- :func:`section_map` — the paper's hyperplane section Σ = {x_i = 0}: integrate whole
  periods, then on to the next crossing of Σ in a chosen direction, located to
  round-off by a safeguarded Newton iteration on the length of the last RK4 step;
- :func:`sample_trajectory` — dense samples over some periods, for figures.

All take states of shape ``(..., dim)`` (any batch), parameters as a pytree (a change
of value does not recompile) and one ``jit`` boundary each.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ._integrate import RK4, Integrator, _batched_field, _lane_field, advance_batch, rk4_step_batch, sample
from ._system import ForcedSystem, check_state_shape

__all__ = [
    "stroboscopic_map",
    "stroboscopic_orbit",
    "section_map",
    "SectionHit",
    "sample_trajectory",
    "STATUS_OK",
    "STATUS_DIVERGED",
    "STATUS_NO_CROSSING",
]

STATUS_OK = 0
STATUS_DIVERGED = 1
STATUS_NO_CROSSING = 2


def _to_batch(system, x0):
    check_state_shape(system, x0)
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    return x0.shape[:-1], x0.reshape(-1, system.dim).T


@eqx.filter_jit
def _strobe_kernel(system, params, Y, t0, periods, integrator):
    return advance_batch(system, params, Y, t0, periods, integrator)


def stroboscopic_map(system: ForcedSystem, params, x0, *, periods: int = 1, t0=0.0,
                     integrator: Integrator = RK4()):
    """Stroboscopic (exact) Poincaré map ``P^periods``: ``x(t0) -> x(t0 + periods*T)``.

    The exact Poincaré map of a forced system (paper eq. 6; MODEL.md §6), the map whose
    fixed points are the P-k motions of paper §4. Times in the system's unit
    (dimensionless ``tau`` for the gear models), states in state units.

    Args:
        x0: states, shape ``(..., dim)``.
        periods: number of forcing periods (an int; sets the loop length).
        t0: start time; the forcing phase is ``2 pi t0 / T``.
    Returns:
        states of shape ``(..., dim)``; a lane that blew up is non-finite.
    """
    lead, Y = _to_batch(system, x0)
    Y = _strobe_kernel(system, params, Y, jnp.asarray(t0, jnp.float64), int(periods), integrator)
    return Y.T.reshape(*lead, system.dim)


@eqx.filter_jit
def _orbit_kernel(system, params, Y, t0, n_points, periods_between, integrator):
    T = system.period(params)

    def step(carry, j):
        Y = advance_batch(system, params, carry, t0 + j * periods_between * T, periods_between, integrator)
        return Y, Y

    _, Ys = jax.lax.scan(step, Y, jnp.arange(n_points))
    return Ys  # (n_points, dim, n)


def stroboscopic_orbit(system: ForcedSystem, params, x0, *, n_points: int, periods_between: int = 1,
                       t0=0.0, integrator: Integrator = RK4()):
    """The iterates ``P(x0), ..., P^n(x0)`` of the stroboscopic map: shape ``(..., n, dim)``.

    ``P`` advances ``periods_between`` forcing periods (the exact Poincaré map of a
    forced system, paper eq. 6; MODEL.md §6). ``x0``: states ``(..., dim)`` at time
    ``t0`` (system time unit); ``n = n_points``. A lane that blew up is non-finite.
    """
    lead, Y = _to_batch(system, x0)
    Ys = _orbit_kernel(system, params, Y, jnp.asarray(t0, jnp.float64), int(n_points), int(periods_between),
                       integrator)
    return jnp.moveaxis(Ys, 2, 0).reshape(*lead, int(n_points), system.dim)


class SectionHit(NamedTuple):
    """Result of :func:`section_map` (arrays with the batch shape of the input).

    state: ``(..., dim)`` state at the crossing (``state[..., index] = 0`` to round-off);
    time: ``(...)`` crossing time; phase: ``(...)`` forcing phase in [0, 2 pi);
    status: ``(...)`` int, ``STATUS_OK``, ``STATUS_DIVERGED`` or ``STATUS_NO_CROSSING``.
    """

    state: jax.Array
    time: jax.Array
    phase: jax.Array
    status: jax.Array


def _crossed(g_old, g_new, direction):
    if direction > 0:
        return (g_old < 0) & (g_new >= 0)
    if direction < 0:
        return (g_old > 0) & (g_new <= 0)
    return ((g_old < 0) & (g_new >= 0)) | ((g_old > 0) & (g_new <= 0))


@eqx.filter_jit
def _section_kernel(system, params, Y, t0, periods, index, direction, max_extra_periods, integrator,
                    search_steps, refine_iters=30):
    T = system.period(params)
    if periods > 0:
        Y = advance_batch(system, params, Y, t0, periods, integrator)
    t_start = t0 + periods * T
    h = T / search_steps
    f = _batched_field(system)
    n = Y.shape[1]
    max_steps = int(max_extra_periods * search_steps)

    def cond(c):
        k, _, found, _, _ = c
        return (k < max_steps) & jnp.any(~found)

    def body(c):
        k, Y, found, Yb, kb = c
        t = t_start + k * h
        Yn = rk4_step_batch(f, t, Y, h, params)
        hit = _crossed(Y[index], Yn[index], direction) & ~found
        Yb = jnp.where(hit[None, :], Y, Yb)
        kb = jnp.where(hit, k, kb)
        found = found | hit | ~jnp.all(jnp.isfinite(Yn), axis=0)
        return k + 1, Yn, found, Yb, kb

    init = (jnp.asarray(0), Y, jnp.zeros(n, bool), Y, jnp.zeros(n, jnp.int64))
    _, Yend, found, Yb, kb = jax.lax.while_loop(cond, body, init)
    tb = t_start + kb * h

    # Safeguarded Newton on the step length s in [0, h] so that RK4(Yb, s)[index] = 0.
    fl = _lane_field(system)
    g0 = Yb[index]
    lo = jnp.zeros(n)
    hi = jnp.full(n, h)

    def refine(_, c):
        s, lo, hi = c
        Ys = rk4_step_batch(fl, tb, Yb, s, params)
        g = Ys[index]
        dg = fl(tb + s, Ys, params)[index]
        same_side = jnp.sign(g) == jnp.sign(g0)
        lo = jnp.where(same_side, s, lo)
        hi = jnp.where(same_side, hi, s)
        s_new = s - g / jnp.where(dg == 0, 1.0, dg)
        # Converged: the Newton correction is at round-off. Keep s; otherwise the bracket
        # end that round-off just moved onto s would reject the step and bisection would
        # throw the converged root away.
        converged = (dg != 0) & (jnp.abs(s_new - s) <= tiny)
        ok = (s_new > lo) & (s_new < hi) & (dg != 0)
        s_new = jnp.where(ok, s_new, 0.5 * (lo + hi))
        s_new = jnp.where((g == 0) | converged, s, s_new)
        return s_new, lo, hi

    tiny = 8 * jnp.finfo(jnp.float64).eps * jnp.abs(h)
    s0 = jnp.full(n, 0.5 * h)
    s, _, _ = jax.lax.fori_loop(0, refine_iters, refine, (s0, lo, hi))
    Yc = rk4_step_batch(fl, tb, Yb, s, params)
    tc = tb + s
    finite = jnp.all(jnp.isfinite(Yc), axis=0) & jnp.all(jnp.isfinite(Yend), axis=0)
    crossed = found & jnp.all(jnp.isfinite(Yb), axis=0)
    status = jnp.where(~finite, STATUS_DIVERGED, jnp.where(crossed, STATUS_OK, STATUS_NO_CROSSING))
    Yc = jnp.where((status == STATUS_OK)[None, :], Yc, jnp.nan)
    phase = jnp.mod(2 * jnp.pi * tc / T, 2 * jnp.pi)
    return Yc, tc, phase, status


def section_map(system: ForcedSystem, params, x0, *, periods: int = 1, t0=0.0, index: int | None = None,
                direction: int = 1, max_extra_periods: float = 4.0, integrator: Integrator = RK4(),
                search_steps_per_period: int | None = None) -> SectionHit:
    """The paper's Poincaré-like map on the hyperplane Σ = {x_index = 0} (paper §3, §4.1).

    From ``x0`` at time ``t0``: integrate ``periods`` whole forcing periods, then on to the
    next crossing of Σ with ``direction`` (+1: ``x_index`` increasing, -1: decreasing,
    0: either). The crossing is located to round-off within the RK4 step that brackets
    it (safeguarded Newton on the step length), so ``state[..., index]`` is ~1e-15.

    Args:
        x0: ``(..., dim)`` states (the paper starts on Σ at phase 0, ``t0 = 0``).
        index: section coordinate; default ``system.section_index``.
        max_extra_periods: how long to search for the crossing before giving up
            (``STATUS_NO_CROSSING``).
        search_steps_per_period: RK4 steps per period during the search (default: the
            integrator's ``steps_per_period``, or 400 for :class:`Adaptive`).
    Returns:
        :class:`SectionHit` with the batch shape of ``x0``; failed lanes have NaN state
        and a non-zero status (never a silent wrong value).
    """
    index = system.section_index if index is None else int(index)
    if index is None:
        raise ValueError(f"{system.name} has no default section: pass index=i for Σ = {{x_i = 0}}.")
    if not 0 <= index < system.dim:
        raise ValueError(f"section index {index} is outside 0..{system.dim - 1}.")
    if direction not in (-1, 0, 1):
        raise ValueError(f"direction must be +1, -1 or 0, got {direction}.")
    if max_extra_periods <= 0:
        raise ValueError("max_extra_periods must be > 0.")
    if search_steps_per_period is None:
        search_steps_per_period = integrator.steps_per_period if isinstance(integrator, RK4) else 400
    lead, Y = _to_batch(system, x0)
    Yc, tc, ph, st = _section_kernel(system, params, Y, jnp.asarray(t0, jnp.float64), int(periods), index,
                                     int(direction), float(max_extra_periods), integrator,
                                     int(search_steps_per_period))
    return SectionHit(Yc.T.reshape(*lead, system.dim), tc.reshape(lead), ph.reshape(lead), st.reshape(lead))


@eqx.filter_jit
def _sample_kernel(system, params, x0, t0, periods, samples_per_period, integrator):
    return sample(system, params, x0, t0, periods, samples_per_period, integrator)


def sample_trajectory(system: ForcedSystem, params, x0, *, periods: int = 1, samples_per_period: int = 100,
                      t0=0.0, integrator: Integrator = RK4()):
    """Trajectory samples for figures: ``(times (m,), states (..., m, dim))``,
    ``m = periods*samples_per_period + 1``, from ``t0`` to ``t0 + periods*T``.

    The phase trajectories of paper Fig. 3-6. ``x0``: states ``(..., dim)`` at ``t0``
    (system time unit; ``T = system.period(params)``). With :class:`RK4` each sample
    interval is a whole number of steps (``steps_per_period`` rounded up to a multiple
    of ``samples_per_period``).
    """
    check_state_shape(system, x0)
    return _sample_kernel(system, params, jnp.asarray(x0, jnp.float64), jnp.asarray(t0, jnp.float64),
                          int(periods), int(samples_per_period), integrator)
