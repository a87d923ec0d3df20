"""Phase trajectory of a periodic orbit with its stroboscopic and section points (paper Fig. 3-6),
and Floquet multipliers against the unit circle."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from .._poincare import sample_trajectory
from .._system import ForcedSystem
from ..integrate import AbstractIntegrator
from ._style import attractor_color


def _section_crossings(states: np.ndarray, index: int) -> np.ndarray:
    """Upward crossings of ``x_index = 0`` in sampled states ``(m, dim)``, linearly interpolated."""
    g = states[:, index]
    i = np.flatnonzero((g[:-1] < 0) & (g[1:] >= 0))
    w = (-g[i] / (g[i + 1] - g[i]))[:, None]
    return states[i] + w * (states[i + 1] - states[i])


def plot_orbit(system, params=None, orbit=None, coords: Sequence[int] = (0, 1), *, t0=None,
               periods: int | None = None, samples_per_period: int | None = None, section: bool = True,
               integrator: AbstractIntegrator | None = None, title: str | None = None) -> Figure:
    """Phase trajectory of a periodic orbit, projected on two or three coordinates (paper Fig. 3-6).

    Draws the trajectory over the orbit's period (``periods`` forcing periods, default
    its period ``m``) with its stroboscopic points (state at ``t0 + jT``, the fixed
    points of ``P^m``) marked and numbered; with ``section`` and a system that has a
    section index, also the crossings of the paper's hyperplane Σ = {x_i = 0} in the
    increasing direction (interpolated between samples).

    Two forms:

    - ``plot_orbit(system, params, orbit, coords)``: ``orbit`` a
      :class:`~jaxgear.PeriodicOrbit` (or anything with ``.points``) or the points
      ``(m, dim)`` themselves. An orbit that carries its sampled trajectory (orbits of
      :func:`~jaxgear.find_periodic_orbits`, also after loading) is drawn from it
      without integrating, unless ``periods``, ``samples_per_period`` or ``t0`` ask for
      something else; otherwise the trajectory is integrated from ``points[0]``.
    - ``plot_orbit(search, i, coords)`` or ``plot_orbit(search, orbit=i)``: orbit
      ``i`` of an :class:`~jaxgear.OrbitSearch` (e.g. from :func:`jaxgear.load`),
      drawn from its stored trajectory; no system, parameters or integration needed.

    Args:
        coords: two or three coordinate indices (e.g. ``(0, 1)`` for x1-x2 or
            ``(0, 1, 2)`` for x1-x2-x3).
        t0: phase of the points (system time unit; default the orbit's ``t0``, else 0).
        samples_per_period: samples per forcing period when integrating (default 200).
    Returns:
        a :class:`matplotlib.figure.Figure` (no pyplot state).
    """
    from ..shooting import OrbitSearch

    if isinstance(system, OrbitSearch):
        search = system
        i = orbit if orbit is not None else (params if params is not None else 0)
        if not isinstance(i, (int, np.integer)) or not 0 <= int(i) < len(search.orbits):
            raise ValueError(f"orbit must be an index in 0..{len(search.orbits) - 1} of the search's orbits, got {i!r}.")
        orbit = search.orbits[int(i)]
        if orbit.trajectory is None:
            raise ValueError("this orbit has no stored trajectory (trajectory_samples=0): call "
                             "plot_orbit(system, params, orbit) to integrate it.")
        names = tuple(search.state_names) or tuple(f"x{j + 1}" for j in range(orbit.points.shape[1]))
        dim, section_index, sys_name = len(names), search.section_index, search.system
    elif isinstance(system, ForcedSystem):
        if orbit is None:
            raise ValueError("plot_orbit(system, params, orbit): give the orbit (a PeriodicOrbit or its points).")
        names, dim, section_index, sys_name = system.state_names, system.dim, system.section_index, system.name
    else:
        raise TypeError(f"plot_orbit needs a ForcedSystem (with params and orbit) or an OrbitSearch, "
                        f"got {type(system).__name__}.")
    pts = np.atleast_2d(np.asarray(getattr(orbit, "points", orbit), dtype=float))
    if pts.ndim != 2 or pts.shape[1] != dim:
        raise ValueError(f"orbit points must have shape (m, {dim}), got {pts.shape}.")
    coords = tuple(int(c) for c in coords)
    if len(coords) not in (2, 3) or not all(0 <= c < dim for c in coords):
        raise ValueError(f"coords must be 2 or 3 indices in 0..{dim - 1}, got {coords}.")
    m = len(pts)
    stored = getattr(orbit, "trajectory", None)
    own_t0 = float(getattr(orbit, "t0", 0.0))
    use_stored = (stored is not None and periods in (None, m)
                  and samples_per_period in (None, getattr(orbit, "samples_per_period", -1))
                  and (t0 is None or float(t0) == own_t0))
    if use_stored:
        states = np.asarray(stored)
    else:
        if not isinstance(system, ForcedSystem):
            raise ValueError("the requested periods/samples/t0 differ from the stored trajectory: "
                             "call plot_orbit(system, params, orbit, ...) to integrate.")
        _, states = sample_trajectory(system, params, pts[0], periods=m if periods is None else int(periods),
                                      samples_per_period=int(samples_per_period or 200),
                                      t0=own_t0 if t0 is None else t0, integrator=integrator)
        states = np.asarray(states)
    fig = Figure(figsize=(6.0, 5.0))
    ax = fig.add_subplot(projection="3d" if len(coords) == 3 else None)
    proj = lambda a: [a[:, c] for c in coords]
    ax.plot(*proj(states), lw=0.9, color="#1f77b4", label="trajectory")
    ax.scatter(*proj(pts), s=36, color="#d62728", zorder=3, label="stroboscopic points (t0 + jT)")
    for j, p in enumerate(pts):
        ax.text(*(p[c] for c in coords), f" {j + 1}", fontsize=8, color="#d62728")
    if section and section_index is not None and section_index not in coords:
        cross = _section_crossings(states, section_index)
        if len(cross):
            ax.scatter(*proj(cross), s=30, marker="x", color="#2ca02c", zorder=3,
                       label=f"crossings of {names[section_index]} = 0")
    ax.set_xlabel(names[coords[0]])
    ax.set_ylabel(names[coords[1]])
    if len(coords) == 3:
        ax.set_zlabel(names[coords[2]])
    period = getattr(orbit, "period", m)
    ax.set_title(title or f"P-{period} orbit of {sys_name}")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return fig


def plot_multipliers(orbits, *, labels: Sequence[str] | None = None, title: str | None = None) -> Figure:
    """Floquet multipliers of periodic orbits in the complex plane with the unit circle (paper §4.1).

    A periodic orbit is asymptotically stable when all its multipliers lie inside the
    unit circle; it loses stability where one leaves it: through +1 (fold), through
    -1 (flip, period doubling) or as a complex pair (Neimark-Sacker).

    Args:
        orbits: an :class:`~jaxgear.OrbitSearch` (e.g. loaded from disk), or a sequence of
            :class:`~jaxgear.PeriodicOrbit` (anything with ``.multipliers (dim,)`` complex
            and ``.period``).
        labels: legend label per orbit (default ``"P-m stable"`` / ``"P-m flip"``, ...).
    Returns:
        a :class:`matplotlib.figure.Figure` with one axes: one marker set per orbit and
        the unit circle (no integration).
    """
    orbits = list(getattr(orbits, "orbits", orbits))
    if labels is not None and len(labels) != len(orbits):
        raise ValueError(f"labels: need one per orbit ({len(orbits)}), got {len(labels)}.")
    fig = Figure(figsize=(5.5, 5.0), layout="constrained")
    ax = fig.add_subplot()
    th = np.linspace(0.0, 2.0 * np.pi, 361)
    ax.plot(np.cos(th), np.sin(th), color="k", lw=0.8, label="|λ| = 1")
    markers = "os^Dv<>ph*"
    rmax = 1.0
    for i, o in enumerate(orbits):
        lam = np.asarray(o.multipliers, dtype=complex)
        rmax = max(rmax, float(np.max(np.abs(lam))) if lam.size else 1.0)
        kind = getattr(o, "instability", "")
        lab = labels[i] if labels is not None else f"P-{getattr(o, 'period', '?')} {kind}".strip()
        ax.scatter(lam.real, lam.imag, s=46, marker=markers[i % len(markers)], color=attractor_color(i),
                   edgecolors="k", linewidths=0.4, zorder=3, label=lab)
    lim = 1.1 * rmax
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.axhline(0.0, color="0.8", lw=0.6, zorder=0)
    ax.axvline(0.0, color="0.8", lw=0.6, zorder=0)
    ax.set_xlabel("Re λ")
    ax.set_ylabel("Im λ")
    ax.set_title(title or "Floquet multipliers")
    ax.legend(fontsize="small", loc="best")
    return fig
