"""Figures (matplotlib). Every function reads a result (or data) and returns a Figure;
nothing here computes an analysis beyond sampling a trajectory to draw it. Colours:
attractor ``i`` is ``attractor_color(i)`` everywhere; the sink is light grey,
unresolved cells black.
"""

from ._basins import (
    plot_attractors as plot_attractors,
)
from ._basins import (
    plot_basin_measures as plot_basin_measures,
)
from ._basins import (
    plot_domains as plot_domains,
)
from ._basins import (
    plot_domains_3d as plot_domains_3d,
)
from ._basins import (
    plot_shares as plot_shares,
)
from ._branch import plot_branch as plot_branch
from ._gear import plot_gear_view as plot_gear_view
from ._gear import plot_regime_map as plot_regime_map
from ._gear import plot_regime_shares as plot_regime_shares
from ._orbit import plot_multipliers as plot_multipliers
from ._orbit import plot_orbit as plot_orbit
from ._style import SINK_COLOR as SINK_COLOR
from ._style import attractor_color as attractor_color
from ._sweep import (
    period_color as period_color,
)
from ._sweep import (
    plot_basin_map as plot_basin_map,
)
from ._sweep import (
    plot_basin_shares as plot_basin_shares,
)
from ._sweep import (
    plot_bifurcation as plot_bifurcation,
)
from ._sweep import (
    plot_parameter_map as plot_parameter_map,
)
