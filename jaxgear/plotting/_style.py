"""Shared figure style: one colour per attractor id, sink and unresolved colours."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg", force=False) if not matplotlib.get_backend() else None

from matplotlib.colors import ListedColormap  # noqa: E402

SINK_COLOR = "#d9d9d9"
UNRESOLVED_COLOR = "#000000"
_PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
            "#bcbd22", "#7f7f7f"]


def attractor_color(i: int) -> str:
    """Colour of attractor ``i`` (consistent across all figures)."""
    return _PALETTE[int(i) % len(_PALETTE)]


def label_colormap(n_attractors: int):
    """(colormap, offset): labels ``-2 (unresolved), -1 (sink), 0..n-1`` -> colours."""
    colors = [UNRESOLVED_COLOR, SINK_COLOR] + [attractor_color(i) for i in range(max(n_attractors, 1))]
    return ListedColormap(colors), 2


def new_figure(**kw):
    """A standalone Figure (no pyplot state, safe in scripts, tests and notebooks)."""
    from matplotlib.figure import Figure

    fig = Figure(**kw)
    return fig

