"""Figures of parameter sweeps: bifurcation diagrams, basin shares, two-parameter maps.

Periods have fixed colours in every sweep figure (:func:`period_color`: P-1 blue, P-2
red, P-3 green, P-4 orange, P-8 cyan, P-12 pink, ... from the attractor palette of
``_style``; aperiodic motion by its type, :func:`type_color`: chaotic plum,
quasi-periodic dark gold, of unknown type dark grey; escaped the sink's light grey);
global attractors of a basin sweep use ``attractor_color(id)`` like the domain figures
and are labelled with their id and type (``"2: chaotic"``, ``"0: P-4/P-8"``).
"""

from __future__ import annotations

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from .._checks import check_enum
from .._lyapunov import AttractorType
from .._system import state_index
from ..sweep import MapQuantity, SweepDirection, period_label, type_label
from ._style import _PALETTE, SINK_COLOR, UNRESOLVED_COLOR, attractor_color, new_figure

APERIODIC_COLOR = "#404040"
CHAOTIC_COLOR = "#7a0177"
QUASI_PERIODIC_COLOR = "#b8860b"


# P-1..P-6 and P-8 take the attractor palette's first colours; P-12 and P-16 get their own.
_PERIOD_COLORS = {1: _PALETTE[0], 2: _PALETTE[1], 3: _PALETTE[2], 4: _PALETTE[3], 5: _PALETTE[4], 6: _PALETTE[5],
                  7: "#bcbd22", 8: _PALETTE[7], 12: _PALETTE[6], 16: "#393b79"}
_OTHER_PERIODS = ["#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5", "#c49c94"]


def period_color(k: int) -> str:
    """Colour of period code ``k`` (P-k for k >= 1; 0 aperiodic; -1 escaped)."""
    k = int(k)
    if k >= 1:
        return _PERIOD_COLORS.get(k, _OTHER_PERIODS[k % len(_OTHER_PERIODS)])
    return APERIODIC_COLOR if k == 0 else SINK_COLOR


def type_color(k: int, kind: int) -> str:
    """Colour of an attractor of period code ``k`` and type ``kind`` (an
    :class:`~jaxgear.AttractorType` value): :func:`period_color` for P-k and escaped;
    for period 0 chaotic plum, quasi-periodic dark gold, unknown dark grey."""
    if int(k) != 0:
        return period_color(k)
    return {int(AttractorType.CHAOTIC): CHAOTIC_COLOR,
            int(AttractorType.QUASI_PERIODIC): QUASI_PERIODIC_COLOR}.get(int(kind), APERIODIC_COLOR)


_DIR_STYLE = {  # marker, size, legend label, horizontal offset (in units of the dodge)
    SweepDirection.UP: ("^", 9.0, "sweep up (state carried)", -1.0),
    SweepDirection.INDEPENDENT: ("o", 5.0, "independent starts", 0.0),
    SweepDirection.DOWN: ("v", 9.0, "sweep down (state carried)", 1.0),
}


def plot_bifurcation(diagram, coordinate="x1", *, directions=None, title: str | None = None):
    """Bifurcation diagram: a state coordinate of the stroboscopic points against the parameter.

    Points are coloured by the period of the (value, start) they belong to, aperiodic
    ones by their type from the largest Lyapunov exponent (:func:`type_color`: chaotic,
    quasi-periodic, or of unknown type); a P-k lane contributes its k points, an
    aperiodic lane all its recorded points. With several
    sweeps each value's column is split: up sweep (``^``, left), independent starts
    (``o``, middle), down sweep (``v``, right); where up and down differ the sweeps
    followed different attractors (hysteresis). Escaped lanes are marked with grey
    crosses along the top edge.

    Args:
        diagram: a :class:`~jaxgear.BifurcationDiagram` (computed or loaded).
        coordinate: state name (``"x1"``) or index.
        directions: subset of ``diagram.directions`` to draw (default all;
            :class:`~jaxgear.SweepDirection` members or their texts).
    Returns a :class:`matplotlib.figure.Figure`.
    """
    j = state_index(diagram.state_names, coordinate)
    dirs = list(diagram.directions if directions is None else directions)
    for d in dirs:
        if d not in diagram.directions:
            raise ValueError(f"direction {d!r} is not in this diagram ({', '.join(map(str, diagram.directions))}).")
    dirs = [diagram.directions[diagram.directions.index(d)] for d in dirs]  # the members
    fig = new_figure(figsize=(8.0, 4.8), layout="constrained")
    ax = fig.add_subplot()
    vals = np.asarray(diagram.values)
    step = float(np.min(np.diff(vals))) if len(vals) > 1 else 1.0
    dodge = 0.22 * step if len(dirs) > 1 else 0.0
    R = diagram.points.shape[-2]
    periods_seen = set()
    n_escaped = 0
    for name in dirs:
        d = diagram.directions.index(name)
        per = diagram.period[d]  # (V, S)
        kind = np.where(per == 0, diagram.attractor_type[d], int(AttractorType.PERIODIC))  # (V, S): the type of aperiodic lanes
        pts = diagram.points[d][..., j]  # (V, S, R)
        marker, size, _, off = _DIR_STYLE[name]
        codes = {(int(k), int(t)) for k, t in zip(per.ravel(), kind.ravel()) if k != -1}
        for k, t in sorted(codes, key=lambda c: -int(((per == c[0]) & (kind == c[1])).sum())):  # rare ones on top
            vi, si = np.nonzero((per == k) & (kind == t))
            take = R if k == 0 else k
            y = pts[vi, si, R - take:].reshape(-1)
            x = np.repeat(vals[vi] + off * dodge, take)
            ax.scatter(x, y, s=size, marker=marker, color=type_color(k, t), linewidths=0)
            periods_seen.add((k, t))
        n_escaped += int((per == -1).sum())
        esc = np.nonzero((per == -1).any(axis=1))[0]
        if len(esc):
            ax.plot(vals[esc] + off * dodge, np.full(len(esc), 0.98), "x", color="#999999", ms=5,
                    transform=ax.get_xaxis_transform())
    handles = [Patch(color=type_color(k, t), label=type_label(k, t))
               for k, t in sorted(periods_seen, key=lambda c: (c[0] <= 0, c[0], c[1]))]
    if n_escaped:
        handles.append(Line2D([], [], marker="x", ls="none", color="#999999", label=f"escaped ({n_escaped} runs)"))
    if len(dirs) > 1 or dirs[0] != SweepDirection.INDEPENDENT:
        for name in sorted(dirs, key=lambda n: _DIR_STYLE[n][3]):
            marker, _, label, _ = _DIR_STYLE[name]
            handles.append(Line2D([], [], marker=marker, ls="none", color="k", ms=5, label=label))
    ax.legend(handles=handles, fontsize="small", loc="center left", bbox_to_anchor=(1.01, 0.5))
    ax.set_xlabel(diagram.axis_label)
    ax.set_ylabel(f"{diagram.state_names[j]} at forcing phase 0")
    ax.set_title(title or f"Bifurcation diagram of {diagram.system} ({len(diagram.starts)} starts per value)")
    return fig


def plot_basin_shares(sweep, *, percent: bool = True, mark_events: bool = True, multipliers: bool = False,
                      exponents: bool = False, title: str | None = None):
    """Stacked basin shares against the parameter (a :class:`~jaxgear.BasinSweep`).

    One band per global attractor (``attractor_color(id)``, labelled with its id and
    type: its period(s), e.g. ``"1: P-4/P-8"`` when it doubles along the sweep,
    ``"2: chaotic"``, ``"3: quasi-periodic"``, ``"0: P-4/chaotic"``), then the sink and
    unresolved cells. With ``mark_events`` a dotted line marks where an attractor
    appears or vanishes. With ``multipliers`` a second panel below draws each
    attractor's largest Floquet multiplier modulus (``sweep.multiplier``) against the
    parameter, with the stability limit 1: a curve that nears it marks a bifurcation
    ahead (a period doubling where the attractor's period changes). With ``exponents`` a
    panel below draws each attractor's largest Lyapunov exponent per forcing period
    (``sweep.largest_exponent``, with its error bars) and zero: chaotic above it,
    quasi-periodic on it, cycles below.
    """
    x = np.asarray(sweep.values)
    f = 100.0 if percent else 1.0
    ys, cols, labels = [], [], []
    for g in range(sweep.n_attractors):
        ys.append(f * sweep.shares[:, g])
        cols.append(attractor_color(g))
        labels.append(f"{g}: {sweep.attractor_label(g)}")
    if np.any(sweep.sink_share > 0) or not ys:
        ys.append(f * sweep.sink_share)
        cols.append(SINK_COLOR)
        labels.append("sink")
    if np.any(sweep.unresolved_share > 0):
        ys.append(f * sweep.unresolved_share)
        cols.append(UNRESOLVED_COLOR)
        labels.append("unresolved")
    panels = 1 + bool(multipliers) + bool(exponents)
    fig = new_figure(figsize=(7.5, 4.2 + 2.2 * (panels - 1)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(panels, 1, sharex=True, height_ratios=(2,) + (1,) * (panels - 1)))
    ax = axes[0]
    if len(x) == 1:
        bottom = 0.0
        for y, c, lab in zip(ys, cols, labels):
            ax.bar(x, y, bottom=bottom, color=c, label=lab, width=1.0)
            bottom = bottom + y
    else:
        ax.stackplot(x, *ys, colors=cols, labels=labels, step=None)
    if mark_events and len(x) > 1:
        for e in sweep.events():
            if e["event"] in ("appears", "vanishes"):
                i = e["index"]
                ax.axvline(0.5 * (x[i - 1] + x[i]), color="k", ls=":", lw=0.8)
    if len(x) > 1:
        ax.set_xlim(x.min(), x.max())
    ax.set_ylim(0, f)
    ax.set_xlabel(sweep.axis_label)
    ax.set_ylabel("share of the grid [%]" if percent else "share of the grid")
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize="small")
    ax.set_title(title or f"Basin shares ({sweep.method.name}, {sweep.grid.n_cells} cells per value)")
    if multipliers:
        ax_mu = axes[1]
        mu = np.asarray(sweep.multiplier, dtype=float)
        for g in range(sweep.n_attractors):
            ax_mu.plot(x, mu[:, g], "o-", color=attractor_color(g), ms=3, lw=1.2)
        ax_mu.axhline(1.0, color="k", ls="--", lw=0.8)
        top = np.nanmax(mu, initial=1.0)
        ax_mu.set_ylim(0.0, max(1.05, 1.02 * top))
        ax_mu.set_ylabel("max |Floquet multiplier|")
    if exponents:
        ax_l = axes[-1]
        lam, err = np.asarray(sweep.largest_exponent, dtype=float), np.asarray(sweep.exponent_error, dtype=float)
        for g in range(sweep.n_attractors):
            ax_l.errorbar(x, lam[:, g], yerr=np.where(np.isfinite(err[:, g]), err[:, g], 0.0), fmt="o-",
                          color=attractor_color(g), ms=3, lw=1.2, capsize=2)
        ax_l.axhline(0.0, color="k", ls="--", lw=0.8)
        ax_l.set_ylabel("largest Lyapunov exponent\n[1/forcing period]")
    for a in axes[:-1]:
        a.set_xlabel("")
    axes[-1].set_xlabel(sweep.axis_label)
    return fig


def _edges(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=float)
    if len(c) == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])


def plot_parameter_map(pmap, quantity: MapQuantity | str | None = None, *, title: str | None = None):
    """Two-parameter map as an image (a :class:`~jaxgear.ParameterMap`).

    ``quantity`` (a :class:`~jaxgear.MapQuantity` or its text; default: the map's own):
    ``"period"``, the period reached from the first start, one colour per period
    (:func:`period_color`) with a legend; ``"n_attractors"``: the number of distinct
    attractors reached from the starts.
    """
    from matplotlib.colors import ListedColormap

    quantity = check_enum(pmap.quantity if quantity is None else quantity, "quantity", MapQuantity)
    fig = new_figure(figsize=(7.0, 5.0), layout="constrained")
    ax = fig.add_subplot()
    X, Y = _edges(pmap.values_x), _edges(pmap.values_y)
    if quantity == MapQuantity.PERIOD:
        data = np.asarray(pmap.period[:, :, 0])
        codes = sorted(np.unique(data).tolist(), key=lambda k: (k <= 0, k if k > 0 else -k))
        idx = np.searchsorted(np.array(sorted(codes)), data)
        order = sorted(codes)
        cmap = ListedColormap([period_color(k) for k in order])
        ax.pcolormesh(X, Y, idx, cmap=cmap, vmin=-0.5, vmax=len(order) - 0.5, shading="flat")
        handles = [Patch(color=period_color(k), label=period_label(k)) for k in codes]
        ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize="small",
                  title="from start 0")
    else:
        _count_panel(fig, ax, X, Y, np.asarray(pmap.n_attractors), f"distinct attractors from {len(pmap.starts)} starts")
    ax.set_xlabel(pmap.param_x)
    ax.set_ylabel(pmap.param_y)
    ax.set_title(title or ("Period of the attractor reached" if quantity == MapQuantity.PERIOD
                           else "Number of coexisting attractors"))
    return fig


def _count_panel(fig, ax, X, Y, data: np.ndarray, label: str) -> None:
    """A map of counts (0, 1, 2, ...) on the cell edges ``X, Y``: one shade of a sequential
    palette per count, darker for more (not the attractor colours, which name ids), a
    colour bar with integer ticks labelled ``label``."""
    import matplotlib
    from matplotlib.colors import BoundaryNorm, ListedColormap

    top = max(int(data.max()), 1)
    shades = matplotlib.colormaps["YlGnBu"](np.linspace(0.15, 0.95, top))
    cmap = ListedColormap(["#f7f7f7", *shades])
    m = ax.pcolormesh(X, Y, data, cmap=cmap, norm=BoundaryNorm(np.arange(-0.5, top + 1.5), cmap.N), shading="flat")
    fig.colorbar(m, ax=ax, ticks=np.arange(0, top + 1)).set_label(label)


def plot_basin_map(bmap, attractor: int | str | None = None, *, title: str | None = None):
    """Basin shares over two parameters (a :class:`~jaxgear.BasinMap`) as images.

    ``attractor=None`` (default): two panels, the attractor with the largest share at
    each parameter point (``attractor_color(id)``, the sink light grey, black where
    unresolved cells hold most; its share in percent written in each box of maps up to
    12 x 12) and the number of coexisting
    attractors. ``attractor=g``: the share of global attractor ``g`` (percent; white
    where it does not exist). ``attractor="all"``: one such panel per attractor.
    """
    from matplotlib.colors import ListedColormap

    X, Y = _edges(bmap.values_x), _edges(bmap.values_y)
    G = bmap.n_attractors
    if attractor is None:
        fig = new_figure(figsize=(12.0, 4.8), layout="constrained")
        ax, ax2 = fig.subplots(1, 2)
        dom = np.asarray(bmap.dominant)
        cmap = ListedColormap([UNRESOLVED_COLOR, SINK_COLOR] + [attractor_color(g) for g in range(G)])
        ax.pcolormesh(X, Y, dom + 2, cmap=cmap, vmin=-0.5, vmax=G + 1.5, shading="flat")
        ny, nx = dom.shape
        if nx * ny <= 144:
            share = np.where(dom >= 0, np.take_along_axis(bmap.shares, np.maximum(dom, 0)[..., None], -1)[..., 0],
                             np.where(dom == -1, bmap.sink_share, bmap.unresolved_share))
            for iy in range(ny):
                for ix in range(nx):
                    ax.text(bmap.values_x[ix], bmap.values_y[iy], f"{100 * share[iy, ix]:.0f}", ha="center",
                            va="center", fontsize="x-small", color="k" if dom[iy, ix] == -1 else "w")
        shown = sorted(set(dom.ravel().tolist()))
        other = {-1: (SINK_COLOR, "sink"), -2: (UNRESOLVED_COLOR, "unresolved")}
        handles = [Patch(color=attractor_color(g) if g >= 0 else other[g][0],
                         label=f"{g}: {bmap.attractor_label(g)}" if g >= 0 else other[g][1]) for g in shown]
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small",
                  title="largest basin")
        ax.set_title("Attractor with the largest basin" + (" (its share, %)" if nx * ny <= 144 else ""))
        _count_panel(fig, ax2, X, Y, np.asarray(bmap.coexisting), "coexisting attractors")
        ax2.set_title("Number of coexisting attractors")
        axes = [ax, ax2]
    else:
        ok = attractor == "all" or (isinstance(attractor, (int, np.integer)) and not isinstance(attractor, bool)
                                    and 0 <= attractor < G)
        if not ok or G == 0:
            raise ValueError(f"attractor must be None, 'all' or a global id in 0..{G - 1}, got {attractor!r}."
                             if G else "the map has no attractor (every cell in the sink or unresolved).")
        gs = list(range(G)) if attractor == "all" else [int(attractor)]
        cols = min(len(gs), 3)
        rows = -(-len(gs) // cols)
        fig = new_figure(figsize=(4.2 * cols + 1.0, 3.6 * rows), layout="constrained")
        axes = np.atleast_1d(fig.subplots(rows, cols)).ravel().tolist()
        for ax in axes[len(gs):]:
            ax.set_visible(False)
        for ax, g in zip(axes, gs):
            data = np.where(bmap.present[..., g], 100 * bmap.shares[..., g], np.nan)
            m = ax.pcolormesh(X, Y, data, cmap="viridis", vmin=0, vmax=100, shading="flat")
            ax.set_title(f"{g}: {bmap.attractor_label(g)}", color=attractor_color(g))
        fig.colorbar(m, ax=axes[: len(gs)]).set_label("share of the cell grid [%] (white: absent)")
        axes = axes[: len(gs)]
    for ax in axes:
        ax.set_xlabel(bmap.axis_labels[0])
        ax.set_ylabel(bmap.axis_labels[1])
    fig.suptitle(title or f"Basin shares over {bmap.param_x} x {bmap.param_y} ({bmap.method.name}, "
                 f"{bmap.grid.n_cells} cells per point)")
    return fig
