"""The lane pool's options: one small module that the pool (:mod:`jaxgear.analysis._lanes`)
and its recurrence view (:func:`~jaxgear.analysis.classify_by_recurrence`) read."""

from __future__ import annotations

import dataclasses

import equinox as eqx

from .._batching import DEFAULT_CHUNK_CELLS
from .._checks import check_int, check_number

__all__ = ["PoolOptions", "SADDLE_FACTOR"]

SADDLE_FACTOR = 15
"""``saddle_periods`` by default, in multiples of ``max_periods``: a long chaotic transient
of the gear model (b = 1.15, a lifetime of about 5,000 periods) leaves all but 0.1 % of
its cells decided after 30,000 periods."""


class PoolOptions(eqx.Module):
    """Every option of the lane pool (static: they shape the compiled program, except
    ``lanes`` and ``pilot``, which only the host reads: :meth:`compiled`).

    Attributes:
        max_period: largest period ``M`` recognised (P-1 ... P-M).
        round_periods: periods ``R`` per round between decisions.
        period_tol: relative recurrence tolerance ``|x_t - x_(t-k)| <= tol (1 + |x_t|)``.
        merge_tol: relative distance under which a recurring lane lies on a known cycle.
        max_periods: periods per cell before it is unresolved.
        saddle_periods: the same for the cells of a value with a chaotic saddle (a long
            chaotic transient, found by the verification of the detection by recurrences):
            its lanes wander on the saddle for thousands of periods before they leave it
            for an attractor, so they run up to this many periods before they are
            unresolved (at least ``max_periods``; ``None``: :data:`SADDLE_FACTOR` times
            ``max_periods``).
        escape_bound: norm beyond which a state has escaped (state units).
        capture_radius: radius around a known cycle's points within which a lane that
            follows the whole cycle is captured (state units), or ``None``: a quarter of
            the smallest distance between two known attractors' points, at most 1 % of
            their scale.
        lanes: lanes of the pool (memory is bounded by it); on a CPU at most as many as keep
            its ring of points in the cache (:func:`~jaxgear.analysis._pool.pool_lanes`).
        pilot: states of the pilot pool that runs first (0: none).
    """

    max_period: int = eqx.field(static=True, default=16)
    round_periods: int = eqx.field(static=True, default=5)
    period_tol: float = eqx.field(static=True, default=1e-6)
    merge_tol: float = eqx.field(static=True, default=1e-4)
    max_periods: int = eqx.field(static=True, default=2000)
    saddle_periods: int | None = eqx.field(static=True, default=None)
    escape_bound: float = eqx.field(static=True, default=1e6)
    capture_radius: float | None = eqx.field(static=True, default=None)
    lanes: int = eqx.field(static=True, default=DEFAULT_CHUNK_CELLS)
    pilot: int = eqx.field(static=True, default=1024)

    def to_dict(self) -> dict:
        """Every option, JSON-able (``PoolOptions(**d)`` rebuilds it)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @property
    def saddle_limit(self) -> int:
        """Periods a cell of a value with a chaotic saddle may run (``saddle_periods``)."""
        return SADDLE_FACTOR * self.max_periods if self.saddle_periods is None else self.saddle_periods

    def compiled(self) -> PoolOptions:
        """These options as the compiled rounds see them: ``lanes`` and ``pilot`` (read by
        the host only, to size the pools) at their defaults, so pools that differ only in
        them share one compiled program."""
        return dataclasses.replace(self, lanes=PoolOptions.lanes, pilot=PoolOptions.pilot)

    def __check_init__(self):
        check_int(self.max_period, "max_period", 1)
        check_int(self.round_periods, "round_periods", 1)
        check_int(self.max_periods, "max_periods", 1)
        if self.saddle_periods is not None:
            check_int(self.saddle_periods, "saddle_periods", 1)
        if self.saddle_limit < self.max_periods:
            raise ValueError(f"saddle_periods={self.saddle_periods} must be at least max_periods={self.max_periods}: "
                             "the cells of a value with a chaotic saddle run longer, never shorter.")
        check_int(self.lanes, "lanes", 1)
        check_int(self.pilot, "pilot", 0)
        check_number(self.period_tol, "period_tol", 0, strict_min=True)
        check_number(self.merge_tol, "merge_tol", 0, strict_min=True)
        check_number(self.escape_bound, "escape_bound", 0, strict_min=True)
        if self.capture_radius is not None:
            check_number(self.capture_radius, "capture_radius", 0)
