"""Figures (matplotlib). Every function reads a result (or data) and returns a Figure;
nothing here computes an analysis beyond sampling a trajectory to draw it. Colours:
attractor ``i`` is ``attractor_color(i)`` everywhere; the sink is light grey,
unresolved cells black.
"""

from ._style import attractor_color as attractor_color, SINK_COLOR as SINK_COLOR
from ._basins import (
    plot_domains as plot_domains,
    plot_domains_3d as plot_domains_3d,
    plot_attractors as plot_attractors,
    plot_shares as plot_shares,
)
from ._orbit import plot_orbit as plot_orbit
from ._branch import plot_branch as plot_branch

from ._orbit import plot_multipliers as plot_multipliers

from ._sweep import (
    plot_bifurcation as plot_bifurcation,
    plot_basin_shares as plot_basin_shares,
    plot_parameter_map as plot_parameter_map,
    period_color as period_color,
)
