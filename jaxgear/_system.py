"""A periodically forced dynamical system ``x' = f(t, x, params)``, ``f(t + T) = f(t)``.

This is paper eq. (6). Every analysis in jaxgear (Poincaré maps, cell mapping,
shooting, sweeps) takes a :class:`ForcedSystem` plus a parameter pytree; the gear
models of :mod:`jaxgear._model` are two such systems.
"""

from __future__ import annotations

from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["ForcedSystem", "check_system"]


class ForcedSystem(eqx.Module):
    """A non-autonomous system periodic in time (paper eq. 6).

    Attributes:
        vector_field: ``f(t, x, params) -> dx/dt``; ``t`` a scalar, ``x`` of shape
            ``(dim,)``, pure JAX (it is jitted, vmapped and differentiated).
        period: ``period(params) -> T``, the forcing period (same time unit as ``t``).
        state_names: names of the ``dim`` state coordinates, e.g. ``("x1", "x2")``.
        section_index: coordinate ``i`` of the default hyperplane section
            ``{x_i = 0}`` (the paper's Σ = {x4 = 0} is index 3), or ``None``.
        name: a short label used in results and figures.

    Times and states are in the user's units (the gear models are dimensionless:
    time ``tau = omega_n t``, lengths in ``b_c``, MODEL.md §3).
    """

    vector_field: Callable[[Any, Any, Any], Any] = eqx.field(static=True)
    period: Callable[[Any], Any] = eqx.field(static=True)
    state_names: tuple[str, ...] = eqx.field(static=True)
    section_index: int | None = eqx.field(static=True, default=None)
    name: str = eqx.field(static=True, default="system")

    def __check_init__(self):
        if not callable(self.vector_field):
            raise TypeError("ForcedSystem.vector_field must be callable f(t, x, params).")
        if not callable(self.period):
            raise TypeError("ForcedSystem.period must be callable period(params) -> T.")
        if len(self.state_names) < 1:
            raise ValueError("ForcedSystem.state_names must name at least one coordinate.")
        if self.section_index is not None and not 0 <= self.section_index < len(self.state_names):
            raise ValueError(
                f"ForcedSystem.section_index={self.section_index} is outside "
                f"0..{len(self.state_names) - 1} (the state has {len(self.state_names)} coordinates)."
            )

    @property
    def dim(self) -> int:
        """Number of state coordinates."""
        return len(self.state_names)


def check_system(system: ForcedSystem, params: Any, x0: Any | None = None) -> None:
    """Check a system (paper eq. 6) and its parameters once, outside any ``jit``, with clear errors.

    Args:
        system: the :class:`ForcedSystem`.
        params: its parameter pytree (scalars; batched parameters only have their
            periods checked).
        x0: a state of shape ``(dim,)`` (or ``(..., dim)``: its first row) at which the
            vector field is evaluated at ``t = 0``; default the origin.
    Raises:
        ValueError: the period ``T`` (system time unit) is not a positive finite number,
            the vector field returns a shape other than ``(dim,)``, or a non-finite
            value at ``x0``.
    """
    T = np.asarray(system.period(params), dtype=float)
    if T.ndim == 0:
        if not np.isfinite(T) or T <= 0:
            raise ValueError(f"{system.name}: the forcing period must be positive and finite, got {float(T)}.")
    elif not (np.all(np.isfinite(T)) and np.all(T > 0)):
        raise ValueError(f"{system.name}: the forcing period must be positive and finite, got {T}.")
    if T.ndim:
        return  # batched parameters: the per-lane field check happens in the caller
    x = jnp.zeros(system.dim) if x0 is None else jnp.asarray(x0, dtype=float)
    check_state_shape(system, x)
    if x.ndim > 1:
        x = x.reshape(-1, system.dim)[0]
    dx = jax.eval_shape(lambda xx: system.vector_field(0.0, xx, params), x)
    if dx.shape != (system.dim,):
        raise ValueError(
            f"{system.name}: the vector field must return shape ({system.dim},) for a state "
            f"of shape ({system.dim},); it returned {dx.shape}."
        )
    val = np.asarray(system.vector_field(0.0, x, params))
    if not np.all(np.isfinite(val)):
        raise ValueError(
            f"{system.name}: the vector field is not finite at t=0, x={np.asarray(x).tolist()}: "
            f"{val.tolist()}. Check the parameters."
        )


def check_state_shape(system: ForcedSystem, x: Any) -> None:
    """Raise ``ValueError`` unless ``x`` has shape ``(..., dim)`` and finite values."""
    shape = np.shape(x)
    if len(shape) == 0 or shape[-1] != system.dim:
        raise ValueError(
            f"{system.name}: states must have shape (..., {system.dim}) "
            f"({', '.join(system.state_names)}); got shape {shape}."
        )
    if not isinstance(x, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(x))):
        raise ValueError(f"{system.name}: initial states contain NaN or infinite values.")
