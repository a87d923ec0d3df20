"""One invariant curve seen as several attractors of boxes, and the test that joins them.

Near a resonance (a rotation number within 1e-5 of a rational p/q) the cloud of one start
on a quasi-periodic attractor is q tight clusters along its invariant curve, and starts at
other phases fill other clusters: their clouds share no boxes, so the lane pool reports one
torus as several quasi-periodic attractors (Datseris & Wagemakers 2022 note the same limit
of recurrences in boxes).

The test: the asymptotic phase along an attracting curve is continuous in the start, so
the states reached from starts spread along the segment that joins the nearest points of
two clouds move continuously from one cloud to the other when both lie on one curve
(neighbouring starts end about ``1 / JOIN_STARTS`` of the segment apart). Between two
distinct attractors the segment crosses a basin boundary, and neighbouring starts there
end on different attractors: a gap of at least the distance between them.
"""

from __future__ import annotations

import math

import numpy as np

from .._lyapunov import AttractorType
from ._orbits import advance_states

__all__ = ["JOIN_STARTS", "JOIN_GAP", "JOIN_CONTRACTION", "joined_tori"]

JOIN_STARTS = 128
"""Starts along the segment between two clouds."""
JOIN_GAP = 1 / 16
"""Two clouds are one curve when no two neighbouring starts end farther apart than this
fraction of the clouds' distance (one curve gives about 1/128; a basin boundary at least
the distance between the attractors)."""
JOIN_CONTRACTION = 30.0
"""e-foldings of the transverse contraction (the second exponent) the starts run for
before their ends are compared (between 50 and 2,000 periods)."""


def _nearest_pair(A: np.ndarray, B: np.ndarray):
    """The nearest points ``(a, b, distance)`` of two clouds (numpy, rows of A in chunks)."""
    best = (np.inf, 0, 0)
    for lo in range(0, len(A), 512):
        d = np.linalg.norm(A[lo:lo + 512, None, :] - B[None, :, :], axis=-1)
        i, j = np.unravel_index(np.argmin(d), d.shape)
        if d[i, j] < best[0]:
            best = (float(d[i, j]), lo + int(i), int(j))
    return A[best[1]], B[best[2]], best[0]


def joined_tori(system, params, integrator, clouds, kinds, exponents) -> np.ndarray | None:
    """Group ids ``(A,)`` of the attractors ``clouds`` (their points; ``kinds`` their
    :class:`~jaxgear.AttractorType` values, ``exponents`` their leading exponents per
    period) where two or more quasi-periodic ones are one curve (the module's test, every
    pair of them in one batch), else ``None``. Ids number the groups in order of first
    member; an attractor of another type is its own group."""
    torus = [i for i, k in enumerate(kinds) if int(k) == int(AttractorType.QUASI_PERIODIC)
             and len(exponents[i]) > 1 and exponents[i][1] < 0]
    pairs = [(i, j) for n, i in enumerate(torus) for j in torus[n + 1:]]
    if not pairs:
        return None
    s = np.linspace(0.0, 1.0, JOIN_STARTS)[:, None]
    starts, dist = [], []
    for i, j in pairs:
        a, b, d = _nearest_pair(*(np.asarray(c, float)[np.all(np.isfinite(c), axis=1)] for c in (clouds[i], clouds[j])))
        starts.append(a + s * (b - a))
        dist.append(d)
    rate = min(-exponents[i][1] for i in torus)
    periods = int(min(max(math.ceil(JOIN_CONTRACTION / rate), 50), 2000))
    ends = advance_states(system, params, np.concatenate(starts), periods, integrator).reshape(len(pairs),
                                                                                                 JOIN_STARTS, -1)
    gaps = np.linalg.norm(np.diff(ends, axis=1), axis=-1).max(axis=1)
    parent = list(range(len(clouds)))

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for (i, j), gap, d in zip(pairs, gaps, dist):
        if d > 0 and np.isfinite(gap) and gap < JOIN_GAP * d:
            parent[max(root(i), root(j))] = min(root(i), root(j))
    roots = [root(i) for i in range(len(clouds))]
    if len(set(roots)) == len(clouds):
        return None
    first = {r: n for n, r in enumerate(dict.fromkeys(roots))}
    return np.array([first[r] for r in roots], np.int64)
