"""Attractors of every type by recurrences on a fine partition of the section.

The stroboscopic map's state space is divided into fine boxes (:class:`FinePartition`);
a trajectory is followed box by box. A trajectory that keeps landing in the boxes its own
recent past visited has reached an attractor, whatever its type (fixed point, periodic,
quasi-periodic or chaotic), and the boxes it then visits are that attractor; a later
trajectory that lands in a known attractor's boxes a given number of times in a row
belongs to it (Datseris & Wagemakers, "Effortless estimation of basins of attraction",
Chaos 32, 023104, 2022; Attractors.jl's ``AttractorsViaRecurrences``). Periodic
attractors keep the point-level recognition of the direct method (exact cycle points to
``period_tol``); the partition adds the attractors that never repeat a point.

Pure functions the direct method's lane pool calls per period or per round:

- :func:`cell_keys` — each state's box as one ``int64`` key (packed integer coordinates
  up to four dimensions, a 64-bit hash of them beyond, so memory does not grow with the
  state dimension), ``-1`` outside the partition;
- :class:`CellTable`, :func:`empty_table`, :func:`lookup`, :func:`insert` — a fixed-size
  open-addressing hash table on the device from box keys to attractor labels (bounded
  memory; an overflow is counted, never silent);
- :func:`track_hits` — per lane, the run of consecutive hits on one attractor's boxes;
- :func:`near_cycle_lanes`, :func:`oldest_off_cycle` — per lane, whether it is approaching a
  cycle (its repetition errors within a box and shrinking; then no candidate), and the
  round's candidate among the oldest eligible lanes;
- :func:`attractor_cloud`, :func:`recurrence_share`, :func:`near_periodic`,
  :func:`overlap_shares` — a candidate's point cloud, whether it recurs, whether it is a
  cycle the point-level recognition will take, and which known attractor it overlaps;
- :func:`leaving_share` (:func:`continue_states`, :func:`settled_lanes`,
  :func:`verification_starts`) — the verification of a new attractor of boxes: the share
  of its points that leave it within ``verify_periods`` periods (a chaotic saddle, a long
  chaotic transient, loses them at its escape rate; an attractor keeps them);
- :func:`classify_by_recurrence` — a standalone batched classifier built from them, one
  ``lax.while_loop`` over rounds of a refilled lane queue inside one ``jit``: the
  reference for the pool's wiring.

Wiring into the lane pool (:mod:`jaxgear.analysis._pool`), as the classifier does it:

- per period, after ``advance``: ``lookup(table, cell_keys(partition, Y))`` and
  :func:`track_hits` on three ``(L,)`` int32 lane arrays (attractor, hits, misses); a
  fourth, ``tried``, holds the age of a lane's last candidacy. They are reset with the lane.
- per round: ``hits >= options.hits`` decides a lane with its run's attractor; then at most
  one candidate (:func:`oldest_off_cycle`: the oldest live undecided lane with ``age >=
  transient``, ``age - tried >= transient``, no run of hits, not periodic, and not
  :func:`near_cycle_lanes` on its last ``2 M`` points of the pool's ring, looked for among
  the :data:`CANDIDATE_POOL` oldest) gets a staged cloud (``CLOUD_STAGES``, stopped on a
  cycle, :func:`near_periodic`, or an escape); an accepted cloud joins the attractor of
  boxes it overlaps or takes a new slot, and its boxes enter the table in the round's one
  :func:`insert`. A cloud that would take a new slot is verified first
  (:func:`leaving_share` of ``verify_lanes`` of its points over ``verify_periods``):
  when ``leave_share`` of them leave, it is a chaotic saddle and no attractor (the
  classifier drops it; the pool keeps its boxes as a saddle that labels no cell).
- "approaching a cycle" means repetition errors within one box that shrink, not within
  one box alone: an attractor that spans only a few boxes (the gear model's chaotic
  attractor at b = 1.455 is about one box of the partition over region D wide in x1 and
  x2, 9 boxes in all) comes back within a box with some period, yet never converges, and
  the point-level recognition never takes it.
- labels are one space for cycles and attractors of boxes: a cycle registered by point
  recurrence also enters its ``k`` boxes (a chaotic lane visiting them resets its run);
  a repeller's boxes never do. The pool's ``att_k = 0`` means an empty slot, so an
  attractor of boxes needs another mark there, and its cloud (``max_points`` points) its
  own array: the capture radius and the per-slot cycle loop must skip it.
- a sweep in one pool needs one table per parameter row, or the row mixed into the key.
- the partition is built once per analysis from the region (the non-gridded coordinates,
  e.g. ``x4``, get the mean box width of the gridded ones), so boxes mean the same for
  every lane.
- a cloud of 8 copies over 600 periods costs about two rounds of a 1,024-lane pool on CPUs
  (the compiled kernel, parameters passed as traced arguments: closed over as constants
  the gear model falls back to the pure-JAX steps, 200 times slower).
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_int, check_number, split_changes, with_changes
from ..integrate import resolve_integrator
from ._pool_options import PoolOptions

__all__ = ["FinePartition", "partition_from_box", "partition_of_states", "cell_keys", "row_keys", "CellTable",
           "empty_table", "lookup", "insert",
           "track_hits", "attractor_cloud", "recurrence_share", "near_periodic", "near_cycle_lanes", "oldest_off_cycle",
           "overlap_shares",
           "continue_states", "settled_lanes", "verification_starts", "leaving_share", "SETTLED",
           "RecurrenceOptions", "RecurrenceResult", "classify_by_recurrence", "APERIODIC", "INDEX_BITS",
           "MAX_PROBES"]

INDEX_BITS = 15
"""Bits of each integer box coordinate: ``2**15`` boxes per axis, the given box in the
middle of that range (so states far outside it still have a box)."""

_PACKED_DIMS = 63 // INDEX_BITS
"""Up to this state dimension keys are the exact packed coordinates; beyond, a hash."""

MAX_PROBES = 32
"""Slots a lookup or an insertion probes at most (linear probing); an insertion that finds
no free slot among them is dropped and counted."""

CLOUD_STAGES = 4
"""A candidate's cloud runs in this many stages; one whose stage ends on a cycle (or
escapes) stops there (a lane slowly approaching a cycle costs a quarter of a cloud)."""

APERIODIC = 0
"""The period recorded for an attractor found by recurrence of boxes (not of points)."""

_SINK, _UNRESOLVED = -1, -2

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_SALTS = tuple(np.uint64((0x9E3779B97F4A7C15 * (d + 1)) % 2**64) for d in range(64))


def _mix(z):
    """SplitMix64's finaliser on ``uint64``: a bijection that spreads every input bit."""
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


# --------------------------------------------------------------------------- partition
class FinePartition(eqx.Module):
    """A partition of the state space (at the section) into equal boxes.

    Box ``i = floor((y - lo) / width)`` per coordinate, valid for ``0 <= i < 2**INDEX_BITS``
    on every axis. Attributes (float64 arrays, state units): ``lo (dim,)`` the corner of
    box 0, ``width (dim,)`` the box widths. Build it with :func:`partition_from_box`.
    """

    lo: Any
    width: Any

    def __check_init__(self):
        if jnp.shape(self.lo) != jnp.shape(self.width) or jnp.ndim(self.lo) != 1:
            raise ValueError(f"FinePartition: lo {jnp.shape(self.lo)} and width {jnp.shape(self.width)} must be "
                             "vectors of the state dimension.")


def partition_from_box(lower, upper, resolution) -> FinePartition:
    """The partition whose boxes divide ``[lower, upper]`` into ``resolution`` boxes per axis.

    ``lower``, ``upper``: ``(dim,)`` state units (``upper > lower``); ``resolution``: boxes
    across the box per axis (a number or ``(dim,)``, at most ``2**(INDEX_BITS - 1)``). The
    box sits in the middle of the index range, which extends ``2**INDEX_BITS / resolution``
    times its size, so trajectories that leave it keep their boxes. ``ValueError`` names
    the bad argument.
    """
    lower = np.asarray(lower, dtype=np.float64)
    upper = np.asarray(upper, dtype=np.float64)
    res = np.broadcast_to(np.asarray(resolution, dtype=np.float64), lower.shape)
    if lower.ndim != 1 or upper.shape != lower.shape:
        raise ValueError(f"partition_from_box: lower {lower.shape} and upper {upper.shape} must be (dim,) vectors.")
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(upper > lower)):
        raise ValueError(f"partition_from_box: need finite bounds with upper > lower on every axis, got "
                         f"lower={lower.tolist()}, upper={upper.tolist()}.")
    if not np.all((res >= 1) & (res <= 2 ** (INDEX_BITS - 1))):
        raise ValueError(f"resolution={np.asarray(resolution).tolist()} must be between 1 and "
                         f"{2 ** (INDEX_BITS - 1)} boxes per axis.")
    width = (upper - lower) / res
    lo = 0.5 * (lower + upper) - 2 ** (INDEX_BITS - 1) * width
    return FinePartition(lo=jnp.asarray(lo), width=jnp.asarray(width))


def partition_of_states(X, resolution) -> FinePartition:
    """The partition over the bounding box of the states ``X (n, dim)`` with ``resolution``
    boxes per axis (:func:`partition_from_box`); an axis on which the states do not vary
    (a section coordinate, say) gets the mean width of the others, so boxes stay boxes."""
    X = np.asarray(X, dtype=np.float64)
    lo, hi = X.min(axis=0), X.max(axis=0)
    ext = hi - lo
    ext = np.where(ext > 0, ext, ext[ext > 0].mean() if np.any(ext > 0) else 1.0)
    mid = 0.5 * (lo + hi)
    return partition_from_box(mid - ext / 2, mid + ext / 2, resolution)


@jax.jit
def cell_keys(partition: FinePartition, Y):
    """The box key of each state of ``Y (dim, L)``: ``int64 (L,)``, ``-1`` for a state
    outside the partition's index range or not finite.

    For ``dim <= 4`` the key packs the integer coordinates exactly (``INDEX_BITS`` bits
    each); for larger states (the N-planet models, ``dim = 2N + 2``) it is a 64-bit hash of
    them (SplitMix64 steps) cut to 63 bits: distinct boxes collide with probability about
    ``n**2 / 2**64`` for ``n`` boxes in use, and the memory stays that of the table.
    """
    dim = Y.shape[0]
    idx = jnp.floor((Y - partition.lo[:, None]) / partition.width[:, None])
    ok = jnp.all(jnp.isfinite(idx) & (idx >= 0) & (idx < 2 ** INDEX_BITS), axis=0)
    i = jnp.where(ok[None], idx, 0.0).astype(jnp.int64)
    if dim <= _PACKED_DIMS:
        key = sum(i[d] << (INDEX_BITS * d) for d in range(dim))
    else:
        h = jnp.full(i.shape[1], np.uint64(dim), dtype=jnp.uint64)
        for d in range(dim):
            h = _mix(h ^ (i[d].astype(jnp.uint64) + _SALTS[d % 64]))
        key = (h >> np.uint64(1)).astype(jnp.int64)
    return jnp.where(ok, key, -1).astype(jnp.int64)


def row_keys(partition: FinePartition, Y, rows, n_rows: int):
    """:func:`cell_keys` of ``Y (dim, L)`` made distinct per parameter row ``rows (L,)``
    (the values of a sweep in one pool share one table): the box key itself for one row,
    else a 63-bit hash of (key, row)."""
    keys = cell_keys(partition, Y)
    if n_rows == 1:
        return keys
    salted = keys.astype(jnp.uint64) ^ ((jnp.asarray(rows).astype(jnp.uint64) + np.uint64(1)) * _SALTS[0])
    return jnp.where(keys >= 0, (_mix(salted) >> np.uint64(1)).astype(jnp.int64), -1).astype(jnp.int64)


# --------------------------------------------------------------------------- table
class CellTable(eqx.Module):
    """Box key -> attractor label, an open-addressing hash table of fixed capacity ``C``
    (a power of two) with linear probing. ``keys (C,) int64`` (``-1``: empty slot),
    ``labels (C,) int32``. Build it with :func:`empty_table`; nothing is ever removed."""

    keys: Any
    labels: Any


def empty_table(capacity: int) -> CellTable:
    """An empty :class:`CellTable` of ``capacity`` slots (a power of two >= 2 * MAX_PROBES)."""
    capacity = check_int(capacity, "capacity", 2 * MAX_PROBES)
    if capacity & (capacity - 1):
        raise ValueError(f"capacity={capacity} must be a power of two.")
    return CellTable(keys=jnp.full(capacity, -1, jnp.int64), labels=jnp.full(capacity, -1, jnp.int32))


def _probe(table: CellTable, keys):
    """Slots ``(m, MAX_PROBES)`` of each key's probe sequence, and the index of the first
    slot holding the key or empty (``found``: one of them lies in the sequence)."""
    C = table.keys.shape[0]
    start = (_mix(keys.astype(jnp.uint64)) & np.uint64(C - 1)).astype(jnp.int64)
    slots = (start[:, None] + jnp.arange(MAX_PROBES, dtype=jnp.int64)[None]) & (C - 1)
    k = table.keys[slots]
    stop = (k == keys[:, None]) | (k == -1)
    first = jnp.argmax(stop, axis=1)
    slot = jnp.take_along_axis(slots, first[:, None], axis=1)[:, 0]
    return slot, jnp.any(stop, axis=1)


@jax.jit
def lookup(table: CellTable, keys):
    """The label of each key of ``keys (L,)``: ``int32 (L,)``, ``-1`` when the key is absent
    (or is ``-1``). Vectorised over the keys, ``MAX_PROBES`` probes each."""
    slot, found = _probe(table, keys)
    hit = found & (table.keys[slot] == keys) & (keys >= 0)
    return jnp.where(hit, table.labels[slot], -1).astype(jnp.int32)


@jax.jit
def insert(table: CellTable, keys, label):
    """Insert ``keys (m,)`` with ``label`` (an int, or ``(m,)`` one per key): ``(table, n_dropped)``.

    Keys already present keep their label (the first attractor that registered a box owns
    it); keys ``-1`` are skipped; a key that finds no free slot within ``MAX_PROBES`` probes
    is dropped and counted in ``n_dropped`` (int32: the caller reports it). Only the
    distinct keys are inserted (the first label of a repeated key), one after the other
    (a ``while_loop`` over the distinct keys: an insertion must see the previous ones).
    """
    keys = jnp.asarray(keys, jnp.int64)
    label = jnp.broadcast_to(jnp.asarray(label, jnp.int32), keys.shape)
    order = jnp.argsort(keys, stable=True)
    sk, sl = keys[order], label[order]
    first = (sk >= 0) & jnp.concatenate([jnp.ones(1, bool), sk[1:] != sk[:-1]])
    pick = jnp.argsort(~first, stable=True)  # the distinct keys first
    uk, ul = sk[pick], sl[pick]
    count = jnp.sum(first, dtype=jnp.int32)

    def body(c):
        j, tk, tl, dropped = c
        key = uk[j]
        slot, found = _probe(CellTable(tk, tl), key[None])
        slot, found = slot[0], found[0]
        put = found & (tk[slot] == -1)
        tk = tk.at[slot].set(jnp.where(put, key, tk[slot]))
        tl = tl.at[slot].set(jnp.where(put, ul[j], tl[slot]))
        return j + 1, tk, tl, dropped + (~found).astype(jnp.int32)

    _, tk, tl, dropped = jax.lax.while_loop(lambda c: c[0] < count, body,
                                            (jnp.asarray(0, jnp.int32), table.keys, table.labels,
                                             jnp.asarray(0, jnp.int32)))
    return CellTable(tk, tl), dropped


# --------------------------------------------------------------------------- per-lane tracking
@jax.jit
def track_hits(cell_label, att, hits, misses, max_misses):
    """One period of the per-lane hit counters (all ``(L,)`` arrays, int32).

    ``cell_label``: the label of the box of each lane's new stroboscopic point
    (:func:`lookup`; ``-1`` for a box no attractor has registered); ``att``: the attractor
    the lane's current run of hits is on (``-1``: none); ``hits``: the run's length;
    ``misses``: consecutive visits to unregistered boxes since the last hit. A hit on
    ``att`` lengthens the run; a hit on another attractor starts a run on it (a visit to
    another attractor's box resets); a visit to an unregistered box is tolerated (a finite
    cloud covers a chaotic attractor only partly) up to ``max_misses`` in a row, then the
    run is dropped. A lane belongs to ``att`` once ``hits`` reaches the required number of
    consecutive hits (Datseris & Wagemakers 2022, ``consecutive_attractor_steps``).
    Returns ``(att, hits, misses)``.
    """
    known = cell_label >= 0
    same = known & (cell_label == att)
    att_n = jnp.where(known, cell_label, att)
    hits_n = jnp.where(same, hits + 1, jnp.where(known, 1, hits))
    misses_n = jnp.where(known, 0, misses + 1)
    lost = misses_n > max_misses
    return (jnp.where(lost, -1, att_n).astype(jnp.int32), jnp.where(lost, 0, hits_n).astype(jnp.int32),
            jnp.where(lost, 0, misses_n).astype(jnp.int32))


# --------------------------------------------------------------------------- characterisation
def attractor_cloud(system, params, integrator, y, *, periods: int, lanes: int, spread: float = 1e-7, key=None,
                    stages: int = 1, stop=None):
    """The stroboscopic points of ``lanes`` copies of the state ``y (dim,)`` over ``periods``
    forcing periods: ``(cloud (periods, dim, lanes), periods run)``.

    Copy 0 is ``y``; the others are moved by ``spread (1 + |y|)`` in random directions, so on
    a chaotic attractor they soon sample it independently (more of the attractor per period
    of wall time) while on a periodic one they stay together. The periods run in
    ``stages`` equal stages (``periods`` a multiple of ``stages``), each a ``lax.scan`` of
    the integrator's ``advance`` at phase 0; after each, ``stop(points of the stage (S, dim,
    lanes))`` (optional, a traced bool) may end the cloud early: the rows not run are NaN.
    """
    if periods % stages:
        raise ValueError(f"periods={periods} must be a multiple of stages={stages}.")
    S = periods // stages
    dim = y.shape[0]
    key = jax.random.PRNGKey(0) if key is None else key
    d = jax.random.normal(key, (dim, lanes))
    d = d / jnp.linalg.norm(d, axis=0, keepdims=True)
    d = d.at[:, 0].set(0.0)
    Y0 = y[:, None] + spread * (1.0 + jnp.linalg.norm(y)) * d

    def step(Y, _):
        Y = integrator.advance(system, params, Y, jnp.asarray(0.0), 1)
        return Y, Y

    def body(c):
        j, Y, buf, _ = c
        Y, pts = jax.lax.scan(step, Y, None, length=S)
        buf = jax.lax.dynamic_update_slice_in_dim(buf, pts, j * S, axis=0)
        halt = jnp.asarray(False) if stop is None else stop(pts)
        return j + 1, Y, buf, halt

    buf = jnp.full((periods, dim, lanes), jnp.nan)
    j, _, buf, _ = jax.lax.while_loop(lambda c: (c[0] < stages) & ~c[3], body,
                                      (jnp.asarray(0, jnp.int32), Y0, buf, jnp.asarray(False)))
    return buf, j * S


def _flat(cloud):
    """``(P, dim, K)`` -> ``(dim, P K)``."""
    P, dim, K = cloud.shape
    return jnp.moveaxis(cloud, 1, 0).reshape(dim, P * K)


@jax.jit
def recurrence_share(partition: FinePartition, cloud):
    """Share of the second half's points of ``cloud (P, dim, K)`` whose box the first half
    visited (points outside the partition count as not recurring): near 1 on an attractor
    sampled long enough, small on a transient that is still moving on."""
    P = cloud.shape[0]
    k1 = jnp.sort(cell_keys(partition, _flat(cloud[: P // 2])))
    k2 = cell_keys(partition, _flat(cloud[P // 2:]))
    pos = jnp.clip(jnp.searchsorted(k1, k2), 0, k1.shape[0] - 1)
    return jnp.mean(((k1[pos] == k2) & (k2 >= 0)).astype(jnp.float64))


SHRINK = 0.5
"""A motion approaches a cycle when its largest repetition error over the second half of a
window is at most this share of that over the first half (a stable cycle's multiplier
``rho`` per period gives ``rho ** (window / 2)``: below 0.5 for ``|rho| < 0.99`` over a
150-period stage); a chaotic or quasi-periodic motion's largest error stays."""

ON_CYCLE = 1e-6
"""Repetition errors at most this many box widths are a cycle already (they stopped
shrinking at round-off): far below the point-level recognition's tolerance."""


def _shrinking_repeats(points, width, max_period: int, split: int, ratio: float, newest_first: bool):
    """Per period ``k = 1 .. max_period``, whether ``points (m, dim, ...)`` repeat within one
    box ``width (dim,)`` on every coordinate over their later part, and shrink there:
    ``(max_period, ...)`` bool. The repetition errors ``e_t = max_d |x_(t+k) - x_t|_d /
    width_d`` (``t = 0 .. m - max_period - 1``) split at ``split``; the later part (the
    second, or the first when the points are ``newest_first``) has ``max e <= 1`` and
    ``max e <= ratio`` times the other part's (or ``max e <=`` :data:`ON_CYCLE`: converged).
    NaN points (no history yet) never repeat."""
    n = points.shape[0] - max_period
    w = width.reshape((1, -1) + (1,) * (points.ndim - 2))

    def rep(k):
        later = jax.lax.dynamic_slice_in_dim(points, k, n, axis=0)
        e = jnp.max(jnp.abs(later - points[:n]) / w, axis=1)  # (n, ...)
        first = jnp.max(e[:split], axis=0)
        second = jnp.max(e[split:], axis=0) if split < n else jnp.full_like(first, jnp.inf)
        late, early = (first, second) if newest_first else (second, first)
        return (late <= 1.0) & ((late <= ratio * early) | (late <= ON_CYCLE))

    return jax.vmap(rep)(jnp.arange(1, max_period + 1))


@functools.partial(jax.jit, static_argnames="max_period")
def near_periodic(partition: FinePartition, cloud, max_period: int):
    """Whether copy 0 of ``cloud (P, dim, K)`` (a stage of a candidate's cloud, oldest first)
    approaches a cycle: for some period ``k <= max_period`` its repetition errors
    ``|x_(t+k) - x_t|`` stay within one box width on every coordinate over the second half
    of the stage and have shrunk there to at most :data:`SHRINK` times their largest value
    over the first half (or are at round-off, :data:`ON_CYCLE`). Such a motion is a cycle
    (or an approach to one) that the point-level recognition of periodic attractors will
    take, not an attractor of boxes.

    The shrinking, not the box width alone, decides: an attractor smaller than a few
    boxes (a small chaotic attractor, a small torus) comes back within a box with some
    period too, but its errors do not die out."""
    P = cloud.shape[0]
    M = min(max_period, P - 2)
    if M < 1:
        return jnp.asarray(False)
    return jnp.any(_shrinking_repeats(cloud[:, :, 0], partition.width, M, (P - M) // 2, SHRINK, False))


def near_cycle_lanes(points, width, max_period: int):
    """Per lane, whether its last points ``points (2 max_period, dim, L)`` (newest first; NaN
    before the lane has them) approach a cycle of some period ``k <= max_period``: the
    repetition errors ``|x_t - x_(t-k)|`` of the newest half of its last ``max_period``
    points stay within one box ``width (dim,)`` on every coordinate and are at most the
    largest of the older half. A lane approaching a cycle, which the point-level
    recognition will take, is no candidate for an attractor of boxes (its cloud would be
    integrated for nothing); a lane on an attractor smaller than a few boxes (repeating
    within a box without converging) is one in about every other round. ``(L,)`` bool."""
    near = _shrinking_repeats(points, width, max_period, (max_period + 1) // 2, 1.0, True)  # (M, L)
    return jnp.any(near, axis=0)


CANDIDATE_POOL = 64
"""A round's candidate is the oldest lane not approaching a cycle (:func:`near_cycle_lanes`)
among this many oldest eligible lanes: the test runs on these few lanes, not on every lane
of the pool (a round whose oldest eligible lanes all approach cycles has no candidate;
they are recognised by their points soon)."""


def oldest_off_cycle(eligible, age, ring, width, max_period: int):
    """The round's candidate: ``(lane, found)``, the oldest of the lanes ``eligible (L,)``
    (by ``age (L,)``) whose last ``2 max_period`` points do not approach a cycle, looked for
    among the :data:`CANDIDATE_POOL` oldest eligible ones. ``ring``: a function of lane
    indices ``(K,)`` giving their last points ``(2 max_period, dim, K)`` newest first (so
    only those lanes' points are read)."""
    K = min(CANDIDATE_POOL, age.shape[0])
    oldest, lanes = jax.lax.top_k(jnp.where(eligible, age, -1), K)  # oldest first
    ok = (oldest >= 0) & ~near_cycle_lanes(ring(lanes), width, max_period)
    j = jnp.argmax(ok)
    return lanes[j].astype(jnp.int32), ok[j]


SETTLED = 1e-3
"""A continued state has settled on a cycle when its last ``2 M`` points repeat with some
period ``k <= M`` to this many box widths on every coordinate: far below a chaotic
motion's spread over a box, even on an attractor about a box wide."""


def continue_states(system, params, integrator, Y, *, periods: int, keep: int):
    """The states ``Y (dim, K)`` (at forcing phase 0) continued ``periods`` forcing periods
    on the stroboscopic map: their last ``keep`` points ``(keep, dim, K)``, newest first
    (``keep <= periods``). Only those are stored (one ``lax.scan`` of the integrator's
    ``advance`` without output, then one that keeps them)."""
    if not 1 <= keep <= periods:
        raise ValueError(f"keep={keep} must be between 1 and periods={periods}.")

    def step(Y, _):
        return integrator.advance(system, params, Y, jnp.asarray(0.0), 1), None

    def kept(Y, _):
        Y = integrator.advance(system, params, Y, jnp.asarray(0.0), 1)
        return Y, Y

    Y, _ = jax.lax.scan(step, Y, None, length=periods - keep)
    _, pts = jax.lax.scan(kept, Y, None, length=keep)
    return pts[::-1]


def settled_lanes(points, width, max_period: int):
    """Per lane, whether its last points ``points (2 max_period, dim, K)`` (newest first)
    lie on a cycle of some period ``k <= max_period``: ``|x_t - x_(t-k)|`` at most
    :data:`SETTLED` box widths ``width (dim,)`` on every coordinate over the newest
    ``max_period`` points. ``(K,)`` bool (NaN points never settle)."""
    M = max_period
    w = width.reshape((1, -1) + (1,) * (points.ndim - 2))

    def rep(k):
        e = jnp.abs(jax.lax.dynamic_slice_in_dim(points, k, M, axis=0) - points[:M]) / w  # (M, dim, K)
        return jnp.max(e, axis=(0, 1)) <= SETTLED

    return jnp.any(jax.vmap(rep)(jnp.arange(1, M + 1)), axis=0)


def verification_starts(second, lanes: int):
    """``lanes`` states ``(dim, lanes)`` spread evenly over the points ``second (dim, m)``
    of a cloud's second half (periods and copies interleaved), where a verification
    continues the set."""
    m = second.shape[1]
    idx = (jnp.arange(lanes) * m) // lanes
    return second[:, idx]


def leaving_share(system, params, integrator, partition: FinePartition, starts, *, periods: int, max_period: int,
                  bound, elsewhere=None):
    """Share of the states ``starts (dim, K)``, points of a candidate attractor of boxes,
    that leave it within ``periods`` forcing periods: their continuation
    (:func:`continue_states`) ends on a cycle (:func:`settled_lanes`), escapes (norm
    above ``bound`` or not finite), or (``elsewhere``, optional: a function of the last
    points ``(2 max_period, dim, K)`` giving ``(K,)`` bool) ends on another known attractor.

    An attractor keeps its points: none leave. A chaotic saddle (a long chaotic transient,
    Lai & Tél, *Transient Chaos*, Springer 2011, ch. 1-2) loses them at the escape rate
    ``kappa``: a share ``1 - exp(-kappa periods)`` leaves, so a cloud that recurred for a
    few hundred periods on a saddle of mean lifetime ``1 / kappa`` of the order of
    ``periods`` is told from an attractor."""
    pts = continue_states(system, params, integrator, starts, periods=periods, keep=2 * max_period)
    left = settled_lanes(pts, partition.width, max_period) | ~(jnp.sqrt(_sqn(pts[0])) <= bound)
    if elsewhere is not None:
        left = left | elsewhere(pts)
    return jnp.mean(left.astype(jnp.float64))


@functools.partial(jax.jit, static_argnames="n_labels")
def overlap_shares(table: CellTable, partition: FinePartition, points, n_labels: int):
    """Share of ``points (dim, m)`` lying in boxes of each label ``0 .. n_labels - 1`` of the
    table: ``(n_labels,)``. A new cloud whose share on a known attractor is large is that
    attractor (matching by occupied boxes, not by point distance)."""
    lab = lookup(table, cell_keys(partition, points))
    return jnp.mean((lab[None] == jnp.arange(n_labels, dtype=jnp.int32)[:, None]).astype(jnp.float64), axis=1)


# --------------------------------------------------------------------------- options and result
def _as(dtype):
    """Field converter: a JAX array (or tracer) stays one; anything else becomes a numpy array,
    so that building the default options at import starts no JAX backend (a multi-process run
    calls ``jax.distributed.initialize`` after ``import jaxgear``)."""
    return lambda x: jnp.asarray(x, dtype=dtype) if isinstance(x, jax.Array) else np.asarray(x, dtype=dtype)


def verify_length(options, max_period: int) -> int:
    """Periods the verification of a new attractor of boxes runs: ``verify_periods``, and
    at least ``2 max_period`` (the history :func:`settled_lanes` judges)."""
    return max(int(options.verify_periods), 2 * int(max_period))


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
            of :data:`CLOUD_STAGES`).
        cloud_lanes: copies of a candidate integrated together (static).
        max_points: cloud points kept per attractor (static; >= the largest period).
        capacity: slots of the box table (static, a power of two; ``8 * capacity`` bytes
            of keys, whatever the state dimension).
        max_attractors: attractor slots (static).
        verify_periods: periods a new attractor of boxes is continued from
            ``verify_lanes`` of its cloud's points before it is registered (static; 0: no
            verification): when at least ``leave_share`` of them leave it (settle on a
            cycle, escape or reach another known attractor) the set is a chaotic saddle,
            a long transient, and no attractor (:func:`leaving_share`). At least ``2
            max_period`` periods are run (:func:`verify_length`): the cycle test reads the
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


class RecurrenceResult(eqx.Module):
    """Result of :func:`classify_by_recurrence`.

    Attributes:
        labels: ``(n,)`` int32 attractor index, ``-1`` sink (escaped), ``-2`` unresolved.
        periods_used: ``(n,)`` int32 forcing periods integrated per state (a state decided
            by its own cloud counts its cloud's periods too).
        periods: ``(A,)`` int32 per attractor: ``k`` for a P-k cycle, ``0`` (:data:`APERIODIC`)
            for an attractor found by recurrence of boxes.
        points: ``(A, max_points, dim)`` per attractor its cycle in order (first ``k`` rows)
            or its cloud (NaN padded).
        cells: ``(A,)`` int32 boxes registered per attractor.
        table, partition: the box table and the partition.
        cloud_work: lane-periods spent integrating candidate clouds (all copies).
        dropped_cells: boxes that found no slot in the table (0 unless it overflowed).
        attractor_overflow: a new attractor found no free slot (``max_attractors``).
    """

    labels: Any
    periods_used: Any
    periods: Any
    points: Any
    cells: Any
    table: CellTable
    partition: FinePartition
    cloud_work: Any
    dropped_cells: Any
    attractor_overflow: Any


# --------------------------------------------------------------------------- standalone classifier
class _State(NamedTuple):
    Y: Any  # (dim, L)
    ring: Any  # (2M, dim, L) last 2M points, newest first
    streak: Any  # (M, L)
    age: Any  # (L,)
    cell: Any  # (L,) state held, -1 idle
    att: Any  # (L,)
    hits: Any  # (L,)
    misses: Any  # (L,)
    tried: Any  # (L,) age at the lane's last candidacy (-transient: never)
    labels: Any  # (n,)
    used: Any  # (n,)
    next_cell: Any
    n_done: Any
    table: CellTable
    kind: Any  # (A,) period, 0 aperiodic, -1 empty
    points: Any  # (A, Q, dim)
    n_att: Any
    dropped: Any
    overflow: Any
    cloud_work: Any
    rounds: Any


def _sqn(a):
    return sum(a[i] ** 2 for i in range(a.shape[0]))


class _Run(NamedTuple):
    """What every round of one classification reads: the flow, the options, the fine
    partition and the traced tolerances."""

    system: Any
    params: Any
    integrator: Any
    opt: RecurrenceOptions
    part: FinePartition
    tol: Any
    merge_tol: Any
    bound: Any
    max_periods: Any


def _period(run: _Run, s: _State) -> _State:
    """One forcing period of every lane: the point, the periodic streaks and the hit runs."""
    M = s.streak.shape[0]
    busy = s.cell >= 0
    Y = run.integrator.advance(run.system, run.params, s.Y, jnp.asarray(0.0), 1)
    age = jnp.where(busy, s.age + 1, s.age)
    thr = (run.tol * (1.0 + jnp.sqrt(_sqn(Y)))) ** 2
    ks = jnp.arange(1, M + 1, dtype=jnp.int32)
    d = jax.vmap(lambda r: _sqn(Y - r))(s.ring[:M])  # (M, L)
    ok = (d <= thr[None]) & (age[None] > ks[:, None])
    streak = jnp.where(ok, s.streak + 1, 0)
    ring = jnp.concatenate([Y[None], s.ring[:-1]], axis=0)
    lab = lookup(s.table, cell_keys(run.part, Y))
    att, hits, misses = track_hits(lab, s.att, s.hits, s.misses, run.opt.max_misses)
    return s._replace(Y=Y, ring=ring, streak=streak, age=age, att=att, hits=hits, misses=misses)


def _register(s: _State, pts, kind):
    """A new attractor slot with ``pts (Q, dim)`` (NaN padded) and period ``kind``; with no
    free slot, the overflow flag. Returns ``(state, label)`` (label ``-1``: no slot); the
    caller enters its boxes in the table."""
    A = s.kind.shape[0]
    room = s.n_att < A
    a = jnp.minimum(s.n_att, A - 1)
    s = s._replace(kind=jnp.where(room, s.kind.at[a].set(kind), s.kind),
                   points=jnp.where(room, s.points.at[a].set(pts), s.points),
                   n_att=s.n_att + room.astype(jnp.int32), overflow=s.overflow | ~room)
    return s, jnp.where(room, a, -1).astype(jnp.int32)


def _on_known_cycles(run: _Run, s: _State, per, rec):
    """The label of each recurring lane whose period and newest point are a known cycle's
    (point level), ``-1`` for the others."""
    M = s.streak.shape[0]
    cyc = s.points[:, :M]  # (A, M, dim)
    dist = jax.vmap(lambda P: jax.vmap(lambda p: _sqn(s.Y - p[:, None]))(P))(cyc)  # (A, M, L)
    valid = jnp.arange(M, dtype=jnp.int32)[None, :] < s.kind[:, None]  # (A, M)
    dmin = jnp.min(jnp.where(valid[..., None], dist, jnp.inf), axis=1)  # (A, L)
    scale = 1.0 + jnp.nanmax(jnp.where(valid[..., None], jnp.abs(cyc), 0.0), axis=(1, 2))  # (A,)
    on = (s.kind[:, None] == per[None]) & (dmin <= (run.merge_tol * scale[:, None]) ** 2)
    return jnp.where(rec & jnp.any(on, axis=0), jnp.argmax(on, axis=0), -1).astype(jnp.int32)


def _new_cycle(run: _Run, s: _State, label, new, per):
    """The first recurring lane on no known cycle (``new``) registers its cycle; the lanes
    of ``new`` on that cycle take its label. Returns ``(state, label, the cycle's box keys
    (M,), its slot)`` (keys -1 and slot -1 when ``new`` is empty or the table is full)."""
    M = s.streak.shape[0]
    Q = s.points.shape[1]

    def register(c):
        s, label = c
        l0 = jnp.argmax(new)
        k0 = per[l0]
        i = jnp.arange(Q, dtype=jnp.int32)
        back = s.ring[:M, :, l0]  # (M, dim) newest first
        pts = jnp.where((i < k0)[:, None], back[jnp.clip(k0 - 1 - i, 0, M - 1)], jnp.nan)
        s, a = _register(s, pts, k0)
        ckeys = jnp.where((jnp.arange(M, dtype=jnp.int32) < k0) & (a >= 0), cell_keys(run.part, back.T), -1)
        d0 = jax.vmap(lambda p: _sqn(s.Y - p[:, None]))(pts[:M])  # (M, L)
        sc = 1.0 + jnp.max(jnp.where((i[:M] < k0)[:, None], jnp.abs(pts[:M]), 0.0))
        joins = new & (per == k0) & (jnp.nanmin(jnp.where((i[:M] < k0)[:, None], d0, jnp.inf), axis=0)
                                     <= (run.merge_tol * sc) ** 2)
        return s, jnp.where(joins & (a >= 0), a, label).astype(jnp.int32), ckeys, a

    def none(c):
        return (*c, jnp.full(M, -1, jnp.int64), jnp.asarray(-1, jnp.int32))

    return jax.lax.cond(jnp.any(new), register, none, (s, label))


def _characterise(run: _Run, s: _State, label, l0):
    """The cloud of lane ``l0`` (:func:`attractor_cloud`): when it recurs, is no cycle and
    (with ``opt.verify_periods``) is no chaotic saddle, it joins the attractor of boxes it
    overlaps or registers a new one, and the lane takes that label. Returns ``(state,
    label, the cloud's box keys, its slot)`` (keys and slot -1 when it is rejected)."""
    opt, part, bound = run.opt, run.part, run.bound
    M = s.streak.shape[0]
    A, Q, dim = s.points.shape
    P = opt.cloud_periods

    def stop(pts):  # a cycle (left to the point-level recognition) or an escape ends the cloud
        return near_periodic(part, pts, M) | ~jnp.all(jnp.sqrt(_sqn(_flat(pts))) <= bound)

    cloud, ran = attractor_cloud(run.system, run.params, run.integrator, s.Y[:, l0], periods=P,
                                 lanes=opt.cloud_lanes, key=jax.random.fold_in(jax.random.PRNGKey(0), s.rounds),
                                 stages=CLOUD_STAGES, stop=stop)
    share = recurrence_share(part, cloud)
    ok = (ran == P) & ~stop(cloud[P - P // CLOUD_STAGES:]) & (share >= opt.accept_share)
    second = _flat(cloud[P // 2:])
    over = overlap_shares(s.table, part, second, A)
    over = jnp.where(s.kind > 0, 0.0, over)  # only attractors of boxes absorb clouds
    best = jnp.argmax(over)
    joins = over[best] >= opt.overlap_share
    if opt.verify_periods:  # a new set is continued first: a chaotic saddle is no attractor
        def leaves(_):
            return leaving_share(run.system, run.params, run.integrator, part,
                                 verification_starts(second, opt.verify_lanes), periods=verify_length(opt, M),
                                 max_period=M, bound=bound,
                                 elsewhere=lambda pts: jnp.all(lookup(s.table, cell_keys(part, _flat(pts))).reshape(
                                     pts.shape[0], -1) >= 0, axis=0))
        share = jax.lax.cond(ok & ~joins, leaves, lambda _: jnp.asarray(0.0), None)
        ok = ok & (joins | (share < opt.leave_share))
    keys = cell_keys(part, _flat(cloud))
    step = max(second.shape[1] // Q, 1)
    pts = jnp.full((Q, dim), jnp.nan).at[: min(Q, second.shape[1])].set(second[:, ::step][:, :Q].T)

    def accept(s):
        return jax.lax.cond(joins, lambda s: (s, best.astype(jnp.int32)),
                            lambda s: _register(s, pts, jnp.asarray(APERIODIC, jnp.int32)), s)

    s, a = jax.lax.cond(ok, accept, lambda s: (s, jnp.asarray(-1, jnp.int32)), s)
    s = s._replace(tried=s.tried.at[l0].set(s.age[l0]),
                   cloud_work=s.cloud_work + (ran * opt.cloud_lanes).astype(jnp.int64),
                   age=s.age.at[l0].add(jnp.where(a >= 0, P, 0)))
    return s, label.at[l0].set(jnp.where(a >= 0, a, label[l0])), jnp.where(a >= 0, keys, -1), a


def _refill(run: _Run, X, s: _State, decided, value) -> _State:
    """Write the ``decided`` lanes' labels ``value`` and periods, and refill every free
    lane from the queue ``X`` (a fresh ring, streaks and hit runs)."""
    n = X.shape[0]
    busy = s.cell >= 0
    target = jnp.where(decided, s.cell, n)
    labels = s.labels.at[target].set(value, mode="drop")
    used = s.used.at[target].set(s.age, mode="drop")
    free = ~busy | decided
    rank = jnp.cumsum(free, dtype=jnp.int32) - 1
    nc = s.next_cell + rank
    take = free & (nc < n)
    cell = jnp.where(take, nc, jnp.where(free, -1, s.cell)).astype(jnp.int32)
    Xn = X[jnp.clip(nc, 0, n - 1)].T
    Y = jnp.where(take[None], Xn, jnp.where(free[None], 0.0, s.Y))

    def reset(a, v):
        return jnp.where(free, v, a).astype(a.dtype)

    return s._replace(
        Y=Y, ring=jnp.where(free[None, None], jnp.nan, s.ring), streak=jnp.where(free[None], 0, s.streak),
        age=reset(s.age, 0), cell=cell, att=reset(s.att, -1), hits=reset(s.hits, 0), misses=reset(s.misses, 0),
        tried=reset(s.tried, -run.opt.transient), labels=labels, used=used,
        next_cell=jnp.minimum(s.next_cell + jnp.sum(take, dtype=jnp.int32), n).astype(jnp.int32),
        n_done=s.n_done + jnp.sum(decided, dtype=jnp.int32), rounds=s.rounds + 1)


def _decide(run: _Run, X, s: _State) -> _State:
    """After a round: decide the lanes that escaped, recur onto a cycle (known or new),
    completed a run of hits on an attractor's boxes, or whose cloud is an attractor (one
    candidate per round); the undecided past ``max_periods`` are unresolved; then refill."""
    M, opt = s.streak.shape[0], run.opt
    busy = s.cell >= 0
    esc = busy & ~(jnp.sqrt(_sqn(s.Y)) <= run.bound)
    live = busy & ~esc
    ks = jnp.arange(1, M + 1, dtype=jnp.int32)
    per = jnp.min(jnp.where(s.streak >= (ks + 1)[:, None], ks[:, None], M + 1), axis=0).astype(jnp.int32)
    rec = live & (per <= M)
    label = _on_known_cycles(run, s, per, rec)
    s, label, ckeys, clabel = _new_cycle(run, s, label, rec & (label < 0), per)
    # consecutive hits on a known attractor's boxes
    label = jnp.where(live & (label < 0) & (s.att >= 0) & (s.hits >= opt.hits), s.att, label).astype(jnp.int32)
    # one candidate per round: the oldest undecided lane past the transient, not in a run of hits
    eligible = live & (label < 0) & (per > M) & (s.age >= opt.transient) & (s.age - s.tried >= opt.transient) \
        & (s.hits == 0)
    l0, found = oldest_off_cycle(eligible, s.age, lambda i: s.ring[:, :, i], run.part.width, M)
    KP = opt.cloud_periods * opt.cloud_lanes
    s, label, vkeys, vlabel = jax.lax.cond(
        found, lambda c: _characterise(run, *c, l0),
        lambda c: (*c, jnp.full(KP, -1, jnp.int64), jnp.asarray(-1, jnp.int32)), (s, label))
    # the boxes of this round's new cycle and cloud enter the table (one insertion per round)
    keys = jnp.concatenate([ckeys, vkeys])
    klab = jnp.concatenate([jnp.full(M, clabel), jnp.full(KP, vlabel)])

    def enter(s):
        table, dropped = insert(s.table, keys, klab)
        return s._replace(table=table, dropped=s.dropped + dropped)

    s = jax.lax.cond(jnp.any(keys >= 0), enter, lambda s: s, s)
    unres = live & (label < 0) & (s.age >= run.max_periods)
    decided = esc | (label >= 0) | unres
    value = jnp.where(esc, _SINK, jnp.where(unres, _UNRESOLVED, label)).astype(jnp.int32)
    return _refill(run, X, s, decided, value)


@eqx.filter_jit
def _classify_kernel(run: _Run, X, L: int, M: int, R: int):
    """The classification of ``X (n, dim)`` by ``L`` lanes (one ``lax.while_loop`` of rounds
    of ``R`` periods; ``M`` the largest period recognised)."""
    opt = run.opt
    n, dim = X.shape
    A, Q = opt.max_attractors, opt.max_points
    take = min(L, n)
    lanes = jnp.arange(L, dtype=jnp.int32)
    s = _State(
        Y=jnp.zeros((dim, L)).at[:, :take].set(X[:take].T), ring=jnp.full((2 * M, dim, L), jnp.nan),
        streak=jnp.zeros((M, L), jnp.int32), age=jnp.zeros(L, jnp.int32),
        cell=jnp.where(lanes < take, lanes, -1).astype(jnp.int32), att=jnp.full(L, -1, jnp.int32),
        hits=jnp.zeros(L, jnp.int32), misses=jnp.zeros(L, jnp.int32),
        tried=jnp.full(L, -1, jnp.int32) * opt.transient, labels=jnp.full(n, -3, jnp.int32),
        used=jnp.zeros(n, jnp.int32), next_cell=jnp.asarray(take, jnp.int32), n_done=jnp.asarray(0, jnp.int32),
        table=empty_table(opt.capacity), kind=jnp.full(A, -1, jnp.int32), points=jnp.full((A, Q, dim), jnp.nan),
        n_att=jnp.asarray(0, jnp.int32), dropped=jnp.asarray(0, jnp.int32), overflow=jnp.asarray(False),
        cloud_work=jnp.asarray(0, jnp.int64), rounds=jnp.asarray(0, jnp.int32))

    def body(s):
        s = jax.lax.fori_loop(0, R, lambda _, s: _period(run, s), s)
        return _decide(run, X, s)

    return jax.lax.while_loop(lambda s: s.n_done < n, body, s)


def classify_by_recurrence(system, params, X, *, options: RecurrenceOptions | None = None,
                           pool: PoolOptions | None = None, integrator=None,
                           partition: FinePartition | None = None, **changes) -> RecurrenceResult:
    """Label the states ``X (n, dim)`` (at forcing phase 0) by the attractor of their
    stroboscopic-map trajectories, attractors of every type included.

    ``pool.lanes`` lanes integrate the states, refilled from a queue, inside one
    ``lax.while_loop`` of rounds of ``pool.round_periods`` periods (one ``jit``). Every
    period each lane's point updates its periodic streaks (P-k when ``|x_t - x_(t-k)| <=
    period_tol (1 + |x_t|)`` holds ``k + 1`` periods in a row, ``k <= max_period``, as the
    direct method) and its run of hits on known attractors' boxes (:func:`track_hits`).
    After each round a lane is decided when it escaped (norm above ``pool.escape_bound``
    or not finite: ``-1``), recurs onto a known cycle or registers a new one (one per round, its
    boxes entered in the table), completed ``options.hits`` consecutive hits on an
    attractor's boxes, or was the round's candidate (undecided for ``options.transient``
    periods) whose cloud (:func:`attractor_cloud`) recurs (:func:`recurrence_share`) and is
    no cycle (:func:`near_periodic`): the cloud then joins the known attractor of boxes it
    overlaps (:func:`overlap_shares`) or registers a new aperiodic one (Datseris &
    Wagemakers 2022). After ``pool.max_periods`` periods a lane is unresolved (``-2``).

    ``pool``: the :class:`~jaxgear.analysis.PoolOptions` the direct method's lane pool
    reads too (default ``PoolOptions(lanes=1024)``; ``capture_radius`` and ``pilot`` are
    the pool's own and not read here). Keyword arguments (``**changes``) replace fields of
    ``options`` or ``pool`` by name (``max_periods=3000``); an unknown name raises
    ``ValueError``.

    ``partition``: default :func:`partition_of_states` of ``X`` with
    ``options.resolution`` boxes per axis. ``integrator``: default
    :func:`~jaxgear.integrate.default_integrator`. Returns a :class:`RecurrenceResult`
    (attractor arrays cut to the attractors found).
    """
    rec_changes, pool_changes = split_changes(changes, RecurrenceOptions, PoolOptions)
    options = with_changes(options, RecurrenceOptions, rec_changes)
    pool = with_changes(PoolOptions(lanes=1024) if pool is None else pool, PoolOptions, pool_changes)
    integrator = resolve_integrator(integrator)
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != system.dim or X.shape[0] < 1 or not np.all(np.isfinite(X)):
        raise ValueError(f"X must be a finite (n, {system.dim}) array of states, got shape {X.shape}.")
    M = pool.max_period
    if options.max_points < M:
        raise ValueError(f"options.max_points={options.max_points} must be >= max_period={M}.")
    if options.cloud_periods // CLOUD_STAGES < 2 * M + 1:
        raise ValueError(f"options.cloud_periods={options.cloud_periods} must be at least {CLOUD_STAGES * (2 * M + 1)} "
                         f"({CLOUD_STAGES} stages of 2 max_period + 1 periods) for max_period={M}.")
    if partition is None:
        partition = partition_of_states(X, float(options.resolution))
    elif not isinstance(partition, FinePartition) or partition.lo.shape != (system.dim,):
        raise ValueError(f"partition must be a FinePartition of dimension {system.dim} or None.")
    run = _Run(system, params, integrator, options, partition, jnp.asarray(pool.period_tol),
               jnp.asarray(pool.merge_tol), jnp.asarray(pool.escape_bound), jnp.asarray(pool.max_periods, jnp.int32))
    s = _classify_kernel(run, jnp.asarray(X), min(pool.lanes, X.shape[0]), M, pool.round_periods)
    A = int(s.n_att)
    labels = s.labels
    cells = jnp.sum(s.table.labels[None] == jnp.arange(A, dtype=jnp.int32)[:, None], axis=1, dtype=jnp.int32)
    return RecurrenceResult(labels=labels, periods_used=s.used, periods=s.kind[:A], points=s.points[:A],
                            cells=cells, table=s.table, partition=partition, cloud_work=s.cloud_work,
                            dropped_cells=s.dropped, attractor_overflow=s.overflow)
