"""The options of the detection by recurrences on a fine partition: one small module that
the lane pool (:mod:`jaxgear.analysis._lanes`, through its :class:`~jaxgear.analysis._lanes.Boxes`),
the direct method and :func:`~jaxgear.analysis.classify_by_recurrence` read (the method:
:mod:`jaxgear.analysis._recurrence`)."""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_int, check_number
from ._boxes import INDEX_BITS, MAX_PROBES
from ._cloud import CLOUD_STAGES

__all__ = ["RecurrenceOptions"]


def _as(dtype):
    """Field converter: a JAX array (or tracer) stays one; anything else becomes a numpy array,
    so that building the default options at import starts no JAX backend (a multi-process run
    calls ``jax.distributed.initialize`` after ``import jaxgear``)."""
    return lambda x: jnp.asarray(x, dtype=dtype) if isinstance(x, jax.Array) else np.asarray(x, dtype=dtype)


class RecurrenceOptions(eqx.Module):
    """Knobs of the detection by recurrences (numeric fields are arrays: changing them does
    not recompile; those that set shapes are static).

    Attributes:
        resolution: boxes per axis across the partition's box (the analysis region).
        transient: periods a lane runs undecided before it becomes a candidate for a new
            attractor (and between two tries of the same lane).
        hits: consecutive hits on a known attractor's boxes that decide a lane.
        max_misses: visits in a row to unregistered boxes tolerated within a run of hits.
        accept_share: a candidate's cloud is an attractor when at least this share of its
            second half falls in boxes of its first half.
        overlap_share: a new cloud with at least this share of its points in a known
            attractor's boxes is that attractor (its boxes join it).
        cloud_periods: periods each copy of a candidate is integrated (static; a multiple
            of :data:`~jaxgear.analysis._cloud.CLOUD_STAGES`).
        cloud_lanes: copies of a candidate integrated together (static).
        max_points: cloud points kept per attractor of boxes (static).
        capacity: slots of the box table (static, a power of two; ``8 * capacity`` bytes
            of keys, whatever the state dimension).
        max_attractors: not read (static): the lane pool grows its attractor tables as it
            finds attractors. Kept so that options saved with results before load.
        verify_periods: periods a new attractor of boxes is continued from
            ``verify_lanes`` of its cloud's points before it is registered (static; 0: no
            verification): when at least ``leave_share`` of them leave it (settle on a
            cycle, escape or reach another known attractor) the set is a chaotic saddle,
            a long transient, and no attractor (:func:`~jaxgear.analysis._cloud.leaving_share`). At least ``2
            max_period`` periods are run (:func:`~jaxgear.analysis._cloud.verify_length`): the cycle test reads the
            last ``2 max_period`` points.
        verify_lanes: cloud points continued by the verification (static).
        leave_share: share of the continued points that leaving makes the set a saddle.
    """

    resolution: Any = eqx.field(converter=_as(jnp.float64), default=100.0)
    transient: Any = eqx.field(converter=_as(jnp.int32), default=80)
    hits: Any = eqx.field(converter=_as(jnp.int32), default=20)
    max_misses: Any = eqx.field(converter=_as(jnp.int32), default=4)
    accept_share: Any = eqx.field(converter=_as(jnp.float64), default=0.8)
    overlap_share: Any = eqx.field(converter=_as(jnp.float64), default=0.5)
    cloud_periods: int = eqx.field(static=True, default=600)
    cloud_lanes: int = eqx.field(static=True, default=8)
    max_points: int = eqx.field(static=True, default=2048)
    capacity: int = eqx.field(static=True, default=2 ** 16)
    max_attractors: int = eqx.field(static=True, default=16)
    verify_periods: int = eqx.field(static=True, default=2000)
    verify_lanes: int = eqx.field(static=True, default=64)
    leave_share: Any = eqx.field(converter=_as(jnp.float64), default=0.25)

    def to_dict(self) -> dict:
        """Every knob as a plain number (JSON-able; ``RecurrenceOptions(**d)`` rebuilds it)."""
        import dataclasses

        return {f.name: np.asarray(getattr(self, f.name)).item() for f in dataclasses.fields(self)}

    def __check_init__(self):
        check_number(float(self.resolution), "resolution", 1, 2 ** (INDEX_BITS - 1))
        check_int(int(self.transient), "transient", 1)
        check_int(int(self.hits), "hits", 1)
        check_int(int(self.max_misses), "max_misses", 0)
        check_number(float(self.accept_share), "accept_share", 0, 1, strict_min=True)
        check_number(float(self.overlap_share), "overlap_share", 0, 1, strict_min=True)
        check_int(self.cloud_periods, "cloud_periods", 8 * CLOUD_STAGES)
        if self.cloud_periods % CLOUD_STAGES:
            raise ValueError(f"cloud_periods={self.cloud_periods} must be a multiple of {CLOUD_STAGES}.")
        check_int(self.cloud_lanes, "cloud_lanes", 1)
        check_int(self.max_points, "max_points", 1)
        c = check_int(self.capacity, "capacity", 2 * MAX_PROBES)
        if c & (c - 1):
            raise ValueError(f"capacity={c} must be a power of two.")
        check_int(self.max_attractors, "max_attractors", 1)
        check_int(self.verify_periods, "verify_periods", 0)
        check_int(self.verify_lanes, "verify_lanes", 1)
        check_number(float(self.leave_share), "leave_share", 0, 1, strict_min=True)
