"""Options of the shooting method (paper §4.1): one solve (:class:`ShootOptions`) and a search
over many seeds and periods (:class:`SearchOptions`).

Both are immutable ``eqx.Module``s checked at construction (a bad value raises a
``ValueError`` naming the field). The solver is an optimistix object or ``None`` (the
library's choice, :func:`default_solver`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import equinox as eqx

from .._checks import check_int, check_number, split_changes, with_changes
from ..integrate import AbstractIntegrator, integrator_from_dict

__all__ = ["ShootOptions", "SearchOptions", "VerifyOptions", "default_solver", "check_solver", "with_changes", "split_changes",
           "solver_to_dict", "solver_from_dict"]

STEP_RTOL, STEP_ATOL = 1e-10, 1e-12
"""Step tolerances of the library's solver: steps below ``1e-12 + 1e-10 |x|`` end the iteration
(whether a seed converged is then decided on the residual ``||P^k(x) - x|| <= tol``)."""


def _optx():
    """optimistix, imported on first use (it adds a tenth of a second to every ``import jaxgear``)."""
    import optimistix

    return optimistix


def default_solver():
    """The solver used when none is given: ``optimistix.LevenbergMarquardt``.

    Measured on the paper preset (``benchmarks/shooting.py``): from 64 random seeds over
    region D with a transient of 40 periods it reaches the unstable P-1 from 45 seeds
    (``optimistix.Dogleg`` 44, ``optimistix.Newton`` 31: its full steps overshoot near the
    flip-unstable P-1), and from seeds 0.05 off the stable P-4 it converges from every
    seed, where Dogleg's trust region collapses on the kinks of the backlash map and stalls
    on one of four seeds. Its damping keeps the iterates of far seeds bounded.
    """
    return _optx().LevenbergMarquardt(rtol=STEP_RTOL, atol=STEP_ATOL)


def check_solver(solver) -> None:
    """Raise ``ValueError`` unless ``solver`` is ``None`` or an optimistix root finder
    (``optx.Newton``, ``optx.Chord``) or least-squares solver (``optx.Dogleg``,
    ``optx.LevenbergMarquardt``, ``optx.GaussNewton``) instance."""
    if solver is None:
        return
    optx = _optx()
    allowed = (optx.AbstractRootFinder, optx.AbstractLeastSquaresSolver)
    hint = ("must be None (the library's choice) or an optimistix solver instance such as "
            "optimistix.Newton(rtol=1e-10, atol=1e-12), optimistix.Dogleg(...) or optimistix.LevenbergMarquardt(...)")
    if isinstance(solver, str):
        raise ValueError(f"solver={solver!r} {hint}; solver names are for the command line only.")
    if isinstance(solver, type) and issubclass(solver, allowed):
        raise ValueError(f"solver={solver.__name__} is a class: {hint} (call it with its tolerances).")
    if isinstance(solver, optx.Bisection):
        raise ValueError(f"solver={solver!r}: Bisection solves scalar equations only; the solver {hint}.")
    if not isinstance(solver, allowed):
        raise ValueError(f"solver={solver!r} {hint}.")


def solver_to_dict(solver) -> dict[str, Any] | None:
    """A solver as saved in a result file: ``None`` (the library's choice) or its class name
    and tolerances (:func:`solver_from_dict` rebuilds it)."""
    if solver is None:
        return None
    return {"type": type(solver).__name__, "rtol": float(solver.rtol), "atol": float(solver.atol)}


def solver_from_dict(d: dict[str, Any] | None):
    """The solver :func:`solver_to_dict` saved: the optimistix class of that name with those
    tolerances (``None`` for the library's choice)."""
    if d is None:
        return None
    optx, name = _optx(), str(d["type"])
    cls = getattr(optx, name, None) if name.isidentifier() else None
    if not (isinstance(cls, type) and issubclass(cls, (optx.AbstractRootFinder, optx.AbstractLeastSquaresSolver))):
        raise ValueError(f"solver type {name!r} is not an optimistix root finder or least-squares solver.")
    solver = cls(rtol=float(d["rtol"]), atol=float(d["atol"]))
    check_solver(solver)
    return solver


def _integrator_to_dict(integrator) -> dict[str, Any] | None:
    return None if integrator is None else integrator.to_dict()


def _integrator_from_dict(d) -> AbstractIntegrator | None:
    return None if d is None else integrator_from_dict(d)


class ShootOptions(eqx.Module):
    """Options of one Newton-type solve of ``P^k(x) - x = 0`` (paper §4.1).

    Attributes:
        solver: an optimistix root finder (``optx.Newton``, ``optx.Dogleg``,
            ``optx.LevenbergMarquardt`` instance) or ``None``: the library's choice
            (:func:`default_solver`).
        tol: convergence on ``||P^k(x) - x||`` (Euclidean, state units).
        max_iter: iteration limit of the solver.
        max_norm: an iterate with ``||x|| > max_norm`` is reported as diverged (state units).
        period_tol: ``P^j(x*) = x*`` for a divisor ``j`` of ``k`` when
            ``||P^j(x*) - x*|| <= period_tol (1 + ||x*||)`` (minimal period).
        segments: ``M``, segments of the multiple shooting (1: single shooting).
        deflation_power, deflation_shift: ``p`` and ``shift`` of the deflation operator
            ``prod (1 / ||x - r_i||^p + shift)`` (Farrell, Birkisson & Funke 2015).
    """

    solver: Any = eqx.field(default=None, metadata=dict(encode=solver_to_dict, decode=solver_from_dict))
    tol: float = 1e-10
    max_iter: int = eqx.field(static=True, default=40)
    max_norm: float = 1e6
    period_tol: float = 1e-6
    segments: int = eqx.field(static=True, default=1)
    deflation_power: float = 2.0
    deflation_shift: float = 1.0

    def __check_init__(self):
        check_solver(self.solver)
        check_number(self.tol, "tol", 0, strict_min=True)
        check_int(self.max_iter, "max_iter", 1)
        check_number(self.max_norm, "max_norm", 0, strict_min=True)
        check_number(self.period_tol, "period_tol", 0, strict_min=True)
        check_int(self.segments, "segments", 1)
        check_number(self.deflation_power, "deflation_power", 1, strict_min=True)
        check_number(self.deflation_shift, "deflation_shift", 0)

    @property
    def root_finder(self):
        """The optimistix solver itself (:func:`default_solver` when ``solver`` is ``None``)."""
        return default_solver() if self.solver is None else self.solver

    def shoot_options(self) -> ShootOptions:
        """The options of one solve (these, without any search options)."""
        return ShootOptions(**{f.name: getattr(self, f.name) for f in dataclasses.fields(ShootOptions)})

    def to_dict(self) -> dict[str, Any]:
        """Every option, JSON-able (the solver as its class name and tolerances)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "solver":
                s = self.root_finder
                v = {"type": type(s).__name__, "rtol": float(s.rtol), "atol": float(s.atol),
                     "default": self.solver is None}
            elif isinstance(v, AbstractIntegrator):
                v = v.to_dict()
            out[f.name] = v
        return out


class SearchOptions(ShootOptions):
    """Options of :func:`~jaxgear.find_periodic_orbits`: those of each solve
    (:class:`ShootOptions`) and of the search over many seeds and periods.

    The same options serve one period and a range of periods (``jaxgear shoot --period K``
    and ``--periods K1-K2`` alike).

    Attributes:
        transient: forcing periods each seed is mapped forward (direct integration)
            before shooting. Seeds drawn at random over a region need it: it brings them
            near the attractors and the unstable orbits they are born from (on the paper
            preset it lifts the converged fraction from about 1 % to about 80 %,
            ``benchmarks/shooting.py``); seeds already near an orbit (a user's point, an
            unstable orbit) do not, and would be carried away from an unstable one.
            ``jaxgear shoot --random`` uses 40.
        deflation_rounds: deflated rounds after the plain one: the same seeds shot again
            with the orbits found so far deflated away (0: none; rounds stop when one
            finds nothing new).
        search_integrator: integrator of the rounds (``None``: the search's own
            integrator). When it differs, each distinct orbit is re-converged (polished)
            with the search's integrator and only orbits that re-converge are reported.
        dedup_tol: two converged seeds give the same orbit when a point of one lies
            within ``dedup_tol (1 + ||x||)`` of a point of the other (any cyclic shift).
        chunk_size: seeds per batch (memory bound; results do not depend on it).
        trajectory_samples: samples per forcing period of each orbit's stored
            trajectory (0: none).
        verify: when > 0, check each orbit by direct integration over ``verify``
            periods (:func:`~jaxgear.verify_orbit`).
    """

    transient: int = eqx.field(static=True, default=0)
    deflation_rounds: int = eqx.field(static=True, default=0)
    search_integrator: AbstractIntegrator | None = eqx.field(
        static=True, default=None, metadata=dict(encode=_integrator_to_dict, decode=_integrator_from_dict))
    dedup_tol: float = 1e-6
    chunk_size: int = eqx.field(static=True, default=256)
    trajectory_samples: int = eqx.field(static=True, default=200)
    verify: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        check_int(self.transient, "transient", 0)
        check_int(self.deflation_rounds, "deflation_rounds", 0)
        if self.search_integrator is not None and not isinstance(self.search_integrator, AbstractIntegrator):
            raise ValueError(f"search_integrator={self.search_integrator!r} must be None or an integrator object "
                             "(jaxgear.RK4(...), jaxgear.KinkAwareRK4(...), jaxgear.Adaptive(...)).")
        check_number(self.dedup_tol, "dedup_tol", 0, strict_min=True)
        check_int(self.chunk_size, "chunk_size", 1)
        check_int(self.trajectory_samples, "trajectory_samples", 0)
        check_int(self.verify, "verify", 0)


class VerifyOptions(eqx.Module):
    """Options of :func:`~jaxgear.verify_orbit`, the paper's check of an orbit by direct
    integration from perturbed starts (§4.1).

    Attributes:
        periods: forcing periods integrated per trial.
        perturbation: relative size of the initial perturbation (dimensionless): the
            starts are ``x* + perturbation (1 + ||x*||) u`` for random unit vectors ``u``.
        n_trials: number of perturbed starts.
        leave_tol: distance (state units) above which the motion has left the orbit.
        n_final: number of final stroboscopic points returned per trial (at most ``periods``).
        seed: seed of the random directions ``u``.
    """

    periods: int = eqx.field(static=True, default=300)
    perturbation: float = 1e-6
    n_trials: int = eqx.field(static=True, default=4)
    leave_tol: float = 1e-3
    n_final: int = eqx.field(static=True, default=8)
    seed: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        check_int(self.periods, "periods", 1)
        check_number(self.perturbation, "perturbation", 0)
        check_int(self.n_trials, "n_trials", 1)
        check_number(self.leave_tol, "leave_tol", 0, strict_min=True)
        check_int(self.n_final, "n_final", 1, int(self.periods))
        check_int(self.seed, "seed", 0)
