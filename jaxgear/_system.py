"""A periodically forced dynamical system ``x' = f(t, x, params)``, ``f(t + T) = f(t)``.

This is paper eq. (6). Every analysis in jaxgear (Poincaré maps, cell mapping,
shooting, sweeps) takes a :class:`ForcedSystem` plus a parameter pytree; the gear
models of :mod:`jaxgear._model` are two such systems.
"""

from __future__ import annotations

import enum
import functools
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import is_traced

__all__ = ["ForcedSystem", "NativeKernel", "check_system", "check_state_shape", "state_index"]


class NativeKernel(enum.Enum):
    """The compiled CPU kernel that integrates a built-in model (``ForcedSystem.native``).

    ``REDUCED``: the reduced 2-DOF gear model of paper §4.1 (``jaxgear/integrate/native/gear_kernel.cc``).
    """

    REDUCED = "reduced"


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
        switching: ``switching(t, x, params) -> (m,)``, or ``None``: functions whose zero
            sets are where the vector field has a kink (its derivative jumps, as at the
            backlash boundaries ``|X| = b``) or a jump. The kink-aware integrator splits
            every step at their crossings, which keeps its fourth order and gives exact
            monodromy matrices through those surfaces.
        time_breaks: ``time_breaks(params) -> (q,)``, or ``None``: phases in ``[0, 1)``
            (fractions of the forcing period) at which the vector field jumps or kinks
            in time (a rectangular mesh-stiffness wave); steps are split there exactly.
        piece_field: ``piece_field(t, x, params, sides) -> dx/dt``, or ``None``: the smooth
            piece of the vector field on the sides ``sides`` (``(m,)`` of ``+1``/``-1``,
            the signs of ``switching``) of every surface, extended across them. With it the
            kink-aware integrator evaluates every stage of a split step on its own piece,
            which makes each sub-step a step of a smooth field: Floquet multipliers then
            converge at a regular fourth order (without it, at fourth order with a
            coefficient that depends on where the crossings fall in the steps).
        field_jumps: ``True`` when the vector field itself (not only its derivative)
            jumps across a switching surface (requires ``piece_field``); the integrator
            then applies the saltation matrix to first derivatives (monodromy matrices);
            second derivatives (gradients of multipliers) through a jump are not exact.
        native: the :class:`NativeKernel` that integrates this system on CPUs (the
            built-in reduced gear model has one), or ``None`` (the pure-JAX steps). The
            kernel computes this system's own equations: leave it ``None`` for any other.

    Times and states are in the user's units (the gear models are dimensionless:
    time ``tau = omega_n t``, lengths in ``b_c``, model document §3). Systems without
    switching functions behave as smooth systems.
    """

    vector_field: Callable[[Any, Any, Any], Any] = eqx.field(static=True)
    period: Callable[[Any], Any] = eqx.field(static=True)
    state_names: tuple[str, ...] = eqx.field(static=True, converter=tuple)  # a list too (hashable: a jit key)
    section_index: int | None = eqx.field(static=True, default=None)
    name: str = eqx.field(static=True, default="system")
    switching: Callable[[Any, Any, Any], Any] | None = eqx.field(static=True, default=None)
    time_breaks: Callable[[Any], Any] | None = eqx.field(static=True, default=None)
    piece_field: Callable[[Any, Any, Any, Any], Any] | None = eqx.field(static=True, default=None)
    field_jumps: bool = eqx.field(static=True, default=False)
    native: NativeKernel | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if self.native is not None and not isinstance(self.native, NativeKernel):
            raise ValueError(f"ForcedSystem.native={self.native!r} must be a NativeKernel member (the compiled "
                             f"kernel of a built-in model: {', '.join(k.name for k in NativeKernel)}) or None.")
        if not callable(self.vector_field):
            raise TypeError("ForcedSystem.vector_field must be callable f(t, x, params).")
        if not callable(self.period):
            raise TypeError("ForcedSystem.period must be callable period(params) -> T.")
        if self.field_jumps and (self.switching is None or self.piece_field is None):
            raise ValueError("ForcedSystem(field_jumps=True) needs switching functions and a piece_field: "
                             "a field that jumps across a surface is integrated piece by piece.")
        if self.piece_field is not None and self.switching is None:
            raise ValueError("ForcedSystem.piece_field needs switching functions (its sides are their signs).")
        for name in ("switching", "time_breaks", "piece_field"):
            if getattr(self, name) is not None and not callable(getattr(self, name)):
                raise TypeError(f"ForcedSystem.{name} must be callable or None.")
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

    @property
    def is_piecewise(self) -> bool:
        """True when the system declares switching surfaces or time breaks."""
        return self.switching is not None or self.time_breaks is not None


def check_system(system: ForcedSystem, params: Any, x0: Any | None = None, *, batched: bool | None = None) -> None:
    """Check a user system (paper eq. 6) and its parameters once, outside any ``jit``, with clear errors.

    Raises ``ValueError`` when

    - ``system.period(params)`` fails, is not a positive finite real number, is so
      small that its time steps are lost in float64 rounding (:data:`STEPS_RESOLVED`),
      or is not a scalar although the parameters are not batched (a period that depends
      on the parameters in a non-scalar way);
    - ``system.vector_field(0, x, params)`` fails, returns something other than a real
      floating-point array of shape ``(dim,)`` for a state of shape ``(dim,)`` (complex
      or integer values are refused), or a non-finite value
      at ``x0`` (default: the origin; the first state if ``x0`` is a batch).

    Args:
        batched: ``False``: the parameters are one set (the period must be a scalar);
            ``True``: batched parameters for a sweep (a period of any shape, all
            positive; the per-lane field check is the caller's); ``None`` (default):
            batched only if some parameter leaf is an array and the period is one.
    """
    name = getattr(system, "name", "system")
    try:
        raw = system.period(params)
    except Exception as e:  # a user function failing on these parameters
        raise ValueError(f"{name}: period(params) failed on these parameters: {type(e).__name__}: {e}") from e
    if np.iscomplexobj(raw):
        raise ValueError(f"{name}: period(params) must be a real number; it returned complex values "
                         f"({np.asarray(raw).tolist()}).")
    try:
        T = np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: period(params) must return a number; it returned {type(raw).__name__}.") from e
    if T.ndim:
        leaves_nd = [np.ndim(leaf) for leaf in jax.tree_util.tree_leaves(params)]
        if batched is None:
            batched = any(d > 0 for d in leaves_nd)
        if not batched:
            raise ValueError(
                f"{name}: period(params) must return a scalar (the forcing period T); it returned shape "
                f"{T.shape}. Write it as a scalar function of the parameters, e.g. 2*pi/params.omega."
            )
    if not (np.all(np.isfinite(T)) and np.all(T > 0)):
        got = float(T) if T.ndim == 0 else T
        raise ValueError(f"{name}: the forcing period must be positive and finite, got period(params) = {got}.")
    if np.any(1.0 + T / STEPS_RESOLVED == 1.0):
        got = float(np.min(T))
        raise ValueError(f"{name}: the forcing period {got:g} is too small for float64 times: a step of "
                         f"period/{STEPS_RESOLVED:g} is lost in rounding next to t = 1, so the integration "
                         "would not advance as asked. Rescale time so that the period is of order 1 (e.g. "
                         "time in units of 1/omega).")
    if T.ndim:
        return  # batched parameters: the per-lane field check happens in the caller
    x = jnp.zeros(system.dim) if x0 is None else jnp.asarray(x0, dtype=float)
    check_state_shape(system, x)
    if x.ndim > 1:
        x = x.reshape(-1, system.dim)[0]
    try:
        dx = _field_at_time_zero(system, x, params)
    except Exception as e:
        raise ValueError(f"{name}: vector_field(t, x, params) failed for a state of shape ({system.dim},): "
                         f"{type(e).__name__}: {e}") from e
    if not isinstance(dx, jax.Array):
        raise ValueError(f"{name}: the vector field must return one array of shape ({system.dim},) "
                         f"(use jnp.stack([...])); it returned {type(dx).__name__}.")
    if not jnp.issubdtype(dx.dtype, jnp.floating):
        raise ValueError(f"{name}: the vector field must return real floating-point values (float64); it "
                         f"returned dtype {dx.dtype}"
                         + (" (take the real part, or keep the state real)" if jnp.issubdtype(dx.dtype, jnp.complexfloating)
                            else " (compute in floats: 1.0 * x, jnp.asarray(..., float))") + ".")
    if dx.shape != (system.dim,):
        raise ValueError(
            f"{name}: the vector field must return shape ({system.dim},) for a state "
            f"of shape ({system.dim},) ({', '.join(system.state_names)}); it returned {dx.shape}."
        )
    val = np.asarray(dx)
    if not np.all(np.isfinite(val)):
        raise ValueError(
            f"{name}: the vector field is not finite at t=0, x={np.asarray(x).tolist()}: "
            f"{val.tolist()}. Check the parameters."
        )


STEPS_RESOLVED = 1000.0
"""A step of ``period / STEPS_RESOLVED`` must change a time of 1 in float64:
:func:`check_system` refuses a smaller period (about 1e-13), whose steps vanish in
rounding next to the times an integration meets (the steps of the built-in integrators
are ``period / steps_per_period``, 200 by default)."""


@functools.partial(jax.jit, static_argnums=0)
def _field_at_time_zero(system: ForcedSystem, x, params):
    """``system.vector_field(0, x, params)``, compiled once per system and parameter
    structure: :func:`check_system` runs before every analysis (of a sweep's every value),
    and a fresh ``jit`` of a closure would trace and compile each time (0.1 s)."""
    return system.vector_field(0.0, x, params)


def check_state_shape(system: ForcedSystem, x: Any) -> None:
    """Raise ``ValueError`` unless ``x`` has shape ``(..., dim)`` and finite values."""
    shape = np.shape(x)
    if len(shape) == 0 or shape[-1] != system.dim:
        raise ValueError(
            f"{system.name}: states must have shape (..., {system.dim}) "
            f"({', '.join(system.state_names)}); got shape {shape}."
        )
    if not is_traced(x) and not np.all(np.isfinite(np.asarray(x))):
        raise ValueError(f"{system.name}: initial states contain NaN or infinite values.")


def state_index(state_names, name) -> int:
    """Index of a state coordinate given by name (``"x3"``) or index; ``ValueError`` naming
    the valid ones."""
    if isinstance(name, str):
        if name not in state_names:
            raise ValueError(f"unknown coordinate {name!r}; the state is ({', '.join(state_names)}).")
        return list(state_names).index(name)
    if isinstance(name, bool) or not isinstance(name, (int, np.integer)) or not 0 <= int(name) < len(state_names):
        raise ValueError(f"coordinate {name!r} must be a name or an index in 0..{len(state_names) - 1}.")
    return int(name)
