"""The direct method: every cell centre integrated until its attractor is recognised.

No discretisation of images: each cell centre (on the section at forcing phase 0) is
integrated on the stroboscopic map until it escapes (the sink), recurs with a period
``<= max_period`` (a new or known attractor) or shadows a known attractor's cycle
(capture), or until ``max_periods`` periods have passed (unresolved). The reference for
the cell methods, and the default method.

A cycle recognised by recurrence is an attractor only when it is stable: near a
period-doubling a trajectory can shadow the unstable parent cycle (multiplier just
beyond -1) for hundreds of periods, long enough to recur on it within ``period_tol``.
Every cycle found is therefore checked by its largest Floquet multiplier
(:func:`~jaxgear.analysis._orbits.largest_multipliers`); the cells of an unstable one are
integrated again from their centres with that cycle as a repeller (lanes that shadow it
integrate on) until they reach a stable attractor.

Attractors that never repeat a point (quasi-periodic and chaotic ones) are found by
recurrences on a fine partition of the region (``recurrence``; Datseris & Wagemakers
2022, :mod:`jaxgear.analysis._recurrence`): a cell is decided once its trajectory keeps
landing in a known attractor's boxes, and an attractor of boxes is registered when a
trajectory still undecided after a transient recurs in its own boxes. Such an attractor
is reported with period 0 and a cloud of its points.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .._cells import CellGrid
from .._checks import check_int
from ..integrate import AbstractIntegrator, default_integrator
from ._boxes import partition_of_states
from ._cloud import verify_length
from ._lanes import Boxes
from ._method import AbstractGlobalMethod, Classification, register_method
from ._orbits import largest_multipliers, refine_orbits
from ._pool import PoolOptions, run_pool, run_pools
from ._recurrence_options import RecurrenceOptions
from ._result import UNRESOLVED
from ._saddles import saddle_lifetimes

__all__ = ["Direct", "STABLE_BELOW"]

STABLE_BELOW = 1.0 + 1e-3
"""A cycle is an attractor when its largest Floquet multiplier modulus is below this
(the margin covers the central differences' error; a cycle this close to |lambda| = 1 is
at a bifurcation, where either answer is within the model's resolution)."""

REPELLER_PASSES = 3
"""Times the cells of unstable cycles are integrated again (a pass can find another
unstable cycle); cells still on one after the last pass are unresolved."""


_POOL_NAMES = tuple(f.name for f in dataclasses.fields(PoolOptions))
"""The options of the lane pool, which :class:`Direct` also takes one by one."""

_RECURRENCE = RecurrenceOptions()
"""The default detection by recurrences."""


@register_method
class Direct(AbstractGlobalMethod):
    """Direct integration of every cell centre on the stroboscopic map (the default method).

    A pool of ``lanes`` (``chunk_size``) lanes, kept on the device
    (:mod:`jaxgear.analysis._pool`), runs rounds of ``round_periods`` forcing periods;
    after each round a lane is decided when its trajectory escapes (norm >
    ``escape_bound`` or not finite: the sink), when its last k stroboscopic points follow
    the whole cycle of a known P-k attractor within ``capture_radius`` without moving away
    from it, when it recurs with a period ``<= max_period``, or after ``max_periods``
    periods (unresolved); freed lanes take the next cells. A recurring cycle whose largest
    Floquet multiplier is not below :data:`STABLE_BELOW` is not an attractor: its cells run
    again with it as a repeller (see the module).

    Built as ``Direct(integrator=..., pool=PoolOptions(...), recurrence=...)``, or with
    the pool's options one by one: ``Direct(max_periods=4000, max_period=8)`` is
    ``Direct(pool=PoolOptions(max_periods=4000, max_period=8))`` (``chunk_size`` is the
    pool's ``lanes``; given with ``pool``, they change it). :meth:`replace` takes them
    the same way. The pool's options also read as attributes of the method
    (``method.max_periods`` is ``method.pool.max_periods``).

    Attributes:
        pool: the lane pool's options (:class:`~jaxgear.analysis.PoolOptions`:
            ``max_period``, ``round_periods`` (periods per round between checks),
            ``period_tol``, ``merge_tol``, ``max_periods`` (limit per cell, then
            ``UNRESOLVED``), ``escape_bound`` (norm beyond which a state counts as escaped),
            ``capture_radius`` (a number >= 0, or ``None``: a quarter of the smallest
            distance between two known attractors' points, at most 1 % of their scale),
            ``lanes`` and ``pilot``).
        recurrence: the detection of attractors of every type by recurrences on a fine
            partition (:class:`~jaxgear.analysis.RecurrenceOptions`), or ``None``: periodic
            attractors only (cells on other attractors stay unresolved).
        integrator: see :class:`AbstractGlobalMethod`; ``max_period``, ``period_tol``,
            ``merge_tol`` and ``chunk_size`` (``pool.lanes``) read the pool's.
    """

    name: ClassVar[str] = "direct"
    pool: PoolOptions
    recurrence: RecurrenceOptions | None

    def __init__(self, *, integrator: AbstractIntegrator | None = None, pool: PoolOptions | None = None,
                 recurrence: RecurrenceOptions | None = _RECURRENCE, **options):
        unknown = [k for k in options if k not in _POOL_NAMES and k != "chunk_size"]
        if unknown:
            raise TypeError(f"Direct got an unexpected option {unknown[0]!r}; its options are integrator, pool, "
                            f"recurrence, chunk_size and those of PoolOptions: {', '.join(_POOL_NAMES)}.")
        if pool is not None and not isinstance(pool, PoolOptions):
            raise ValueError(f"pool={pool!r} must be a jaxgear.analysis.PoolOptions (or None for the defaults).")
        if "chunk_size" in options:
            if "lanes" in options:
                raise TypeError("Direct takes chunk_size or lanes (the same option), not both.")
            options["lanes"] = check_int(options.pop("chunk_size"), "chunk_size", 1)
        pool = PoolOptions() if pool is None else pool
        self.integrator = default_integrator() if integrator is None else integrator
        self.pool = dataclasses.replace(pool, **options) if options else pool
        self.recurrence = recurrence

    @classmethod
    def option_names(cls) -> tuple[str, ...]:
        return (*super().option_names(), *_POOL_NAMES, "chunk_size")

    def __getattr__(self, name: str):  # the pool's options as the method's (only called for names it lacks)
        if name in _POOL_NAMES:
            return getattr(object.__getattribute__(self, "pool"), name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def max_period(self) -> int:
        return self.pool.max_period

    @property
    def period_tol(self) -> float:
        return self.pool.period_tol

    @property
    def merge_tol(self) -> float:
        return self.pool.merge_tol

    @property
    def chunk_size(self) -> int:
        return self.pool.lanes

    def to_dict(self) -> dict:
        """The method's name and every option, the pool's as one record (JSON-able;
        :func:`~jaxgear.analysis.method_from_dict` rebuilds it)."""
        return {"name": self.name, "integrator": self.integrator.to_dict(), "pool": self.pool.to_dict(),
                "recurrence": None if self.recurrence is None else self.recurrence.to_dict()}

    def check(self, system, grid: CellGrid) -> None:
        return None

    @classmethod
    def like(cls, method: AbstractGlobalMethod, integrator=None) -> Direct:
        """The direct method with the options every method shares (integrator, periods,
        tolerances, batch size) taken from ``method``; ``method`` itself when it is one."""
        if isinstance(method, Direct) and integrator is None:
            return method
        if isinstance(method, Direct):
            return dataclasses.replace(method, integrator=integrator)
        return cls(integrator=method.integrator if integrator is None else integrator, max_period=method.max_period,
                   period_tol=method.period_tol, merge_tol=method.merge_tol, lanes=method.chunk_size)

    def pool_options(self, pilot: int | None = None) -> PoolOptions:
        """The lane pool's options (:attr:`pool`), with ``pilot`` states in the pilot pool
        where given (0: none; the passes off repellers run without one)."""
        return self.pool if pilot is None else dataclasses.replace(self.pool, pilot=pilot)

    def boxes(self, X: np.ndarray) -> Boxes | None:
        """The fine partition of the detection by recurrences over the bounding box of the
        states ``X (n, dim)`` (an axis on which they do not vary gets the mean width of the
        others), or ``None`` when it is off."""
        if self.recurrence is None:
            return None
        return Boxes(self.recurrence, partition_of_states(X, float(self.recurrence.resolution)))

    def classify(self, system, params, grid: CellGrid, progress: bool) -> Classification:
        return self.classify_values(system, [params], grid, progress)[0]

    def classify_values(self, system, params_list, grid: CellGrid, progress: bool) -> list[Classification]:
        """:meth:`classify` at several parameter sets in one lane pool (each lane carries
        its value's parameters; attractor tables per value): one classification per
        value, each that of :meth:`classify` at that value."""
        out = []
        for labels, atts, mean, saddles, complete in self.label_states_values(system, params_list, grid.centres(),
                                                                               progress, details=True):
            out.append(Classification(labels, atts, [np.zeros(0, np.int64)] * len(atts), mean, saddles, complete))
        return out

    def label_states(self, system, params, X: np.ndarray, progress: bool = False):
        """Label the states ``X (n, dim)`` (at forcing phase 0): ``(labels (n,), [(points,
        period, residual)], mean periods per state)``."""
        return self.label_states_values(system, [params], X, progress)[0]

    def label_states_values(self, system, params_list, X: np.ndarray, progress: bool = False, label="direct",
                            details: bool = False):
        """:meth:`label_states` of the same states ``X (n, dim)`` under each parameter set of
        ``params_list``, in one lane pool: a list of its results, one per value; with
        ``details``, each with two more items: the value's chaotic saddles with their
        lifetimes (:func:`~jaxgear.analysis._saddles.saddle_lifetimes`) and whether the
        pool's pilot found all of its attractors."""
        X = np.asarray(X, np.float64)
        boxes = self.boxes(X)
        pooled = run_pools(system, params_list, [X] * len(params_list), self.integrator, self.pool_options(),
                           boxes=boxes, progress=progress, label=label)
        out = []
        for params, (labels, atts, used, met, complete) in zip(params_list, pooled):
            res = self._refined(system, params, atts)
            labels, res, used = self._stable_only(system, params, X, boxes, labels, res, used, progress)
            one = (labels, res, float(used.mean()) if len(used) else 0.0)
            if details:
                one += (saddle_lifetimes(system, params, self.integrator, boxes.partition, met,
                                         [(p, k) for p, k, _ in res], periods=verify_length(self.recurrence,
                                                                                           self.max_period),
                                         max_period=self.max_period, bound=self.pool.escape_bound)
                        if met else (), complete)
            out.append(one)
        return out

    def _refined(self, system, params, atts) -> list:
        """``[(points, k, residual)]`` of the pool's attractors ``[(points, k)]``: cycles
        refined 200 periods on, attractors of boxes (``k = 0``) as they are (residual NaN)."""
        cycles = [i for i, (_, k) in enumerate(atts) if k > 0]
        refined = dict(zip(cycles, refine_orbits(system, params, [(atts[i][0][-1], atts[i][1]) for i in cycles],
                                                 self.integrator, settle=200, max_period=self.max_period)))
        return [(refined[i][0], k, refined[i][1]) if i in refined else (pts, 0, np.nan)
                for i, (pts, k) in enumerate(atts)]

    def _stable_only(self, system, params, X, boxes, labels, res, used, progress: bool):
        """Drop the unstable cycles of ``res`` (largest multiplier not below
        :data:`STABLE_BELOW`): their cells are labelled again from their states in ``X``,
        in a pool holding the stable attractors first and every unstable cycle met so far
        as a repeller; cycles found there are checked the same way (at most
        :data:`REPELLER_PASSES` passes; then the cells left on an unstable cycle are
        unresolved). Returns ``(labels, res, used)`` with the attractors renumbered in
        their order, the new ones last, and the periods of both passes in ``used``."""
        repellers = []
        for passes in range(REPELLER_PASSES + 1):
            cycles = [i for i, (_, k, _) in enumerate(res) if k > 0]
            mu = np.zeros(len(res))  # attractors of boxes are attractors by construction
            mu[cycles] = largest_multipliers(system, params, [res[i][:2] for i in cycles], self.integrator,
                                             self.max_period)
            bad = np.flatnonzero(~(mu < STABLE_BELOW))
            if not len(bad):
                break
            keep = np.flatnonzero(mu < STABLE_BELOW)
            lut = np.full(len(res), -1, np.int64)
            lut[keep] = np.arange(len(keep))
            cells = np.flatnonzero(np.isin(labels, bad))
            labels = np.where(labels >= 0, lut[np.maximum(labels, 0)], labels)
            repellers += [(res[i][0], -res[i][1]) for i in bad]
            res = [res[i] for i in keep]
            if passes == REPELLER_PASSES:  # still on unstable cycles: not decided
                labels[cells] = UNRESOLVED
                break
            if not len(cells):  # (a cycle no cell ended on: nothing to label again)
                continue
            seeds = [(p, k) for p, k, _ in res] + repellers
            # (the pool pads its queue to a few compiled lengths itself: queue_length)
            lab, atts, use, *_ = run_pool(system, params, X[cells], self.integrator, self.pool_options(pilot=0),
                                      boxes=boxes, attractors=seeds, progress=progress,
                                      label="direct (off repellers)")
            found = atts[len(seeds):]  # slots after the seeds: cycles met on the way
            labels[cells] = np.where(lab >= len(seeds), lab - len(seeds) + len(res), lab)
            used = used.copy()
            used[cells] += use
            res = res + self._refined(system, params, found)
        return labels, res, used
