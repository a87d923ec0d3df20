"""Time integration of a :class:`~jaxgear.ForcedSystem`: fixed-step RK4 and diffrax.

Two strategies behind one interface (:func:`advance`, :func:`sample`):

- :class:`RK4` — the classical fourth-order Runge-Kutta method with a fixed number of
  steps per forcing period, the paper's integrator (§4.1). Batches of states are kept
  as ``(dim, n)`` arrays (struct of arrays) so each coordinate is one contiguous
  vector, and time-only terms (mesh stiffness, errors) are evaluated once per stage
  for the whole batch.
- :class:`Adaptive` — any diffrax solver with a PID step-size controller.

Times are in the system's own unit; durations are whole forcing periods.
"""

from __future__ import annotations

from typing import Any

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from ._system import ForcedSystem

__all__ = ["RK4", "Adaptive", "Integrator", "advance", "advance_batch", "sample", "rk4_step_batch"]


class Integrator(eqx.Module):
    """Base class of the integration strategies."""


class RK4(Integrator):
    """Classical RK4 with ``steps_per_period`` fixed steps per forcing period (paper §4.1).

    The gear model's vector field has kinks at ``|X| = b`` (backlash), where RK4
    converges at about second order; 200-400 steps per period give periodic points
    to ~1e-4 (MODEL.md §8). Use :class:`Adaptive` for reference solutions. The step is
    ``h = T / steps_per_period`` in the system's time unit.
    """

    steps_per_period: int = eqx.field(static=True, default=200)

    def __check_init__(self):
        if int(self.steps_per_period) < 1:
            raise ValueError(f"steps_per_period={self.steps_per_period} must be >= 1.")


class Adaptive(Integrator):
    """A diffrax solver with adaptive steps (default Tsit5, rtol=atol=1e-10).

    The reference integrator for the flow of paper eq. (6) (MODEL.md §8): ``rtol`` and
    ``atol`` are the relative and absolute error tolerances per step (``atol`` in state
    units: ``b_c`` and ``b_c omega_n`` for the gear models). ``max_steps`` bounds the
    steps over one call; a lane that exceeds it is returned as non-finite (it ends in
    the sink of a cell map, never as a silent wrong value).
    """

    solver: Any = eqx.field(static=True, default_factory=diffrax.Tsit5)
    rtol: float = eqx.field(static=True, default=1e-10)
    atol: float = eqx.field(static=True, default=1e-10)
    max_steps: int = eqx.field(static=True, default=200_000)


# ----------------------------------------------------------------------- RK4 kernel
def _batched_field(system: ForcedSystem):
    """``f(t, Y, params)`` on a ``(dim, n)`` batch; time-only terms computed once."""
    return jax.vmap(system.vector_field, in_axes=(None, 1, None), out_axes=1)


def _lane_field(system: ForcedSystem):
    """``f(t, Y, params)`` on a ``(dim, n)`` batch with one time per lane (``t`` of shape ``(n,)``)."""
    return jax.vmap(system.vector_field, in_axes=(0, 1, None), out_axes=1)


def rk4_step_batch(f, t, Y, h, params):
    """One classical RK4 step of size ``h`` for a batch ``Y`` of shape ``(dim, n)``.

    ``f`` is :func:`_batched_field` (scalar ``t`` and ``h``) or :func:`_lane_field`
    (``t`` and ``h`` of shape ``(n,)``).
    """
    h2 = 0.5 * h
    k1 = f(t, Y, params)
    k2 = f(t + h2, Y + h2 * k1, params)
    k3 = f(t + h2, Y + h2 * k2, params)
    k4 = f(t + h, Y + h * k3, params)
    return Y + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


def _rk4_advance_T(system, params, Y, t0, n_steps, h):
    """``n_steps`` RK4 steps of size ``h`` on a batch ``Y (dim, n)``, chunked when large.

    A batch larger than :func:`_chunk_cells` is cut into equal chunks that run one
    after the other, each through all its steps, inside the same computation: a
    chunk's working set (the state and the RK4 stages) stays in the last-level cache
    instead of streaming through main memory at every stage. Chunks are read from
    ``Y`` and written into the result in place; the last one is shifted back to end at
    lane ``n`` (its overlap with the previous chunk is computed twice, from the same
    input, to the same values). Each lane's arithmetic is unchanged, so the result is
    bit-for-bit that of the unchunked loop.
    """
    dim, n = Y.shape
    chunk = _chunk_cells(dim)
    if n <= chunk:
        return _rk4_loop(system, params, Y, t0, n_steps, h)
    n_chunks = -(-n // chunk)
    per_chunk = -(-n // n_chunks)
    size = min(n, -(-per_chunk // 8) * 8)  # equal chunks of whole SIMD vectors

    def one_chunk(i, out):
        start = jnp.minimum(i * size, n - size)
        Yb = jax.lax.dynamic_slice_in_dim(Y, start, size, axis=1)
        Yb = _rk4_loop(system, params, Yb, t0, n_steps, h)
        return jax.lax.dynamic_update_slice_in_dim(out, Yb, start, axis=1)

    return jax.lax.fori_loop(0, n_chunks, one_chunk, Y)


# Working set of one chunk of the RK4 loop (state, three stages and the new state,
# 5 arrays of dim x chunk float64), sized for a shared last-level cache of >= 16 MiB.
# Measured on 2-core AMD EPYC (32 MiB L3), reduced model, 10^6 cells: 22.7 ns per
# step per cell unchunked, 6.0 ns with chunks of 65,536-100,000 cells, 9.8 ns with
# 32,768 (each stage is one multithreaded XLA loop whose start-up cost then shows).
_CHUNK_BYTES = 16 * 2**20


def _chunk_cells(dim: int) -> int:
    """Largest number of lanes :func:`_rk4_advance_T` integrates in one piece."""
    return max(4096, _CHUNK_BYTES // (5 * 8 * int(dim)))


def _rk4_loop(system, params, Y, t0, n_steps, h):
    f = _batched_field(system)

    def body(i, Y):
        return rk4_step_batch(f, t0 + i * h, Y, h, params)

    return jax.lax.fori_loop(0, n_steps, body, Y)


# ----------------------------------------------------------------------- interface
def advance_batch(system: ForcedSystem, params, Y, t0, periods: int, integrator: Integrator = RK4()):
    """Advance a batch ``Y`` of shape ``(dim, n)`` from ``t0`` by ``periods`` forcing periods.

    ``periods`` is a Python int (it sets the loop length). Returns ``(dim, n)``.
    """
    T = system.period(params)
    if isinstance(integrator, RK4):
        n = integrator.steps_per_period * int(periods)
        return _rk4_advance_T(system, params, Y, t0, n, T / integrator.steps_per_period)
    if isinstance(integrator, Adaptive):
        one = lambda y: _diffrax_solve(system, params, y, t0, t0 + periods * T, integrator)
        return jax.vmap(one, in_axes=1, out_axes=1)(Y)
    raise TypeError(f"unknown integrator {integrator!r}; use jaxgear.RK4 or jaxgear.Adaptive.")


def advance(system: ForcedSystem, params, x0, t0, periods: int, integrator: Integrator = RK4()):
    """Advance states ``x0`` of shape ``(..., dim)`` by ``periods`` forcing periods from ``t0``.

    The flow of paper eq. (6) over ``periods * T`` (``T = system.period(params)``;
    ``t0`` in the system's time unit, dimensionless ``tau = omega_n t`` for the gear
    models, MODEL.md §3). Returns states of shape ``(..., dim)`` (state units); a lane
    that blew up is non-finite."""
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    lead = x0.shape[:-1]
    Y = x0.reshape(-1, system.dim).T
    Y = advance_batch(system, params, Y, t0, periods, integrator)
    return Y.T.reshape(*lead, system.dim)


def _diffrax_solve(system, params, y0, t0, t1, integ: Adaptive, ts=None):
    term = diffrax.ODETerm(lambda t, y, args: system.vector_field(t, y, args))
    T = system.period(params)
    saveat = diffrax.SaveAt(t1=True) if ts is None else diffrax.SaveAt(ts=ts)
    sol = diffrax.diffeqsolve(
        term, integ.solver, t0, t1, dt0=T / 64, y0=y0, args=params, saveat=saveat,
        stepsize_controller=diffrax.PIDController(rtol=integ.rtol, atol=integ.atol),
        max_steps=integ.max_steps, throw=False,
    )
    ok = sol.result == diffrax.RESULTS.successful
    ys = sol.ys if ts is not None else sol.ys[-1]
    return jnp.where(ok, ys, jnp.nan)


def sample(system: ForcedSystem, params, x0, t0, periods: int, samples_per_period: int = 100,
           integrator: Integrator = RK4()):
    """Sample trajectories for plots: times ``(m,)`` and states ``(..., m, dim)``.

    ``m = periods * samples_per_period + 1`` points from ``t0`` to ``t0 + periods*T``.
    With :class:`RK4` the sample spacing is a whole number of steps: ``steps_per_period``
    is rounded up to a multiple of ``samples_per_period``.
    """
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    lead = x0.shape[:-1]
    Y0 = x0.reshape(-1, system.dim).T
    T = system.period(params)
    m = int(periods) * int(samples_per_period)
    ts = t0 + T * jnp.arange(m + 1) / samples_per_period
    if isinstance(integrator, RK4):
        sub = -(-integrator.steps_per_period // samples_per_period)
        h = T / (sub * samples_per_period)
        f = _batched_field(system)

        def one_sample(Y, i):
            t_start = t0 + i * sub * h
            Y = jax.lax.fori_loop(0, sub, lambda j, Y: rk4_step_batch(f, t_start + j * h, Y, h, params), Y)
            return Y, Y

        _, Ys = jax.lax.scan(one_sample, Y0, jnp.arange(m))
        Ys = jnp.concatenate([Y0[None], Ys], axis=0)  # (m+1, dim, n)
    elif isinstance(integrator, Adaptive):
        Ys = jax.vmap(lambda y: _diffrax_solve(system, params, y, t0, ts[-1], integrator, ts=ts),
                      in_axes=1, out_axes=2)(Y0)  # (m+1, dim, n)
    else:
        raise TypeError(f"unknown integrator {integrator!r}")
    states = jnp.moveaxis(Ys, 2, 0).reshape(*lead, m + 1, system.dim)
    return ts, states
