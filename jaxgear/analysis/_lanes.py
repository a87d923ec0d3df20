"""The direct method's lane pool on the device: its state and one round (its options,
:class:`PoolOptions`, live in :mod:`jaxgear.analysis._pool_options`).

``L`` lanes integrate cell centres on the stroboscopic map, one forcing period at a time
(the integrator's ``advance``; on CPUs the compiled kernel). Everything the method
decides happens on the device inside one ``lax.while_loop`` over rounds of
``round_periods`` periods (:func:`run_rounds`), with no host round trip of per-lane data:

- every period the new stroboscopic point goes into a ring of the last ``H = 2M + 1``
  points (``M = max_period``; one slot for all lanes, they share the clock) and, for
  each ``k <= M``, a per-lane streak counts the consecutive periods with
  ``|x_t - x_(t-k)| <= tol (1 + |x_t|)``: a lane is P-k when the streak of ``k`` reaches
  ``k + 1`` (a whole cycle and one more step repeat), the smallest such ``k`` wins;
- after each round a lane is decided (:func:`decide`) when it escaped (norm above
  ``escape_bound`` or not finite: the sink), when its last ``k`` points follow the cycle
  of a known P-k attractor within the capture radius and did not move away from it over
  the ``k`` before (capture), when it recurs (a known attractor if its newest point lies
  on one, else a new attractor is registered, one per value and round), or when it
  reached ``max_periods`` (unresolved; ``saddle_periods`` for a value with a chaotic
  saddle, whose cells' lanes may wander on that long transient for thousands of periods);
- decided lanes write their cell's label and take the next cells of the queue; once the
  queue is empty, the busy lanes beyond the first ``c`` (the busy count) move into the
  free lanes below it (:func:`compact`), so only ``n_active = c`` lanes are integrated.

Attractors that never repeat a point (quasi-periodic, chaotic) are found by recurrences
on a fine partition of the state space (:mod:`jaxgear.analysis._recurrence`, Datseris &
Wagemakers 2022) when the pool is given :class:`Boxes`: every period a lane's point
looks up its box in a device hash table of the known attractors' boxes and counts its
consecutive hits on one attractor (enough hits decide it); once per round the oldest
lane still undecided after ``transient`` periods, and not approaching a cycle (its
repetition errors within a box and shrinking), is the candidate (none for a while after
one that was a brief transient). The round stops there (:class:`Phase`): the pool's
program returns, and a program of its own with no lane axis
(:func:`characterise`: one for every pool size, and most of the recurrence machinery's
code, so the pool's programs stay small) integrates a cloud of its trajectory; the next
call of the pool's program finishes the round. When the cloud recurs in its own boxes it
is an attractor
(a new slot of its value's table, a ``SlotKind.BOXES``, its cloud kept), or
joins the attractor of boxes it overlaps; its boxes enter the table. A new set is
verified first: a sample of its cloud's points is continued for thousands of periods, and
when a clear share of them leaves it (settles on a cycle, escapes, reaches another known
set) it is a chaotic saddle, a long transient (``SlotKind.SADDLE``): its boxes enter the
table so that the lanes wandering on it are no candidates again, but it labels no cell
(they integrate on until they leave it, or time out).

Several parameter sets (the values of a sweep) share one pool: each cell carries its
value's row, a lane integrates with its row's parameters (``integrator.advance_rows``)
and decides against its row's own attractor table. The queue runs value after value,
so the busy lanes hold a short range of rows at a time, and a round's decisions loop
over the (row, slot) pairs of that range only.

The host side (the pilot, steering, placement on devices) is
:mod:`jaxgear.analysis._pool` and :mod:`jaxgear.analysis._placement`.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import power_of_two_at_least
from ._boxes import CellTable, FinePartition, empty_table, insert, lookup, row_keys, track_hits
from ._cloud import (
    CLOUD_STAGES,
    CONTINUE_SHARE,
    attractor_cloud,
    escaped,
    flat_cloud,
    leaving_share,
    near_periodic,
    oldest_off_cycle,
    overlap_shares,
    recurrence_share,
    staged_cloud,
    verification_starts,
    verify_length,
)
from ._pool_options import PoolOptions
from ._recurrence_options import RecurrenceOptions
from ._result import SINK, UNRESOLVED

__all__ = ["PoolState", "AttractorTable", "Boxes", "init_pool", "run_rounds", "resize", "compact", "seed_tables",
           "table_slots", "NOT_DONE", "APERIODIC", "SlotKind", "slot_code", "slot_kind", "slot_period", "Phase",
           "Candidate", "candidate_of", "characterise", "with_candidate"]

NOT_DONE = -3
"""Label of a cell not decided yet (never returned)."""
_ON_REPELLER = -4
"""A round's mark of a lane that shadows a repeller (never a label): it is neither
decided nor registers a new attractor, and integrates on."""

COMPACT_BELOW = 7 / 8
"""A round ends with a compaction once the busy lanes fill at most this share of the
active range (a compaction costs about a tenth of a period of the lanes' integration:
more often loses more to its cost than it saves)."""

MOVE_CHUNK = 1024
"""Lanes moved per step of a compaction (:func:`compact`)."""


class Boxes(eqx.Module):
    """The fine partition and the knobs of the detection by recurrences (a traced argument
    of the pool: changing the numbers does not recompile)."""

    options: RecurrenceOptions
    partition: FinePartition


APERIODIC = 0
"""The period of an attractor of boxes (no cycle of period ``<= M``) in the attractor
lists the pool takes (:func:`seed_tables`) and returns
(:func:`~jaxgear.analysis._pool.run_pool`): ``(cloud (m, dim), APERIODIC)``."""


class SlotKind(enum.IntEnum):
    """What a slot of a value's attractor table holds: the one vocabulary of the slot codes.

    The pool stores one int32 code per slot (:attr:`AttractorTable.codes`), which carries a
    cycle's period too; :func:`slot_code` writes it and :func:`slot_kind` /
    :func:`slot_period` read it, on the device and on the host (nothing else spells a code).

    - ``EMPTY`` (code 0): no attractor yet;
    - ``CYCLE`` (code ``k``, ``1 <= k <= M``): a P-k attractor, its points in
      :attr:`AttractorTable.points`;
    - ``REPELLER`` (code ``-k``): an unstable P-k cycle; lanes that shadow it integrate on;
    - ``BOXES`` (code ``M + 1``): an attractor of boxes (no cycle of period ``<= M``), its
      cloud in :attr:`AttractorTable.clouds` and its boxes in the box table;
    - ``SADDLE`` (code ``M + 2``): a chaotic saddle, a set of boxes that recurred like an
      attractor but whose points leave it (a long transient; see
      :func:`~jaxgear.analysis._cloud.leaving_share`). Its boxes keep the lanes that visit
      them from being candidates again, and it never labels a cell (they integrate on);
      the host drops it from the attractors.
    """

    EMPTY = 0
    CYCLE = 1
    REPELLER = 2
    BOXES = 3
    SADDLE = 4


def slot_code(kind: SlotKind, M: int, k: int = 0) -> int:
    """The code (:attr:`AttractorTable.codes`) of a slot of ``kind`` (``k``: the period of a cycle or a repeller,
    ``1 <= k <= M``, an int or a traced int32; ``M``: the pool's ``max_period``)."""
    kind = SlotKind(kind)
    if kind in (SlotKind.CYCLE, SlotKind.REPELLER):
        if isinstance(k, (int, np.integer)) and not 1 <= k <= M:
            raise ValueError(f"a {kind.name.lower()}'s period k={k} must be between 1 and max_period={M}.")
        return k if kind == SlotKind.CYCLE else -k
    return {SlotKind.EMPTY: 0, SlotKind.BOXES: int(M) + 1, SlotKind.SADDLE: int(M) + 2}[kind]


def slot_kind(code, M: int):
    """The :class:`SlotKind` of each code of ``code`` (a JAX or numpy int array, or an
    int), as int32 values of the enum (``slot_kind(c, M) == SlotKind.SADDLE``)."""
    xp = jnp if isinstance(code, jax.Array) else np
    code = xp.asarray(code)
    kind = xp.where(code == 0, SlotKind.EMPTY, xp.where(code < 0, SlotKind.REPELLER, SlotKind.CYCLE))
    kind = xp.where(code == slot_code(SlotKind.BOXES, M), SlotKind.BOXES, kind)
    kind = xp.where(code == slot_code(SlotKind.SADDLE, M), SlotKind.SADDLE, kind)
    return kind.astype(xp.int32)


def slot_period(code, M: int):
    """The cycle period ``k`` of each code (a cycle's or a repeller's), 0 for the other kinds."""
    xp = jnp if isinstance(code, jax.Array) else np
    kind = slot_kind(code, M)
    cycle = (kind == SlotKind.CYCLE) | (kind == SlotKind.REPELLER)
    return xp.where(cycle, xp.abs(xp.asarray(code)), 0).astype(xp.int32)


def _of_boxes(codes, M: int):
    """Whether the table slots of codes ``codes`` hold a set of boxes (an attractor or a saddle)."""
    kind = slot_kind(codes, M)
    return (kind == SlotKind.BOXES) | (kind == SlotKind.SADDLE)


class AttractorTable(NamedTuple):
    """The attractor tables of ``V`` values (parameter sets), ``A`` slots each: one pytree
    (numpy arrays on the host, JAX arrays on the device; on a mesh every leaf has a leading
    device axis). Slot ``a`` of value ``v`` holds one attractor, repeller or saddle
    (:class:`SlotKind`, read from its code)."""

    points: jax.Array  # (V, A, M, dim) a cycle's points in cycle order (NaN padded)
    codes: jax.Array  # (V, A) int32 slot codes (SlotKind: slot_code, slot_kind)
    counts: jax.Array  # (V,) int32 slots in use
    clouds: jax.Array  # (V, A, Q, dim) the cloud of each attractor of boxes (NaN elsewhere)

    @property
    def n_values(self) -> int:
        """``V`` (a static shape)."""
        return self.codes.shape[-2]

    @property
    def n_slots(self) -> int:
        """``A`` (a static shape)."""
        return self.codes.shape[-1]

    def with_slots(self, A: int) -> AttractorTable:
        """The tables grown to ``A >= n_slots`` slots per value (new slots empty)."""
        xp = jnp if isinstance(self.codes, jax.Array) else np
        V, A0, M, dim = self.points.shape
        Q = self.clouds.shape[2]
        return AttractorTable(
            points=xp.concatenate([self.points, xp.full((V, A - A0, M, dim), xp.nan)], axis=1),
            codes=xp.concatenate([self.codes, xp.full((V, A - A0), slot_code(SlotKind.EMPTY, M), xp.int32)], axis=1),
            counts=self.counts,
            clouds=xp.concatenate([self.clouds, xp.full((V, A - A0, Q, dim), xp.nan)], axis=1))


class PoolState(NamedTuple):
    """The pool's state (device arrays); ``L`` lanes, ``n`` cells, ``V`` values, ``A`` attractor slots."""

    Y: jax.Array  # (dim, L) current states
    hist: jax.Array  # (2H, dim, L) ring of the last H stroboscopic points, written at slots c and c + H
    #                  (c = clock % H), so any M consecutive points back are one contiguous slice
    streak: jax.Array  # (M, L) int32 recurrence streaks
    cell: jax.Array  # (L,) int32 cell held, -1 idle
    row: jax.Array  # (L,) int32 parameter row (value) of the cell held
    age: jax.Array  # (L,) int32 periods integrated for the cell held
    labels: jax.Array  # (n,) int32
    used: jax.Array  # (n,) int32 periods integrated per cell
    next_cell: jax.Array  # () int32
    n_done: jax.Array  # () int32
    clock: jax.Array  # () int32
    attractors: AttractorTable  # the attractor table of each parameter row (value)
    radius: jax.Array  # (V,) capture radius
    quiet: jax.Array  # (V,) int32 clock before which the value has no candidate (after a brief transient's cloud)
    n_active: jax.Array  # () int32 lanes [0, n_active) may be busy
    overflow: jax.Array  # () bool: a new attractor found no free slot
    rounds: jax.Array  # () int32 rounds run
    table: CellTable  # box key (row-mixed) -> slot of the value's table
    hit_att: jax.Array  # (L,) int32 slot of the lane's run of box hits (-1 none)
    hits: jax.Array  # (L,) int32 length of the run
    misses: jax.Array  # (L,) int32 unregistered boxes in a row within the run
    tried: jax.Array  # (L,) int32 age at the lane's last candidacy
    dropped: jax.Array  # () int32 boxes that found no slot in the table
    # a round stopped at its candidate (Phase) and what the rest of the round needs
    phase: jax.Array  # () int32 Phase
    pending: jax.Array  # (L,) int32 the round's labels up to its candidate
    saddle_rows: jax.Array  # (V,) bool values with a chaotic saddle before the candidate
    candidate: jax.Array  # () int32 the candidate's lane
    cand_y: jax.Array  # (dim,) its state
    cand_row: jax.Array  # () int32 its value
    cand_label: jax.Array  # () int32 the slot it takes (-1: none), once characterised
    cand_charge: jax.Array  # () int32 the periods charged to it, once characterised


class Phase(enum.IntEnum):
    """Where a round stands (``PoolState.phase``). A round whose decisions chose a candidate
    for a new attractor of boxes stops there: the pool's program returns, the candidate is
    characterised by a program of its own (:func:`characterise`, with no lane axis: one
    program for every pool size), and the next call of the pool's program finishes the
    round as if it had never stopped."""

    READY = 0  # between rounds
    CANDIDATE = 1  # stopped at a candidate, to be characterised
    CHARACTERISED = 2  # the candidate characterised, the round's decisions to finish


# ----------------------------------------------------------------------------- attractor tables
def table_slots(count: int) -> int:
    """Slots of an attractor table that holds ``count`` attractors: 8, or the next power of two."""
    return power_of_two_at_least(count, 8)


def seed_tables(attractors, M: int, dim: int, Q: int = 1) -> AttractorTable:
    """The :class:`AttractorTable` (numpy; ``M`` points and ``Q`` cloud points per slot) of
    ``V`` values, each holding its value's known attractors ``[(points (k, dim), k)]``
    first (``A``: :func:`table_slots`): a P-k cycle; a cycle of period ``-k``, a repeller
    (an unstable P-k cycle whose lanes integrate on); period :data:`APERIODIC`, an
    attractor of boxes given by its cloud (at most ``Q`` points kept)."""
    known = [[(np.asarray(p, np.float64).reshape(-1, dim), int(k)) for p, k in att] for att in attractors]
    if any(not abs(k) <= M for kn in known for _, k in kn):
        raise ValueError(f"known attractors must have periods 1..{M} (repellers -1..-{M}, {APERIODIC}: of boxes)")
    A = table_slots(max(len(kn) for kn in known))
    V = len(known)
    pts = np.full((V, A, M, dim), np.nan)
    ks = np.full((V, A), slot_code(SlotKind.EMPTY, M), np.int32)
    clouds = np.full((V, A, Q, dim), np.nan)
    for v, kn in enumerate(known):
        for a, (p, k) in enumerate(kn):
            if k == APERIODIC:
                clouds[v, a, :min(Q, len(p))] = p[np.linspace(0, len(p) - 1, min(Q, len(p))).astype(int)]
                ks[v, a] = slot_code(SlotKind.BOXES, M)
            else:
                pts[v, a, :abs(k)] = p[:abs(k)]
                ks[v, a] = slot_code(SlotKind.CYCLE if k > 0 else SlotKind.REPELLER, M, abs(k))
    return AttractorTable(points=pts, codes=ks, counts=np.array([len(kn) for kn in known], np.int32), clouds=clouds)


# ----------------------------------------------------------------------------- the state
def init_pool(L: int, M: int, X, Xrow, attractors: AttractorTable, boxes: Boxes | None = None,
              n_real=None) -> PoolState:
    """The pool of ``L`` lanes over the queue ``X (n, dim)`` (parameter rows ``Xrow (n,)``),
    its first lanes holding the first cells, with the attractor tables ``attractors``;
    ``n_real`` (traced, optional): the queue's real length when ``X`` is padded (the
    padding never enters a lane). The boxes of the known attractors of boxes (their
    clouds) enter the box table."""
    n, dim = X.shape
    H = 2 * M + 1
    take = jnp.asarray(min(L, n), jnp.int32)
    if n_real is not None:
        take = jnp.minimum(take, n_real).astype(jnp.int32)
    lane = jnp.arange(L, dtype=jnp.int32)
    first = lane < take
    src = jnp.minimum(lane, n - 1)
    return PoolState(
        Y=jnp.where(first[None], X[src].T, 0.0), hist=jnp.full((2 * H, dim, L), jnp.nan, dtype=jnp.float64),
        streak=jnp.zeros((M, L), jnp.int32), cell=jnp.where(first, lane, -1).astype(jnp.int32),
        row=jnp.where(first, Xrow[src], 0).astype(jnp.int32), age=jnp.zeros(L, jnp.int32),
        labels=jnp.full(n, NOT_DONE, jnp.int32), used=jnp.zeros(n, jnp.int32), next_cell=take,
        n_done=jnp.asarray(0, jnp.int32), clock=jnp.asarray(0, jnp.int32),
        attractors=attractors._replace(counts=jnp.asarray(attractors.counts, jnp.int32)),
        radius=jnp.zeros(attractors.n_values, jnp.float64), quiet=jnp.zeros(attractors.n_values, jnp.int32),
        n_active=take, overflow=jnp.asarray(False),
        rounds=jnp.asarray(0, jnp.int32), table=_seeded_table(boxes, attractors, M), hit_att=jnp.full(L, -1, jnp.int32),
        hits=jnp.zeros(L, jnp.int32), misses=jnp.zeros(L, jnp.int32), tried=jnp.zeros(L, jnp.int32),
        dropped=jnp.asarray(0, jnp.int32), phase=jnp.asarray(Phase.READY, jnp.int32),
        pending=jnp.full(L, -1, jnp.int32), saddle_rows=jnp.zeros(attractors.n_values, bool),
        candidate=jnp.asarray(0, jnp.int32), cand_y=jnp.zeros(dim, jnp.float64), cand_row=jnp.asarray(0, jnp.int32),
        cand_label=jnp.asarray(-1, jnp.int32), cand_charge=jnp.asarray(0, jnp.int32))


def _seeded_table(boxes: Boxes | None, attractors: AttractorTable, M: int) -> CellTable:
    """The box table holding the boxes of the seeded attractors of boxes (an empty table of
    the smallest size when there is no detection by recurrences)."""
    if boxes is None:
        return empty_table(64)
    V, A, Q, dim = attractors.clouds.shape
    pts = attractors.clouds.reshape(V * A * Q, dim).T
    rows = jnp.repeat(jnp.arange(V, dtype=jnp.int32), A * Q)
    slot = jnp.tile(jnp.repeat(jnp.arange(A, dtype=jnp.int32), Q), V)
    mark = jnp.repeat(_of_boxes(attractors.codes, M).reshape(-1), Q)
    keys = jnp.where(mark, row_keys(boxes.partition, pts, rows, V), -1)
    table, _ = insert(empty_table(boxes.options.capacity), keys, slot)
    return table


def resize(s: PoolState, L: int | None = None, A: int | None = None) -> PoolState:
    """The pool with ``L`` lanes (the first ``L``: busy lanes are at the front) or ``A``
    attractor slots per value."""
    if L is not None:
        s = s._replace(Y=s.Y[:, :L], hist=s.hist[:, :, :L], streak=s.streak[:, :L], cell=s.cell[:L], row=s.row[:L],
                       age=s.age[:L], hit_att=s.hit_att[:L], hits=s.hits[:L], misses=s.misses[:L],
                       tried=s.tried[:L], pending=s.pending[:L], n_active=jnp.minimum(s.n_active, L))
    if A is not None:
        s = s._replace(attractors=s.attractors.with_slots(A), overflow=jnp.asarray(False))
    return s


# ----------------------------------------------------------------------------- one period
def _sqdist(a, b):
    """Squared Euclidean distance over axis ``-2`` (the state coordinates of ``(..., dim, L)``
    arrays), summed coordinate by coordinate (XLA fuses this; a reduction over a middle
    axis it runs several times slower)."""
    a, b = jnp.broadcast_arrays(a, b)
    return sum((a[..., i, :] - b[..., i, :]) ** 2 for i in range(a.shape[-2]))


def _back(hist, g, start: int, count: int):
    """The points ``start, ..., start + count - 1`` periods back from period ``g`` (newest
    first): ``(count, dim, L)`` (one contiguous slice of the doubled ring)."""
    H = hist.shape[0] // 2
    top = g % H + H - start  # slot of the point `start` periods back
    return jax.lax.dynamic_slice_in_dim(hist, top - count + 1, count, axis=0)[::-1]


def one_period(system, params, integrator, o: PoolOptions, boxes: Boxes | None, s: PoolState) -> PoolState:
    """Every active lane one forcing period on, its point into the ring, its streaks and
    its run of box hits updated."""
    H = s.hist.shape[0] // 2
    if s.attractors.n_values == 1:  # one parameter set
        Y = integrator.advance(system, params, s.Y, jnp.asarray(0.0), 1, n_active=s.n_active)
    else:  # params holds one row per value; each lane uses its cell's
        Y = integrator.advance_rows(system, params, s.row, s.Y, jnp.asarray(0.0), 1, n_active=s.n_active)
    g = s.clock + 1
    c = g % H
    hist = jax.lax.dynamic_update_slice_in_dim(s.hist, Y[None], c, axis=0)
    hist = jax.lax.dynamic_update_slice_in_dim(hist, Y[None], c + H, axis=0)
    busy = s.cell >= 0
    age = jnp.where(busy, s.age + 1, s.age)
    thr = (o.period_tol * (1.0 + jnp.sqrt(_sqdist(Y, 0.0)))) ** 2
    ks = jnp.arange(1, o.max_period + 1, dtype=jnp.int32)
    prev = _back(hist, g, 1, o.max_period)  # (M, dim, L): x_(t-1), ..., x_(t-M)
    ok = (_sqdist(Y[None], prev) <= thr[None]) & (age[None] > ks[:, None])  # x_(t-k) is this cell's
    streak = jnp.where(ok, s.streak + 1, 0)
    s = s._replace(Y=Y, hist=hist, streak=streak, age=age, clock=g)
    if boxes is None:
        return s

    def track(s):  # only once an attractor of boxes is known
        lab = lookup(s.table, row_keys(boxes.partition, s.Y, s.row, s.attractors.n_values))
        hit_att, hits, misses = track_hits(lab, s.hit_att, s.hits, s.misses, boxes.options.max_misses)
        return s._replace(hit_att=hit_att, hits=hits, misses=misses)

    return jax.lax.cond(jnp.any(_of_boxes(s.attractors.codes, o.max_period)), track, lambda s: s, s)


# ----------------------------------------------------------------------------- decisions
def capture_radius(points, codes, capture: float | None):
    """The capture radius of one value's table, its points ``(A, M, dim)`` and codes
    ``(A,)``: ``capture`` itself, or (``None``) a quarter of the smallest distance between
    two attractors' points, at most 1 % of ``1 + max |point|``."""
    if capture is not None:
        return jnp.asarray(capture, jnp.float64)
    A, M, _ = points.shape
    cycle = slot_kind(codes, M) == SlotKind.CYCLE
    valid = (jnp.arange(M, dtype=jnp.int32)[None] < slot_period(codes, M)[:, None]) & cycle[:, None]  # (A, M)
    pts = jnp.where(valid[..., None], points, 0.0)
    scale = 1.0 + jnp.max(jnp.where(valid[..., None], jnp.abs(pts), 0.0))
    d = jnp.sqrt(jnp.sum((pts[:, None, :, None] - pts[None, :, None, :]) ** 2, axis=-1))  # (A, A, M, M)
    pair = valid[:, None, :, None] & valid[None, :, None, :] & ~jnp.eye(A, dtype=bool)[:, :, None, None]
    gap = jnp.min(jnp.where(pair, d, jnp.inf))
    return jnp.minimum(0.01 * scale, 0.25 * gap)


class _Lanes(NamedTuple):
    """What a round's decisions know of each lane ``(L,)``."""

    esc: jax.Array  # escaped (the sink)
    live: jax.Array  # busy and not escaped
    per: jax.Array  # smallest recurring period (M + 1: none)
    rec: jax.Array  # live and recurring


def _lane_status(o: PoolOptions, s: PoolState) -> _Lanes:
    M = o.max_period
    busy = s.cell >= 0
    esc = busy & escaped(s.Y, o.escape_bound)
    ks = jnp.arange(1, M + 1, dtype=jnp.int32)
    per = jnp.min(jnp.where(s.streak >= (ks + 1)[:, None], ks[:, None], M + 1), axis=0).astype(jnp.int32)
    live = busy & ~esc
    return _Lanes(esc=esc, live=live, per=per, rec=live & (per <= M))


def _min_rows(d):
    """``(jnp.min(d, axis=0), jnp.argmin(d, axis=0))`` of ``d (M, L)`` for a small static
    ``M``, the first row on ties and a NaN first, as those give them: one elementwise pass
    over the rows (XLA runs an argmin over the rows as a reduction several times slower)."""
    best, arg = d[0], jnp.zeros(d.shape[1], jnp.int32)
    for i in range(1, d.shape[0]):
        take = (d[i] < best) | (jnp.isnan(d[i]) & ~jnp.isnan(best))
        best, arg = jnp.where(take, d[i], best), jnp.where(take, i, arg)
    return best, arg


def _cycle_distances(s: PoolState, P, m, k):
    """The largest distance of the lanes' last ``k`` points to the cycle ``P (M, dim)``
    followed back from ``P[m]`` (``m (L,)``: the cycle point nearest the newest point),
    and of the ``k`` points before those: one slice of the ring per step, so no
    ``(M, dim, L)`` copy of the ring or of the cycle is made."""
    H = s.hist.shape[0] // 2
    g = s.clock
    kk = jnp.maximum(k, 1)

    def point(j, c):
        d_now, d_bef, i = c  # i = (m - j) mod k: the cycle point j periods back
        q = jnp.take(P, i, axis=0).T  # (dim, L)
        w_now = jax.lax.dynamic_index_in_dim(s.hist, g % H + H - j, axis=0, keepdims=False)
        w_bef = jax.lax.dynamic_index_in_dim(s.hist, g % H + H - j - k, axis=0, keepdims=False)
        return (jnp.maximum(d_now, _sqdist(w_now, q)), jnp.maximum(d_bef, _sqdist(w_bef, q)),
                jnp.where(i == 0, kk - 1, i - 1))

    zero = jnp.zeros(s.cell.shape[0])
    d_now, d_bef, _ = jax.lax.fori_loop(0, k, point, (zero, zero, jnp.mod(m, kk)))
    d_now = jnp.where(s.age >= k, jnp.sqrt(d_now), jnp.inf)
    d_bef = jnp.where(s.age >= 2 * k, jnp.sqrt(d_bef), jnp.inf)
    return d_now, d_bef


def _match_slot(o: PoolOptions, s: PoolState, lanes: _Lanes, v, a, label):
    """Lanes captured by (or recurring onto) the attractor in slot ``a`` of value ``v``'s
    table, a P-k cycle: every quantity of the attractor is a scalar or broadcast over the
    lanes. A repeller's slot (period ``-k``) marks its lanes ``_ON_REPELLER`` instead:
    they integrate on (an attractor's slot still takes them)."""
    P = s.attractors.points[v, a]  # (M, dim)
    repeller = slot_kind(s.attractors.codes[v, a], o.max_period) == SlotKind.REPELLER
    k = slot_period(s.attractors.codes[v, a], o.max_period)  # 0 for a set of boxes: it is matched by its boxes
    valid = jnp.arange(o.max_period, dtype=jnp.int32) < k
    dn = jnp.where(valid[:, None], jnp.sqrt(_sqdist(s.Y[None], P[:, :, None])), jnp.inf)  # (M, L)
    d_min, m = _min_rows(dn)  # the newest point is near P[m] ...
    d_now, d_bef = _cycle_distances(s, P, m, k)
    cap = lanes.live & (k > 0) & (d_now <= s.radius[v]) & ((d_now <= d_bef) | ~jnp.isfinite(d_bef))
    scale = 1.0 + jnp.max(jnp.where(valid[:, None], jnp.abs(P), 0.0))
    same = lanes.rec & (k > 0) & (lanes.per == k) & (d_min <= o.merge_tol * scale)
    hit = cap | same
    if s.attractors.n_values > 1:
        hit = hit & (s.row == v)  # the lanes of value v; a lane's label is a slot of its value's table
    return jnp.where((label < 0) & hit, jnp.where(repeller, _ON_REPELLER, a), label).astype(jnp.int32)


def _busy_rows(s: PoolState):
    """The range ``[lo, hi]`` of values the busy lanes hold."""
    busy = s.cell >= 0
    V = s.attractors.n_values
    return jnp.min(jnp.where(busy, s.row, V)), jnp.max(jnp.where(busy, s.row, -1))


def _over_rows(s: PoolState, body, carry):
    """``body(v, carry)`` over the values the busy lanes hold (value 0 alone for one value)."""
    if s.attractors.n_values == 1:
        return body(0, carry)
    lo, hi = _busy_rows(s)
    return jax.lax.fori_loop(lo, hi + 1, body, carry)


def _match_known(o: PoolOptions, s: PoolState, lanes: _Lanes):
    """Each lane's attractor slot among the known ones (-1: none; ``_ON_REPELLER``)."""
    def row(v, label):
        return jax.lax.fori_loop(0, s.attractors.counts[v], lambda a, label: _match_slot(o, s, lanes, v, a, label),
                                 label)

    return _over_rows(s, row, jnp.full(s.cell.shape[0], -1, jnp.int32))


def _register_new(o: PoolOptions, s: PoolState, lanes: _Lanes, label, radius):
    """A recurring lane on no known attractor or repeller of its value registers a new one
    (the first such lane, one per value and round); the other recurring lanes of the value
    whose newest point lies on it join it. Returns the tables (an :class:`AttractorTable`),
    the radii, the labels and the overflow flag."""
    M = o.max_period
    i = jnp.arange(M, dtype=jnp.int32)
    new = lanes.rec & (label == -1)

    def register(v, c):
        tables, radius, label, overflow = c
        new_v = new if tables.n_values == 1 else new & (s.row == v)
        has_new = jnp.any(new_v)
        room = tables.counts[v] < tables.n_slots
        l0 = jnp.argmax(new_v)
        k0 = lanes.per[l0]
        last = _back(s.hist[:, :, l0], s.clock, 0, M)  # (M, dim), newest first
        valid0 = i < k0
        pts0 = jnp.where(valid0[:, None], last[jnp.clip(k0 - 1 - i, 0, M - 1)], jnp.nan)  # oldest of the last k0 first

        def add(c):
            tables, radius, label = c
            slot = tables.counts[v]
            tables = tables._replace(points=tables.points.at[v, slot].set(pts0),
                                     codes=tables.codes.at[v, slot].set(slot_code(SlotKind.CYCLE, M, k0)),
                                     counts=tables.counts.at[v].add(1))
            scale0 = 1.0 + jnp.max(jnp.where(valid0[:, None], jnp.abs(pts0), 0.0))
            d0 = jnp.where(valid0[:, None], _sqdist(s.Y[None], pts0[:, :, None]), jnp.inf)  # (M, L)
            joins = new_v & (lanes.per == k0) & (jnp.min(d0, axis=0) <= (o.merge_tol * scale0) ** 2)
            radius = radius.at[v].set(capture_radius(tables.points[v], tables.codes[v], o.capture_radius))
            return tables, radius, jnp.where(joins, slot, label).astype(jnp.int32)

        c = jax.lax.cond(has_new & room, add, lambda c: c, (tables, radius, label))
        return (*c, overflow | (has_new & ~room))

    return _over_rows(s, register, (s.attractors, radius, label, s.overflow))


def _refill(s: PoolState, decided, X, Xrow, n) -> PoolState:
    """Freed lanes take the next cells of the queue (only lanes below ``n_active`` once it
    is empty)."""
    L = s.cell.shape[0]
    lane = jnp.arange(L, dtype=jnp.int32)
    free = ((s.cell < 0) | decided) & (lane < jnp.where(s.next_cell < n, L, s.n_active))
    nc = s.next_cell + jnp.cumsum(free, dtype=jnp.int32) - 1
    take = free & (nc < n)
    src = jnp.clip(nc, 0, X.shape[0] - 1)
    cell = jnp.where(take, nc, jnp.where(free, -1, s.cell)).astype(jnp.int32)
    row = jnp.where(take, Xrow[src], s.row).astype(jnp.int32)
    Y = jnp.where(take[None], X[src].T, jnp.where(free[None], 0.0, s.Y))
    next_cell = jnp.minimum(s.next_cell + jnp.sum(take, dtype=jnp.int32), n).astype(jnp.int32)
    highest = jnp.max(jnp.where(cell >= 0, lane, -1)) + 1  # busy lanes lie below it
    n_active = jnp.where(s.next_cell < n, jnp.maximum(s.n_active, highest), s.n_active).astype(jnp.int32)
    return s._replace(Y=Y, cell=cell, row=row, age=jnp.where(free, 0, s.age),
                      streak=jnp.where(free[None], 0, s.streak), next_cell=next_cell, n_active=n_active,
                      hit_att=jnp.where(free, -1, s.hit_att).astype(jnp.int32),
                      hits=jnp.where(free, 0, s.hits).astype(jnp.int32),
                      misses=jnp.where(free, 0, s.misses).astype(jnp.int32),
                      tried=jnp.where(free, 0, s.tried).astype(jnp.int32))


def _choose_candidate(o: PoolOptions, boxes: Boxes, s: PoolState, lanes: _Lanes, label) -> PoolState:
    """The round's candidate for a new attractor of boxes (at most one in the pool): the
    oldest live undecided lane past the transient (and as long since its last try), in no
    run of box hits, not recurring and not approaching a cycle (among the oldest such lanes,
    :func:`~jaxgear.analysis._cloud.oldest_off_cycle`), of a value not quiet
    (``PoolState.quiet``: see :func:`characterise`). With one, the round stops there
    (``Phase.CANDIDATE``) to have it characterised (:func:`characterise`)."""
    opt, part = boxes.options, boxes.partition
    M = o.max_period
    eligible = (lanes.live & (label < 0) & (lanes.per > M) & (s.age >= opt.transient)
                & (s.age - s.tried >= opt.transient) & (s.hits == 0) & (s.clock >= s.quiet[s.row])
                & (s.age < o.max_periods))  # past it, a lane on a chaotic saddle has been tried often enough
    l0, found = oldest_off_cycle(eligible, s.age, lambda i: _back(s.hist[:, :, i], s.clock, 0, 2 * M), part.width, M)
    return s._replace(phase=jnp.where(found, Phase.CANDIDATE, s.phase).astype(jnp.int32),
                      candidate=jnp.asarray(l0, jnp.int32), cand_y=s.Y[:, l0], cand_row=s.row[l0])


class Candidate(NamedTuple):
    """What characterising a round's candidate reads and writes (:func:`characterise`):
    no lane axis, so one compiled program serves every pool size (on a mesh every leaf has
    a leading device axis)."""

    phase: jax.Array  # () int32 Phase: characterised only at Phase.CANDIDATE
    y: jax.Array  # (dim,) the candidate's state
    row: jax.Array  # () int32 its value
    clock: jax.Array  # () int32 the pool's clock
    quiet: jax.Array  # (V,) int32 the pool's quiet clock per value (PoolState.quiet)
    rounds: jax.Array  # () int32 rounds run (its cloud's random key)
    attractors: AttractorTable
    table: CellTable
    overflow: jax.Array  # () bool
    dropped: jax.Array  # () int32
    label: jax.Array  # () int32 the slot the lane takes (-1: none)
    charge: jax.Array  # () int32 the periods charged to the lane


def candidate_of(s: PoolState) -> Candidate:
    """The pool's candidate (fields of its state: no computation)."""
    return Candidate(phase=s.phase, y=s.cand_y, row=s.cand_row, clock=s.clock, quiet=s.quiet, rounds=s.rounds,
                     attractors=s.attractors, table=s.table, overflow=s.overflow, dropped=s.dropped, label=s.cand_label,
                     charge=s.cand_charge)


def with_candidate(s: PoolState, c: Candidate) -> PoolState:
    """The pool with its candidate characterised (``c`` from :func:`characterise`)."""
    return s._replace(phase=c.phase, attractors=c.attractors, quiet=c.quiet, table=c.table, overflow=c.overflow,
                      dropped=c.dropped, cand_label=c.label, cand_charge=c.charge)


def characterise(system, params, integrator, o: PoolOptions, boxes: Boxes, c: Candidate) -> Candidate:
    """A round's candidate (at ``Phase.CANDIDATE``, else ``c`` unchanged). Its cloud
    (:func:`~jaxgear.analysis._cloud.attractor_cloud`, staged, stopped on a cycle or
    an escape) is accepted when it recurs in its own boxes (a cloud that falls short of
    ``accept_share`` by little, as on a torus, is continued once:
    :data:`~jaxgear.analysis._cloud.CONTINUE_SHARE`); it then joins the attractor of
    boxes (or the saddle) of its value that it overlaps, or takes a new slot; its boxes
    enter the table and the lane takes the attractor's label (its cloud's periods are
    charged to it).

    A new set is verified first (``verify_periods > 0``): ``verify_lanes`` of its cloud's
    points are continued ``verify_periods`` periods
    (:func:`~jaxgear.analysis._cloud.leaving_share`); when at least ``leave_share``
    of them settle on a cycle, escape or reach another known set, it is a chaotic saddle
    (a long transient, not an attractor): its slot is a ``SlotKind.SADDLE``, its
    boxes enter the table (lanes visiting them are no candidates again) and the lane
    integrates on.

    A cloud that reached a cycle within its first stage was a brief transient: its value
    has no candidate for as many periods of the pool (``PoolState.quiet``), so a value
    whose slow cells are many brief transients (the paper preset: 79 such clouds in one
    analysis, 5 with the quiet periods) does not pay a cloud for each, while a longer
    transient (a chaotic saddle, whose clouds run longer) keeps its candidates."""
    opt, part = boxes.options, boxes.partition
    M, V = o.max_period, c.attractors.n_values
    mark, saddle = slot_code(SlotKind.BOXES, M), slot_code(SlotKind.SADDLE, M)

    def run(c):
        v0 = c.row
        p0 = params if V == 1 else jax.tree.map(lambda a: a[v0], params)
        tables = c.attractors
        P, A, Q = opt.cloud_periods, tables.n_slots, tables.clouds.shape[2]

        def stop(pts):  # a cycle (left to the point-level recognition) or an escape ends the cloud
            return near_periodic(part, pts, M) | jnp.any(escaped(flat_cloud(pts), o.escape_bound))

        cloud, ran = attractor_cloud(system, p0, integrator, c.y, periods=P, lanes=opt.cloud_lanes,
                                     key=jax.random.fold_in(jax.random.PRNGKey(0), c.rounds), stages=CLOUD_STAGES,
                                     stop=stop)
        def ran_out(cloud, ran):  # to its end, its last stage off a cycle
            return (ran == P) & ~stop(cloud[P - P // CLOUD_STAGES:])

        whole, share = ran_out(cloud, ran), recurrence_share(part, cloud)
        S = P // CLOUD_STAGES
        brief = (ran == S) & near_periodic(part, cloud[:S], M)  # a short transient: on a cycle within one stage
        longer = whole & (share < opt.accept_share) & (share >= CONTINUE_SHARE)

        def continued(_):  # a torus's copies stay together: the continuation against the whole cloud
            more, extra = staged_cloud(system, p0, integrator, cloud[-1], periods=P, stages=CLOUD_STAGES, stop=stop)
            return more, ran + extra, ran_out(more, extra), recurrence_share(part, jnp.concatenate([cloud, more]))

        cloud, ran, whole, share = jax.lax.cond(longer, continued, lambda _: (cloud, ran, whole, share), None)
        ok = whole & (share >= opt.accept_share)
        second = flat_cloud(cloud[P // 2:])  # (dim, m)
        second_keys = row_keys(part, second, jnp.full(second.shape[1], v0, jnp.int32), V)
        over = overlap_shares(c.table, second_keys, A)
        over = jnp.where(_of_boxes(tables.codes[v0], M), over, 0.0)  # only sets of boxes absorb clouds
        best = jnp.argmax(over).astype(jnp.int32)
        joins = over[best] >= opt.overlap_share
        transient = jnp.asarray(False)
        if opt.verify_periods:
            def leaves(_):
                def elsewhere(pts):  # (2M, dim, K): every last point in a known set's boxes
                    flat = flat_cloud(pts)
                    lab = lookup(c.table, row_keys(part, flat, jnp.full(flat.shape[1], v0, jnp.int32), V))
                    return jnp.all(lab.reshape(pts.shape[0], -1) >= 0, axis=0)

                return leaving_share(system, p0, integrator, part, verification_starts(second, opt.verify_lanes),
                                     periods=verify_length(opt, M), max_period=M, bound=o.escape_bound,
                                     elsewhere=elsewhere) >= opt.leave_share

            transient = jax.lax.cond(ok & ~joins, leaves, lambda _: jnp.asarray(False), None)
        room = tables.counts[v0] < A
        slot = jnp.where(joins, best, tables.counts[v0]).astype(jnp.int32)
        step = max(second.shape[1] // Q, 1)
        pts = jnp.full((Q, second.shape[0]), jnp.nan).at[: min(Q, second.shape[1])].set(second[:, ::step][:, :Q].T)
        new = ok & ~joins & room
        taken = ok & (joins | room)
        attractor = taken & ~transient & ~(joins & (tables.codes[v0, best] == saddle))  # the lane is labelled
        keys = jnp.where(taken, second_keys, -1)
        table, dropped = insert(c.table, keys, slot)
        charged = ran + jnp.where(new, verify_length(opt, M) if opt.verify_periods else 0, 0)
        tables = tables._replace(
            codes=jnp.where(new, tables.codes.at[v0, slot].set(jnp.where(transient, saddle, mark)), tables.codes),
            clouds=jnp.where(new, tables.clouds.at[v0, slot].set(pts), tables.clouds),
            counts=tables.counts.at[v0].add(new.astype(jnp.int32)))
        return c._replace(phase=jnp.asarray(Phase.CHARACTERISED, jnp.int32), attractors=tables,
                          quiet=jnp.where(brief, c.quiet.at[v0].set(c.clock + S), c.quiet),
                          overflow=c.overflow | (ok & ~joins & ~room), table=table, dropped=c.dropped + dropped,
                          label=jnp.where(attractor, slot, -1).astype(jnp.int32),
                          charge=jnp.where(attractor, charged, 0).astype(jnp.int32))

    return jax.lax.cond(c.phase == Phase.CANDIDATE, run, lambda c: c, c)


def _round_head(o: PoolOptions, boxes: Boxes | None, s: PoolState):
    """A round's decisions up to its candidate (see the module): each lane's label among
    the known attractors (capture, recurrence, a run of box hits), new cycles registered,
    the candidate chosen. Returns the state, the labels and the lanes' status."""
    lanes = _lane_status(o, s)
    label = _match_known(o, s, lanes)
    # the capture radius follows its value's table: computed for every value in the
    # pool's first round (it starts at 0), then only for a value whose table grew
    radius = jax.lax.cond(s.rounds == 0, lambda: jax.vmap(lambda p, k: capture_radius(p, k, o.capture_radius))(
        s.attractors.points, s.attractors.codes), lambda: s.radius)
    tables, radius, label, overflow = _register_new(o, s, lanes, label, radius)
    s = s._replace(attractors=tables, radius=radius, overflow=overflow)
    if boxes is None:
        return s, label, lanes
    kinds = slot_kind(s.attractors.codes, o.max_period)  # (V, A)
    on_saddle = kinds[s.row, jnp.maximum(s.hit_att, 0)] == SlotKind.SADDLE
    hit = lanes.live & (label < 0) & (s.hit_att >= 0) & (s.hits >= boxes.options.hits) & ~on_saddle
    label = jnp.where(hit, s.hit_att, label).astype(jnp.int32)
    # the values with a chaotic saddle before the candidate: their cells' lanes may still
    # be on that long transient
    s = s._replace(saddle_rows=jnp.any(kinds == SlotKind.SADDLE, axis=1))
    return _choose_candidate(o, boxes, s, lanes, label), label, lanes


def _round_tail(o: PoolOptions, boxes: Boxes | None, s: PoolState, label, lanes: _Lanes, X, Xrow, n) -> PoolState:
    """The rest of a round's decisions: the characterised candidate's lane takes its label
    and its periods, escaped, labelled and timed-out lanes write their cells' labels, freed
    lanes refill."""
    limit = o.max_periods
    if boxes is not None:
        l0, done = s.candidate, s.phase == Phase.CHARACTERISED
        label = label.at[l0].set(jnp.where(done & (s.cand_label >= 0), s.cand_label, label[l0])).astype(jnp.int32)
        s = s._replace(tried=s.tried.at[l0].set(jnp.where(done, s.age[l0], s.tried[l0])),
                       age=s.age.at[l0].add(jnp.where(done, s.cand_charge, 0)),
                       phase=jnp.asarray(Phase.READY, jnp.int32))
        limit = jnp.where(s.saddle_rows[s.row], o.saddle_limit, o.max_periods)
    unres = lanes.live & (label < 0) & (s.age >= limit)
    decided = lanes.esc | (label >= 0) | unres
    value = jnp.where(lanes.esc, SINK, jnp.where(unres, UNRESOLVED, label)).astype(jnp.int32)
    target = jnp.where(decided, s.cell, s.labels.shape[0])  # dropped
    s = s._replace(labels=s.labels.at[target].set(value, mode="drop"), used=s.used.at[target].set(s.age, mode="drop"),
                   n_done=s.n_done + jnp.sum(decided, dtype=jnp.int32), rounds=s.rounds + 1)
    return _refill(s, decided, X, Xrow, n)


def compact(s: PoolState) -> PoolState:
    """Move the busy lanes that lie beyond the first ``c`` lanes (``c``: the busy count)
    into the free lanes below ``c``, so lanes ``[0, c)`` hold every busy lane and only
    those are integrated (``n_active = c``). Only the lanes out of place move, in steps of
    :data:`MOVE_CHUNK`, so a compaction costs what it moves (the ring of a lane is most of
    the pool's memory)."""
    L = s.cell.shape[0]
    pos = jnp.arange(L, dtype=jnp.int32)
    busy = s.cell >= 0
    c = jnp.sum(busy, dtype=jnp.int32)
    out_of_place = busy & (pos >= c)
    m = jnp.sum(out_of_place, dtype=jnp.int32)
    src_all = jnp.nonzero(out_of_place, size=L, fill_value=L)[0].astype(jnp.int32)
    dst_all = jnp.nonzero(~busy & (pos < c), size=L, fill_value=L)[0].astype(jnp.int32)
    K = min(MOVE_CHUNK, L)
    pad = jnp.full(K, L, jnp.int32)  # so the last chunk's slice stays inside the arrays
    src_all, dst_all = jnp.concatenate([src_all, pad]), jnp.concatenate([dst_all, pad])

    def move(j, s):
        src = jax.lax.dynamic_slice_in_dim(src_all, j * K, K)
        dst = jax.lax.dynamic_slice_in_dim(dst_all, j * K, K)
        src_c = jnp.minimum(src, L - 1)

        def mv(a):  # lanes on the last axis
            return a.at[..., dst].set(jnp.take(a, src_c, axis=-1), mode="drop")

        return s._replace(Y=mv(s.Y), hist=mv(s.hist), streak=mv(s.streak), cell=mv(s.cell), row=mv(s.row),
                          age=mv(s.age), hit_att=mv(s.hit_att), hits=mv(s.hits), misses=mv(s.misses),
                          tried=mv(s.tried))

    s = jax.lax.fori_loop(0, (m + K - 1) // K, move, s)
    cell = jnp.where(pos >= c, -1, s.cell).astype(jnp.int32)  # the lanes moved from
    return s._replace(cell=cell, n_active=jnp.minimum(s.n_active, c).astype(jnp.int32))


def _unless_ring(pred, f, s: PoolState) -> PoolState:
    """``f(s)`` where ``pred``, else ``s``, for an ``f`` that reads the ring but does not
    write it: the ring (most of the pool's memory) is no output of the conditional, which
    would copy it."""
    out = jax.lax.cond(pred, lambda s: f(s)._replace(hist=None), lambda s: s._replace(hist=None), s)
    return out._replace(hist=s.hist)


def run_rounds(s: PoolState, system, params, integrator, o: PoolOptions, boxes: Boxes | None, X, Xrow, n,
               L_min: int, rounds):
    """At most ``rounds`` rounds (traced: the host sizes its calls by their duration), fewer
    when every cell of the queue ``X[:n]`` is decided, an attractor table overflows, the
    pool can move to ``L_min`` lanes, or a round stops at a candidate for a new attractor
    of boxes (``Phase.CANDIDATE``: characterised by :func:`characterise`, the call after
    finishes that round). ``n`` may be traced (a padded block of a sharded queue). Returns
    the state and its progress row ``(done, overflow, n_active, next_cell, attractors,
    candidate)``."""
    def periods(s, count=o.round_periods):
        return jax.lax.fori_loop(0, count, lambda _, s: one_period(system, params, integrator, o, boxes, s), s)

    def compacted(s):  # once the queue is empty, the busy lanes are gathered at the front as lanes free up
        busy = jnp.sum(s.cell >= 0, dtype=jnp.int32)
        worth = (s.next_cell >= n) & (busy.astype(jnp.float64) <= COMPACT_BELOW * s.n_active.astype(jnp.float64))
        return jax.lax.cond(worth, compact, lambda s: s, s)

    def between_rounds(s, r):
        shrink = (s.next_cell >= n) & (s.n_active <= L_min) & (s.Y.shape[1] > L_min)
        return (r < rounds) & (s.n_done < n) & ~s.overflow & ~shrink

    if boxes is None:  # no candidates: whole rounds
        def body(c):
            s, r = c
            s, label, lanes = _round_head(o, boxes, periods(s))
            return compacted(_round_tail(o, boxes, s, label, lanes, X, Xrow, n)), r + 1

        cond = lambda c: between_rounds(*c)  # noqa: E731
    else:
        def body(c):
            s, r = c

            fresh = s.phase == Phase.READY  # else a round characterised: its periods were run
            s = periods(s, jnp.where(fresh, o.round_periods, 0))

            def head(s):  # a new round's decisions, up to its candidate
                s, label, _ = _round_head(o, boxes, s)
                return s._replace(pending=label)

            def tail(s):  # the lanes' status is the head's: the candidate changes none of what it reads
                return _round_tail(o, boxes, s, s.pending, _lane_status(o, s), X, Xrow, n)

            s = _unless_ring(fresh, head, s)
            stopped = s.phase == Phase.CANDIDATE
            s = _unless_ring(~stopped, tail, s)
            return jax.lax.cond(~stopped, compacted, lambda s: s, s), r + (~stopped).astype(jnp.int32)

        def cond(c):  # a round characterised is finished first
            s, r = c
            return (s.phase == Phase.CHARACTERISED) | ((s.phase == Phase.READY) & between_rounds(s, r))

    s, _ = jax.lax.while_loop(cond, body, (s, jnp.asarray(0, jnp.int32)))
    info = jnp.stack([s.n_done, s.overflow.astype(jnp.int32), s.n_active, s.next_cell,
                      jnp.sum(s.attractors.counts, dtype=jnp.int32), (s.phase == Phase.CANDIDATE).astype(jnp.int32)])
    return s, info
