"""Options of the parameter sweeps: the sequence sweeps that follow starts for a number of
forcing periods (:class:`SequenceOptions`: :func:`~jaxgear.bifurcation_diagram`,
:func:`~jaxgear.parameter_map`) and the sweeps of global analyses (:class:`BasinOptions`:
:func:`~jaxgear.basin_sweep`, :func:`~jaxgear.basin_map`).

Both are immutable ``eqx.Module``s checked at construction (a bad value raises a
``ValueError`` naming the field).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx

from .._checks import check_bool, check_int, check_number
from ..analysis._uncertainty import DEFAULT_SAMPLES

__all__ = ["SequenceOptions", "BasinOptions", "DIAGRAM_RECORD"]

DIAGRAM_RECORD = 64
"""Recorded periods of :func:`~jaxgear.bifurcation_diagram` when ``record`` is ``None``."""


class SequenceOptions(eqx.Module):
    """How a sequence sweep follows each start and classifies what it recorded (paper §3:
    the stroboscopic map iterated, recurrences of its points).

    Attributes:
        transient: forcing periods integrated before recording.
        record: forcing periods recorded (``R`` stroboscopic points per start, at least
            ``2 max_period + 1``); ``None``: the sweep's choice (:data:`DIAGRAM_RECORD` for
            a bifurcation diagram, ``2 max_period + 2`` for a parameter map).
        max_period: largest period ``k`` detected.
        tol: relative recurrence tolerance of the period detection:
            ``|x_j - x_(j-k)| <= tol (1 + |x_j|)`` over the last ``k + 1`` points.
        merge_tol: relative distance under which two starts reached the same attractor.
        escape_bound: a state beyond it (any coordinate, in absolute value; state units)
            escaped.
        chunk_size: trajectories per compiled batch (memory bound; a bifurcation diagram's
            block of values is ``chunk_size // S``). The result does not depend on it.
    """

    transient: int = eqx.field(static=True, default=400)
    record: int | None = eqx.field(static=True, default=None)
    max_period: int = eqx.field(static=True, default=16)
    tol: float = 1e-6
    merge_tol: float = 1e-3
    escape_bound: float = 1e6
    chunk_size: int = eqx.field(static=True, default=1024)

    def __check_init__(self):
        check_int(self.transient, "transient", 0)
        check_int(self.max_period, "max_period", 1)
        if self.record is not None:
            check_int(self.record, "record (or None for the sweep's choice)", 2 * int(self.max_period) + 1)
        check_number(self.tol, "tol", 0, strict_min=True)
        check_number(self.merge_tol, "merge_tol", 0, strict_min=True)
        check_number(self.escape_bound, "escape_bound", 0, strict_min=True)
        check_int(self.chunk_size, "chunk_size", 1)

    def with_record(self, default: int) -> SequenceOptions:
        """These options with ``record`` set (``default`` when it is ``None``)."""
        return self if self.record is not None else dataclasses.replace(self, record=int(default))


class BasinOptions(eqx.Module):
    """How a sweep of global analyses runs and continues its attractors.

    Attributes:
        match_tol: cycles of neighbouring values (or grid points) farther apart than this
            (Hausdorff distance of their stroboscopic points, state units) are not
            matched; clouds are compared on boxes of edge ``match_tol / 2``. ``None``: 5 %
            of the diagonal of the grid's box.
        batched: run the values of a block in one lane pool over (value, cell) pairs
            (:func:`~jaxgear.analysis.analyze_global_values`) instead of one analysis
            after another.
        uncertainty: cells sampled at each value for its label uncertainty
            (:func:`~jaxgear.analysis.label_uncertainty`); 0 skips it.
    """

    match_tol: float | None = None
    batched: bool = eqx.field(static=True, default=False)
    uncertainty: int = eqx.field(static=True, default=DEFAULT_SAMPLES)

    def __check_init__(self):
        if self.match_tol is not None:
            check_number(self.match_tol, "match_tol (or None for 5 % of the grid's diagonal)", 0, strict_min=True)
        check_bool(self.batched, "batched")
        check_int(self.uncertainty, "uncertainty", 0)
