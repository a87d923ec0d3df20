"""The direct method: every cell centre integrated until its attractor is recognised.

No discretisation of images: each cell centre (on the section at forcing phase 0) is
integrated on the stroboscopic map until it escapes (the sink), recurs with a period
``<= max_period`` (a new or known attractor) or shadows a known attractor's cycle
(capture), or until ``max_periods`` periods have passed (unresolved). The reference for
the cell methods, and the default method.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import chunks, pad_rows, progress_bar
from .._cells import CellGrid
from .._checks import check_int, check_number
from .._matching import same_attractor
from ._method import AbstractGlobalMethod, Classification, register_method
from ._orbits import detect_period, refine_orbit
from ._result import SINK, UNRESOLVED

__all__ = ["Direct"]


@register_method
class Direct(AbstractGlobalMethod):
    """Direct integration of every cell centre on the stroboscopic map (the default method).

    A pool of ``chunk_size`` lanes runs rounds of ``round_periods`` forcing periods; after
    each round a lane is decided when its trajectory escapes (norm > ``escape_bound`` or
    not finite: the sink), when its last k stroboscopic points follow the whole cycle
    of a known P-k attractor within ``capture_radius`` without moving away from it,
    when it recurs with a period ``<= max_period``, or after ``max_periods`` periods
    (unresolved). A pilot sample of ``pilot`` cells runs first so the common attractors
    are known before the bulk starts (the labels do not depend on it, only the time).

    Attributes:
        round_periods: periods per round between checks (>= 1).
        max_periods: limit per cell (then ``UNRESOLVED``).
        capture_radius: ``"auto"`` (a quarter of the smallest distance between two known
            attractors' points, at most 1 % of their scale) or a number >= 0 (state units).
        escape_bound: norm beyond which a state counts as escaped (state units).
        pilot: cells of the pilot sample (>= 0).
        integrator, max_period, period_tol, merge_tol, chunk_size: see
            :class:`AbstractGlobalMethod`.
    """

    name: ClassVar[str] = "direct"
    round_periods: int = eqx.field(static=True, default=5)
    max_periods: int = eqx.field(static=True, default=2000)
    capture_radius: float | str = eqx.field(static=True, default="auto")
    escape_bound: float = eqx.field(static=True, default=1e6)
    pilot: int = eqx.field(static=True, default=1024)

    def __check_init__(self):
        check_int(self.round_periods, "round_periods", 1)
        check_int(self.max_periods, "max_periods", 1)
        check_int(self.pilot, "pilot", 0)
        if self.capture_radius != "auto":
            check_number(self.capture_radius, "capture_radius", 0)
        check_number(self.escape_bound, "escape_bound", 0, strict_min=True)

    def check(self, system, grid: CellGrid) -> None:
        return None

    def classify(self, system, params, grid: CellGrid, progress: bool) -> Classification:
        labels, atts, mean = self.label_states(system, params, grid.centres(), progress)
        return Classification(labels, atts, [np.zeros(0, np.int64)] * len(atts), mean)

    def label_states(self, system, params, X: np.ndarray, progress: bool = False):
        """Label the states ``X (n, dim)`` (at forcing phase 0): ``(labels (n,), [(points,
        period, residual)], mean periods per state)``."""
        return _direct(system, params, X, self.integrator, self.chunk_size, self.round_periods,
                       self.max_periods, self.max_period, self.period_tol, self.capture_radius,
                       self.escape_bound, self.merge_tol, progress, pilot=self.pilot)


@eqx.filter_jit
def _direct_round(system, params, X, periods, integrator):
    """Advance ``X (C, dim)`` by ``periods`` periods, returning all stroboscopic points ``(C, periods, dim)``."""
    def step(Y, _):
        Y = integrator.advance(system, params, Y, jnp.asarray(0.0), 1)
        return Y, Y

    _, Ys = jax.lax.scan(step, X.T, None, length=periods)
    return jnp.transpose(Ys, (2, 0, 1))


def _pool_size(n_busy: int, pool: int, smallest: int = 256) -> int:
    """Padded batch size for ``n_busy`` lanes: the pool size, or ``smallest * 4^j`` below it,
    so a draining pool compiles few shapes (each costs ~0.5 s) for some idle lanes."""
    if n_busy >= pool:
        return pool
    size = smallest
    while size < n_busy:
        size *= 4
    return min(size, pool)


def capture_radius(attractors: list, capture) -> float:
    """Capture radius around known attractors' points (state units).

    ``capture="auto"``: a quarter of the smallest distance between points of two
    different known attractors, and at most 1 % of ``1 + max |point|`` (the attractors'
    scale); a number is used as given.
    """
    if capture != "auto":
        return float(capture)
    pts = [np.asarray(p) for p, _, _ in attractors]
    r = 0.01 * (1.0 + max(float(np.abs(p).max()) for p in pts))
    for i in range(len(pts)):
        for j in range(i):
            d = np.linalg.norm(pts[i][:, None, :] - pts[j][None, :, :], axis=-1).min()
            r = min(r, 0.25 * float(d))
    return r


def _shadowing(hist: np.ndarray, points: np.ndarray) -> np.ndarray:
    """How closely each lane's last ``k`` stroboscopic points follow a period-k cycle.

    ``hist (lanes, H, dim)`` (newest last), ``points (k, dim)`` in the cycle's order
    (``points[j+1] = P(points[j])``). Returns ``(lanes,)``: the smallest, over the k
    alignments of the cycle, of the largest distance along the last k points, and
    ``inf`` for lanes whose window holds non-finite values (not yet filled).
    """
    k = len(points)
    W = hist[:, -k:]  # (lanes, k, dim), W[:, i] aligned with points[(j + i) % k]
    best = np.full(len(hist), np.inf)
    for j in range(k):
        d = np.linalg.norm(W - np.roll(points, -j, axis=0)[None], axis=-1).max(axis=1)
        best = np.minimum(best, np.where(np.isfinite(d), d, np.inf))
    return best


def _direct(system, params, X, integrator, chunk, R, max_periods, max_period, tol, capture, bound, merge_tol,
            progress, pilot: int = 1024):
    """Direct classification of the states ``X (n, dim)``: a pilot sample first, then the rest.

    The pilot (``pilot`` cells drawn with a fixed seed) runs alone until each of its
    trajectories recurs, so the common attractors are known before the bulk of the
    cells starts and those can be decided by capture (:func:`_direct_pool`) as soon as
    they reach an attractor instead of after a full recurrence test. Attractors the
    pilot misses are still found by recurrence in the second pass; the labels do not
    depend on the pilot, only the time does.
    Returns ``(labels, [(points, period, residual)], mean periods per cell)``.
    """
    X = np.asarray(X, dtype=float)
    n = len(X)
    attractors: list[list] = []
    labels = np.full(n, UNRESOLVED, dtype=np.int64)
    used = np.zeros(n, dtype=np.int64)
    first = np.sort(np.random.default_rng(0).choice(n, size=min(int(pilot), n), replace=False))
    rest = np.setdiff1d(np.arange(n), first)
    bar = progress_bar(n, "direct", progress)
    for part in (first, rest):
        if len(part):
            labels[part], used[part] = _direct_pool(system, params, X[part], integrator, chunk, R, max_periods,
                                                    max_period, tol, capture, bound, merge_tol, attractors, bar)
    bar.close()
    out = []
    for pts, k, _ in attractors:
        pts, res = refine_orbit(system, params, pts[-1], k, integrator, settle=200)
        out.append((pts, k, res))
    return labels, out, float(used.mean())


def _direct_pool(system, params, X, integrator, chunk, R, max_periods, max_period, tol, capture, bound, merge_tol,
                 attractors, bar):
    """Integrate every cell centre on the stroboscopic map until its fate is known.

    A pool of ``chunk`` lanes runs rounds of ``R`` periods; after each round a lane is
    decided and leaves the pool when its trajectory escapes (norm > ``bound`` or not
    finite: the sink), when its last k stroboscopic points follow, within the capture
    radius (:func:`_capture_radius`), the whole cycle of a known P-k attractor and their
    distance to it has not grown over that cycle (:func:`_shadowing`; a single close
    point is not enough), when it recurs with a period ``<= max_period`` (a new or known
    attractor, :func:`detect_period`), or after ``max_periods`` periods (unresolved).
    Freed lanes take the next cells, so the pool stays full until the grid is used up;
    then the busy lanes are compacted into a batch padded to a power of two, so no
    lane idles for long and memory stays bounded by ``chunk``, not by the grid.
    ``attractors`` (a list of ``[points (k, dim) in cycle order, period, residual]``) is
    extended in place. Returns ``(labels (n,), periods integrated per cell (n,))``.
    """
    n, dim = X.shape
    H = 2 * max_period + 1
    pool = max(1, min(int(chunk), n))
    labels = np.full(n, UNRESOLVED, dtype=np.int64)
    used = np.zeros(n, dtype=np.int64)  # periods integrated per cell
    cell = np.full(pool, -1, dtype=np.int64)  # cell held by each lane, -1: free
    state = np.zeros((pool, dim))
    hist = np.full((pool, H, dim), np.nan)
    age = np.zeros(pool, dtype=np.int64)
    fed = 0
    while True:
        free = np.nonzero(cell < 0)[0][: n - fed]
        if len(free):
            cell[free] = np.arange(fed, fed + len(free))
            state[free] = X[fed : fed + len(free)]
            hist[free] = np.nan
            age[free] = 0
            fed += len(free)
        busy = np.nonzero(cell >= 0)[0]
        if not len(busy):
            break
        size = _pool_size(len(busy), pool)
        P = np.empty((len(busy), R, dim))
        for a, b in chunks(len(busy), size):
            P[a:b] = np.asarray(_direct_round(system, params, jnp.asarray(pad_rows(state[busy[a:b]], size)), int(R),
                                              integrator))[: b - a]
        state[busy] = P[:, -1]
        age[busy] += R
        H_b = np.concatenate([hist[busy], P], axis=1)[:, -H:]
        hist[busy] = H_b
        newX = P[:, -1]
        lab = np.full(len(busy), UNRESOLVED, dtype=np.int64)
        decided = np.zeros(len(busy), dtype=bool)
        # escape -> sink
        norms = np.linalg.norm(newX, axis=1)
        esc = ~np.isfinite(norms) | (norms > bound)
        lab[esc] = SINK
        decided |= esc
        # capture: the last k points shadow a known P-k cycle, not moving away from it
        if attractors:
            r = capture_radius(attractors, capture)
            for ai, (apts, k, _) in enumerate(attractors):
                und = np.nonzero(~decided)[0]
                if len(und) and k <= H:  # cheap pre-filter: the newest point must be close already
                    und = und[np.linalg.norm(newX[und, None] - apts[None], axis=-1).min(axis=1) <= r]
                if not len(und) or k > H:
                    continue
                d_now = _shadowing(H_b[und], apts)
                d_before = _shadowing(H_b[und, :-k], apts) if H > 2 * k else np.full(len(und), np.inf)
                cap = und[(d_now <= r) & ((d_now <= d_before) | ~np.isfinite(d_before))]
                lab[cap] = ai
                decided[cap] = True
        # recurrence -> a new attractor, or one found in this round by another lane
        cand = np.nonzero(~decided & (age[busy] >= H))[0]
        if len(cand):  # cheap pre-filter: the newest point must return within max_period periods
            back = np.linalg.norm(H_b[cand, -1:] - H_b[cand, -1 - max_period : -1], axis=-1).min(axis=1)
            cand = cand[~(back > tol * (1.0 + norms[cand]))]  # keeps non-finite for detect_period
        if len(cand):
            per = detect_period(H_b[cand], max_period, tol)
            rec, per = cand[per > 0], per[per > 0]
            while len(rec):
                li, k = rec[0], int(per[0])
                pts = H_b[li, -k:]
                scale = 1.0 + np.abs(pts).max()
                found = next((ai for ai, (apts, ak, _) in enumerate(attractors)
                              if same_attractor(pts, k, apts, ak, merge_tol)), -1)
                if found < 0:
                    attractors.append([pts, k, np.nan])
                    found = len(attractors) - 1
                apts = attractors[found][0]
                last = H_b[rec, -1]
                same = (per == k) & (np.linalg.norm(last[:, None] - apts[None], axis=-1).min(axis=1)
                                     <= merge_tol * scale)
                same[0] = True
                lab[rec[same]] = found
                decided[rec[same]] = True
                rec, per = rec[~same], per[~same]
        # out of time -> unresolved
        decided |= age[busy] >= max_periods
        done = busy[decided]
        labels[cell[done]] = lab[decided]
        used[cell[done]] = age[done]
        cell[done] = -1
        bar.update(int(decided.sum()))
        bar.set_postfix_str(f"{len(busy) - int(decided.sum())} in flight, {len(attractors)} attractors", refresh=False)
    return labels, used


