"""The global-analysis method interface (the "mapper": algorithm + its options).

A method object holds every option of one algorithm and its defaults; the
system, its parameters and the grid are given to :func:`~jaxgear.analyze_global`, and
the result records the method's :meth:`~AbstractGlobalMethod.to_dict`. Analyses never
check a method's type: they call :meth:`~AbstractGlobalMethod.check` and
:meth:`~AbstractGlobalMethod.classify`.
"""

# no ``from __future__ import annotations``: equinox reads the ``AbstractVar`` annotations
import abc
import dataclasses
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import numpy as np
from equinox import AbstractVar

from .._cells import CellGrid
from .._checks import check_int, check_number
from .._model import REDUCED
from ..integrate import AbstractIntegrator, default_integrator, integrator_from_dict
from ._pool_options import PoolOptions
from ._recurrence_options import RecurrenceOptions

__all__ = ["AbstractGlobalMethod", "Classification", "METHODS", "method_from_dict", "method_from_name",
           "register_method"]

METHODS: dict[str, type] = {}
"""Method classes by name (``"direct"``, ``"poincare-like"``, ``"stroboscopic"``)."""


def register_method(cls):
    """Class decorator: make a method known by its ``name`` (CLI choices, saved settings)."""
    METHODS[cls.name] = cls
    return cls


class Classification(NamedTuple):
    """What a method returns to :func:`~jaxgear.analyze_global` before the common steps
    (minimal periods, merging, sorting by share, section points).

    labels: ``(n_cells,)`` attractor index, ``SINK`` or ``UNRESOLVED``; attractors:
    ``[(points (k, dim), period k, residual), ...]``; cycles: the periodic cells of each
    attractor (cell methods; empty arrays otherwise); mean_periods: forcing periods
    integrated per cell; saddles: the chaotic saddles met (:class:`~jaxgear.ChaoticSaddle`,
    direct method); pilot_complete: whether the lane pool's pilot found every attractor
    (direct method; in a pool shared with other values, the labels of a value whose
    attractors were not all found by then may depend on the other values).
    """

    labels: np.ndarray
    attractors: list
    cycles: list
    mean_periods: float
    saddles: tuple = ()
    pilot_complete: bool = True


class AbstractGlobalMethod(eqx.Module):
    """Options shared by every global-analysis method.

    Attributes:
        integrator: the integration strategy (default
            :func:`~jaxgear.integrate.default_integrator`).
        max_period: largest period k detected (P-1 ... P-max_period).
        period_tol: relative recurrence tolerance of the period detection.
        merge_tol: relative distance under which two attractors are the same
            (:func:`jaxgear._matching.same_attractor`).
        chunk_size: cells integrated in one batch (memory is bounded by it, not by the
            grid; results do not depend on it).

    A method declares the last four as fields (the cell methods) or reads them from the
    options it holds (:class:`~jaxgear.Direct`, from its ``pool``).
    """

    name: ClassVar[str] = "abstract"
    integrator: AbstractIntegrator = eqx.field(static=True, default_factory=default_integrator)
    max_period: AbstractVar[int]
    period_tol: AbstractVar[float]
    merge_tol: AbstractVar[float]
    chunk_size: AbstractVar[int]

    def __check_init__(self):
        if not isinstance(self.integrator, AbstractIntegrator):
            raise ValueError(f"integrator={self.integrator!r} must be an integrator object "
                             "(jaxgear.RK4(...), jaxgear.Adaptive(...)).")
        check_int(self.max_period, "max_period", 1)
        check_number(self.period_tol, "period_tol", 0, strict_min=True)
        check_number(self.merge_tol, "merge_tol", 0, strict_min=True)
        check_int(self.chunk_size, "chunk_size", 1)

    @abc.abstractmethod
    def check(self, system, grid: CellGrid) -> None:
        """Raise ``ValueError`` when the method cannot run on ``system`` with ``grid``."""

    @abc.abstractmethod
    def classify(self, system, params, grid: CellGrid, progress: bool) -> Classification:
        """Label every cell of ``grid`` and return the attractors found."""

    def default_grid(self, system) -> CellGrid:
        """The grid used when none is given (the paper's region D for the gear model)."""
        if system is not REDUCED:
            raise ValueError("analyze_global: pass a CellGrid for your system (CellGrid.box(bounds, counts, ...)).")
        return CellGrid.paper()

    @property
    def section_index(self) -> int | None:
        """Coordinate of the section Σ whose crossings are reported (None: the system's)."""
        return None

    @property
    def direction(self) -> int:
        """Crossing direction of Σ for the reported section points."""
        return 1

    def replace(self, **changes) -> "AbstractGlobalMethod":
        """A copy with some options changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        """The keyword arguments the method's constructor takes (its fields; a method may
        take more: :class:`~jaxgear.Direct` also takes its pool's options one by one)."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def to_dict(self) -> dict[str, Any]:
        """The method's name and every option (JSON-able; :func:`method_from_dict` rebuilds it)."""
        out: dict[str, Any] = {"name": self.name}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = v.to_dict() if hasattr(v, "to_dict") else v
        return out


def method_from_name(name: str, **options) -> AbstractGlobalMethod:
    """The method called ``name`` with ``options`` (the others at their defaults).

    Methods register themselves where they are defined (:func:`register_method`); the
    package :mod:`jaxgear.analysis` imports them all before this can run."""
    if name not in METHODS:
        raise ValueError(f"method={name!r} must be one of {', '.join(repr(m) for m in METHODS)}.")
    return METHODS[name](**options)


def method_from_dict(d: dict[str, Any]) -> AbstractGlobalMethod:
    """Rebuild a method from :meth:`AbstractGlobalMethod.to_dict` (also the flat options
    of the direct method that files of format 4 hold: ``max_periods``, ``chunk_size``, ...)."""
    name = d.get("name")
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; known: {', '.join(METHODS)}.")
    cls = METHODS[name]
    fields = set(cls.option_names())
    opts = {k: v for k, v in d.items() if k in fields and k != "integrator"}
    if isinstance(opts.get("recurrence"), dict):
        opts["recurrence"] = RecurrenceOptions(**opts["recurrence"])
    if isinstance(opts.get("pool"), dict):
        opts["pool"] = PoolOptions(**opts["pool"])
    if isinstance(d.get("integrator"), dict):
        opts["integrator"] = integrator_from_dict(d["integrator"])
    return cls(**opts)
