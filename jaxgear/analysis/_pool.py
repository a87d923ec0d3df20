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
- decided lanes write their cell's label and take the next cells of the queue; when the
  queue is empty the busy lanes are gathered at the front and only those are integrated
  (``n_active``), and the host moves them to a smaller pool when few remain.

The host only reads a few scalars per call (progress, a full attractor table, a pool
to shrink).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import progress_bar

__all__ = ["PoolState", "run_pool", "NOT_DONE"]

NOT_DONE = -3
"""Label of a cell not decided yet (never returned)."""
_SINK, _UNRESOLVED = -1, -2


class PoolState(NamedTuple):
    """The pool's state (device arrays); ``L`` lanes, ``n`` cells, ``A`` attractor slots."""

    Y: jax.Array  # (dim, L) current states
    hist: jax.Array  # (2H, dim, L) ring of the last H stroboscopic points, written at slots c and c + H
    #                  (c = clock % H), so any M consecutive points back are one contiguous slice
    streak: jax.Array  # (M, L) int32 recurrence streaks
    cell: jax.Array  # (L,) int32 cell held, -1 idle
    age: jax.Array  # (L,) int32 periods integrated for the cell held
    labels: jax.Array  # (n,) int32
    used: jax.Array  # (n,) int32 periods integrated per cell
    next_cell: jax.Array  # () int32
    n_done: jax.Array  # () int32
    clock: jax.Array  # () int32
    att_pts: jax.Array  # (A, M, dim) attractor points in cycle order (NaN padded)
    att_k: jax.Array  # (A,) int32 periods (0: empty slot)
    n_att: jax.Array  # () int32
    radius: jax.Array  # () capture radius
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
    rounds_per_call: int


@eqx.filter_jit
def _init(n: int, L: int, dim: int, M: int, X, att_pts, att_k, n_att) -> PoolState:
    H = 2 * M + 1
    take = min(L, n)
    cell = jnp.where(jnp.arange(L) < take, jnp.arange(L), -1).astype(jnp.int32)
    Y = jnp.zeros((dim, L)).at[:, :take].set(X[:take].T)
    return PoolState(
        Y=Y, hist=jnp.full((2 * H, dim, L), jnp.nan, dtype=jnp.float64), streak=jnp.zeros((M, L), jnp.int32), cell=cell,
        age=jnp.zeros(L, jnp.int32), labels=jnp.full(n, NOT_DONE, jnp.int32), used=jnp.zeros(n, jnp.int32),
        next_cell=jnp.asarray(take, jnp.int32), n_done=jnp.asarray(0, jnp.int32), clock=jnp.asarray(0, jnp.int32),
        att_pts=att_pts, att_k=att_k, n_att=jnp.asarray(n_att, jnp.int32), radius=jnp.asarray(0.0, jnp.float64),
        n_active=jnp.asarray(take, jnp.int32), overflow=jnp.asarray(False), rounds=jnp.asarray(0, jnp.int32))


def _sqdist(a, b):
    """Squared Euclidean distance over axis ``-2`` (the state coordinates of ``(..., dim, L)``
    arrays), summed coordinate by coordinate (XLA fuses this; a reduction over a middle
    axis it runs several times slower)."""
    a, b = jnp.broadcast_arrays(a, b)
    return sum((a[..., i, :] - b[..., i, :]) ** 2 for i in range(a.shape[-2]))


def _back(hist, g, start: int, count: int, extra=0):
    """The points ``start, ..., start + count - 1`` periods back from period ``g`` (newest
    first), plus ``extra`` more periods back: ``(count, dim, L)`` (one contiguous slice of
    the doubled ring)."""
    H = hist.shape[0] // 2
    top = g % H + H - start - extra  # slot of the point `start + extra` periods back
    return jax.lax.dynamic_slice_in_dim(hist, top - count + 1, count, axis=0)[::-1]


def _one_period(system, params, integrator, o: _Options, s: PoolState) -> PoolState:
    H = s.hist.shape[0] // 2
    Y = integrator.advance(system, params, s.Y, jnp.asarray(0.0), 1, n_active=s.n_active)
    g = s.clock + 1
    c = g % H
    hist = jax.lax.dynamic_update_slice_in_dim(s.hist, Y[None], c, axis=0)
    hist = jax.lax.dynamic_update_slice_in_dim(hist, Y[None], c + H, axis=0)
    busy = s.cell >= 0
    age = jnp.where(busy, s.age + 1, s.age)
    thr = (o.tol * (1.0 + jnp.sqrt(_sqdist(Y, 0.0)))) ** 2
    ks = jnp.arange(1, o.M + 1)
    prev = _back(hist, g, 1, o.M)  # (M, dim, L): x_(t-1), ..., x_(t-M)
    ok = (_sqdist(Y[None], prev) <= thr[None]) & (age[None] > ks[:, None])  # x_(t-k) is this cell's
    streak = jnp.where(ok, s.streak + 1, 0)
    return s._replace(Y=Y, hist=hist, streak=streak, age=age, clock=g)


def _capture_radius(att_pts, att_k, capture):
    if capture is not None:
        return jnp.asarray(capture, jnp.float64)
    A, M, _ = att_pts.shape
    valid = (jnp.arange(M)[None] < att_k[:, None])  # (A, M)
    pts = jnp.where(valid[..., None], att_pts, 0.0)
    scale = 1.0 + jnp.max(jnp.where(valid[..., None], jnp.abs(pts), 0.0))
    d = jnp.sqrt(jnp.sum((pts[:, None, :, None] - pts[None, :, None, :]) ** 2, axis=-1))  # (A, A, M, M)
    pair = valid[:, None, :, None] & valid[None, :, None, :] & ~jnp.eye(A, dtype=bool)[:, :, None, None]
    gap = jnp.min(jnp.where(pair, d, jnp.inf))
    return jnp.minimum(0.01 * scale, 0.25 * gap)


def _decide(o: _Options, s: PoolState, X, n: int) -> PoolState:
    H2, dim, L = s.hist.shape
    H = H2 // 2
    M = o.M
    A = s.att_k.shape[0]
    g = s.clock
    Y = s.Y
    busy = s.cell >= 0
    norms = jnp.sqrt(_sqdist(Y, 0.0))
    esc = busy & (~jnp.isfinite(norms) | (norms > o.bound))
    ks = jnp.arange(1, M + 1)
    per = jnp.min(jnp.where(s.streak >= (ks + 1)[:, None], ks[:, None], M + 1), axis=0).astype(jnp.int32)  # (L,)
    rec = busy & ~esc & (per <= M)
    live = busy & ~esc
    label = jnp.full(L, -1, jnp.int32)
    i = jnp.arange(M)
    W_now = _back(s.hist, g, 0, M)  # (M, dim, L): the point i periods back

    def against(a, label, P, k, r):
        """Lanes captured by (or recurring onto) the P-k attractor ``P (M, dim)`` in slot ``a``."""
        if True:
            valid = i < k
            dn = jnp.sqrt(_sqdist(Y[None], P[:, :, None]))  # (M, L)
            dn = jnp.where(valid[:, None], dn, jnp.inf)
            m = jnp.argmin(dn, axis=0)  # the newest point is near P[m] ...
            dmin = jnp.min(dn, axis=0)
            Q = jnp.moveaxis(P[jnp.mod(m[None] - i[:, None], jnp.maximum(k, 1))], 2, 1)  # ... the one i back near
            W_bef = _back(s.hist, g, 0, M, extra=k)  # the k points before those          # P[m - i]: (M, dim, L)
            now = jnp.sqrt(_sqdist(W_now, Q))  # (M, L)
            before = jnp.sqrt(_sqdist(W_bef, Q))
            d_now = jnp.where(s.age >= k, jnp.max(jnp.where(valid[:, None], now, 0.0), axis=0), jnp.inf)
            d_bef = jnp.where(s.age >= 2 * k, jnp.max(jnp.where(valid[:, None], before, 0.0), axis=0), jnp.inf)
            cap = live & (d_now <= r) & ((d_now <= d_bef) | ~jnp.isfinite(d_bef))
            scale = 1.0 + jnp.max(jnp.where(valid[:, None], jnp.abs(P), 0.0))
            same = rec & (per == k) & (dmin <= o.merge_tol * scale)
            return jnp.where((label < 0) & (cap | same), a, label).astype(jnp.int32)

    label = jax.lax.fori_loop(0, s.n_att, lambda a, lab: against(a, lab, s.att_pts[a], s.att_k[a], s.radius), label)

    # a recurring lane on no known attractor registers a new one (one per round)
    new = rec & (label < 0)
    has_new = jnp.any(new)
    room = s.n_att < A
    l0 = jnp.argmax(new)
    k0 = per[l0]
    last = _back(s.hist, g, 0, M)[:, :, l0]  # (M, dim), newest first
    pts0 = last[jnp.clip(k0 - 1 - i, 0, M - 1)]  # oldest of the last k0 first
    pts0 = jnp.where((i < k0)[:, None], pts0, jnp.nan)
    add = has_new & room
    slot = jnp.minimum(s.n_att, A - 1)
    att_pts = jnp.where(add, s.att_pts.at[slot].set(pts0), s.att_pts)
    att_k = jnp.where(add, s.att_k.at[slot].set(k0), s.att_k)
    n_att = s.n_att + add.astype(jnp.int32)
    # the other recurring lanes whose newest point lies on the new attractor join it
    P0 = att_pts[slot]
    scale0 = 1.0 + jnp.max(jnp.where((i < k0)[:, None], jnp.abs(P0), 0.0))
    d0 = jnp.where((i < k0)[:, None], _sqdist(Y[None], P0[:, :, None]), jnp.inf)  # (M, L)
    joins = add & new & (per == k0) & (jnp.min(d0, axis=0) <= (o.merge_tol * scale0) ** 2)
    label = jnp.where(joins, slot, label).astype(jnp.int32)
    radius = _capture_radius(att_pts, att_k, o.capture)
    overflow = s.overflow | (has_new & ~room)

    unres = live & (label < 0) & (s.age >= o.max_periods)
    decided = esc | (label >= 0) | unres
    value = jnp.where(esc, _SINK, jnp.where(unres, _UNRESOLVED, label)).astype(jnp.int32)
    target = jnp.where(decided, s.cell, n)  # n: dropped
    labels = s.labels.at[target].set(value, mode="drop")
    used = s.used.at[target].set(s.age, mode="drop")

    # freed lanes take the next cells of the queue (only lanes below n_active while it drains)
    n_done = s.n_done + jnp.sum(decided).astype(jnp.int32)
    free = (~busy | decided) & (jnp.arange(L) < jnp.where(s.next_cell < n, L, s.n_active))
    rank = (jnp.cumsum(free) - 1).astype(jnp.int32)
    nc = s.next_cell + rank
    take = free & (nc < n)
    cell = jnp.where(take, nc, jnp.where(free, -1, s.cell)).astype(jnp.int32)
    Ynew = jnp.where(take[None], X[jnp.clip(nc, 0, n - 1)].T, jnp.where(free[None], 0.0, Y))
    age = jnp.where(free, 0, s.age)
    streak = jnp.where(free[None], 0, s.streak)
    next_cell = jnp.minimum(s.next_cell + jnp.sum(take), n).astype(jnp.int32)
    highest = jnp.max(jnp.where(cell >= 0, jnp.arange(L), -1)) + 1  # busy lanes lie below it
    n_active = jnp.where(s.next_cell < n, jnp.maximum(s.n_active, highest), s.n_active).astype(jnp.int32)
    s = s._replace(Y=Ynew, cell=cell, age=age, streak=streak, labels=labels, used=used, next_cell=next_cell,
                   n_done=n_done, att_pts=att_pts, att_k=att_k, n_att=n_att, radius=radius, overflow=overflow,
                   rounds=s.rounds + 1, n_active=n_active)
    return s


@functools.partial(jax.jit, donate_argnums=0)
def _compact(s: PoolState) -> PoolState:
    """Gather the busy lanes at the front and integrate only those (called by the host once
    the queue is empty and they fill at most three quarters of the active range)."""
    busy = s.cell >= 0
    order = jnp.argsort(~busy, stable=True)
    t = lambda a, ax: jnp.take(a, order, axis=ax)  # noqa: E731
    return s._replace(Y=t(s.Y, 1), hist=t(s.hist, 2), streak=t(s.streak, 1), cell=t(s.cell, 0), age=t(s.age, 0),
                      n_active=jnp.sum(busy).astype(jnp.int32))


@functools.partial(jax.jit, static_argnames=("system", "integrator", "o", "n", "L_min"), donate_argnums=0)
def _run(s: PoolState, system, params, integrator, o: _Options, X, n: int, L_min: int):
    def cond(c):
        s, r = c
        shrink = (s.next_cell >= n) & (s.n_active <= L_min) & (s.Y.shape[1] > L_min)
        return (r < o.rounds_per_call) & (s.n_done < n) & ~s.overflow & ~shrink

    def body(c):
        s, r = c
        s = jax.lax.fori_loop(0, o.R, lambda _, s: _one_period(system, params, integrator, o, s), s)
        return _decide(o, s, X, n), r + 1

    s, _ = jax.lax.while_loop(cond, body, (s, jnp.asarray(0, jnp.int32)))
    return s


def _resize(s: PoolState, L: int | None = None, A: int | None = None) -> PoolState:
    """The pool with ``L`` lanes (the first ``L``: busy lanes are at the front) or ``A``
    attractor slots."""
    if L is not None:
        s = s._replace(Y=s.Y[:, :L], hist=s.hist[:, :, :L], streak=s.streak[:, :L], cell=s.cell[:L], age=s.age[:L],
                       n_active=jnp.minimum(s.n_active, L))
    if A is not None:
        A0, M, dim = s.att_pts.shape
        s = s._replace(att_pts=jnp.concatenate([s.att_pts, jnp.full((A - A0, M, dim), jnp.nan)]),
                       att_k=jnp.concatenate([s.att_k, jnp.zeros(A - A0, jnp.int32)]), overflow=jnp.asarray(False))
    return s


def run_pool(system, params, X: np.ndarray, integrator, *, chunk: int, R: int, max_periods: int, max_period: int,
             tol: float, capture, bound: float, merge_tol: float, progress: bool, pilot: int = 1024,
             attractors=(), label: str = "direct"):
    """Label the states ``X (n, dim)`` (see the module): ``(labels (n,) with attractor slot,
    SINK or UNRESOLVED; [(points (k, dim) in cycle order, k)]; periods per state (n,))``.

    A pilot sample of ``pilot`` states (drawn with a fixed seed) runs first in a small pool
    until each of its states is decided, so the common attractors are known (and capture
    decides the bulk early) when the other states start with the pilot's attractors.
    ``attractors``: known ``(points, k)`` cycles (``k <= max_period``) that take the first
    slots, in that order.
    """
    X = np.asarray(X, dtype=np.float64)
    n, dim = X.shape
    M = int(max_period)
    o = _Options(M=M, R=int(R), tol=float(tol), merge_tol=float(merge_tol), max_periods=int(max_periods),
                 bound=float(bound), capture=None if capture == "auto" else float(capture), rounds_per_call=4)
    n_p = min(int(pilot), n) if 0 < int(pilot) < n else 0
    first = np.sort(np.random.default_rng(0).choice(n, size=n_p, replace=False))
    order = np.concatenate([first, np.setdiff1d(np.arange(n), first)])
    att = _seed_attractors(attractors, M, dim)
    bar = progress_bar(n, label, progress)
    parts = []
    for part in (order[:n_p], order[n_p:]):
        if len(part):
            L = max(1, min(int(chunk), len(part)))
            s = _drive(system, params, integrator, o, jnp.asarray(X[part]), L, att, bar)
            att = (s.att_pts, s.att_k, int(s.n_att))
            parts.append(jax.device_get((s.labels, s.used)))
    bar.close()
    labels = np.empty(n, dtype=np.int64)
    used = np.empty(n, dtype=np.int64)
    labels[order] = np.concatenate([np.asarray(p[0]) for p in parts])
    used[order] = np.concatenate([np.asarray(p[1]) for p in parts])
    att_pts, att_k = jax.device_get(att[:2])
    atts = [(np.asarray(att_pts[a, : int(att_k[a])]), int(att_k[a])) for a in range(int(att[2]))]
    return labels, atts, used


def _seed_attractors(attractors, M: int, dim: int):
    """The attractor table ``(points (A, M, dim), periods (A,), count)`` holding the known
    cycles first (``A``: 8 slots, or the next power of two that holds them)."""
    known = [(np.asarray(p, np.float64).reshape(-1, dim), int(k)) for p, k in attractors]
    if any(not 0 < k <= M for _, k in known):
        raise ValueError(f"known attractors must have periods 1..{M}")
    A = max(8, 1 << max(0, len(known) - 1).bit_length())
    pts = np.full((A, M, dim), np.nan)
    ks = np.zeros(A, np.int32)
    for a, (p, k) in enumerate(known):
        pts[a, :k] = p[:k]
        ks[a] = k
    return jnp.asarray(pts), jnp.asarray(ks), len(known)


def _drive(system, params, integrator, o: _Options, Xd, L: int, att, bar) -> PoolState:
    """Run one pool over the states ``Xd (n, dim)`` until every one is decided."""
    n, dim = Xd.shape
    s = _init(n, L, dim, o.M, Xd, *att)
    done = 0
    while True:
        L_min = _next_pool(s.Y.shape[1])
        s = _run(s, system, params, integrator, o, Xd, n, L_min)
        n_done, overflow, n_active, next_cell, n_att, busy = (int(v) for v in jax.device_get(
            (s.n_done, s.overflow, s.n_active, s.next_cell, s.n_att, jnp.sum(s.cell >= 0))))
        bar.update(n_done - done)
        done = n_done
        bar.set_postfix_str(f"{n_active} lanes busy, {n_att} attractors", refresh=False)
        if n_done >= n:
            return s
        if overflow:
            s = _resize(s, A=2 * s.att_k.shape[0])
            continue
        if next_cell >= n and busy <= (3 * n_active) // 4:
            s = _compact(s)
            n_active = busy
        if next_cell >= n and n_active <= L_min < s.Y.shape[1]:
            s = _resize(s, L=L_min)


TAIL_LANES = 1024
"""Lanes of the pool the last slow cells move to (a second compiled shape), so the rounds
of a draining pool stop costing the bookkeeping of the full one."""


def _next_pool(L: int) -> int:
    """The pool size the lanes move to once they fit (:data:`TAIL_LANES`)."""
    return TAIL_LANES if L > 2 * TAIL_LANES else L
