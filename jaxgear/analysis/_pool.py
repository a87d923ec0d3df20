"""Driving the direct method's lane pool from the host: pilot, steering, several values.

The pool itself (its state and one round, all on the device) is
:mod:`jaxgear.analysis._lanes`; where it runs (one device, a mesh, processes) is
:mod:`jaxgear.analysis._placement`. The host only reads a few scalars per call
(progress, a full attractor table, a pool to shrink, a round stopped at its candidate)
and makes those decisions (:func:`drive`): it has a candidate for a new attractor of
boxes characterised (by a program of its own, one for every pool size), grows every
attractor table when one overflows, and moves a draining pool to one :data:`SHRINK`
times smaller once its busy lanes fit (down to :data:`TAIL_LANES`), so the bookkeeping
of the last rounds covers few idle lanes.

:func:`run_pools` labels the states of ``V`` parameter sets (the values of a sweep) in
one pool: each cell carries its value's row, each lane integrates with its row's
parameters and decides against its value's own attractor table, so every value is
labelled as it would be alone while the pool stays full from one value to the next. A
pilot sample of each value runs first, so the common attractors are known (and capture
decides the bulk early) when the other states start.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import NamedTuple

import numpy as np

from .._batching import progress_bar
from .._devices import local_devices
from ..integrate import stack_params
from ._lanes import APERIODIC, AttractorTable, Boxes, SlotKind, seed_tables, slot_kind, slot_period
from ._placement import OneDevice, queue_length, run_blocks
from ._pool_options import PoolOptions

__all__ = ["PoolOptions", "Boxes", "run_pool", "run_pools", "drive", "first_pool", "main_queue"]

CALL_SECONDS = 0.5
"""Wall time the host aims each call of a pool at (it sizes the next call's rounds by the
last one's duration)."""

TAIL_LANES = 1024
"""Lanes of the smallest pool the last slow cells move to."""

SHRINK = 8
"""A draining pool moves to one ``SHRINK`` times smaller once its busy lanes fit (down to
:data:`TAIL_LANES`): the bookkeeping of a round covers every lane of the pool, so a pool
that stayed large would spend most of its last rounds on lanes that are idle (each size
is one more compiled shape)."""


CPU_RING_BYTES = 16 * 2**20
"""On a CPU a pool has at most as many lanes as keep its ring of stroboscopic points (the
bulk of its state, ``2 (2 max_period + 1) dim`` float64 per lane) within this many bytes:
a round's decisions read the ring of every lane, and a ring that stays in the last-level
cache makes them several times cheaper than one streamed from memory. Measured on the
paper preset (2-core Xeon, 90,000 cells, M = 16: 2 KiB per lane), the analysis without
its extra measures: 2.75 s with 8,192 or 16,384 lanes, 2.8 s with 4,096 or 32,768, 3.1 s
with 65,536 or 89,088 (188 MiB of ring), the same labels; the integration alone costs the
same per lane at every size. A GPU keeps the ``lanes`` it is given."""


def pool_lanes(lanes: int, dim: int, max_period: int) -> int:
    """The lanes of a pool given at most ``lanes``: on a CPU no more than
    :data:`CPU_RING_BYTES` of ring hold (a multiple of :data:`TAIL_LANES`, at least one);
    ``lanes`` on other platforms."""
    if local_devices()[0].platform != "cpu":
        return int(lanes)
    ring = 2 * (2 * int(max_period) + 1) * int(dim) * 8
    return min(int(lanes), max(TAIL_LANES, CPU_RING_BYTES // ring // TAIL_LANES * TAIL_LANES))


def _next_pool(L: int) -> int:
    """The pool size the lanes move to once they fit (``L`` itself: no smaller pool): the
    ladder ends on :data:`TAIL_LANES`, the pilot's size, so that a value's pilot and the
    tail of its main pool are one compiled program."""
    if L <= TAIL_LANES:
        return L
    return L // SHRINK if L // SHRINK >= 2 * TAIL_LANES else TAIL_LANES


def first_pool(n: int, queue: int, lanes: int) -> int:
    """The lanes a pool of ``n`` states starts with when its queue is padded to ``queue``
    (the shape of another pool): the smallest size of that pool's ladder
    (:func:`_next_pool` from ``min(lanes, queue)``) that holds all ``n``, so this pool's
    programs are that pool's (a pilot's are its main pool's tail, the label uncertainty's
    start moves a rung of the analysis's ladder)."""
    need = min(lanes, queue_length(n))
    L = min(lanes, max(queue_length(n), queue_length(queue) if queue else 0))
    while need <= _next_pool(L) < L:
        L = _next_pool(L)
    return L


def main_queue(counts, pilot: int) -> int:
    """The states of the main phase of :func:`run_pools` over values of ``counts`` states
    each: all but each value's pilot sample (``pilot`` states where ``0 < pilot < n``)."""
    return sum(int(n) - (pilot if 0 < pilot < n else 0) for n in counts)


def drive(placement, X_blocks, row_blocks, *, system, params, integrator, o: PoolOptions, boxes,
          attractors: AttractorTable, bar, queue: int = 0) -> list[tuple]:
    """Run the pools of ``placement`` over the queue blocks ``X_blocks`` (one per device;
    value rows ``row_blocks``) from the attractor tables ``attractors`` until every state
    is decided: ``[(labels, used, attractor tables)]`` per block (numpy). ``queue``: pad
    the queue to at least this length and start on that pool's ladder
    (:func:`first_pool`): the shape of another pool whose compiled programs this one
    shares."""
    n = np.array([len(b) for b in X_blocks])
    s, data = placement.start(params, boxes, X_blocks, row_blocks, first_pool(int(n.max()), queue, o.lanes),
                              o.max_period, attractors, queue=queue)
    done, rounds, compiled = 0, 4, o.compiled()
    while True:
        L = s.Y.shape[-1]
        L_min = _next_pool(L)
        t = time.perf_counter()
        s, info = placement.run(s, data, system, integrator, compiled, L_min, np.int32(rounds))
        n_done, overflow, n_active, next_cell, n_att, candidate = info.T
        if candidate.any():  # a round stopped at a candidate: characterised, then the round goes on
            s = placement.characterise(s, data, system, integrator, compiled)
            continue
        # calls of about CALL_SECONDS: few host round trips, a progress bar still moving
        rounds = int(np.clip(rounds * CALL_SECONDS / max(time.perf_counter() - t, 1e-3), 1, 4 * rounds))
        bar.update(int(n_done.sum()) - done)
        done = int(n_done.sum())
        bar.set_postfix_str(f"{int(n_active.sum())} lanes busy, {int(n_att.max())} attractors", refresh=False)
        finished = n_done >= n
        if finished.all():
            return placement.collect(s)
        if overflow.any():
            s = placement.resize(s, A=2 * s.attractors.n_slots)
        elif L_min < L and np.all(finished | ((next_cell >= n) & (n_active <= L_min))):
            s = placement.resize(s, L=L_min)


class PoolLabels(NamedTuple):
    """What the pool returns for one value (:func:`run_pool`, :func:`run_pools`)."""

    labels: np.ndarray  # (n,) attractor slot, SINK or UNRESOLVED per state
    attractors: list  # [(points (k, dim) in cycle order, k)]; a cloud with period APERIODIC; -k a repeller
    used: np.ndarray  # (n,) periods integrated per state
    saddles: list  # [cloud (m, dim)] of each chaotic saddle met
    pilot_complete: bool  # the pilot found every attractor (none was added after it; False: no pilot ran)


def run_pool(system, params, X: np.ndarray, integrator, options: PoolOptions, *, boxes: Boxes | None = None,
             attractors=(), progress: bool = False, label: str = "direct"):
    """Label the states ``X (n, dim)`` at phase 0 (see the module): a :class:`PoolLabels`
    (labels, attractors, periods per state, chaotic saddles met, whether the pilot found
    every attractor).

    ``attractors``: known ``(points, k)`` cycles (``k <= max_period``) that take the first
    slots, in that order; a period ``-k`` makes the cycle a repeller (an unstable P-k
    cycle: lanes that shadow it are not decided there and integrate on), listed in the
    returned cycles with its period ``-k``; a period ``0`` gives an attractor of boxes by
    its cloud ``(m, dim)``. ``boxes``: the detection of attractors of boxes (quasi-periodic,
    chaotic; :class:`~jaxgear.analysis._lanes.Boxes`), or ``None``: cycles only. Attractors
    of boxes are returned as ``(cloud (m, dim), 0)`` (:data:`~jaxgear.analysis._lanes.APERIODIC`).
    """
    return run_pools(system, [params], [X], integrator, options, boxes=boxes, attractors=[attractors],
                     progress=progress, label=label)[0]


def run_pools(system, params_list, X_list, integrator, options: PoolOptions, *, boxes: Boxes | None = None,
              attractors=None, progress: bool = False, label: str = "direct", like: int = 0):
    """:func:`run_pool` for ``V`` parameter sets at once, in one pool: the states
    ``X_list[v] (n_v, dim)`` under the parameters ``params_list[v]`` (one pytree
    structure). ``attractors``: per value, its known cycles. Returns a
    :class:`PoolLabels` per value, each what :func:`run_pool` returns for that value
    alone.

    The pilots of all values run first in one pool on the first device, then all the
    other states in one pool per device (:func:`jaxgear.analysis._placement.run_blocks`),
    value after value: the compilation, the pilot's draining and the draining tail are
    paid once. ``like``: the main phase's states of another run (:func:`main_queue`), whose
    compiled pools this one's main phase shares when it is no longer (its queue padded to
    that run's, its lanes a size of that run's ladder: :func:`first_pool`); the labels do
    not depend on it.
    """
    o = options
    V = len(params_list)
    Xs = [np.asarray(X, dtype=np.float64) for X in X_list]
    dim = Xs[0].shape[1]
    params = params_list[0] if V == 1 else stack_params(params_list)
    orders, n_ps = [], []
    for X in Xs:
        n_p = len(X) - main_queue([len(X)], o.pilot)
        first = np.sort(np.random.default_rng(0).choice(len(X), size=n_p, replace=False))
        rest = np.ones(len(X), dtype=bool)
        rest[first] = False
        orders.append(np.concatenate([first, np.flatnonzero(rest)]))
        n_ps.append(n_p)
    Q = boxes.options.max_points if boxes is not None else 1
    tables = seed_tables(attractors if attractors is not None else [()] * V, o.max_period, dim, Q)
    bar = progress_bar(sum(len(X) for X in Xs), label, progress)
    labels = [np.empty(len(X), dtype=np.int64) for X in Xs]
    used = [np.empty(len(X), dtype=np.int64) for X in Xs]
    after_pilot = np.asarray(tables.counts).copy()
    for phase in (0, 1):
        parts = [order[:n_p] if phase == 0 else order[n_p:] for order, n_p in zip(orders, n_ps)]
        if not sum(len(p) for p in parts):
            continue
        Xp = np.concatenate([X[p] for X, p in zip(Xs, parts)])
        rows = np.concatenate([np.full(len(p), v, np.int32) for v, p in enumerate(parts)])
        # the pool of one value, refilled from the next
        o_phase = dataclasses.replace(o, lanes=min(pool_lanes(o.lanes, dim, o.max_period),
                                                   queue_length(max([len(p) for p in parts] + [like]))))
        run = functools.partial(drive, system=system, params=params, integrator=integrator, o=o_phase, boxes=boxes,
                                attractors=tables, bar=bar)
        if phase == 0:  # the pilot, on the first device, in the queue shape of the main pool (its tail's program)
            rest = sum(len(order) - n_p for order, n_p in zip(orders, n_ps))
            lab, use, tables = run(OneDevice(), [Xp], [rows], queue=queue_length(rest) if rest else 0)[0]
            after_pilot = np.asarray(tables.counts).copy()
        else:  # one pool per device over a block of the queue, the attractors merged
            lab, use, tables = run_blocks(run, Xp, rows, tables, o.merge_tol,
                                          None if boxes is None else boxes.partition, like=like)
        start = 0
        for v, p in enumerate(parts):
            labels[v][p] = lab[start:start + len(p)]
            used[v][p] = use[start:start + len(p)]
            start += len(p)
    bar.close()
    out = []
    for v in range(V):
        found, lut = _attractors(tables, v, o.max_period)
        out.append(PoolLabels(np.where(labels[v] >= 0, lut[np.maximum(labels[v], 0)], labels[v]), found, used[v],
                              _saddles(tables, v, o.max_period),
                              bool(np.asarray(tables.counts)[v] == after_pilot[v])))
    return out


def _saddles(tables: AttractorTable, v: int, M: int) -> list[np.ndarray]:
    """The clouds ``(m, dim)`` (finite points) of value ``v``'s chaotic saddles
    (``SlotKind.SADDLE``: long chaotic transients the pool met, which label no cell)."""
    codes, clouds = np.asarray(tables.codes)[v], np.asarray(tables.clouds)[v]
    kinds = slot_kind(codes, M)
    return [clouds[a][np.all(np.isfinite(clouds[a]), axis=1)] for a in range(int(np.asarray(tables.counts)[v]))
            if kinds[a] == SlotKind.SADDLE]


def _attractors(tables: AttractorTable, v: int, M: int):
    """Value ``v``'s table as ``[(points, k)]``: a cycle's ``k`` points (a repeller's with
    period ``-k``), an attractor of boxes' cloud (its finite points) with period
    :data:`~jaxgear.analysis._lanes.APERIODIC`; a chaotic saddle's slot
    (``SlotKind.SADDLE``, which labels no cell) is left out. Also the label of each slot
    in that list ``(A,)`` (-1 for a saddle)."""
    points, codes, counts, clouds = (np.asarray(tables.points), np.asarray(tables.codes), np.asarray(tables.counts),
                                     np.asarray(tables.clouds))
    kinds, periods = slot_kind(codes[v], M), slot_period(codes[v], M)
    out = []
    lut = np.full(max(codes.shape[1], 1), -1, np.int64)
    for a in range(int(counts[v])):
        if kinds[a] == SlotKind.SADDLE:
            continue
        lut[a] = len(out)
        if kinds[a] == SlotKind.BOXES:
            cloud = clouds[v, a]
            out.append((cloud[np.all(np.isfinite(cloud), axis=1)], APERIODIC))
        else:
            k = int(periods[a])
            out.append((points[v, a, :k], k if kinds[a] == SlotKind.CYCLE else -k))
    return out, lut
