"""Shooting (paper §4.1): periodic orbits of the stroboscopic map, Floquet multipliers, verification.

- :mod:`._options` — :class:`ShootOptions` (one solve) and :class:`SearchOptions` (a search);
- :mod:`._solve` — single and multiple shooting with deflation, solved by optimistix;
- :mod:`._orbit` — :func:`periodic_orbit` from one seed or a batch, :class:`ShootResult`;
- :mod:`._floquet` — monodromy matrices, multipliers, :class:`Instability`;
- :mod:`._search` — :func:`find_periodic_orbits` over many seeds and periods, :class:`OrbitSearch`;
- :mod:`._seeds` — seeds from a global-analysis result or a random box;
- :mod:`._verify` — the paper's check by direct integration.
"""

from ._floquet import Instability, classify_multipliers, floquet_multipliers, monodromy, sorted_eigvals
from ._options import SearchOptions, ShootOptions, VerifyOptions, default_solver
from ._orbit import ShootResult, periodic_orbit
from ._search import (
    NEWTON_STATUSES,
    OrbitSearch,
    OrbitVerification,
    PeriodConvergence,
    PeriodicOrbit,
    SearchSettings,
    find_periodic_orbits,
)
from ._seeds import seeds_from_result, seeds_in_box
from ._verify import OrbitCheck, verify_orbit

__all__ = ["SearchOptions", "ShootOptions", "VerifyOptions", "default_solver", "Instability", "classify_multipliers", "floquet_multipliers", "monodromy", "sorted_eigvals",
           "ShootResult", "periodic_orbit", "OrbitSearch", "SearchSettings", "PeriodicOrbit", "find_periodic_orbits",
           "PeriodConvergence", "OrbitVerification",
           "NEWTON_STATUSES", "seeds_from_result", "seeds_in_box", "OrbitCheck", "verify_orbit"]
