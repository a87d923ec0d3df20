"""Parameter sweeps: bifurcation diagrams, basin shares across one or two parameters, 2-parameter maps.

- :mod:`._bifurcation` — :func:`bifurcation_diagram` (stroboscopic points against a parameter);
- :mod:`._basins` — :func:`basin_sweep` (global analysis per value, attractors matched);
- :mod:`._basin_map` — :func:`basin_map` (global analysis over a grid of two parameters);
- :mod:`._parameter_map` — :func:`parameter_map` (a grid of two parameters);
- :mod:`._options` — :class:`SequenceOptions`, :class:`BasinOptions`;
- :mod:`._kernels` — the batched (values x starts) kernels;
- :mod:`._classify` — period codes and distinct attractors of recorded sequences;
- :mod:`._values` — checking and applying parameter values;
- :mod:`._physical` — :func:`sweep_axis`: a :class:`~jaxgear.GearSet` field in physical units
  mapped to the dimensionless fields it changes;
- :mod:`._runner` — :class:`Runner`: the sweeps' output folder, kill-and-resume and
  progress (its helper :mod:`._checkpoint`: the checkpoints of long sweeps).
"""

from ._basin_map import BasinMap, basin_map, match_on_grid
from ._basins import BasinSweep, basin_sweep, match_across_values
from ._bifurcation import DIRECTIONS, BifurcationDiagram, SequenceSettings, SweepDirection, bifurcation_diagram
from ._classify import APERIODIC, ESCAPED, period_label, type_label
from ._options import BasinOptions, SequenceOptions
from ._parameter_map import MapQuantity, ParameterMap, parameter_map
from ._physical import PHYSICAL_ALIASES, SweepAxis, physical_names, sweep_axis
from ._runner import Runner
from ._values import check_values

__all__ = ["Runner", "SequenceOptions", "BasinOptions", "BifurcationDiagram", "SequenceSettings", "BasinSweep", "BasinMap", "ParameterMap", "bifurcation_diagram",
           "basin_sweep", "basin_map", "parameter_map", "match_on_grid", "ESCAPED", "APERIODIC", "DIRECTIONS",
           "SweepDirection", "MapQuantity",
           "period_label", "type_label", "match_across_values",
           "check_values", "SweepAxis", "sweep_axis", "physical_names", "PHYSICAL_ALIASES"]
