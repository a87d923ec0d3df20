"""Attractors of every type by recurrences on a fine partition of the section.

The stroboscopic map's state space is divided into fine boxes; a trajectory is followed
box by box. A trajectory that keeps landing in the boxes its own recent past visited has
reached an attractor, whatever its type (fixed point, periodic, quasi-periodic or
chaotic), and the boxes it then visits are that attractor; a later trajectory that lands
in a known attractor's boxes a given number of times in a row belongs to it (Datseris &
Wagemakers, "Effortless estimation of basins of attraction", Chaos 32, 023104, 2022;
Attractors.jl's ``AttractorsViaRecurrences``). Periodic attractors keep the point-level
recognition of the direct method (exact cycle points to ``period_tol``); the partition
adds the attractors that never repeat a point.

One engine runs it: the direct method's lane pool (:mod:`jaxgear.analysis._lanes`, driven
by :func:`jaxgear.analysis._pool.run_pool`) when it is given
:class:`~jaxgear.analysis._lanes.Boxes`. Its pieces live by concept:

- :mod:`jaxgear.analysis._boxes` — the partition (:class:`~jaxgear.analysis._boxes.FinePartition`),
  the box keys, the device hash table of the known attractors' boxes and the per-lane
  runs of hits on them;
- :mod:`jaxgear.analysis._cloud` — the round's candidate, its point cloud, whether the
  cloud recurs, is a cycle, or overlaps a known attractor, and the verification that
  tells a chaotic saddle (a long transient) from an attractor;
- :mod:`jaxgear.analysis._recurrence_options` — :class:`RecurrenceOptions`, the knobs;
- this module — :func:`classify_by_recurrence`, a view of the pool that labels a set of
  states and returns a :class:`RecurrenceResult`.

Design notes (the pool's decisions are described in :mod:`jaxgear.analysis._lanes`):

- "approaching a cycle" means repetition errors within one box that shrink, not within
  one box alone: an attractor that spans only a few boxes (the gear model's chaotic
  attractor at b = 1.455 is about one box of the partition over region D wide in x1 and
  x2, 9 boxes in all) comes back within a box with some period, yet never converges, and
  the point-level recognition never takes it.
- labels are one space for cycles and attractors of boxes: a slot of an attractor table
  holds a :class:`~jaxgear.analysis._lanes.SlotKind` (a cycle, a repeller, an attractor
  of boxes with its cloud of ``max_points`` points, a chaotic saddle that labels no cell).
- a sweep in one pool needs one table per parameter row, or the row mixed into the key
  (:func:`~jaxgear.analysis._boxes.row_keys`).
- the partition is built once per analysis from the region (the non-gridded coordinates,
  e.g. ``x4``, get the mean box width of the gridded ones), so boxes mean the same for
  every lane.
- a cloud of 8 copies over 600 periods costs about two rounds of a 1,024-lane pool on CPUs
  (the compiled kernel, parameters passed as traced arguments: closed over as constants
  the gear model falls back to the pure-JAX steps, 200 times slower).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import numpy as np

from .._checks import split_changes, with_changes
from ..integrate import resolve_integrator
from ._boxes import FinePartition, partition_of_states
from ._cloud import CANDIDATE_POOL
from ._lanes import APERIODIC, Boxes
from ._pool import run_pool
from ._pool_options import PoolOptions
from ._recurrence_options import RecurrenceOptions

# CANDIDATE_POOL is read here by jaxgear.cli (the memory check of the pool's cycle test)
__all__ = ["RecurrenceOptions", "RecurrenceResult", "classify_by_recurrence", "APERIODIC", "CANDIDATE_POOL"]


class RecurrenceResult(eqx.Module):
    """Result of :func:`classify_by_recurrence` (numpy arrays).

    Attributes:
        labels: ``(n,)`` int32 attractor index, ``-1`` sink (escaped), ``-2`` unresolved.
        periods_used: ``(n,)`` int32 forcing periods integrated per state (a state decided
            by its own cloud counts its cloud's periods, and a new attractor's
            verification, too).
        periods: ``(A,)`` int32 per attractor: ``k`` for a P-k cycle, ``0`` (:data:`APERIODIC`)
            for an attractor found by recurrence of boxes.
        points: ``(A, max(max_points, max_period), dim)`` per attractor its cycle in order
            (first ``k`` rows) or the cloud the pool kept of it (NaN padded).
        partition: the fine partition of the boxes
            (:class:`~jaxgear.analysis._boxes.FinePartition`).
    """

    labels: Any
    periods_used: Any
    periods: Any
    points: Any
    partition: FinePartition


def classify_by_recurrence(system, params, X, *, options: RecurrenceOptions | None = None,
                           pool: PoolOptions | None = None, integrator=None,
                           partition: FinePartition | None = None, **changes) -> RecurrenceResult:
    """Label the states ``X (n, dim)`` (at forcing phase 0) by the attractor of their
    stroboscopic-map trajectories, attractors of every type included.

    The direct method's lane pool does the work (:func:`~jaxgear.analysis._pool.run_pool`
    with :class:`~jaxgear.analysis._lanes.Boxes` of ``options`` and ``partition``; its
    decisions: :mod:`jaxgear.analysis._lanes`): a state is decided when its trajectory
    escapes (norm above ``pool.escape_bound`` or not finite: ``-1``), recurs onto a cycle
    of period ``<= pool.max_period`` or follows a known one, completes ``options.hits``
    consecutive hits on an attractor's boxes, or is the candidate whose cloud recurs in
    its own boxes, is no cycle and (``options.verify_periods``) no chaotic saddle (Datseris
    & Wagemakers 2022). After ``pool.max_periods`` periods it is unresolved (``-2``).

    ``pool``: the :class:`~jaxgear.analysis.PoolOptions` (default ``PoolOptions(lanes=1024)``).
    Keyword arguments (``**changes``) replace fields of ``options`` or ``pool`` by name
    (``max_periods=3000``); an unknown name raises ``ValueError``.

    ``partition``: default :func:`~jaxgear.analysis._boxes.partition_of_states` of ``X``
    with ``options.resolution`` boxes per axis (as the direct method builds it).
    ``integrator``: default :func:`~jaxgear.integrate.default_integrator`. Returns a
    :class:`RecurrenceResult` (attractor arrays cut to the attractors found; a chaotic
    saddle the pool met is no attractor and is not listed).
    """
    rec_changes, pool_changes = split_changes(changes, RecurrenceOptions, PoolOptions)
    options = with_changes(options, RecurrenceOptions, rec_changes)
    pool = with_changes(PoolOptions(lanes=1024) if pool is None else pool, PoolOptions, pool_changes)
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != system.dim or X.shape[0] < 1 or not np.all(np.isfinite(X)):
        raise ValueError(f"X must be a finite (n, {system.dim}) array of states, got shape {X.shape}.")
    if partition is None:
        partition = partition_of_states(X, float(options.resolution))
    elif not isinstance(partition, FinePartition) or partition.lo.shape != (system.dim,):
        raise ValueError(f"partition must be a FinePartition of dimension {system.dim} or None.")
    labels, found, used, *_ = run_pool(system, params, X, resolve_integrator(integrator), pool,
                                   boxes=Boxes(options, partition))
    rows = max(options.max_points, pool.max_period)
    points = np.full((len(found), rows, X.shape[1]), np.nan)
    for a, (p, _) in enumerate(found):
        points[a, :len(p)] = p[:rows]
    return RecurrenceResult(labels=np.asarray(labels, np.int32), periods_used=np.asarray(used, np.int32),
                            periods=np.array([k for _, k in found], np.int32).reshape(len(found)), points=points,
                            partition=partition)
