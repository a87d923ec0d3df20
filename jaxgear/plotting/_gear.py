"""The gear view's figure: for each mesh, its transmission error over the attractor with
the contact states shaded, and its amplitude spectrum (:func:`~jaxgear.gear_view`)."""

from __future__ import annotations

import numpy as np

from .._contact import GearView, _layout, _switching_at
from .._poincare import sample_trajectory
from ._style import attractor_color, new_figure

__all__ = ["plot_gear_view", "plot_regime_shares", "plot_regime_map"]

GAP_COLOR = "#fdd49e"
BACK_COLOR = "#d7301f"


def plot_gear_view(view: GearView, system, params, *, periods: int | None = None):
    """One row per mesh of ``view`` (a :class:`~jaxgear.GearView` of ``system`` and
    ``params``): left, the dynamic transmission error over ``periods`` forcing periods
    from the view's start (default: the ``k`` periods of a P-k, 4 periods of an aperiodic
    attractor), the backlash ``+-b`` dashed, the time in the gap shaded light and on the
    back flank dark; right, its amplitude spectrum against the order of the mesh frequency
    (in Hz on top with a gear set). The trajectory is sampled again from ``view.start``
    with the view's integrator (the figure computes nothing else). Returns a Figure."""
    if not isinstance(view, GearView):
        raise ValueError(f"view={type(view).__name__} must be a jaxgear.GearView (from jaxgear.gear_view).")
    n_periods = int(periods) if periods is not None else (view.period if view.period > 0 else 4)
    if n_periods < 1:
        raise ValueError(f"periods={periods!r} must be at least 1.")
    layout = _layout(system, params, np.asarray(view.start), None)
    if len(layout.pairs) != len(view.meshes):
        raise ValueError(f"view has {len(view.meshes)} meshes, {system.name} {len(layout.pairs)}: the view is not "
                         "of this system (or was made with a MeshSpec; draw it with the same meshes).")
    s = int(view.samples_per_period)
    ts, xs = sample_trajectory(system, params, view.start, periods=n_periods, samples_per_period=s,
                               integrator=view.integrator)
    ts, xs = np.asarray(ts), np.asarray(xs)
    T = float(system.period(params))
    S = np.asarray(_switching_at(system, params, ts, xs))
    phase = ts / T
    fig = new_figure(figsize=(10.0, 2.6 * len(view.meshes)), layout="constrained")
    axes = fig.subplots(len(view.meshes), 2, squeeze=False, gridspec_kw={"width_ratios": (2.2, 1.0)})
    color = attractor_color(view.attractor_id)
    for row, ((i_drive, i_back), m) in enumerate(zip(layout.pairs, view.meshes)):
        ax, sp = axes[row]
        te = 0.5 * (S[:, i_drive] + S[:, i_back]) * view.length_scale
        b = 0.5 * (S[:, i_back] - S[:, i_drive]) * view.length_scale
        gap = (S[:, i_drive] <= 0) & (S[:, i_back] > 0)
        back = S[:, i_back] <= 0
        ax.fill_between(phase, 0, 1, where=gap, transform=ax.get_xaxis_transform(), color=GAP_COLOR, lw=0,
                        label="gap (no contact)")
        ax.fill_between(phase, 0, 1, where=back, transform=ax.get_xaxis_transform(), color=BACK_COLOR, alpha=0.5,
                        lw=0, label="back-flank contact")
        ax.plot(phase, te, color=color, lw=1.2, label="transmission error")
        ax.plot(phase, b, "k--", lw=0.8, label="+-b")
        ax.plot(phase, -b, "k--", lw=0.8)
        ax.set_ylabel(f"TE [{view.length_unit}]")
        ax.set_title(f"{m.name}: {m.regime.text}, RMS {m.te_rms:.4g} {view.length_unit}, "
                     f"dynamic factor {m.dynamic_factor:.3g}", fontsize="medium")
        ax.set_xlim(phase[0], phase[-1])
        sp.vlines(m.orders, 0, m.amplitudes, color=color, lw=1.5)
        sp.set_xlabel("order of the mesh frequency")
        sp.set_ylabel(f"amplitude [{view.length_unit}]")
        sp.set_ylim(bottom=0)
        if np.isfinite(view.mesh_frequency_hz):
            top = sp.secondary_xaxis("top", functions=(lambda o: o * view.mesh_frequency_hz,
                                                      lambda f: f / view.mesh_frequency_hz))
            top.set_xlabel("Hz")
    axes[-1][0].set_xlabel("time [forcing periods]")
    axes[0][0].legend(fontsize="small", loc="upper right", ncols=2)
    fig.suptitle(f"attractor {view.attractor_id} ({view.label})", fontsize="medium")
    return fig


REGIME_COLORS = ("#2ca02c", "#ff7f0e", "#d62728")
"""No impact, single-sided impact, double-sided impact."""


def plot_regime_shares(shares):
    """The share of the state space in each contact regime against the swept parameter, one
    panel per mesh (a :class:`~jaxgear.RegimeShares` of :func:`~jaxgear.regime_shares`):
    stacked no impact, single-sided and double-sided impact, and the cells on no attractor
    in grey. Returns a Figure."""
    from .._contact import ContactRegime, RegimeShares
    from ._style import SINK_COLOR

    if not isinstance(shares, RegimeShares):
        raise ValueError(f"shares={type(shares).__name__} must be a jaxgear.RegimeShares (from jaxgear.regime_shares).")
    n = len(shares.meshes)
    fig = new_figure(figsize=(6.0, 2.4 * n + 0.6), layout="constrained")
    axes = fig.subplots(n, 1, squeeze=False, sharex=True)[:, 0]
    x = np.asarray(shares.values)
    for ax, j, name in zip(axes, range(n), shares.meshes):
        ys = [shares.shares[:, j, int(r)] for r in ContactRegime] + [shares.no_attractor]
        ax.stackplot(x, ys, labels=[r.text for r in ContactRegime] + ["no attractor"],
                     colors=[*REGIME_COLORS, SINK_COLOR], step=None)
        ax.set_ylim(0, 1)
        ax.set_ylabel("share of the cells")
        ax.set_title(name, fontsize="medium")
    axes[-1].set_xlabel(shares.label or shares.param)
    axes[0].legend(fontsize="small", loc="upper right")
    return fig


def plot_regime_map(regimes, *, title: str | None = None):
    """Contact regimes over two parameters (a :class:`~jaxgear.RegimeMap` of
    :func:`~jaxgear.regime_shares` on a basin map), one row per mesh: left, the regime of
    the attractor with the largest basin at each point (no impact, single-sided,
    double-sided impact; grey where the sink or the unresolved cells hold most); right, the
    share of the cells whose motion has double-sided impacts (percent). Returns a Figure."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from .._contact import ContactRegime, RegimeMap
    from ._style import SINK_COLOR
    from ._sweep import _edges

    if not isinstance(regimes, RegimeMap):
        raise ValueError(f"regimes={type(regimes).__name__} must be a jaxgear.RegimeMap (from jaxgear.regime_shares "
                         "of a basin map).")
    X, Y = _edges(np.asarray(regimes.values_x)), _edges(np.asarray(regimes.values_y))
    n = len(regimes.meshes)
    fig = new_figure(figsize=(11.0, 3.8 * n + 0.6), layout="constrained")
    axes = fig.subplots(n, 2, squeeze=False)
    cmap = ListedColormap([SINK_COLOR, *REGIME_COLORS])
    double = int(ContactRegime.DOUBLE_SIDED)
    for j, name in enumerate(regimes.meshes):
        ax, ax2 = axes[j]
        ax.pcolormesh(X, Y, np.asarray(regimes.dominant_regime)[..., j] + 1, cmap=cmap, vmin=-0.5, vmax=3.5,
                      shading="flat")
        ax.set_title(f"{name}: regime of the largest basin", fontsize="medium")
        m = ax2.pcolormesh(X, Y, 100 * np.asarray(regimes.shares)[..., j, double], cmap="Reds", vmin=0, vmax=100,
                           shading="flat")
        fig.colorbar(m, ax=ax2).set_label("double-sided impact [% of the cells]")
        ax2.set_title(f"{name}: share with double-sided impacts", fontsize="medium")
        for a in (ax, ax2):
            a.set_xlabel(regimes.label_x or regimes.param_x)
            a.set_ylabel(regimes.label_y or regimes.param_y)
    handles = [Patch(color=c, label=r.text) for r, c in zip(ContactRegime, REGIME_COLORS)]
    handles.append(Patch(color=SINK_COLOR, label="no attractor"))
    axes[0][0].legend(handles=handles, fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(title or "Contact regimes", fontsize="medium")
    return fig
