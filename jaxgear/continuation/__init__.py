"""Continuation of periodic orbits in one parameter (pseudo-arclength), with bifurcations.

- :mod:`._arclength` — :func:`continue_orbit`, :func:`switch_branch` (the algorithm);
- :mod:`._options` — :class:`ContinuationOptions` (step control, bifurcation search);
- :mod:`._branch` — :class:`Branch`, :class:`BifurcationPoint` (the result).
"""

from ._arclength import continue_orbit, switch_branch
from ._branch import (
    BIFURCATION_KINDS,
    BRANCH_STATUS,
    BifurcationKind,
    BifurcationPoint,
    Branch,
    BranchSettings,
    BranchStatus,
    bifurcation_orbit,
)
from ._options import CORRECTOR, ContinuationOptions

__all__ = ["continue_orbit", "switch_branch", "ContinuationOptions", "CORRECTOR", "Branch", "BranchSettings", "BifurcationPoint", "BifurcationKind", "BranchStatus", "BIFURCATION_KINDS", "BRANCH_STATUS",
           "bifurcation_orbit"]
