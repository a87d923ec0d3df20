"""Warnings that say when a global-analysis result looks unreliable, and what to change."""

from __future__ import annotations

import warnings

import numpy as np

from .._lyapunov import AttractorType
from ._cellmap import PoincareCellMap, StroboscopicCellMap
from ._orbits import LONG_CYCLE_FACTOR
from ._result import GlobalResult

__all__ = ["warn_if_unreliable", "MIN_CELLS"]

MIN_CELLS = 10
"""Cell methods: an attractor resolved by fewer cells triggers a 'refine the grid' warning."""


def warn_if_unreliable(r: GlobalResult) -> None:
    """Warn when a result looks unreliable, naming what the user can change.

    - many sink cells (> 20 %): cell methods -> enlarge the region (the grid's bounds,
      ``--region``); direct -> unbounded motion or a blow-up of the integration
      (``steps_per_period``, ``escape_bound``);
    - an attractor's points on or beyond the region's edge -> enlarge the region;
    - period detection at its limit: an attractor with no period <= ``max_period``
      -> raise ``max_period`` / ``settle_periods``; many unresolved cells (> 1 %, direct)
      -> raise ``max_periods`` / ``saddle_periods`` / ``max_period``;
    - cell methods: an attractor resolved by fewer than ``MIN_CELLS`` cells, or a P-k
      whose k points share cells (stroboscopic) -> refine the grid (more cells).
    """
    m = r.method
    n = r.n_cells
    cell_method = isinstance(m, (PoincareCellMap, StroboscopicCellMap))
    if r.n_sink > 0.2 * n:
        if cell_method:
            warnings.warn(f"{100 * r.n_sink / n:.1f} % of the cells went to the sink (their images left the "
                          f"region): enlarge the region (the CellGrid bounds, --region), or check for unbounded "
                          f"motion.", stacklevel=3)
        else:
            warnings.warn(f"{100 * r.n_sink / n:.1f} % of the cells went to the sink (the motion blew up or "
                          f"exceeded escape_bound={getattr(m, 'escape_bound', None)}): check for unbounded motion, raise "
                          f"steps_per_period (now {getattr(m.integrator, 'steps_per_period', None)}) if the integration blew up, or raise "
                          f"escape_bound.", stacklevel=3)
    if r.n_unresolved > 0.01 * n:
        warnings.warn(f"{r.n_unresolved} cells ({100 * r.n_unresolved / n:.1f} %) were not resolved within "
                      f"max_periods={getattr(m, 'max_periods', None)} periods ({_saddle_limit(m)} where a chaotic saddle "
                      f"was found): raise max_periods (slow transients), saddle_periods (a long chaotic transient), "
                      f"or max_period (now {m.max_period}) if the motion has a longer period, or period_tol.",
                      stacklevel=3)
    g = r.grid
    for a in r.attractors:
        typed = getattr(m, "recurrence", None) is not None and a.type in (AttractorType.CHAOTIC,
                                                                         AttractorType.QUASI_PERIODIC)
        if a.type == AttractorType.UNDETERMINED:
            warnings.warn(f"attractor {a.id}: its type is not decided: {a.type_reason}.", stacklevel=3)
        elif a.period == 0 and not typed:  # a cell group with no period, or a cycle found by its boxes
            warnings.warn(f"attractor {a.id} showed no period <= max_period={m.max_period}"
                          + (" and its largest Lyapunov exponent is negative: a cycle whose period is above "
                             f"{LONG_CYCLE_FACTOR * m.max_period} (or that converges slowly)"
                             if a.type == AttractorType.PERIODIC else
                             ": it may have a longer period, be quasi-periodic or chaotic, or be a slow transient")
                          + "; raise max_period (or settle_periods).", stacklevel=3)
        pts = np.asarray(a.points)
        if len(pts):
            for j, ax in enumerate(g.axes):
                lo, hi = g.lower[j], g.upper[j]
                h = 0.02 * (hi - lo)
                if np.any(pts[:, ax] < lo + h) or np.any(pts[:, ax] > hi - h):
                    warnings.warn(f"attractor {a.id} ({a.label}) lies on or beyond the region's edge along "
                                  f"{g.axis_names[j]} (region [{lo:g}, {hi:g}]): enlarge the region (the CellGrid "
                                  f"bounds, --region).", stacklevel=3)
                    break
        if cell_method and a.cell_count < MIN_CELLS:
            warnings.warn(f"attractor {a.id} ({a.label}) was resolved by only {a.cell_count} cell(s): its domain and "
                          f"share are unreliable; refine the grid (more cells per axis, --grid).", stacklevel=3)
        elif isinstance(m, StroboscopicCellMap) and 0 < len(a.periodic_cells) < a.period:
            warnings.warn(f"the {a.period} points of attractor {a.id} ({a.label}) fall into only "
                          f"{len(a.periodic_cells)} cell(s): the cells are too coarse to separate them; refine the "
                          f"grid (more cells per axis, --grid).", stacklevel=3)


def _saddle_limit(m) -> str:
    """The periods a cell of a value with a chaotic saddle may run under the method ``m``."""
    pool = getattr(m, "pool", None)
    return f"saddle_periods={pool.saddle_limit}" if pool is not None else "saddle_periods"
