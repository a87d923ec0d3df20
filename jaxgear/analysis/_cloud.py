"""The characterisation of a candidate for an attractor of boxes (Datseris & Wagemakers
2022; the method and its wiring into the lane pool: :mod:`jaxgear.analysis._recurrence`).

Pure functions the lane pool (:mod:`jaxgear.analysis._lanes`) calls once per round, on
its one candidate:

- :func:`near_cycle_lanes`, :func:`oldest_off_cycle` — per lane, whether it is approaching a
  cycle (its repetition errors within a box and shrinking; then no candidate), and the
  round's candidate among the oldest eligible lanes;
- :func:`attractor_cloud` (:func:`staged_cloud`), :func:`recurrence_share`, :func:`near_periodic`,
  :func:`overlap_shares` — a candidate's point cloud, whether it recurs, whether it is a
  cycle the point-level recognition will take, and which known attractor it overlaps;
- :func:`leaving_share` (:func:`continue_states`, :func:`settled_lanes`,
  :func:`verification_starts`, :func:`verify_length`) — the verification of a new
  attractor of boxes: the share of its points that leave it within ``verify_periods``
  periods (a chaotic saddle, a long chaotic transient, loses them at its escape rate; an
  attractor keeps them).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ._boxes import CellTable, FinePartition, cell_keys, lookup

__all__ = ["CLOUD_STAGES", "CONTINUE_SHARE", "CANDIDATE_POOL", "SHRINK", "ON_CYCLE", "SETTLED", "flat_cloud",
           "escaped", "attractor_cloud", "staged_cloud", "recurrence_share", "near_periodic", "near_cycle_lanes",
           "oldest_off_cycle", "continue_states", "settled_lanes", "verification_starts", "leaving_share", "verify_length",
           "overlap_shares"]

CLOUD_STAGES = 4
"""A candidate's cloud runs in this many stages; one whose stage ends on a cycle (or
escapes) stops there (a lane slowly approaching a cycle costs a quarter of a cloud)."""

CONTINUE_SHARE = 0.5
"""A candidate's cloud that ran to its end off a cycle with a recurrence share at least
this, but below ``accept_share``, runs once more as long, and the share of the
continuation's points in the boxes of the whole first cloud decides. On a torus the copies
stay together (a zero exponent), so each half of a cloud of ``P`` periods holds only about
``P / 2`` distinct points, too few to come back to every box of a long closed curve: the
generic torus of the forced van der Pol oscillator (mu = 0.1, F = 0.05, omega = 0.618)
gives 0.55-0.70 after 600 periods and 0.95-0.98 on the continuation, where a chaotic
attractor's copies, spread over it, give 0.9-1.0 at once."""

def attractor_cloud(system, params, integrator, y, *, periods: int, lanes: int, spread: float = 1e-7, key=None,
                    stages: int = 1, stop=None):
    """The stroboscopic points of ``lanes`` copies of the state ``y (dim,)`` over ``periods``
    forcing periods: ``(cloud (periods, dim, lanes), periods run)``.

    Copy 0 is ``y``; the others are moved by ``spread (1 + |y|)`` in random directions, so on
    a chaotic attractor they soon sample it independently (more of the attractor per period
    of wall time) while on a periodic one they stay together. The periods run as in
    :func:`staged_cloud` (``stages``, ``stop``).
    """
    dim = y.shape[0]
    key = jax.random.PRNGKey(0) if key is None else key
    d = jax.random.normal(key, (dim, lanes))
    d = d / jnp.linalg.norm(d, axis=0, keepdims=True)
    d = d.at[:, 0].set(0.0)
    Y0 = y[:, None] + spread * (1.0 + jnp.linalg.norm(y)) * d
    return staged_cloud(system, params, integrator, Y0, periods=periods, stages=stages, stop=stop)


def staged_cloud(system, params, integrator, Y0, *, periods: int, stages: int = 1, stop=None):
    """The stroboscopic points of the states ``Y0 (dim, K)`` (at phase 0) over ``periods``
    forcing periods: ``(cloud (periods, dim, K), periods run)``. The periods run in
    ``stages`` equal stages (``periods`` a multiple of ``stages``), each a ``lax.scan`` of
    the integrator's ``advance``; after each, ``stop(points of the stage (S, dim, K))``
    (optional, a traced bool) may end the cloud early: the rows not run are NaN."""
    if periods % stages:
        raise ValueError(f"periods={periods} must be a multiple of stages={stages}.")
    S = periods // stages
    dim, K = Y0.shape

    def step(Y, _):
        Y = integrator.advance(system, params, Y, jnp.asarray(0.0), 1)
        return Y, Y

    def body(c):
        j, Y, buf, _ = c
        Y, pts = jax.lax.scan(step, Y, None, length=S)
        buf = jax.lax.dynamic_update_slice_in_dim(buf, pts, j * S, axis=0)
        halt = jnp.asarray(False) if stop is None else stop(pts)
        return j + 1, Y, buf, halt

    buf = jnp.full((periods, dim, K), jnp.nan)
    j, _, buf, _ = jax.lax.while_loop(lambda c: (c[0] < stages) & ~c[3], body,
                                      (jnp.asarray(0, jnp.int32), Y0, buf, jnp.asarray(False)))
    return buf, j * S


def flat_cloud(cloud):
    """The points of ``cloud (P, dim, K)`` as columns ``(dim, P K)`` (periods and copies
    interleaved)."""
    P, dim, K = cloud.shape
    return jnp.moveaxis(cloud, 1, 0).reshape(dim, P * K)


def escaped(Y, bound):
    """Whether each state of ``Y (dim, ...)`` has escaped: its norm is above ``bound`` or not
    finite (the sink). The norm is summed coordinate by coordinate (XLA fuses this)."""
    return ~(jnp.sqrt(sum(Y[i] ** 2 for i in range(Y.shape[0]))) <= bound)


@jax.jit
def recurrence_share(partition: FinePartition, cloud):
    """Share of the second half's points of ``cloud (P, dim, K)`` whose box the first half
    visited (points outside the partition count as not recurring): near 1 on an attractor
    sampled long enough, small on a transient that is still moving on."""
    P = cloud.shape[0]
    k1 = jnp.sort(cell_keys(partition, flat_cloud(cloud[: P // 2])))
    k2 = cell_keys(partition, flat_cloud(cloud[P // 2:]))
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

    def search(_):
        oldest, lanes = jax.lax.top_k(jnp.where(eligible, age, -1), K)  # oldest first
        ok = (oldest >= 0) & ~near_cycle_lanes(ring(lanes), width, max_period)
        j = jnp.argmax(ok)
        return lanes[j].astype(jnp.int32), ok[j]

    # in most rounds no lane is eligible (its value quiet, or every lane in its transient or
    # tried since): no sort of the lanes then (the result is top_k's of no eligible lane)
    return jax.lax.cond(jnp.any(eligible), search, lambda _: (jnp.int32(0), jnp.asarray(False)), None)


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
    left = settled_lanes(pts, partition.width, max_period) | escaped(pts[0], bound)
    if elsewhere is not None:
        left = left | elsewhere(pts)
    return jnp.mean(left.astype(jnp.float64))


@functools.partial(jax.jit, static_argnames="n_labels")
def overlap_shares(table: CellTable, keys, n_labels: int):
    """Share of the points whose box keys are ``keys (m,)`` (:func:`~jaxgear.analysis._boxes.cell_keys`,
    or :func:`~jaxgear.analysis._boxes.row_keys` in a pool of several values) lying in boxes
    of each label ``0 .. n_labels - 1`` of the table: ``(n_labels,)``. A new cloud whose
    share on a known attractor is large is that attractor (matching by occupied boxes, not
    by point distance)."""
    lab = lookup(table, keys)
    return jnp.mean((lab[None] == jnp.arange(n_labels, dtype=jnp.int32)[:, None]).astype(jnp.float64), axis=1)


def verify_length(options, max_period: int) -> int:
    """Periods the verification of a new attractor of boxes runs: ``verify_periods``, and
    at least ``2 max_period`` (the history :func:`settled_lanes` judges)."""
    return max(int(options.verify_periods), 2 * int(max_period))
