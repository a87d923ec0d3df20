"""Seeds for shooting: the points of a global-analysis result, or random points of a box."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["seeds_from_result", "seeds_in_box"]


def seeds_from_result(result) -> dict[int, np.ndarray]:
    """Shooting seeds from a cell-mapping (or any) result: ``{k: (n_k, dim) points}``.

    ``result`` is any object with ``.attractors``, a sequence of objects with ``.points``
    (array ``(k, dim)`` of stroboscopic points) and ``.period`` (int ``k``). Every point
    of a P-k attractor becomes a seed for ``P^k`` (cell centres are approximate, so each
    point is one more chance for Newton). Attractors of the same period are grouped;
    non-periodic attractors (period 0) and non-finite points are skipped. This is the
    paper's sequence (§4): the global analysis locates the attractors, shooting
    (§4.1) makes them exact. Points in state units at the result's phase (phase 0).
    """
    attractors = getattr(result, "attractors", None)
    if attractors is None:
        raise ValueError("seeds_from_result needs an object with .attractors (a sequence of objects "
                         "with .points (k, dim) and .period).")
    groups: dict[int, list[np.ndarray]] = {}
    dim = None
    for i, a in enumerate(attractors):
        if int(a.period) < 1:
            continue  # non-periodic attractor (period 0): nothing to shoot for
        k = int(a.period)
        pts = np.atleast_2d(np.asarray(a.points, dtype=float))
        if pts.ndim != 2:
            raise ValueError(f"attractor {i}: .points must have shape (k, dim), got {pts.shape}.")
        if dim is not None and pts.shape[1] != dim:
            raise ValueError(f"attractor {i}: state dimension {pts.shape[1]} differs from {dim}.")
        dim = pts.shape[1]
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts):
            groups.setdefault(k, []).append(pts)
    return {k: np.concatenate(v, axis=0) for k, v in sorted(groups.items())}


def seeds_in_box(n: int, low, high, *, seed: int = 0) -> np.ndarray:
    """``n`` seeds uniformly distributed in the box ``low <= x <= high``: ``(n, dim)``.

    ``low``, ``high``: ``(dim,)`` bounds in state units (e.g. the paper's region D,
    eq. 10, extended by a range of ``x4``); ``seed`` fixes the random draw (JAX PRNG),
    so the same call gives the same seeds. Seeds for :func:`find_periodic_orbits`.
    """
    low = np.asarray(low, dtype=float)
    high = np.asarray(high, dtype=float)
    if low.shape != high.shape or low.ndim != 1:
        raise ValueError(f"box bounds must be two 1-D arrays of equal length, got {low.shape} and {high.shape}.")
    if not np.all(high > low):
        raise ValueError(f"box bounds need high > low in every coordinate, got low={low}, high={high}.")
    if int(n) < 1:
        raise ValueError(f"n={n} seeds: must be >= 1.")
    u = jax.random.uniform(jax.random.PRNGKey(int(seed)), (int(n), low.size), dtype=jnp.float64)
    return np.asarray(low + (high - low) * np.asarray(u))

