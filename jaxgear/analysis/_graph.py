"""Hsu's analysis of a simple cell map: periodic groups and domains of attraction."""

from __future__ import annotations

import numpy as np

__all__ = ["analyze_cell_map"]


def analyze_cell_map(images: np.ndarray, n_cells: int | None = None) -> dict[str, np.ndarray]:
    """Periodic groups and domains of a simple cell map, vectorised (pointer doubling).

    Hsu's analysis of a simple cell map (paper §3; Hsu 1980): every cell's sequence ends
    in a periodic group (a cycle of cells) or in the sink; the cells ending in a group
    form its domain of attraction. Cells are integer indices (no units).

    Args:
        images: ``(n,)`` image of each regular cell; the value ``n`` is the sink, which
            maps to itself.
        n_cells: ``n`` (default ``len(images)``).
    Returns:
        A dict with ``group`` ``(n,)``: id of the periodic group each cell's sequence
        ends in (the smallest cell index of that cycle; ``n`` for the sink);
        ``periodic`` ``(n,)`` bool: the cell lies on a cycle (a periodic cell);
        ``groups``: sorted ids of the periodic groups (sink excluded);
        ``cycle_length``: number of cells of each group's cycle.

    After ``K >= log2(n+1)`` doublings ``f^(2^K)(i)`` lies on the cycle that cell ``i``
    ends in; the cycle's smallest index is the running minimum over ``2^K`` iterates.
    """
    images = np.asarray(images)
    n = len(images) if n_cells is None else int(n_cells)
    if images.dtype.kind not in "iu" or images.shape != (n,) or images.min(initial=0) < 0 or \
            images.max(initial=0) > n:
        raise ValueError(f"images must be an int array of shape ({n},) with values in 0..{n} (n = sink).")
    f = np.append(images.astype(np.int64), n)  # the sink maps to itself
    K = max(1, int(np.ceil(np.log2(n + 1))) + 1)
    m = np.arange(n + 1)
    P = f.copy()
    for _ in range(K):
        m = np.minimum(m, m[P])
        P = P[P]
    land = P  # f^(2^K)(i): on a cycle
    periodic = np.zeros(n + 1, dtype=bool)
    periodic[land] = True
    # m[i] is the minimum over f^j(i), j < 2^K: for a cycle cell, the whole cycle.
    group = m[land]
    groups, counts = np.unique(group[:n][periodic[:n]], return_counts=True)
    keep = groups != n
    return dict(group=group[:n], periodic=periodic[:n], groups=groups[keep], cycle_length=counts[keep])
