"""The fine partition of the state space and the device table of its boxes.

The detection of attractors by recurrences (Datseris & Wagemakers, "Effortless
estimation of basins of attraction", Chaos 32, 023104, 2022; the method and its use by
the lane pool: :mod:`jaxgear.analysis._recurrence`) follows trajectories box by box on a
partition of the stroboscopic map's state space into equal boxes. This module holds the
boxes themselves, pure functions the pool calls per period:

- :class:`FinePartition`, :func:`partition_from_box`, :func:`partition_of_states` — the
  partition (built once per analysis from the region, so boxes mean the same for every
  lane; the non-gridded coordinates, e.g. ``x4``, get the mean box width of the gridded
  ones);
- :func:`cell_keys`, :func:`row_keys` — each state's box as one ``int64`` key (packed
  integer coordinates up to four dimensions, a 64-bit hash of them beyond, so memory does
  not grow with the state dimension), ``-1`` outside the partition; made distinct per
  parameter row when the values of a sweep share one pool and one table;
- :class:`CellTable`, :func:`empty_table`, :func:`lookup`, :func:`insert` — a fixed-size
  open-addressing hash table on the device from box keys to attractor slots (bounded
  memory; an overflow is counted, never silent);
- :func:`track_hits` — per lane, the run of consecutive hits on one attractor's boxes.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_int

__all__ = ["FinePartition", "partition_from_box", "partition_of_states", "cell_keys", "row_keys", "CellTable",
           "empty_table", "lookup", "insert", "track_hits", "INDEX_BITS", "MAX_PROBES"]

INDEX_BITS = 15
"""Bits of each integer box coordinate: ``2**15`` boxes per axis, the given box in the
middle of that range (so states far outside it still have a box)."""

_PACKED_DIMS = 63 // INDEX_BITS
"""Up to this state dimension keys are the exact packed coordinates; beyond, a hash."""

MAX_PROBES = 32
"""Slots a lookup or an insertion probes at most (linear probing); an insertion that finds
no free slot among them is dropped and counted."""


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
