"""Poincaré maps of a forced system (paper §3, eq. 7-9).

- :func:`stroboscopic_map` — the exact Poincaré map of a forced system,
  ``x(t0) -> x(t0 + periods*T)`` on the full state (model document §6);
- :func:`stroboscopic_orbit` — the sequence ``P(x), P^2(x), ..., P^n(x)``;
- :func:`section_map` — the paper's hyperplane section Σ = {x_i = 0}: integrate whole
  periods, then on to the next crossing of Σ in a chosen direction, located to
  round-off by a safeguarded Newton iteration on the length of the last step;
- :func:`sample_trajectory` — dense samples over some periods, for figures;
- :func:`one_period` — one period from each of a few states: the samples at every step
  and the map's Jacobian, what the points of a cycle need.

All take states of shape ``(..., dim)`` (any batch), parameters as a pytree (a change
of value does not recompile), an integrator object (default
:func:`~jaxgear.integrate.default_integrator`) and one ``jit`` boundary each.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._batching import SMALL_BATCH, pad_rows, power_of_two_at_least
from ._checks import check_choice, check_int, check_number
from ._status import Status
from ._system import ForcedSystem, check_state_shape
from .integrate import AbstractIntegrator, batch_field, resolve_integrator

__all__ = ["stroboscopic_map", "stroboscopic_orbit", "section_map", "SectionHit", "sample_trajectory",
           "one_period", "section_kernel", "check_periods", "locate_sign_changes", "switching_count",
           "LOCATE_BISECTIONS"]


def check_periods(periods, name: str = "periods", minimum: int = 1) -> int:
    """``periods`` as an int >= ``minimum`` (a count of forcing periods), else ``ValueError``."""
    return check_int(periods, name, minimum)


def _to_batch(system, x0):
    check_state_shape(system, x0)
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    return x0.shape[:-1], x0.reshape(-1, system.dim).T


@eqx.filter_jit
def _strobe_kernel(system, params, Y, t0, periods, integrator):
    return integrator.advance(system, params, Y, t0, periods)


def stroboscopic_map(system: ForcedSystem, params, x0: Float[ArrayLike, "*batch dim"], *, periods: int = 1,
                     t0: float = 0.0, integrator: AbstractIntegrator | None = None) -> Float[Array, "*batch dim"]:
    """Stroboscopic (exact) Poincaré map ``P^periods``: ``x(t0) -> x(t0 + periods*T)``.

    The exact Poincaré map of a forced system (paper eq. 6; model document §6), the map
    whose fixed points are the P-k motions of paper §4. Times in the system's unit
    (dimensionless ``tau`` for the gear models), states in state units.

    Args:
        x0: states, shape ``(..., dim)``.
        periods: number of forcing periods (an int >= 1; sets the loop length).
        t0: start time; the forcing phase is ``2 pi t0 / T``.
        integrator: default :func:`~jaxgear.integrate.default_integrator`.
    Returns:
        states of shape ``(..., dim)``; a lane that blew up is non-finite.
    """
    periods = check_periods(periods)
    integrator = resolve_integrator(integrator)
    lead, Y = _to_batch(system, x0)
    Y = _strobe_kernel(system, params, Y, jnp.asarray(t0, jnp.float64), periods, integrator)
    return Y.T.reshape(*lead, system.dim)


@eqx.filter_jit
def _orbit_kernel(system, params, Y, t0, n_points, periods_between, integrator):
    T = system.period(params)

    def step(carry, j):
        Y = integrator.advance(system, params, carry, t0 + j * periods_between * T, periods_between)
        return Y, Y

    _, Ys = jax.lax.scan(step, Y, jnp.arange(n_points, dtype=jnp.float64))
    return Ys  # (n_points, dim, n)


def stroboscopic_orbit(system: ForcedSystem, params, x0: Float[ArrayLike, "*batch dim"], *, n_points: int,
                       periods_between: int = 1, t0: float = 0.0,
                       integrator: AbstractIntegrator | None = None) -> Float[Array, "*batch n_points dim"]:
    """The iterates ``P(x0), ..., P^n(x0)`` of the stroboscopic map: shape ``(..., n, dim)``.

    ``P`` advances ``periods_between`` forcing periods (the exact Poincaré map of a
    forced system, paper eq. 6; model document §6). ``x0``: states ``(..., dim)`` at
    time ``t0`` (system time unit); ``n = n_points``. A lane that blew up is non-finite.
    """
    n_points = check_periods(n_points, "n_points")
    periods_between = check_periods(periods_between, "periods_between")
    integrator = resolve_integrator(integrator)
    lead, Y = _to_batch(system, x0)
    Ys = _orbit_kernel(system, params, Y, jnp.asarray(t0, jnp.float64), n_points, periods_between, integrator)
    return jnp.moveaxis(Ys, 2, 0).reshape(*lead, n_points, system.dim)


class SectionHit(NamedTuple):
    """Result of :func:`section_map` (arrays with the batch shape of the input).

    state: ``(..., dim)`` state at the crossing (``state[..., index] = 0`` to round-off);
    time: ``(...)`` crossing time; phase: ``(...)`` forcing phase in [0, 2 pi);
    status: ``(...)`` int, a :class:`~jaxgear.Status`: ``CONVERGED`` (crossing found),
    ``DIVERGED`` or ``NO_CROSSING``.
    """

    state: Float[Array, "*batch dim"]
    time: Float[Array, "*batch"]
    phase: Float[Array, "*batch"]
    status: Int[Array, "*batch"]


def _crossed(g_old, g_new, direction):
    if direction > 0:
        return (g_old < 0) & (g_new >= 0)
    if direction < 0:
        return (g_old > 0) & (g_new <= 0)
    return ((g_old < 0) & (g_new >= 0)) | ((g_old > 0) & (g_new <= 0))


@eqx.filter_jit
def section_kernel(system, params, Y, t0, periods, index, direction, max_extra_periods, integrator,
                   refine_iters=30):
    """The section map on a batch ``Y (dim, n)``: ``(states (dim, n), times (n,), phases (n,),
    status (n,))`` (see :func:`section_map`)."""
    T = system.period(params)
    if periods > 0:
        Y = integrator.advance(system, params, Y, t0, periods)
    stepper = integrator.crossing_stepper
    search_steps = int(stepper.steps_per_period)
    t_start = t0 + periods * T
    h = T / search_steps
    n = Y.shape[1]
    max_steps = int(max_extra_periods * search_steps)

    def cond(c):
        k, _, found, _, _ = c
        return (k < max_steps) & jnp.any(~found)

    def body(c):
        k, Y, found, Yb, kb = c
        Yn = stepper.step(system, params, t_start + k.astype(jnp.float64) * h, Y, h)
        hit = _crossed(Y[index], Yn[index], direction) & ~found
        Yb = jnp.where(hit[None, :], Y, Yb)
        kb = jnp.where(hit, k, kb)
        found = found | hit | ~jnp.all(jnp.isfinite(Yn), axis=0)
        return k + 1, Yn, found, Yb, kb

    init = (jnp.asarray(0), Y, jnp.zeros(n, bool), Y, jnp.zeros(n, jnp.int64))
    _, Yend, found, Yb, kb = jax.lax.while_loop(cond, body, init)
    tb = t_start + kb.astype(jnp.float64) * h

    # Safeguarded Newton on the step length s in [0, h] so that step(Yb, s)[index] = 0.
    g0 = Yb[index]
    tiny = 8 * jnp.finfo(jnp.float64).eps * jnp.abs(h)

    def refine(_, c):
        s, lo, hi = c
        Ys = stepper.step(system, params, tb, Yb, s)
        g = Ys[index]
        dg = batch_field(system, params, tb + s, Ys)[index]
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

    s0 = jnp.full(n, 0.5 * h)
    s, _, _ = jax.lax.fori_loop(0, refine_iters, refine, (s0, jnp.zeros(n), jnp.full(n, h)))
    Yc = stepper.step(system, params, tb, Yb, s)
    tc = tb + s
    finite = jnp.all(jnp.isfinite(Yc), axis=0) & jnp.all(jnp.isfinite(Yend), axis=0)
    crossed = found & jnp.all(jnp.isfinite(Yb), axis=0)
    status = jnp.where(~finite, int(Status.DIVERGED), jnp.where(crossed, int(Status.CONVERGED),
                                                                 int(Status.NO_CROSSING)))
    Yc = jnp.where((status == Status.CONVERGED)[None, :], Yc, jnp.nan)
    phase = jnp.mod(2 * jnp.pi * tc / T, 2 * jnp.pi)
    return Yc, tc, phase, status


def check_section(system: ForcedSystem, index, direction) -> int:
    """The section coordinate (default ``system.section_index``) after checking ``index``
    and ``direction``; ``ValueError`` naming the problem."""
    index = system.section_index if index is None else index
    if index is None:
        raise ValueError(f"{system.name} has no default section: pass index=i for Σ = {{x_i = 0}}.")
    check_choice(direction, "direction", (1, -1, 0))
    return check_int(index, "index", 0, system.dim - 1)


def section_map(system: ForcedSystem, params, x0: Float[ArrayLike, "*batch dim"], *, periods: int = 1,
                t0: float = 0.0, index: int | None = None,
                direction: int = 1, max_extra_periods: float = 4.0,
                integrator: AbstractIntegrator | None = None) -> SectionHit:
    """The paper's Poincaré-like map on the hyperplane Σ = {x_index = 0} (paper §3, §4.1).

    From ``x0`` at time ``t0``: integrate ``periods`` whole forcing periods, then on to the
    next crossing of Σ with ``direction`` (+1: ``x_index`` increasing, -1: decreasing,
    0: either). The crossing is bracketed by the integrator's
    :attr:`~jaxgear.integrate.AbstractIntegrator.crossing_stepper` and located to
    round-off within the bracketing step (safeguarded Newton on the step length), so
    ``state[..., index]`` is ~1e-15.

    Args:
        x0: ``(..., dim)`` states (the paper starts on Σ at phase 0, ``t0 = 0``).
        periods: whole forcing periods before the search (an int >= 0).
        index: section coordinate; default ``system.section_index``.
        max_extra_periods: how long to search for the crossing before giving up
            (``Status.NO_CROSSING``), in forcing periods (> 0).
    Returns:
        :class:`SectionHit` with the batch shape of ``x0``; failed lanes have NaN state
        and a status other than ``Status.CONVERGED`` (never a silent wrong value).
    """
    index = check_section(system, index, direction)
    periods = check_periods(periods, minimum=0)
    check_number(max_extra_periods, "max_extra_periods", 0, strict_min=True)
    integrator = resolve_integrator(integrator)
    lead, Y = _to_batch(system, x0)
    Yc, tc, ph, st = section_kernel(system, params, Y, jnp.asarray(t0, jnp.float64), periods, index,
                                    int(direction), float(max_extra_periods), integrator)
    return SectionHit(Yc.T.reshape(*lead, system.dim), tc.reshape(lead), ph.reshape(lead), st.reshape(lead))


@eqx.filter_jit
def _sample_kernel(system, params, x0, t0, periods, samples_per_period, integrator):
    lead = x0.shape[:-1]
    ts, Ys = integrator.trajectory(system, params, x0.reshape(-1, system.dim).T, t0, periods, samples_per_period)
    return ts, jnp.moveaxis(Ys, 2, 0).reshape(*lead, Ys.shape[0], system.dim)


def sample_trajectory(system: ForcedSystem, params, x0: Float[ArrayLike, "*batch dim"], *, periods: int = 1,
                      samples_per_period: int = 100, t0: float = 0.0, integrator: AbstractIntegrator | None = None
                      ) -> tuple[Float[Array, " m"], Float[Array, "*batch m dim"]]:
    """Trajectory samples for figures: ``(times (m,), states (..., m, dim))``,
    ``m = periods*samples_per_period + 1``, from ``t0`` to ``t0 + periods*T``.

    The phase trajectories of paper Fig. 3-6. ``x0``: states ``(..., dim)`` at ``t0``
    (system time unit; ``T = system.period(params)``). With a fixed-step integrator each
    sample interval is a whole number of steps (``steps_per_period`` rounded up to a
    multiple of ``samples_per_period``).
    """
    check_state_shape(system, x0)
    periods = check_periods(periods)
    samples_per_period = check_periods(samples_per_period, "samples_per_period")
    integrator = resolve_integrator(integrator)
    return _sample_kernel(system, params, jnp.asarray(x0, jnp.float64), jnp.asarray(t0, jnp.float64),
                          periods, samples_per_period, integrator)


@functools.partial(jax.jit, static_argnames=("system", "integrator"))
def _one_period_kernel(system, params, X, integrator):
    """See :func:`one_period`; ``X (n, dim)`` already padded."""
    n, dim = X.shape
    Y = jnp.repeat(X, dim, axis=0).T  # (dim, n dim)
    T = jnp.tile(jnp.eye(dim, dtype=X.dtype), (1, n))  # (dim, n dim): lane i dim + j moves along e_j
    t0 = jnp.asarray(0.0, jnp.float64)
    stepper = integrator.crossing_stepper

    def samples(Y):
        return stepper.trajectory(system, params, Y, t0, 1, int(stepper.steps_per_period))

    if stepper is integrator:  # a fixed-step method: its last sample is P (the steps of `advance`)
        (ts, Ys), (_, dYs) = jax.jvp(samples, (Y,), (T,))
        dP = dYs[-1]
    else:  # its `flow` is the map's differentiable form (an adaptive solve's forward-mode adjoint)
        ts, Ys = samples(Y)
        flow = jax.vmap(lambda y: integrator.flow(system, params, y, t0, 1), in_axes=1, out_axes=1)
        _, dP = jax.jvp(flow, (Y,), (T,))
    xs = jnp.moveaxis(Ys[:, :, ::dim], 2, 0)  # (n, s + 1, dim): lane i dim is X[i]
    return ts, xs, dP.T.reshape(n, dim, dim).transpose(0, 2, 1)  # [i, :, j] = d P(X[i]) / d x_j


def one_period(system, params, X, integrator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One forcing period from each state of ``X (n, dim)`` (from ``t = 0``), in one
    compiled program: what the points of a cycle need.

    Returns ``(ts (s + 1,), samples (n, s + 1, dim), jacobians (n, dim, dim))``: the
    samples at every step of the integrator's ``crossing_stepper`` (``s`` its steps per
    period; they bracket the section crossings and the contact changes) and ``D P(x)`` of
    the integrator's one-period stroboscopic map, by forward-mode autodiff (the
    kink-aware step's derivatives come from its pure-JAX steps: exact at the backlash
    kinks). Lane ``i dim + j`` starts at ``X[i]`` with the tangent ``e_j`` (the lanes of a
    batch are independent): the step's derivative is traced once, and for a fixed-step
    integrator the same ``jax.jvp`` gives the samples and the derivative (its last sample
    is the map: the steps and step times of ``advance``). The rows are padded to a
    power of two of at least :data:`~jaxgear._batching.SMALL_BATCH` lanes, so every
    call of a process with the same integrator shares one program."""
    X = np.asarray(X, np.float64)
    n, dim = X.shape
    rows = pad_rows(X, power_of_two_at_least(n, max(1, SMALL_BATCH // dim)))
    ts, xs, J = _one_period_kernel(system, params, jax.device_put(rows), integrator)
    return np.asarray(ts), np.asarray(xs)[:n], np.asarray(J)[:n]


LOCATE_BISECTIONS = 48
"""Bisection steps of :func:`locate_sign_changes` by default: the bracket shrinks by
``2**48``, to round-off of a step's length."""


def switching_count(system, params) -> int:
    """The number of the system's switching functions (0 without them), from their shape
    (``jax.eval_shape``: nothing is computed): the index of the coordinate functions in
    :func:`surfaces`."""
    if system.switching is None:
        return 0
    state = jax.ShapeDtypeStruct((system.dim,), jnp.float64)
    return int(jax.eval_shape(system.switching, 0.0, state, params).shape[0])


def surfaces(system, params, t, Z):
    """The functions whose sign changes :func:`locate_sign_changes` locates, at the lanes
    ``Z (dim, n)`` at times ``t (n,)``: the system's switching functions (none without
    them), then the coordinates (a section ``x_i = 0`` is function ``n_switching + i``):
    ``(n, n_switching + dim)``."""
    S = (jax.vmap(system.switching, in_axes=(0, 1, None))(t, Z, params) if system.switching is not None
         else jnp.zeros((Z.shape[1], 0), Z.dtype))
    return jnp.concatenate([S, Z.T], axis=1)


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def locate_sign_changes(system, stepper, n_iter, params, t, Y, H, which, positive):
    """Where function ``which`` of :func:`surfaces` changes sign inside a step: the time
    ``tau`` in ``[0, H]`` after ``t`` and the state there, for the trajectories through
    ``Y (dim, n)`` at ``t (n,)``, by ``n_iter`` bisections on one step of ``stepper`` of
    length ``tau`` from the start (a kink-aware step is split at the kinks it crosses, so
    the located state is as accurate as the integration). ``positive (n,)``: the
    function's sign at the start. Returns ``tau (n,)`` and the states ``(dim, n)``.

    The lanes run in chunks of :data:`~jaxgear._batching.SMALL_BATCH` (``n`` a multiple
    of it): the step is traced once for every caller (contact changes of the gear view,
    section points of the cycles)."""
    n = Y.shape[1]
    W = min(n, SMALL_BATCH)

    def chunk(c):
        t, Y, H, which, positive = c

        def side(tau):
            Z = stepper.step(system, params, t, Y, tau)
            return jnp.take_along_axis(surfaces(system, params, t + tau, Z), which[:, None], axis=1)[:, 0] > 0

        def body(_, b):
            lo, hi = b
            mid = 0.5 * (lo + hi)
            same = side(mid) == positive
            return jnp.where(same, mid, lo), jnp.where(same, hi, mid)

        lo, hi = jax.lax.fori_loop(0, n_iter, body, (jnp.zeros_like(H), H))
        tau = 0.5 * (lo + hi)
        return tau, stepper.step(system, params, t, Y, tau)

    cut = lambda a: a.reshape(a.shape[:-1] + (n // W, W)).swapaxes(0, -2) if a.ndim > 1 else a.reshape(n // W, W)  # noqa: E731
    tau, Z = jax.lax.map(chunk, (cut(t), cut(Y), cut(H), cut(which), cut(positive)))
    return tau.reshape(n), jnp.moveaxis(Z, 0, 1).reshape(Y.shape[0], n)
