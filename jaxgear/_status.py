"""One status enumeration for every batched outcome.

Each lane of a batched computation (a Poincaré-map lane, a Newton run from one seed,
a continuation step, a cell of a global analysis) ends with one of these outcomes,
returned as data (an integer array) instead of an exception or a silent NaN. Files
store the codes with their names (CF ``flag_values`` / ``flag_meanings``), so a saved
result reads the same whatever the codes become in later versions.
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["Status", "status_names", "count_statuses"]


class Status(enum.IntEnum):
    """Outcome of one lane of a batched computation.

    Members (value, meaning):

    - ``CONVERGED`` (0): finished normally — a Poincaré map hit its section, Newton met
      its tolerance, a corrector converged.
    - ``NOT_CONVERGED`` (1): an iteration stopped without meeting its tolerance
      (iteration limit, stalled line search).
    - ``SINGULAR`` (2): a linear system was numerically singular.
    - ``DIVERGED`` (3): the flow or an iterate became non-finite or left the allowed norm.
    - ``ESCAPED`` (4): a trajectory left the region of interest (the sink of a cell map).
    - ``NO_CROSSING`` (5): no crossing of a Poincaré section within the search time.
    - ``UNRESOLVED`` (6): the fate of a lane was not decided within the time allowed.
    - ``MAX_STEPS`` (7): an adaptive integrator used up its step budget.
    """

    CONVERGED = 0
    NOT_CONVERGED = 1
    SINGULAR = 2
    DIVERGED = 3
    ESCAPED = 4
    NO_CROSSING = 5
    UNRESOLVED = 6
    MAX_STEPS = 7

    @property
    def label(self) -> str:
        """Lower-case name with spaces, e.g. ``"not converged"``."""
        return self.name.lower().replace("_", " ")


def status_names() -> dict[int, str]:
    """``{code: name}`` of every :class:`Status` (names as in :attr:`Status.label`)."""
    return {int(s): s.label for s in Status}


def count_statuses(codes, members=None) -> dict[str, int]:
    """How many lanes ended with each status: ``{label: count}`` over ``members``
    (default: every status), in enumeration order."""
    codes = np.asarray(codes).reshape(-1)
    members = list(Status) if members is None else list(members)
    return {s.label: int(np.sum(codes == int(s))) for s in members}
