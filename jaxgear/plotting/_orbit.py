"""Phase trajectory of a periodic orbit with its stroboscopic and section points (paper Fig. 3-6)."""

from __future__ import annotations

from typing import Sequence

import numpy as np
from matplotlib.figure import Figure

from .._integrate import RK4, Integrator
from .._poincare import sample_trajectory
from .._system import ForcedSystem


def _section_crossings(states: np.ndarray, index: int) -> np.ndarray:
    """Upward crossings of ``x_index = 0`` in sampled states ``(m, dim)``, linearly interpolated."""
    g = states[:, index]
    i = np.flatnonzero((g[:-1] < 0) & (g[1:] >= 0))
    w = (-g[i] / (g[i + 1] - g[i]))[:, None]
    return states[i] + w * (states[i + 1] - states[i])


def plot_orbit(system: ForcedSystem, params, orbit, coords: Sequence[int] = (0, 1), *, t0=0.0,
               periods: int | None = None, samples_per_period: int = 200, section: bool = True,
               integrator: Integrator = RK4(), title: str | None = None) -> Figure:
    """Phase trajectory of a periodic orbit, projected on two or three coordinates.

    Integrates one full orbit from its first stroboscopic point (``periods`` forcing
    periods, default its period ``m``) and draws the trajectory with its stroboscopic
    points (state at ``t0 + jT``, the fixed points of ``P^m``) marked and numbered;
    with ``section`` and a system that has a section index, also the crossings of the
    paper's hyperplane Σ = {x_i = 0} in the increasing direction (interpolated between
    samples). The paper's Figures 3-6 are such projections.

    Args:
        orbit: a :class:`~jaxgear.PeriodicOrbit` (or anything with ``.points``), or
            the points ``(m, dim)`` themselves.
        coords: two or three coordinate indices (e.g. ``(0, 1)`` for x1-x2 or
            ``(0, 1, 2)`` for x1-x2-x3).
    Returns:
        a :class:`matplotlib.figure.Figure` (no pyplot state).
    """
    pts = np.atleast_2d(np.asarray(getattr(orbit, "points", orbit), dtype=float))
    if pts.ndim != 2 or pts.shape[1] != system.dim:
        raise ValueError(f"orbit points must have shape (m, {system.dim}), got {pts.shape}.")
    coords = tuple(int(c) for c in coords)
    if len(coords) not in (2, 3) or not all(0 <= c < system.dim for c in coords):
        raise ValueError(f"coords must be 2 or 3 indices in 0..{system.dim - 1}, got {coords}.")
    m = len(pts)
    periods = m if periods is None else int(periods)
    _, states = sample_trajectory(system, params, pts[0], periods=periods, samples_per_period=samples_per_period,
                                  t0=t0, integrator=integrator)
    states = np.asarray(states)
    names = system.state_names
    fig = Figure(figsize=(6.0, 5.0))
    ax = fig.add_subplot(projection="3d" if len(coords) == 3 else None)
    proj = lambda a: [a[:, c] for c in coords]
    ax.plot(*proj(states), lw=0.9, color="#1f77b4", label="trajectory")
    ax.scatter(*proj(pts), s=36, color="#d62728", zorder=3, label="stroboscopic points (t0 + jT)")
    for j, p in enumerate(pts):
        ax.text(*(p[c] for c in coords), f" {j + 1}", fontsize=8, color="#d62728")
    idx = system.section_index
    if section and idx is not None and idx not in coords:
        cross = _section_crossings(states, idx)
        if len(cross):
            ax.scatter(*proj(cross), s=30, marker="x", color="#2ca02c", zorder=3,
                       label=f"crossings of {names[idx]} = 0")
    ax.set_xlabel(names[coords[0]])
    ax.set_ylabel(names[coords[1]])
    if len(coords) == 3:
        ax.set_zlabel(names[coords[2]])
    period = getattr(orbit, "period", m)
    ax.set_title(title or f"P-{period} orbit of {system.name}")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return fig
