"""Adaptive integration by diffrax (the reference flow)."""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import AbstractFixedStep, AbstractIntegrator


def _diffrax():
    """diffrax, imported on first use (it adds half a second to every start otherwise)."""
    import diffrax

    return diffrax

__all__ = ["Adaptive"]


class Adaptive(AbstractIntegrator):
    """A diffrax solver with adaptive steps (default Tsit5, ``rtol = atol = 1e-10``).

    The reference integrator for the flow of paper eq. (6): ``rtol`` and ``atol`` are
    the relative and absolute error tolerances per step (``atol`` in state units).
    ``max_steps`` bounds the steps of one call; a lane that exceeds it is returned as
    non-finite (it ends in the sink of a cell map, never as a silent wrong value).
    Section crossings are bracketed with ``search_steps_per_period`` fixed RK4 steps.
    """

    name: ClassVar[str] = "Adaptive"
    solver: Any = eqx.field(static=True, default_factory=lambda: _diffrax().Tsit5())
    rtol: float = eqx.field(static=True, default=1e-10)
    atol: float = eqx.field(static=True, default=1e-10)
    max_steps: int = eqx.field(static=True, default=200_000)
    search_steps_per_period: int = eqx.field(static=True, default=400)

    def __check_init__(self):
        if not (self.rtol > 0 and self.atol > 0):
            raise ValueError(f"Adaptive: rtol={self.rtol} and atol={self.atol} must be > 0.")
        if int(self.max_steps) < 1:
            raise ValueError(f"Adaptive: max_steps={self.max_steps} must be >= 1.")

    def solve(self, system, params, y0, t0, t1, ts=None, adjoint=None):
        """One state ``y0 (dim,)`` from ``t0`` to ``t1``: the final state, or the states at
        ``ts (m,)`` (``(m, dim)``); NaN where the solve failed."""
        diffrax = _diffrax()
        term = diffrax.ODETerm(lambda t, y, args: system.vector_field(t, y, args))
        T = system.period(params)
        saveat = diffrax.SaveAt(t1=True) if ts is None else diffrax.SaveAt(ts=ts)
        kw = {} if adjoint is None else {"adjoint": adjoint}
        sol = diffrax.diffeqsolve(
            term, self.solver, t0, t1, dt0=T / 64, y0=y0, args=params, saveat=saveat,
            stepsize_controller=diffrax.PIDController(rtol=self.rtol, atol=self.atol),
            max_steps=self.max_steps, throw=False, **kw,
        )
        ok = sol.result == diffrax.RESULTS.successful
        ys = sol.ys if ts is not None else sol.ys[-1]
        return jnp.where(ok, ys, jnp.nan)

    def advance(self, system, params, Y, t0, periods: int, n_active=None):
        t1 = t0 + periods * system.period(params)
        return jax.vmap(lambda y: self.solve(system, params, y, t0, t1), in_axes=1, out_axes=1)(Y)

    def flow(self, system, params, x, t0, periods: int):
        # DirectAdjoint: forward mode (monodromy by jacfwd) and reverse mode (implicit gradients)
        t1 = t0 + periods * system.period(params)
        return self.solve(system, params, x, t0, t1, adjoint=_diffrax().DirectAdjoint())

    def trajectory(self, system, params, Y, t0, periods: int, samples_per_period: int):
        T = system.period(params)
        m = int(periods) * int(samples_per_period)
        ts = t0 + T * jnp.arange(m + 1, dtype=jnp.float64) / samples_per_period
        Ys = jax.vmap(lambda y: self.solve(system, params, y, t0, ts[-1], ts=ts), in_axes=1, out_axes=2)(Y)
        return ts, Ys

    @property
    def crossing_stepper(self) -> AbstractFixedStep:
        from ._kink import KinkAwareRK4

        return KinkAwareRK4(int(self.search_steps_per_period))

    def refined(self) -> Adaptive:
        """Tolerances divided by 16 (and a refined crossing stepper)."""
        return dataclasses.replace(self, rtol=self.rtol / 16, atol=self.atol / 16)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.name, "solver": type(self.solver).__name__, "rtol": float(self.rtol),
                "atol": float(self.atol), "max_steps": int(self.max_steps),
                "search_steps_per_period": int(self.search_steps_per_period)}
