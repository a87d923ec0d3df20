"""Is this the same attractor? One answer, used by every analysis.

An attractor is represented by its stroboscopic points (the ``k`` states of a P-k
orbit at forcing phase 0, in any order and any cyclic shift) and its period ``k``
(0: no period found — quasi-periodic, chaotic or a slow transient; negative: escaped).
Two attractors are the same when their periods agree and the symmetric Hausdorff
distance of their point sets is at most ``tol * (1 + max |x|)`` (state units, ``tol``
relative); two attractors that repeat no point (period 0: quasi-periodic, chaotic) are the
same when their point clouds occupy the same boxes (:func:`same_cloud`); every escape
counts as one.

Used by the global analysis (merging cell-map groups and recurrences of the direct
method, reducing a period to the minimal one), shooting (deduplicating converged
seeds), sweeps (grouping the starts of one parameter value, matching attractors
across values: :func:`match_attractors`, cycles by distance, clouds by the overlap of
their boxes) and the comparison of two results.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "hausdorff",
    "pairwise_hausdorff",
    "attractor_scale",
    "same_attractor",
    "same_cloud",
    "cloud_overlap",
    "group_attractors",
    "match_attractors",
    "minimal_cycle",
]


def _distances(A, B, xp):
    return xp.linalg.norm(A[..., :, None, :] - B[..., None, :, :], axis=-1)


def hausdorff(A, B, xp=np):
    """Symmetric Hausdorff distance of two point sets ``A (k, dim)`` and ``B (m, dim)``.

    Invariant to the order of the points (so to cyclic shifts of a cycle); state units.
    ``xp`` is ``numpy`` (default) or ``jax.numpy`` (inside compiled code).
    """
    d = _distances(A, B, xp)
    return xp.maximum(d.min(axis=-1).max(axis=-1), d.min(axis=-2).max(axis=-1))


def pairwise_hausdorff(P, Q, xp=np):
    """Hausdorff distance of every pair of point sets: ``P (..., S, M, dim)``,
    ``Q (..., T, M', dim)`` -> ``(..., S, T)``."""
    d = _distances(P[..., :, None, :, :], Q[..., None, :, :, :], xp)  # (..., S, T, M, M')
    return xp.maximum(d.min(axis=-1).max(axis=-1), d.min(axis=-2).max(axis=-1))


def attractor_scale(*point_sets) -> float:
    """``1 + max |x|`` over the finite coordinates of the given point sets."""
    m = 0.0
    for P in point_sets:
        P = np.asarray(P, dtype=float)
        if P.size and np.any(np.isfinite(P)):
            m = max(m, float(np.nanmax(np.abs(np.where(np.isfinite(P), P, np.nan)))))
    return 1.0 + m


def same_attractor(A, k_a: int, B, k_b: int, tol: float) -> bool:
    """True when ``(A, k_a)`` and ``(B, k_b)`` are the same attractor (see the module).

    ``A``, ``B``: stroboscopic points ``(k, dim)``; ``k_a``, ``k_b``: periods (0
    non-periodic, negative escaped); ``tol``: relative distance tolerance.
    """
    if int(k_a) != int(k_b):
        return False
    if int(k_a) == 0:
        return same_cloud(A, B)
    if int(k_a) < 0:
        return True
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    if not (len(A) and len(B)):
        return False
    return bool(hausdorff(A, B) <= tol * attractor_scale(A, B))


CLOUD_BOXES = 32
"""Boxes per axis across the joint bounding box of two clouds compared by :func:`same_cloud`."""

MATCH_CLOUD_DISTANCE = 0.5
"""Largest overlap distance ``1 - cloud_overlap`` of two clouds :func:`match_attractors` matches."""


def cloud_overlap(A, B, boxes: int = CLOUD_BOXES, width: float | None = None) -> float:
    """Share of the boxes occupied by the cloud ``A (m, dim)`` or ``B (n, dim)``, whichever
    occupies fewer, that the other cloud occupies too (0 to 1; 0 when either has no
    finite point): the box counting of Datseris & Wagemakers 2022. Boxes divide the joint
    bounding box of the clouds into ``boxes`` per axis, or (``width``, state units) are
    the cubes of that edge of a lattice through the origin, the same for every pair."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    A, B = A[np.all(np.isfinite(A), axis=1)], B[np.all(np.isfinite(B), axis=1)]
    if not (len(A) and len(B)):
        return 0.0
    if width is None:
        lo = np.minimum(A.min(axis=0), B.min(axis=0))
        ext = np.maximum(A.max(axis=0), B.max(axis=0)) - lo
        w = np.where(ext > 0, ext, 1.0) / int(boxes)
    else:
        lo, w = np.zeros(A.shape[1]), float(width)
    boxes_a = set(map(tuple, np.floor((A - lo) / w).astype(np.int64)))
    boxes_b = set(map(tuple, np.floor((B - lo) / w).astype(np.int64)))
    return len(boxes_a & boxes_b) / min(len(boxes_a), len(boxes_b))


def same_cloud(A, B, share: float = 0.5) -> bool:
    """Whether the point clouds ``A (m, dim)`` and ``B (n, dim)`` of two attractors that
    repeat no point (quasi-periodic, chaotic) are one attractor: matched by the boxes they
    occupy, not by point distance (Datseris & Wagemakers 2022). Boxes divide their joint
    bounding box into :data:`CLOUD_BOXES` per axis; they are one attractor when at least
    ``share`` of the boxes of the cloud with fewer boxes lie among the other's
    (:func:`cloud_overlap`)."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    if not (np.all(np.isfinite(A), axis=-1).any() and np.all(np.isfinite(B), axis=-1).any()):
        return False
    return cloud_overlap(A, B) >= share


def group_attractors(sets: Sequence[tuple[np.ndarray, int]], tol: float) -> np.ndarray:
    """Group attractor candidates ``[(points, period), ...]``: ``(n,)`` ids numbered 0.. in
    order of first appearance; a candidate joins the first earlier group it is the
    same attractor as (:func:`same_attractor` against that group's first member)."""
    ids = np.full(len(sets), -1, dtype=np.int64)
    reps: list[int] = []
    for i, (pts, k) in enumerate(sets):
        for g, r in enumerate(reps):
            if same_attractor(pts, k, sets[r][0], sets[r][1], tol):
                ids[i] = g
                break
        else:
            reps.append(i)
            ids[i] = len(reps) - 1
    return ids


def _match_distance(c, kc: int, p, kp: int, width: float) -> float:
    """Distance of a current and a previous attractor for :func:`match_attractors`: the
    Hausdorff distance of two cycles' point sets (state units), ``1 - cloud_overlap`` of
    two clouds (period 0) on the boxes of edge ``width``, inf for a cycle and a cloud
    (never the same attractor) or an empty point set."""
    c, p = np.asarray(c, dtype=float), np.asarray(p, dtype=float)
    if (int(kc) == 0) != (int(kp) == 0) or not (len(c) and len(p)):
        return np.inf
    if int(kc) == 0:
        return 1.0 - cloud_overlap(c, p, width=width)
    return float(hausdorff(c, p))


def match_attractors(previous: Sequence[tuple[np.ndarray, int]], current: Sequence[tuple[np.ndarray, int]],
                     max_distance: float, max_cloud_distance: float = MATCH_CLOUD_DISTANCE) -> np.ndarray:
    """Match the attractors of one parameter value to those of the previous value.

    Greedy, closest pairs first (at equal distance a pair of the same period first).
    Cycles (period ``k != 0``) are compared by the Hausdorff distance of their point sets
    (state units), pairs farther apart than ``max_distance`` unmatched; attractors that
    repeat no point (period 0, quasi-periodic or chaotic: clouds of points) by the boxes
    they occupy, not by point distance: the distance ``1 - cloud_overlap`` on the cubes
    of edge ``max_distance / 2`` of a lattice through the origin (:func:`cloud_overlap`;
    the same scale as the cycles', so an attractor that moves by a small part of
    ``max_distance`` between the values keeps most of its boxes), pairs farther apart
    than ``max_cloud_distance`` unmatched; a cycle never matches a cloud. Returns
    ``(len(current),)``: the index into ``previous`` of each current attractor's match,
    or -1.
    """
    out = np.full(len(current), -1, dtype=np.int64)
    if not previous or not current:
        return out
    D = np.array([[_match_distance(c, kc, p, kp, 0.5 * max_distance) for p, kp in previous] for c, kc in current])
    cloud = np.array([[int(kc) == 0 for _ in previous] for _, kc in current])
    ok = D <= np.where(cloud, max_cloud_distance, max_distance)
    same = np.array([[kc == kp for _, kp in previous] for _, kc in current])
    used = np.zeros(len(previous), bool)
    for flat in np.lexsort((~same.ravel(), D.ravel())):
        i, j = divmod(int(flat), len(previous))
        if ok[i, j] and out[i] < 0 and not used[j]:
            out[i] = j
            used[j] = True
    return out


def minimal_cycle(points: np.ndarray, k: int, tol: float) -> tuple[np.ndarray, int]:
    """Reduce a P-k cycle to its minimal period: the smallest divisor ``j`` of ``k`` with
    ``points`` equal to themselves shifted by ``j`` within ``tol * (1 + max |x|)``.

    A slowly spiralling transient (complex multipliers rotating by about 2 pi / k per
    period) can pass a recurrence test at a multiple of the true period; its refined
    points then repeat with a smaller period. Returns ``(points[:j], j)``.
    """
    pts = np.asarray(points)
    if k > 1 and len(pts) == k and np.all(np.isfinite(pts)):
        scale = tol * attractor_scale(pts)
        for j in (d for d in range(1, k) if k % d == 0):
            if np.max(np.linalg.norm(pts - np.roll(pts, -j, axis=0), axis=1)) <= scale:
                return pts[:j], j
    return pts, int(k)
