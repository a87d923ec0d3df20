"""Global analysis (paper §3-§4): methods, the driver and its result.

- :mod:`._method` — the method interface (options + algorithm) and the registry;
- :mod:`._direct` — :class:`Direct`, direct integration of every cell (the default);
- :mod:`._cellmap` — :class:`PoincareCellMap` (the paper's) and :class:`StroboscopicCellMap` (Hsu's);
- :mod:`._graph` — Hsu's periodic groups and domains of a simple cell map;
- :mod:`._orbits` — periods, refined points and section crossings of attractors;
- :mod:`._global` — :func:`analyze_global`, the common steps and the result;
- :mod:`._result` — :class:`GlobalResult` and :class:`Attractor`;
- :mod:`._diagnostics` — warnings when a result looks unreliable;
- :mod:`._compare` — agreement with direct integration on a sample of cells;
- :mod:`._uncertainty` — :func:`label_uncertainty`, how far a result's labels can be trusted;
- :mod:`._recurrence` — attractors of every type by recurrences on a fine partition (the
  method, and :func:`classify_by_recurrence`, a view of the lane pool); its boxes
  (:mod:`._boxes`), candidate clouds (:mod:`._cloud`) and options (:mod:`._recurrence_options`);
- :mod:`._fractal` — basin entropy and the uncertainty exponent of a basin map;
- :mod:`._lanes`, :mod:`._placement`, :mod:`._pool` — the direct method's device-resident lane
  pool: its device program, where it runs, and its host driver.
"""

from ._cellmap import PoincareCellMap, StroboscopicCellMap, cell_images
from ._compare import compare_with_direct
from ._direct import Direct
from ._fractal import (
                       BasinEntropy,
                       ScalingRange,
                       UncertaintyExponent,
                       basin_entropy,
                       scaling_range,
                       uncertain_fraction,
                       uncertainty_exponent,
)
from ._global import (
                      DEFAULT_METHOD,
                      analyze_global,
                      analyze_global_values,
                      default_method,
                      with_label_uncertainty,
)
from ._graph import analyze_cell_map
from ._method import METHODS, AbstractGlobalMethod, Classification, method_from_dict, method_from_name
from ._orbits import detect_period
from ._pool import PoolOptions
from ._recurrence import RecurrenceResult, classify_by_recurrence
from ._recurrence_options import RecurrenceOptions
from ._result import LABEL_MEANINGS, SINK, UNRESOLVED, Attractor, ChaoticSaddle, GlobalResult, LabelUncertainty
from ._uncertainty import DEFAULT_SAMPLES, label_uncertainty

__all__ = ["AbstractGlobalMethod", "Direct", "PoincareCellMap", "StroboscopicCellMap", "analyze_global",
           "analyze_global_values",
           "default_method", "DEFAULT_METHOD", "analyze_cell_map", "cell_images", "compare_with_direct",
           "detect_period", "GlobalResult", "Attractor", "ChaoticSaddle", "LabelUncertainty", "SINK", "UNRESOLVED", "LABEL_MEANINGS", "METHODS",
           "method_from_dict", "method_from_name", "Classification", "label_uncertainty", "DEFAULT_SAMPLES",
           "with_label_uncertainty", "PoolOptions", "RecurrenceOptions", "RecurrenceResult",
           "classify_by_recurrence", "basin_entropy", "BasinEntropy", "uncertainty_exponent", "UncertaintyExponent",
           "uncertain_fraction", "scaling_range", "ScalingRange"]
