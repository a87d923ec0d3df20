"""Options of the pseudo-arclength continuation (:func:`~jaxgear.continue_orbit`,
:func:`~jaxgear.switch_branch`): the step control and the bifurcation search.

The corrector's Newton tolerances are those of the shooting method,
:class:`~jaxgear.ShootOptions` (``tol``, ``max_iter``, ``max_norm``; :data:`CORRECTOR`
by default). Both are immutable ``eqx.Module``s checked at construction.
"""

from __future__ import annotations

import math

import equinox as eqx

from .._checks import check_bool, check_int, check_number
from ..shooting import ShootOptions

__all__ = ["ContinuationOptions", "CORRECTOR"]

CORRECTOR = ShootOptions(max_iter=10)
"""The corrector's options when none are given: the defaults of :class:`ShootOptions`
with 10 Newton iterations per step (a step needing more is retried with half the step)."""


def _pair(bounds):
    """``bounds`` as a pair of floats (``None`` stays ``None``; anything else is checked later)."""
    if bounds is None:
        return None
    try:
        lo, hi = bounds
        return float(lo), float(hi)
    except (TypeError, ValueError):
        return bounds


class ContinuationOptions(eqx.Module):
    """The step control and bifurcation search of a continuation (paper §4.1 extended
    along a parameter; see :mod:`jaxgear.continuation._arclength`).

    Attributes:
        ds: initial arclength step in ``(x, p)`` (state and parameter units mixed:
            choose it for the faster-changing of the two).
        ds_min, ds_max: the step's bounds (``None``: ``ds / 1e4`` and ``10 ds``).
        max_steps: the most continuation steps (a branch has at most ``max_steps + 1`` points).
        max_angle: largest turn of the tangent per step (rad); a step turning more is
            retried with half the step (keeps the branch from jumping).
        bounds: ``(low, high)`` of the parameter; the branch ends on leaving it (``None``: no bounds).
        detect: detect and locate bifurcations (PD, SN, BP, NS).
        locate_tol: arclength tolerance of the bifurcation location.
    """

    ds: float = 0.01
    ds_min: float | None = None
    ds_max: float | None = None
    max_steps: int = eqx.field(static=True, default=500)
    max_angle: float = 0.5
    bounds: tuple[float, float] | None = eqx.field(static=True, default=None, converter=_pair)
    detect: bool = eqx.field(static=True, default=True)
    locate_tol: float = 1e-10

    def __check_init__(self):
        check_number(self.ds, "ds", 0, strict_min=True)
        for name in ("ds_min", "ds_max"):
            if getattr(self, name) is not None:
                check_number(getattr(self, name), f"{name} (or None for the default)", 0, strict_min=True)
        lo, hi = self.step_range
        if not lo <= self.ds <= hi:
            raise ValueError(f"need ds_min <= ds <= ds_max, got ds_min={lo:g}, ds={self.ds:g}, ds_max={hi:g}.")
        check_int(self.max_steps, "max_steps", 1)
        check_number(self.max_angle, "max_angle (rad)", 0, math.pi, strict_min=True)
        if self.bounds is not None:
            b = self.bounds
            if not (isinstance(b, tuple) and len(b) == 2 and all(math.isfinite(v) for v in b) and b[0] < b[1]):
                raise ValueError(f"bounds={b!r} must be (low, high) with finite low < high, or None.")
        check_bool(self.detect, "detect")
        check_number(self.locate_tol, "locate_tol", 0, strict_min=True)

    @property
    def step_range(self) -> tuple[float, float]:
        """``(ds_min, ds_max)`` with their defaults filled in."""
        lo = self.ds * 1e-4 if self.ds_min is None else float(self.ds_min)
        hi = self.ds * 10.0 if self.ds_max is None else float(self.ds_max)
        return lo, hi
