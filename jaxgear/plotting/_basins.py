"""Domains of attraction and attractors of a :class:`~jaxgear.GlobalResult` (paper Fig. 6-8)."""

from __future__ import annotations

import numpy as np
from matplotlib.patches import Patch

from ..analysis import GlobalResult
from ._style import SINK_COLOR, UNRESOLVED_COLOR, attractor_color, label_colormap, new_figure


def _legend_handles(result: GlobalResult):
    h = [Patch(color=attractor_color(a.id), label=f"{a.id}: {a.label} ({100 * a.share:.1f} %)")
         for a in result.attractors]
    if result.n_sink:
        h.append(Patch(color=SINK_COLOR, label=f"sink ({100 * result.n_sink / result.n_cells:.1f} %)"))
    if result.n_unresolved:
        h.append(Patch(color=UNRESOLVED_COLOR, label="unresolved"))
    return h


def plot_domains(result: GlobalResult, axis: int | str = -1, values=None, n_slices: int = 4, *,
                 show_points: bool = True, ncols: int | None = None):
    """Domains of attraction as 2-D slices through the cell grid (paper Fig. 7-8).

    Args:
        axis: the grid axis cut across (index into the gridded axes, or its name,
            e.g. ``"x3"``); the other two gridded axes are the image axes (for grids
            of more than 3 axes the remaining ones are cut at their middle cell).
        values: coordinates of the slices along ``axis`` (nearest cell); default
            ``n_slices`` evenly spaced slices.
        show_points: mark the attractors' section (or stroboscopic) points that fall
            within the slice's cell layer.
    Returns a Figure with one panel per slice.
    """
    g = result.grid
    names = list(g.axis_names)
    if len(names) < 2:
        raise ValueError("plot_domains needs a grid of at least 2 axes.")
    j = names.index(axis) if isinstance(axis, str) else int(axis) % len(names)
    if len(names) == 2:
        cuts = [None]
    else:
        centres = g.axis_centres(j)
        if values is None:
            idx = np.linspace(0, g.counts[j] - 1, n_slices + 2)[1:-1].round().astype(int)
        else:
            idx = [int(np.argmin(np.abs(centres - v))) for v in np.atleast_1d(values)]
        cuts = list(dict.fromkeys(idx))
    others = [k for k in range(len(names)) if k != j][:2] if len(names) > 2 else [0, 1]
    extra = [k for k in range(len(names)) if k != j and k not in others]
    ncols = ncols or min(len(cuts), 4)
    nrows = -(-len(cuts) // ncols)
    fig = new_figure(figsize=(3.6 * ncols + 1.8, 3.2 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    cmap, off = label_colormap(len(result.attractors))
    lab = result.labels
    for p, c in enumerate(cuts):
        ax = axes[p // ncols][p % ncols]
        sl = [slice(None)] * len(names)
        if c is not None:
            sl[j] = c
        for k in extra:
            sl[k] = g.counts[k] // 2
        img = lab[tuple(sl)]
        if others[0] > others[1]:
            img = img.T
        a0, a1 = others
        ax.imshow(img.T + off, origin="lower", cmap=cmap, vmin=0, vmax=cmap.N - 1, interpolation="nearest",
                  aspect="auto", extent=(g.lower[a0], g.upper[a0], g.lower[a1], g.upper[a1]))
        ax.set_xlabel(names[a0])
        ax.set_ylabel(names[a1])
        if c is not None:
            zc = g.axis_centres(j)[c]
            ax.set_title(f"{names[j]} = {zc:.3g}")
        if show_points:
            for a in result.attractors:
                pts = a.section_points if len(a.section_points) else a.points
                pts = np.asarray(pts)
                if not len(pts):
                    continue
                sel = np.ones(len(pts), bool)
                if c is not None:
                    ax_j = g.axes[j]
                    lo = g.lower[j] + c * g.cell_size[j]
                    sel = (pts[:, ax_j] >= lo - g.cell_size[j]) & (pts[:, ax_j] < lo + 2 * g.cell_size[j])
                if sel.any():
                    ax.plot(pts[sel, g.axes[a0]], pts[sel, g.axes[a1]], "s", mfc="none", mec="k", ms=6)
    for q in range(len(cuts), nrows * ncols):
        axes[q // ncols][q % ncols].set_visible(False)
    fig.legend(handles=_legend_handles(result), loc="outside right center", fontsize="small")
    fig.suptitle(f"Domains of attraction ({result.method.name}, {result.n_cells} cells)")
    return fig


def plot_domains_3d(result: GlobalResult, attractors=None, *, max_cells: int = 20000, seed: int = 0):
    """3-D view of domains of attraction: the cells of each chosen attractor's domain as
    points over the first three grid axes (paper Fig. 7-8), its periodic cells as squares.

    Args:
        result: a :class:`~jaxgear.GlobalResult` (also one loaded from disk: nothing is
            recomputed) with a grid of at least 3 axes; axes in state units.
        attractors: ids to draw (default all).
        max_cells: at most this many cells per domain are drawn (a random subset, ``seed``).
    Returns a Figure with one 3-D axes: one point set per domain (+ one per set of periodic cells).
    """
    g = result.grid
    if len(g.axes) < 3:
        raise ValueError("plot_domains_3d needs a grid of at least 3 axes.")
    ids = [a.id for a in result.attractors] if attractors is None else list(np.atleast_1d(attractors))
    fig = new_figure(figsize=(7, 6), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    rng = np.random.default_rng(seed)
    flat = result.labels.reshape(-1)
    names = g.axis_names
    for a in result.attractors:
        if a.id not in ids:
            continue
        cells = np.nonzero(flat == a.id)[0]
        if len(cells) > max_cells:
            cells = rng.choice(cells, max_cells, replace=False)
        X = g.centres(cells)
        size = float(np.clip(30000.0 / max(len(cells), 1), 1.5, 12.0))
        ax.scatter(X[:, g.axes[0]], X[:, g.axes[1]], X[:, g.axes[2]], s=size, alpha=0.55, color=attractor_color(a.id),
                   depthshade=False,
                   label=f"{a.label} domain ({100 * a.share:.1f} %)")
        if len(a.periodic_cells):
            P = g.centres(a.periodic_cells)
            ax.scatter(P[:, g.axes[0]], P[:, g.axes[1]], P[:, g.axes[2]], marker="s", s=30, color="k",
                       label=f"{a.label} periodic cells")
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.set_zlabel(names[2])
    ax.legend(fontsize="small", loc="upper left")
    ax.set_title("Domains of attraction")
    return fig


def plot_attractors(result: GlobalResult, coords=(0, 1, 2), *, section: bool = True):
    """The attractors' points: section crossings (``section=True``) or stroboscopic points,
    projected on two or three state coordinates (paper Fig. 3-6 markers); a chaotic or
    quasi-periodic attractor (period 0) as the cloud of its stroboscopic points.

    ``coords``: 2 or 3 state indices (e.g. ``(0, 1, 2)`` for x1, x2, x3; state units).
    Reads only the result (works on a loaded one). Returns a Figure with one axes
    (3-D for three coordinates) and one marker set per attractor.
    """
    coords = tuple(coords)
    if len(coords) not in (2, 3):
        raise ValueError("coords must name 2 or 3 state coordinates.")
    fig = new_figure(figsize=(6.5, 5.5), layout="constrained")
    ax = fig.add_subplot(projection="3d") if len(coords) == 3 else fig.add_subplot()
    for a in result.attractors:
        pts = np.asarray(a.section_points if section and len(a.section_points) else a.points)
        if not len(pts):
            continue
        if a.period > 0:  # a cycle's points
            ax.scatter(*[pts[:, c] for c in coords], color=attractor_color(a.id), marker="*", s=80,
                       label=f"{a.id}: {a.label}")
        else:  # the cloud of a chaotic or quasi-periodic attractor
            ax.scatter(*[pts[:, c] for c in coords], color=attractor_color(a.id), marker=".", s=3, alpha=0.6,
                       linewidths=0, label=f"{a.id}: {a.label} ({len(pts)} points)")
    n = result.state_names
    ax.set_xlabel(n[coords[0]])
    ax.set_ylabel(n[coords[1]])
    if len(coords) == 3:
        ax.set_zlabel(n[coords[2]])
    ax.legend(fontsize="small")
    ax.set_title("Attractor points on the section" if section else "Stroboscopic points")
    return fig


def plot_shares(result: GlobalResult):
    """Bar chart of the share of each attractor's domain (and the sink), in % of the cells.

    The paper's measure of global stability (§4.2: P-4 93.9 %, P-8 6.1 % of region D).
    Reads only the result (works on a loaded one). Returns a Figure with one axes and
    ``len(result.attractors) + 1`` bars.
    """
    fig = new_figure(figsize=(5.5, 3.5), layout="constrained")
    ax = fig.add_subplot()
    labels = [f"{a.id}: {a.label}" for a in result.attractors] + ["sink"]
    vals = [100 * a.share for a in result.attractors] + [100 * result.n_sink / result.n_cells]
    cols = [attractor_color(a.id) for a in result.attractors] + [SINK_COLOR]
    bars = ax.bar(labels, vals, color=cols)
    ax.bar_label(bars, fmt="%.2f %%")
    ax.set_ylabel("share of cells [%]")
    ax.set_ylim(0, 105)
    ax.set_title(f"Basin shares ({result.method.name})")
    return fig


def plot_basin_measures(result):
    """The fractal basin measures of a :class:`~jaxgear.GlobalResult`, or of every value of
    a :class:`~jaxgear.BasinSweep`.

    For one result: the uncertain fraction ``f(eps)`` of its label uncertainty against the
    start move ``eps`` (cell sizes) on log-log axes, with the fit ``f ~ eps**alpha`` drawn
    over its scaling range only (the points outside it open) and the slope 1 of a smooth
    boundary for comparison (Grebogi et al. 1983), or "no scaling range", and the basin
    entropies in the title (Daza et al. 2016). For a sweep: ``S_b``, ``S_bb`` (with the
    log 2 line) and ``alpha`` (with its error) against the parameter. Returns a Figure.
    """
    from ..sweep import BasinSweep

    if isinstance(result, BasinSweep):
        return _sweep_measures(result)
    u = result.uncertainty
    if u is None or not u.perturbations:
        raise ValueError("plot_basin_measures needs a result with its label uncertainty (uncertainty > 0).")
    fig = new_figure(figsize=(5.5, 4.0), layout="constrained")
    ax = fig.add_subplot()
    eps, f = np.asarray(u.perturbations), np.asarray(u.start_fractions)
    keep = f > 0
    lo, hi = u.alpha_range if u.alpha_range is not None else (eps[keep].min(initial=np.inf), eps.max())
    fitted = keep & (eps >= lo * (1 - 1e-9)) & (eps <= hi * (1 + 1e-9))  # a file without a range: every f > 0
    if not np.isfinite(u.alpha):
        fitted[:] = False
    err = np.sqrt(f * (1 - f) / u.samples)
    if fitted.any():
        ax.errorbar(eps[fitted], f[fitted], yerr=err[fitted], fmt="o", color="k", label=f"f(eps), {u.samples} cells")
    outside = keep & ~fitted
    if outside.any():
        ax.errorbar(eps[outside], f[outside], yerr=err[outside], fmt="o", mfc="none", color="grey",
                    label="outside the scaling range" if fitted.any() else f"f(eps), {u.samples} cells: no scaling range")
    if fitted.sum() >= 3:
        # the fit's line: its slope alpha and its intercept, that of the weighted fit over the range
        from ..analysis import uncertainty_exponent

        x = eps[fitted]
        c = np.exp(uncertainty_exponent(x, f[fitted], n_samples=u.samples).log_prefactor
                   if u.alpha_range is not None else np.mean(np.log(f[fitted]) - u.alpha * np.log(x)))
        ax.plot(x, c * x ** u.alpha, "-", color=attractor_color(0),
                label=f"fit: alpha = {u.alpha:.2f} +- {u.alpha_error:.2f}")
        ax.plot(x, c * x[0] ** u.alpha * (x / x[0]), ":", color="grey", label="slope 1 (smooth boundary)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylim(top=1.0)  # a share
    ax.set_xlabel("start move eps [cell sizes]")
    ax.set_ylabel("share of uncertain cells f(eps)")
    e = result.basin_entropy
    title = "Uncertain fraction"
    if e is not None and np.isfinite(e.S_b):
        title += f"; S_b = {e.S_b:.3f}, S_bb = {e.S_bb:.3f}"
    ax.set_title(title, fontsize="medium")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize="small")
    return fig


def _sweep_measures(sweep):
    fig = new_figure(figsize=(6.5, 5.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    v = np.asarray(sweep.values)
    top.plot(v, sweep.basin_entropy, "o-", color=attractor_color(0), label="S_b")
    top.plot(v, sweep.boundary_basin_entropy, "s-", color=attractor_color(1), label="S_bb")
    top.axhline(np.log(2.0), color="grey", ls=":", label="log 2")
    top.set_ylabel("basin entropy")
    top.legend(fontsize="small")
    bottom.errorbar(v, sweep.uncertainty_exponent, yerr=sweep.uncertainty_exponent_error, fmt="o-", color="k")
    bottom.axhline(1.0, color="grey", ls=":")
    bottom.set_ylabel("uncertainty exponent alpha")
    bottom.set_xlabel(sweep.axis_label)
    top.set_title("Fractal basin measures", fontsize="medium")
    return fig
