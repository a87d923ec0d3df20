"""The direct method's lane pool, kept on the device.

``L`` lanes integrate cell centres on the stroboscopic map, one forcing period at a time
(the integrator's ``advance``; on CPUs the compiled kernel). Everything the method
decides happens on the device inside one ``lax.while_loop`` over rounds of
``round_periods`` periods, with no host round trip of per-lane data:

- every period the new stroboscopic point goes into a ring of the last ``H = 2M + 1``
  points (``M = max_period``; one slot for all lanes, they share the clock) and, for
  each ``k <= M``, a per-lane streak counts the consecutive periods with
  ``|x_t - x_(t-k)| <= tol (1 + |x_t|)``: a lane is P-k when the streak of ``k`` reaches
  ``k + 1`` (a whole cycle and one more step repeat), the smallest such ``k`` wins;
- after each round a lane is decided when it escaped (norm above ``escape_bound`` or not
  finite: the sink), when its last ``k`` points follow the cycle of a known P-k attractor
  within the capture radius and did not move away from it over the ``k`` before
  (capture), when it recurs (a known attractor if its newest point lies on one, else a
  new attractor is registered, one per round), or when it reached ``max_periods``
  (unresolved);
- decided lanes write their cell's label and take the next cells of the queue; once the
  queue is empty, the busy lanes beyond the first ``c`` (the busy count) move into the
  free lanes below it after a round that left the active range 1/8 free, so only
  ``n_active = c`` lanes are integrated (a compaction moves only the lanes out of place),
  and the host moves them to a pool 8 times smaller whenever they fit (down to 1,024
  lanes), so the bookkeeping of the last rounds covers few idle lanes.

The host only reads a few scalars per call (progress, a full attractor table, a pool
to shrink).

Several parameter sets (the values of a sweep) run in one pool (:func:`run_pools`): each
cell carries its value's row, a lane integrates with its row's parameters
(``integrator.advance_rows``; the compiled kernel reads per-lane rows) and decides
against its row's own attractor table (one table, capture radius and new attractor per
row and round), so every value is labelled as it would be alone, while the pool stays
full from one value to the next. The queue runs value after value, so the busy lanes hold
a short range of rows at a time: a round's decisions loop over the (row, slot) pairs of
that range only, each with the slot's cycle, period and radius as scalars broadcast over
the lanes (masked to the row's lanes), as a one-value pool does for its one row.
"""

from __future__ import annotations

import functools
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._ahead import compile_ahead, wait_for
from .._batching import progress_bar
from .._devices import placement
from .._kept import kept_jit

__all__ = ["PoolState", "run_pool", "run_pools", "prepare_pools", "NOT_DONE"]

NOT_DONE = -3
"""Label of a cell not decided yet (never returned)."""
_SINK, _UNRESOLVED = -1, -2
_ON_REPELLER = -4
"""A round's mark of a lane that shadows a repeller (never a label): it is neither
decided nor registers a new attractor, and integrates on."""


class PoolState(NamedTuple):
    """The pool's state (device arrays); ``L`` lanes, ``n`` cells, ``A`` attractor slots."""

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
    att_pts: jax.Array  # (V, A, M, dim) attractor points in cycle order (NaN padded), per parameter row
    att_k: jax.Array  # (V, A) int32 periods (0: empty slot; -k: a repeller, an unstable P-k cycle)
    n_att: jax.Array  # (V,) int32
    radius: jax.Array  # (V,) capture radius
    n_active: jax.Array  # () int32 lanes [0, n_active) may be busy
    overflow: jax.Array  # () bool: a new attractor found no free slot
    rounds: jax.Array  # () int32 rounds run


class _Options(NamedTuple):
    M: int
    R: int
    tol: float
    merge_tol: float
    max_periods: int
    bound: float
    capture: float | None  # None: "auto"


@kept_jit(static_argnames=("n", "L", "dim", "M"))
def _init(n: int, L: int, dim: int, M: int, X, Xrow, att_pts, att_k, n_att) -> PoolState:
    H = 2 * M + 1
    take = min(L, n)
    cell = jnp.where(jnp.arange(L, dtype=jnp.int32) < take, jnp.arange(L, dtype=jnp.int32), -1).astype(jnp.int32)
    Y = jnp.zeros((dim, L)).at[:, :take].set(X[:take].T)
    row = jnp.zeros(L, jnp.int32).at[:take].set(Xrow[:take])
    return PoolState(
        Y=Y, hist=jnp.full((2 * H, dim, L), jnp.nan, dtype=jnp.float64), streak=jnp.zeros((M, L), jnp.int32), cell=cell,
        row=row, age=jnp.zeros(L, jnp.int32), labels=jnp.full(n, NOT_DONE, jnp.int32), used=jnp.zeros(n, jnp.int32),
        next_cell=jnp.asarray(take, jnp.int32), n_done=jnp.asarray(0, jnp.int32), clock=jnp.asarray(0, jnp.int32),
        att_pts=att_pts, att_k=att_k, n_att=jnp.asarray(n_att, jnp.int32),
        radius=jnp.zeros(att_k.shape[0], jnp.float64),
        n_active=jnp.asarray(take, jnp.int32), overflow=jnp.asarray(False), rounds=jnp.asarray(0, jnp.int32))


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


def _one_period(system, params, integrator, o: _Options, s: PoolState) -> PoolState:
    H = s.hist.shape[0] // 2
    if s.att_k.shape[0] == 1:  # one parameter set
        Y = integrator.advance(system, params, s.Y, jnp.asarray(0.0), 1, n_active=s.n_active)
    else:  # params holds one row per value; each lane uses its cell's
        Y = integrator.advance_rows(system, params, s.row, s.Y, jnp.asarray(0.0), 1, n_active=s.n_active)
    g = s.clock + 1
    c = g % H
    hist = jax.lax.dynamic_update_slice_in_dim(s.hist, Y[None], c, axis=0)
    hist = jax.lax.dynamic_update_slice_in_dim(hist, Y[None], c + H, axis=0)
    busy = s.cell >= 0
    age = jnp.where(busy, s.age + 1, s.age)
    thr = (o.tol * (1.0 + jnp.sqrt(_sqdist(Y, 0.0)))) ** 2
    ks = jnp.arange(1, o.M + 1, dtype=jnp.int32)
    prev = _back(hist, g, 1, o.M)  # (M, dim, L): x_(t-1), ..., x_(t-M)
    ok = (_sqdist(Y[None], prev) <= thr[None]) & (age[None] > ks[:, None])  # x_(t-k) is this cell's
    streak = jnp.where(ok, s.streak + 1, 0)
    return s._replace(Y=Y, hist=hist, streak=streak, age=age, clock=g)


def _capture_radius(att_pts, att_k, capture):
    if capture is not None:
        return jnp.asarray(capture, jnp.float64)
    A, M, _ = att_pts.shape
    valid = (jnp.arange(M, dtype=jnp.int32)[None] < att_k[:, None])  # (A, M)
    pts = jnp.where(valid[..., None], att_pts, 0.0)
    scale = 1.0 + jnp.max(jnp.where(valid[..., None], jnp.abs(pts), 0.0))
    d = jnp.sqrt(jnp.sum((pts[:, None, :, None] - pts[None, :, None, :]) ** 2, axis=-1))  # (A, A, M, M)
    pair = valid[:, None, :, None] & valid[None, :, None, :] & ~jnp.eye(A, dtype=bool)[:, :, None, None]
    gap = jnp.min(jnp.where(pair, d, jnp.inf))
    return jnp.minimum(0.01 * scale, 0.25 * gap)


def _decide(o: _Options, s: PoolState, X, Xrow, n: int) -> PoolState:
    H2, dim, L = s.hist.shape
    H = H2 // 2
    M = o.M
    V, A = s.att_k.shape
    g = s.clock
    Y = s.Y
    busy = s.cell >= 0
    norms = jnp.sqrt(_sqdist(Y, 0.0))
    esc = busy & (~jnp.isfinite(norms) | (norms > o.bound))
    ks = jnp.arange(1, M + 1, dtype=jnp.int32)
    per = jnp.min(jnp.where(s.streak >= (ks + 1)[:, None], ks[:, None], M + 1), axis=0).astype(jnp.int32)  # (L,)
    rec = busy & ~esc & (per <= M)
    live = busy & ~esc
    label = jnp.full(L, -1, jnp.int32)
    i = jnp.arange(M, dtype=jnp.int32)

    def against(v, a, label):
        """Lanes captured by (or recurring onto) the attractor in slot ``a`` of row ``v``'s
        table, a P-k cycle ``P (M, dim)``: every quantity of the attractor is a scalar or
        broadcast over the lanes (no per-lane gather of tables or of the ring). A
        repeller's slot (period ``-k``) marks its lanes ``_ON_REPELLER`` instead: they
        integrate on (an attractor's slot still takes them)."""
        P = s.att_pts[v, a]  # (M, dim)
        repeller = s.att_k[v, a] < 0
        k = jnp.abs(s.att_k[v, a])
        valid = i < k  # (M,)
        dn = jnp.sqrt(_sqdist(Y[None], P[:, :, None]))  # (M, L)
        dn = jnp.where(valid[:, None], dn, jnp.inf)
        m = jnp.argmin(dn, axis=0).astype(jnp.int32)  # the newest point is near P[m] ...
        dmin = jnp.min(dn, axis=0)
        kk = jnp.maximum(k, 1)

        def point(j, dists):
            """The distances of the point ``j`` periods back (and of the one ``k`` before
            it) to the cycle point it should be near, ``P[m - j]``: one slice of the ring
            per step, so no ``(M, dim, L)`` copy of the ring or of the cycle is made."""
            d_now, d_bef = dists
            q = jnp.take(P, jnp.mod(m - j, kk), axis=0).T  # (dim, L)
            w_now = jax.lax.dynamic_index_in_dim(s.hist, g % H + H - j, axis=0, keepdims=False)
            w_bef = jax.lax.dynamic_index_in_dim(s.hist, g % H + H - j - k, axis=0, keepdims=False)
            return jnp.maximum(d_now, _sqdist(w_now, q)), jnp.maximum(d_bef, _sqdist(w_bef, q))

        zero = jnp.zeros(L)
        d_now, d_bef = jax.lax.fori_loop(0, k, point, (zero, zero))
        d_now = jnp.where(s.age >= k, jnp.sqrt(d_now), jnp.inf)
        d_bef = jnp.where(s.age >= 2 * k, jnp.sqrt(d_bef), jnp.inf)
        cap = live & (k > 0) & (d_now <= s.radius[v]) & ((d_now <= d_bef) | ~jnp.isfinite(d_bef))
        scale = 1.0 + jnp.max(jnp.where(valid[:, None], jnp.abs(P), 0.0))
        same = rec & (k > 0) & (per == k) & (dmin <= o.merge_tol * scale)
        hit = cap | same
        if V > 1:
            hit = hit & (s.row == v)  # the lanes of row v; a lane's label is a slot of its row's table
        return jnp.where((label < 0) & hit, jnp.where(repeller, _ON_REPELLER, a), label).astype(jnp.int32)

    def against_row(v, label):
        return jax.lax.fori_loop(0, s.n_att[v], lambda a, label: against(v, a, label), label)

    if V == 1:
        label = against_row(0, label)
    else:  # the queue runs value after value: the busy lanes hold a short range of rows
        lo = jnp.min(jnp.where(busy, s.row, V))
        hi = jnp.max(jnp.where(busy, s.row, -1))
        label = jax.lax.fori_loop(lo, hi + 1, against_row, label)

    # a recurring lane on no known attractor or repeller of its row registers a new one (one per row and round)
    new = rec & (label == -1)
    # the capture radius follows its row's table: computed for every row in the pool's first
    # round (it starts at 0), then only for a row whose table grew
    radius = jax.lax.cond(s.rounds == 0, lambda: jax.vmap(lambda p, k: _capture_radius(p, k, o.capture))(
        s.att_pts, s.att_k), lambda: s.radius)

    def register(v, c):
        att_pts, att_k, n_att, radius, label, overflow = c
        new_v = new if V == 1 else new & (s.row == v)
        has_new = jnp.any(new_v)
        room = n_att[v] < A
        l0 = jnp.argmax(new_v)
        k0 = per[l0]
        last = _back(s.hist[:, :, l0], g, 0, M)  # (M, dim), newest first
        valid0 = i < k0
        pts0 = jnp.where(valid0[:, None], last[jnp.clip(k0 - 1 - i, 0, M - 1)], jnp.nan)  # oldest of the last k0 first

        def add(c):
            att_pts, att_k, n_att, radius, label = c
            slot = n_att[v]
            att_pts, att_k = att_pts.at[v, slot].set(pts0), att_k.at[v, slot].set(k0)
            # the other recurring lanes of the row whose newest point lies on the new attractor join it
            scale0 = 1.0 + jnp.max(jnp.where(valid0[:, None], jnp.abs(pts0), 0.0))
            d0 = jnp.where(valid0[:, None], _sqdist(Y[None], pts0[:, :, None]), jnp.inf)  # (M, L)
            joins = new_v & (per == k0) & (jnp.min(d0, axis=0) <= (o.merge_tol * scale0) ** 2)
            radius = radius.at[v].set(_capture_radius(att_pts[v], att_k[v], o.capture))
            return att_pts, att_k, n_att.at[v].add(1), radius, jnp.where(joins, slot, label).astype(jnp.int32)

        c = jax.lax.cond(has_new & room, add, lambda c: c, (att_pts, att_k, n_att, radius, label))
        return (*c, overflow | (has_new & ~room))

    c = (s.att_pts, s.att_k, s.n_att, radius, label, s.overflow)
    if V == 1:
        c = register(0, c)
    else:  # the rows of the busy lanes
        c = jax.lax.fori_loop(lo, hi + 1, register, c)
    att_pts, att_k, n_att, radius, label, overflow = c

    unres = live & (label < 0) & (s.age >= o.max_periods)
    decided = esc | (label >= 0) | unres
    value = jnp.where(esc, _SINK, jnp.where(unres, _UNRESOLVED, label)).astype(jnp.int32)
    target = jnp.where(decided, s.cell, s.labels.shape[0])  # dropped
    labels = s.labels.at[target].set(value, mode="drop")
    used = s.used.at[target].set(s.age, mode="drop")

    # freed lanes take the next cells of the queue (only lanes below n_active while it drains)
    n_done = s.n_done + jnp.sum(decided, dtype=jnp.int32)
    free = (~busy | decided) & (jnp.arange(L, dtype=jnp.int32) < jnp.where(s.next_cell < n, L, s.n_active))
    rank = jnp.cumsum(free, dtype=jnp.int32) - 1
    nc = s.next_cell + rank
    take = free & (nc < n)
    cell = jnp.where(take, nc, jnp.where(free, -1, s.cell)).astype(jnp.int32)
    row = jnp.where(take, Xrow[jnp.clip(nc, 0, n - 1)], s.row).astype(jnp.int32)
    Ynew = jnp.where(take[None], X[jnp.clip(nc, 0, n - 1)].T, jnp.where(free[None], 0.0, Y))
    age = jnp.where(free, 0, s.age)
    streak = jnp.where(free[None], 0, s.streak)
    next_cell = jnp.minimum(s.next_cell + jnp.sum(take, dtype=jnp.int32), n).astype(jnp.int32)
    highest = jnp.max(jnp.where(cell >= 0, jnp.arange(L, dtype=jnp.int32), -1)) + 1  # busy lanes lie below it
    n_active = jnp.where(s.next_cell < n, jnp.maximum(s.n_active, highest), s.n_active).astype(jnp.int32)
    s = s._replace(Y=Ynew, cell=cell, row=row, age=age, streak=streak, labels=labels, used=used,
                   next_cell=next_cell, n_done=n_done, att_pts=att_pts, att_k=att_k, n_att=n_att, radius=radius,
                   overflow=overflow, rounds=s.rounds + 1, n_active=n_active)
    return s


COMPACT_BELOW = 7 / 8
"""A round ends with a compaction once the busy lanes fill at most this share of the
active range (a compaction costs about a tenth of a period of the lanes' integration:
more often loses more to its cost than it saves)."""

MOVE_CHUNK = 1024
"""Lanes moved per step of a compaction (:func:`_compact`)."""


def _compact(s: PoolState) -> PoolState:
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
                          age=mv(s.age))

    s = jax.lax.fori_loop(0, (m + K - 1) // K, move, s)
    cell = jnp.where(pos >= c, -1, s.cell).astype(jnp.int32)  # the lanes moved from
    return s._replace(cell=cell, n_active=jnp.minimum(s.n_active, c).astype(jnp.int32))


@kept_jit(static_argnames=("system", "integrator", "o", "n", "L_min"), donate_argnums=(0,))
def _run(s: PoolState, system, params, integrator, o: _Options, X, Xrow, n: int, L_min: int, rounds):
    """At most ``rounds`` rounds (a traced int: the host sizes its calls by their duration),
    fewer when every state is decided, an attractor table overflows or the pool can shrink."""
    return _rounds(s, system, params, integrator, o, X, Xrow, n, L_min, rounds)


def _rounds(s: PoolState, system, params, integrator, o: _Options, X, Xrow, n, L_min: int, rounds):
    """:func:`_run`'s loop, traced; ``n`` may be traced too: the queue is ``X[:n]`` (a block
    padded to the shape of the other devices' blocks, :mod:`jaxgear.analysis._sharded`)."""
    def cond(c):
        s, r = c
        shrink = (s.next_cell >= n) & (s.n_active <= L_min) & (s.Y.shape[1] > L_min)
        return (r < rounds) & (s.n_done < n) & ~s.overflow & ~shrink

    def body(c):
        s, r = c
        s = jax.lax.fori_loop(0, o.R, lambda _, s: _one_period(system, params, integrator, o, s), s)
        s = _decide(o, s, X, Xrow, n)
        # once the queue is empty, the busy lanes are gathered at the front as lanes free up
        busy = jnp.sum(s.cell >= 0, dtype=jnp.int32)
        worth = (s.next_cell >= n) & (busy.astype(jnp.float64) <= COMPACT_BELOW * s.n_active.astype(jnp.float64))
        return jax.lax.cond(worth, _compact, lambda s: s, s), r + 1

    s, _ = jax.lax.while_loop(cond, body, (s, jnp.asarray(0, jnp.int32)))
    info = jnp.stack([s.n_done, s.overflow.astype(jnp.int32), s.n_active, s.next_cell, jnp.sum(s.n_att, dtype=jnp.int32)])
    return s, info


@functools.partial(jax.jit, static_argnames=("L", "A"))
def _resize(s: PoolState, L: int | None = None, A: int | None = None) -> PoolState:
    """The pool with ``L`` lanes (the first ``L``: busy lanes are at the front) or ``A``
    attractor slots."""
    if L is not None:
        s = s._replace(Y=s.Y[:, :L], hist=s.hist[:, :, :L], streak=s.streak[:, :L], cell=s.cell[:L], row=s.row[:L],
                       age=s.age[:L], n_active=jnp.minimum(s.n_active, L))
    if A is not None:
        V, A0, M, dim = s.att_pts.shape
        s = s._replace(att_pts=jnp.concatenate([s.att_pts, jnp.full((V, A - A0, M, dim), jnp.nan)], axis=1),
                       att_k=jnp.concatenate([s.att_k, jnp.zeros((V, A - A0), jnp.int32)], axis=1),
                       overflow=jnp.asarray(False))
    return s


DEFAULT_PILOT = 1024
"""States of the pilot pool (the first phase, see :func:`run_pool`)."""


def run_pool(system, params, X: np.ndarray, integrator, *, chunk: int, R: int, max_periods: int, max_period: int,
             tol: float, capture, bound: float, merge_tol: float, progress: bool, pilot: int = DEFAULT_PILOT,
             attractors=(), label: str = "direct"):
    """Label the states ``X (n, dim)`` (see the module): ``(labels (n,) with attractor slot,
    SINK or UNRESOLVED; [(points (k, dim) in cycle order, k)]; periods per state (n,))``.

    A pilot sample of ``pilot`` states (drawn with a fixed seed) runs first in a small pool
    until each of its states is decided, so the common attractors are known (and capture
    decides the bulk early) when the other states start with the pilot's attractors.
    ``attractors``: known ``(points, k)`` cycles (``k <= max_period``) that take the first
    slots, in that order; a period ``-k`` makes the cycle a repeller (an unstable P-k
    cycle: lanes that shadow it are not decided there and integrate on), listed in the
    returned cycles with its period ``-k``.
    """
    return run_pools(system, [params], [X], integrator, chunk=chunk, R=R, max_periods=max_periods,
                     max_period=max_period, tol=tol, capture=capture, bound=bound, merge_tol=merge_tol,
                     progress=progress, pilot=pilot, attractors=[attractors], label=label)[0]


def run_pools(system, params_list, X_list, integrator, *, chunk: int, R: int, max_periods: int, max_period: int,
              tol: float, capture, bound: float, merge_tol: float, progress: bool, pilot: int = DEFAULT_PILOT,
              attractors=None, label: str = "direct"):
    """:func:`run_pool` for ``V`` parameter sets at once, in one pool: the states
    ``X_list[v] (n_v, dim)`` under the parameters ``params_list[v]`` (one pytree
    structure), each lane integrating with its cell's parameters and deciding against
    its value's own attractor table. ``attractors``: per value, its known cycles.
    Returns ``[(labels, attractors, periods)]`` per value, each what :func:`run_pool`
    returns for that value alone.

    The pilots of all values run first in one pool, then all the other states in one
    pool, value after value: the compilation, the pilot's draining and the draining tail
    are paid once. With several local devices the other states run in one pool per
    device, a block of the queue each, in one sharded program (:mod:`jaxgear.analysis._sharded`).
    """
    from ._sharded import drive_blocks

    V = len(params_list)
    Xs = [np.asarray(X, dtype=np.float64) for X in X_list]
    dim = Xs[0].shape[1]
    M = int(max_period)
    o = _options(R, max_periods, max_period, tol, capture, bound, merge_tol)
    params = params_list[0] if V == 1 else _stack(params_list)
    orders, n_ps = [], []
    for X in Xs:
        n = len(X)
        n_p = _pilot_size(pilot, n)
        first = np.sort(np.random.default_rng(0).choice(n, size=n_p, replace=False))
        rest = np.ones(n, dtype=bool)
        rest[first] = False
        orders.append(np.concatenate([first, np.flatnonzero(rest)]))
        n_ps.append(n_p)
    att = _seed_attractors(attractors if attractors is not None else [()] * V, M, dim)
    bar = progress_bar(sum(len(X) for X in Xs), label, progress)
    labels = [np.empty(len(X), dtype=np.int64) for X in Xs]
    used = [np.empty(len(X), dtype=np.int64) for X in Xs]
    n_main = sum(len(X) - n_p for X, n_p in zip(Xs, n_ps))
    if any(n_ps) and n_main:  # the main pools' computations compile while the pilot runs
        _prepare_blocks(system, params, integrator, o, n_main,
                        max(1, min(int(chunk), max(len(X) - n_p for X, n_p in zip(Xs, n_ps)))), dim, V,
                        att[1].shape[1])
    for phase in (0, 1):
        parts = [o_[:n_p] if phase == 0 else o_[n_p:] for o_, n_p in zip(orders, n_ps)]
        total = sum(len(p) for p in parts)
        if not total:
            continue
        Xp = np.concatenate([X[p] for X, p in zip(Xs, parts)])
        rows = np.concatenate([np.full(len(p), v, np.int32) for v, p in enumerate(parts)])
        L = max(1, min(int(chunk), max(len(p) for p in parts)))  # the pool of one value, refilled from the next
        if phase == 0:  # the pilot, on the first device
            s = _drive(system, params, integrator, o, jax.device_put(Xp), jax.device_put(rows), L, att, bar)
            att = (s.att_pts, s.att_k, s.n_att)
            lab, use = (np.asarray(a) for a in jax.device_get((s.labels, s.used)))
        else:  # one pool per device over a block of the queue, the attractors merged
            lab, use, att = drive_blocks(system, params, integrator, o, Xp, rows, L, att, bar)
        start = 0
        for v, p in enumerate(parts):
            labels[v][p] = lab[start:start + len(p)]
            used[v][p] = use[start:start + len(p)]
            start += len(p)
    bar.close()
    att_pts, att_k, n_att = (np.asarray(a) for a in jax.device_get(att))
    out = []
    for v in range(V):
        atts = [(att_pts[v, a, : abs(int(att_k[v, a]))], int(att_k[v, a])) for a in range(int(n_att[v]))]
        out.append((labels[v], atts, used[v]))
    return out


def _pilot_size(pilot: int, n: int) -> int:
    """States of the pilot phase among ``n`` (none when the pilot would hold them all)."""
    return min(int(pilot), n) if 0 < int(pilot) < n else 0


def _options(R, max_periods, max_period, tol, capture, bound, merge_tol) -> _Options:
    return _Options(M=int(max_period), R=int(R), tol=float(tol), merge_tol=float(merge_tol),
                    max_periods=int(max_periods), bound=float(bound),
                    capture=None if capture == "auto" else float(capture))


def _stack(params_list):
    from ..integrate import stack_params

    return stack_params(params_list)


def _seed_attractors(attractors, M: int, dim: int):
    """The attractor tables ``(points (V, A, M, dim), periods (V, A), counts (V,))`` of ``V``
    values holding each value's known cycles first (``A``: 8 slots, or the next power of
    two that holds them); a cycle of period ``-k`` is a repeller (an unstable P-k cycle
    whose lanes integrate on)."""
    known = [[(np.asarray(p, np.float64).reshape(-1, dim), int(k)) for p, k in att] for att in attractors]
    if any(not 0 < abs(k) <= M for kn in known for _, k in kn):
        raise ValueError(f"known attractors must have periods 1..{M} (repellers -1..-{M})")
    most = max(len(kn) for kn in known)
    A = max(8, 1 << max(0, most - 1).bit_length())
    V = len(known)
    pts = np.full((V, A, M, dim), np.nan)
    ks = np.zeros((V, A), np.int32)
    for v, kn in enumerate(known):
        for a, (p, k) in enumerate(kn):
            pts[v, a, :abs(k)] = p[:abs(k)]
            ks[v, a] = k
    return jax.device_put((pts, ks, np.array([len(kn) for kn in known], np.int32)))


def _drive(system, params, integrator, o: _Options, Xd, Xrow, L: int, att, bar, device=None) -> PoolState:
    """Run one pool over the states ``Xd (n, dim)`` (of parameter rows ``Xrow (n,)``)
    until every one is decided (``device``: the device its inputs are committed to, or
    ``None``: the default device, uncommitted)."""
    n, dim = Xd.shape
    _ready(system, integrator, o, n, L, att[1].shape, device)
    s = _init(n, L, dim, o.M, Xd, Xrow, *att)
    return _steer(s, lambda s, L_min, rounds: _run(s, system, params, integrator, o, Xd, Xrow, n, L_min, rounds),
                  _resize, np.array([n]), bar, lambda L: _ready(system, integrator, o, n, L, att[1].shape, device))


def _steer(s, run, resize, n: np.ndarray, bar, ready):
    """Call ``run(s, L_min, rounds)`` until every pool is decided, making the host's
    decisions from the ``info`` rows of the pools (one row, or one per device of a
    sharded pool whose queues hold ``n`` states each): grow every attractor table when one
    overflows, move every pool to the next size (:func:`_next_pool`) once the busy lanes
    of every one fit. ``ready(L)`` waits for the compilation of pools of ``L`` lanes."""
    done = 0
    rounds = 4
    while True:
        L = s.Y.shape[-1]
        L_min = _next_pool(L)
        ready(L)
        t = time.perf_counter()
        s, info = run(s, L_min, np.int32(rounds))
        n_done, overflow, n_active, next_cell, n_att = np.asarray(info).reshape(-1, 5).T
        # calls of about CALL_SECONDS: few host round trips, a progress bar still moving
        rounds = int(np.clip(rounds * CALL_SECONDS / max(time.perf_counter() - t, 1e-3), 1, 4 * rounds))
        bar.update(int(n_done.sum()) - done)
        done = int(n_done.sum())
        bar.set_postfix_str(f"{int(n_active.sum())} lanes busy, {int(n_att.max())} attractors", refresh=False)
        finished = n_done >= n
        if finished.all():
            return s
        if overflow.any():
            s = resize(s, A=2 * s.att_k.shape[-1])
        elif L_min < L and np.all(finished | ((next_cell >= n) & (n_active <= L_min))):
            s = resize(s, L=L_min)


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


def _next_pool(L: int) -> int:
    """The pool size the lanes move to once they fit (``L`` itself: no smaller pool)."""
    return max(TAIL_LANES, L // SHRINK) if L > 2 * TAIL_LANES else L


def _pool_sizes(L: int) -> list[int]:
    """The sizes a pool of ``L`` lanes runs at as it drains, largest first."""
    sizes = [L]
    while _next_pool(sizes[-1]) < sizes[-1]:
        sizes.append(_next_pool(sizes[-1]))
    return sizes


# ----------------------------------------------------------------------------- compiling ahead
# A pool's computations (``_init`` and ``_run`` of each of its sizes) compile on a side
# thread (:mod:`jaxgear._ahead`) while the device works on something else (the pilot, an
# earlier pool); the pool waits for its own warm-up before its first call.


def _key(system, integrator, o: _Options, n: int, L: int, att_shape, device=None) -> tuple:
    """``device``: ``None``, a device, or the mesh of a sharded pool (its devices)."""
    if isinstance(device, jax.sharding.Mesh):
        where = tuple(d.id for d in device.devices.flat)
    else:
        where = None if device is None else device.id
    return (system, integrator, o, int(n), int(L), tuple(att_shape), where)


def prepare_pools(system, params_list, integrator, n: int, *, chunk: int, R: int, max_periods: int,
                  max_period: int, tol: float, capture, bound: float, merge_tol: float, attractors=None,
                  pilot: int = 0) -> None:
    """Compile, on a side thread, the pools that :func:`run_pools` with these arguments
    will run over ``n`` states per value (the pilot's first, then the main one's; a
    later call then starts at once). Returns immediately; a failure here is left for
    the real call to report."""
    V = len(params_list)
    o = _options(R, max_periods, max_period, tol, capture, bound, merge_tol)
    params = params_list[0] if V == 1 else _stack(params_list)
    A = _seed_attractors(attractors if attractors is not None else [()] * V, o.M, system.dim)[1].shape[1]
    n_p = _pilot_size(pilot, int(n))
    if n_p:
        _prepare(system, params, integrator, o, V * n_p, max(1, min(int(chunk), n_p)), system.dim, V, A)
    if int(n) - n_p:
        _prepare_blocks(system, params, integrator, o, V * (int(n) - n_p), max(1, min(int(chunk), int(n) - n_p)),
                        system.dim, V, A)


def _prepare_blocks(system, params, integrator, o: _Options, n: int, L: int, dim: int, V: int, A: int) -> None:
    """:func:`_prepare` for the pools that the queue of ``n`` states runs in after the
    pilot: one block of the queue on one device, or a block per device in one sharded pool
    (:func:`jaxgear.analysis._sharded.block_pool`)."""
    from ._sharded import block_pool

    pool = block_pool(n, L)
    if pool is not None:
        n_b, L_b, where = pool
        _prepare(system, params, integrator, o, n_b, L_b, dim, V, A, where)


def _prepare(system, params, integrator, o: _Options, n: int, L: int, dim: int, V: int, A: int,
             device=None) -> None:
    for size in _pool_sizes(L):
        compile_ahead(_key(system, integrator, o, n, size, (V, A), device),
                      functools.partial(_compile_pool, system, params, integrator, o, n, size, L, dim, V, A, device))


def _compile_pool(system, params, integrator, o: _Options, n: int, size: int, L: int, dim: int, V: int, A: int,
                  device=None):
    """Compile ``_init`` and ``_run`` of a pool of ``size`` lanes (of a pool started at
    ``L``) over ``n`` states, for inputs placed on ``device`` as
    :func:`jaxgear._devices.put` places them (``None``: uncommitted), as the pool will
    call them (a call whose inputs are placed otherwise is a different computation to
    JAX, traced and compiled again). On a mesh (``device``), those of the sharded pool
    whose blocks hold ``n`` states each (:func:`jaxgear.analysis._sharded.compile_blocks`)."""
    if isinstance(device, jax.sharding.Mesh):
        from ._sharded import compile_blocks

        return compile_blocks(system, params, integrator, o, n, size, L, dim, V, A, device)
    f64, i32 = jnp.float64, jnp.int32
    sharding = placement(device)  # as jaxgear._devices.put places the pool's inputs
    where = {} if sharding is None else {"sharding": sharding}
    X = jax.ShapeDtypeStruct((n, dim), f64, **where)
    Xrow = jax.ShapeDtypeStruct((n,), i32, **where)
    att = (jax.ShapeDtypeStruct((V, A, o.M, dim), f64, **where), jax.ShapeDtypeStruct((V, A), i32, **where),
           jax.ShapeDtypeStruct((V,), i32, **where))
    if sharding is not None:
        params = jax.device_put(params, sharding)
    if size == L:
        _init.prepare(n, L, dim, o.M, X, Xrow, *att)
    s = jax.eval_shape(functools.partial(_init, n, size, dim, o.M), X, Xrow, *att)
    s = jax.tree.map(lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype, **where), s)
    _run.prepare(s, system, params, integrator, o, X, Xrow, n, _next_pool(size), np.int32(1))


def _ready(system, integrator, o: _Options, n: int, L: int, att_shape, device=None) -> None:
    """Wait for the side thread's compilation of this pool, if one was started."""
    wait_for(_key(system, integrator, o, n, L, att_shape, device))
