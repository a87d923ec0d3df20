"""Period codes and distinct attractors of recorded stroboscopic sequences."""

from __future__ import annotations

import numpy as np

from .._lyapunov import AttractorType, attractor_label
from .._matching import pairwise_hausdorff
from ..analysis import detect_period

__all__ = ["ESCAPED", "APERIODIC", "classify_sequences", "group_starts", "period_label", "type_label", "label_order"]

ESCAPED = -1
"""Period code of a (value, start) whose motion left ``escape_bound`` or became non-finite."""
APERIODIC = 0
"""Period code when no period <= ``max_period`` recurs (quasi-periodic, chaotic or a slow transient)."""


def classify_sequences(points: np.ndarray, max_period: int, tol: float, bound: float) -> np.ndarray:
    """Period code of each recorded sequence ``points (..., R, dim)``: k, ``APERIODIC`` or ``ESCAPED``."""
    with np.errstate(invalid="ignore", over="ignore"):
        per = detect_period(points, max_period, tol)
        norms = np.linalg.norm(np.nan_to_num(points, nan=np.inf, posinf=np.inf), axis=-1)
        big = ~np.all(np.isfinite(points), axis=(-1, -2)) | (norms.max(axis=-1) > bound)
    return np.where(big, ESCAPED, per).astype(np.int64)


def group_starts(points: np.ndarray, period: np.ndarray, merge_tol: float) -> np.ndarray:
    """Distinct attractors among the starts of each row: ``points (..., S, M, dim)`` (the
    last M >= max_period recorded points), ``period (..., S)`` -> ids ``(..., S)``,
    numbered 0.. in order of first start; ``-1`` for escaped lanes.

    Two lanes are one attractor by the rule of :func:`jaxgear._matching.same_attractor`
    (same period, Hausdorff distance of their point sets within ``merge_tol * (1 + max
    |x|)``; all aperiodic lanes of a row form one set), vectorised over the rows.
    """
    lead = period.shape[:-1]
    S, M, dim = points.shape[-3:]
    P = points.reshape(-1, S, M, dim)
    K = period.reshape(-1, S)
    ids = np.full(K.shape, -1, dtype=np.int64)
    rows = max(1, int(2e6 // max(S * S * M * M * dim, 1)))
    ar = np.arange(S)
    for a in range(0, len(K), rows):
        p, k = P[a:a + rows], K[a:a + rows]
        with np.errstate(invalid="ignore"):
            h = pairwise_hausdorff(p, p)  # (r, S, S)
            scale = 1.0 + np.nanmax(np.abs(np.where(np.isfinite(p), p, np.nan)), axis=(1, 2, 3), initial=0.0)
        valid = k >= 0
        same = (k[:, :, None] == k[:, None, :]) & valid[:, :, None] & valid[:, None, :]
        same &= (k[:, :, None] == APERIODIC) | (h <= merge_tol * scale[:, None, None])
        first = np.argmax(same, axis=1)  # (r, S): first lane i that matches lane j
        is_rep = (first == ar) & valid
        rank = np.cumsum(is_rep, axis=1) - 1
        out = np.take_along_axis(rank, first, axis=1)
        ids[a:a + rows] = np.where(valid, out, -1)
    return ids.reshape(*lead, S)


def period_label(k: int) -> str:
    """``"P-k"``, ``"aperiodic"`` or ``"escaped"`` for a period code."""
    return f"P-{k}" if k > 0 else ("aperiodic" if k == APERIODIC else "escaped")


def type_label(k: int, kind: int) -> str:
    """Label of an attractor of period code ``k`` and type ``kind`` (an
    :class:`~jaxgear.AttractorType` value): ``"P-k"``; for period 0 that of
    :func:`~jaxgear._lyapunov.attractor_label`; ``"escaped"``."""
    if int(k) == APERIODIC:
        return attractor_label(0, kind)
    return period_label(k)


_APERIODIC_ORDER = {"quasi-periodic": 1, "chaotic": 2, "undetermined": 3, "aperiodic": 4}


def label_order(label: str):
    """Sort key of labels: P-1, P-2, ..., then quasi-periodic, chaotic, aperiodic, then escaped."""
    if label.startswith("P-"):
        return (0, int(label[2:]))
    return (1, _APERIODIC_ORDER[label]) if label in _APERIODIC_ORDER else (2, 0)


def carry_decided_types(kind: np.ndarray) -> np.ndarray:
    """The types ``(V, G)`` (:class:`~jaxgear.AttractorType` values) of the globally matched
    attractors of a sweep, where one the test left ``UNDETERMINED`` at a value takes the
    type the test decided for the same attractor at the nearest value (the earlier one on
    a tie); one never decided stays undetermined. A matched attractor keeps its type
    along the sweep unless the test says otherwise (its exponent and error stay as
    measured at every value)."""
    kind = np.asarray(kind)
    out = kind.copy()
    und = int(AttractorType.UNDETERMINED)
    decided = np.isin(kind, [int(AttractorType.PERIODIC), int(AttractorType.QUASI_PERIODIC),
                             int(AttractorType.CHAOTIC)])
    for v, g in zip(*np.nonzero(kind == und)):
        at = np.flatnonzero(decided[:, g])
        if len(at):
            out[v, g] = kind[at[np.argmin(np.abs(at - v) * 2 + (at > v))], g]  # nearest, the earlier on a tie
    return out
