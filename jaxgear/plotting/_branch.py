"""Continuation branch: a solution measure against the parameter, stability and bifurcations."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ._style import attractor_color

_MARKERS = {"PD": ("o", "#d62728"), "SN": ("s", "#2ca02c"), "NS": ("D", "#9467bd"), "BP": ("^", "#ff7f0e")}


def _measure(branch, coordinate):
    """``(m, k)`` values to draw, ``(B, k)`` at the bifurcations, and the axis label."""
    from .._system import state_index
    from ..continuation import bifurcation_orbit

    k = branch.period
    orbits = [bifurcation_orbit(b, k) for b in branch.bifurcations]
    if coordinate in ("norm", "|x|"):
        y = np.linalg.norm(branch.points, axis=-1).max(axis=1, keepdims=True)
        yb = np.array([[np.linalg.norm(o, axis=-1).max()] for o in orbits]).reshape(-1, 1)
        return y, yb, "max ||x|| over the stroboscopic points"
    j = state_index(branch.state_names, 0 if coordinate is None else coordinate)
    y = branch.points[:, :, j]
    yb = np.array([o[:, j] for o in orbits]).reshape(-1, k)
    return y, yb, f"{branch.state_names[j]} (stroboscopic points)"


def _bottom_row(ax) -> bool:
    spec = ax.get_subplotspec() if hasattr(ax, "get_subplotspec") else None
    return spec is None or spec.is_last_row()


def _nodes(branch, y, yb):
    """Branch points with the located bifurcations inserted in arclength order.

    Returns ``(p, Y, lam, seg_stable)``: parameter ``(n,)``, values ``(n, k)``, largest
    ``|lambda|`` ``(n,)`` and the stability of the segment from node ``i`` to ``i + 1``
    ``(n - 1,)`` (so stability changes at the bifurcation, not at the next step).
    """
    stable = np.asarray(branch.stable, bool)
    lam = branch.max_multiplier
    after = {}
    for b_i, bif in enumerate(branch.bifurcations):
        after.setdefault(int(bif.index), []).append(b_i)
    P, Y, L, right = [], [], [], []
    for i in range(len(branch)):
        P.append(branch.values[i]), Y.append(y[i]), L.append(lam[i]), right.append(stable[i])
        if i + 1 < len(branch):
            # bifurcations between i and i + 1, ordered by distance from point i
            bs = sorted(after.get(i, []), key=lambda j: abs(branch.bifurcations[j].param_value - branch.values[i]))
            for j in bs:
                bif = branch.bifurcations[j]
                P.append(bif.param_value), Y.append(yb[j]), L.append(np.max(np.abs(bif.multipliers)))
                right.append(stable[i + 1])
    return np.array(P), np.array(Y).reshape(len(P), -1), np.array(L), np.array(right[:-1], bool)


def _runs(seg_stable: np.ndarray):
    """Node ranges ``(start, stop, stable)`` of segments of constant stability (``stop`` inclusive + 1)."""
    out = []
    start = 0
    n = len(seg_stable)
    for i in range(1, n + 1):
        if i == n or seg_stable[i] != seg_stable[start]:
            out.append((start, i + 1, bool(seg_stable[start])))
            start = i
    return out


def plot_branch(branch, coordinate: str | int | None = None, ax=None, *, multipliers: bool = False,
                color: str | None = None, label: str | None = None, annotate: bool = True,
                title: str | None = None) -> Figure:
    """Draw a :class:`~jaxgear.Branch`: a solution measure against the parameter.

    Stable parts (all ``|lambda| < 1``) are solid, unstable parts dashed; located
    bifurcations are marked and labelled (PD circle, SN square, NS diamond, BP
    triangle; a nonsmooth one gets a ``*``). For a P-k branch the ``k`` stroboscopic
    points are ``k`` curves.

    Args:
        branch: the :class:`~jaxgear.Branch` (computed or loaded).
        coordinate: a state name (e.g. ``"x1"``) or index (default: the first
            coordinate), or ``"norm"`` for the largest ``||x||`` of the orbit's points.
        ax: draw into this Axes (then the figure is ``ax.figure`` and ``multipliers``
            is ignored); default: a new figure.
        multipliers: add a second panel with the largest ``|lambda|`` and the line ``|lambda| = 1``.
        color: line colour (default: one colour per period, P-1, P-2, P-4, ... in turn).
        label: legend label of the branch (default ``"P-k"``).
        annotate: write the bifurcation kinds beside the markers.
    Returns:
        a :class:`matplotlib.figure.Figure` (no pyplot state).
    """
    if len(branch) == 0:
        raise ValueError("the branch has no points to draw.")
    y, yb, ylabel = _measure(branch, coordinate)
    k = int(branch.period)
    color = color or attractor_color(k.bit_length() - 1 if k & (k - 1) == 0 else k)  # P-1, P-2, P-4: 0, 1, 2
    label = label or f"P-{branch.period}"
    if ax is None:
        fig = Figure(figsize=(6.5, 6.0 if multipliers else 4.2))
        if multipliers:
            ax, ax2 = fig.subplots(2, 1, sharex=True, gridspec_kw=dict(height_ratios=(2.2, 1)))
        else:
            ax, ax2 = fig.add_subplot(), None
        own = True
    else:
        fig, ax2, own = ax.figure, None, False
    p, Y, L, seg = _nodes(branch, y, yb)
    first = {True: True, False: True}
    runs = _runs(seg) if len(seg) else [(0, 1, bool(branch.stable[0]))]
    for a, b, st in runs:
        for j in range(Y.shape[1]):
            lab = None
            if first[st] and j == 0:
                lab = f"{label} {'stable' if st else 'unstable'}"
                first[st] = False
            ax.plot(p[a:b], Y[a:b, j], ls="-" if st else "--", lw=1.4 if st else 1.1, color=color, label=lab,
                    marker="." if b - a == 1 else None)
    seen = set()
    for i, bif in enumerate(branch.bifurcations):
        mk, c = _MARKERS.get(bif.kind, ("x", "k"))
        tag = bif.kind + ("*" if bif.nonsmooth else "")
        lab = None if bif.kind in seen else bif.kind
        seen.add(bif.kind)
        ax.scatter(np.full(yb.shape[1], bif.param_value), yb[i], marker=mk, s=42, color=c, zorder=4,
                   edgecolor="k", linewidths=0.5, label=lab)
        if annotate:
            ax.annotate(tag, (bif.param_value, yb[i, 0]), textcoords="offset points", xytext=(5, 5), fontsize=8,
                        color=c)
    ax.set_ylabel(ylabel)
    ax.legend(loc="best", fontsize=8)
    if ax2 is not None:
        ax2.plot(p, L, color=color, lw=1.2)
        ax2.axhline(1.0, color="0.4", lw=0.8, ls=":")
        for bif in branch.bifurcations:
            mk, c = _MARKERS.get(bif.kind, ("x", "k"))
            ax2.scatter([bif.param_value], [np.max(np.abs(bif.multipliers))], marker=mk, s=30, color=c, zorder=4,
                        edgecolor="k", linewidths=0.5)
        ax2.set_ylabel("max |lambda|")
        ax2.set_xlabel(branch.param)
    elif own or _bottom_row(ax):
        ax.set_xlabel(branch.param)
    if own:
        ax.set_title(title or f"P-{branch.period} branch of {branch.system} in {branch.param}")
        fig.tight_layout()
    return fig
