"""Classical fourth-order Runge-Kutta with fixed steps (the paper's integrator, §4.1)."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

from ._base import DEFAULT_STEPS_PER_PERIOD, AbstractFixedStep, batch_field, check_steps_per_period

__all__ = ["RK4", "rk4_step"]


def rk4_step(system, params, t, Y, h):
    """One classical RK4 step of size ``h`` for a batch ``Y (dim, n)`` (``t``, ``h``
    scalars or ``(n,)``)."""
    h2 = 0.5 * h
    k1 = batch_field(system, params, t, Y)
    k2 = batch_field(system, params, t + h2, Y + h2 * k1)
    k3 = batch_field(system, params, t + h2, Y + h2 * k2)
    k4 = batch_field(system, params, t + h, Y + h * k3)
    return Y + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


class RK4(AbstractFixedStep):
    """Classical RK4 with ``steps_per_period`` fixed steps per forcing period (paper §4.1).

    Steps that straddle a kink of the vector field (the backlash of the gear models at
    ``|X| = b``) lose two orders: states converge at second order there (model document
    §8). The step is ``h = T / steps_per_period`` in the system's time unit.
    """

    name: ClassVar[str] = "RK4"
    steps_per_period: int = eqx.field(static=True, default=DEFAULT_STEPS_PER_PERIOD)

    def __check_init__(self):
        check_steps_per_period(self.steps_per_period)

    def step(self, system, params, t, Y, h):
        return rk4_step(system, params, t, Y, h)
