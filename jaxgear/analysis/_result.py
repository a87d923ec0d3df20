"""Result of a global analysis: attractors, their periods, domains and shares."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .._cells import CellGrid
from .._codec import array_field, custom_field, items_field, later_field, result_type
from .._format import format_table
from .._io import save_result, write_json
from .._lyapunov import AttractorType, attractor_label, type_reason
from ..integrate import AbstractFixedStep, AbstractIntegrator, integrator_from_dict
from ._fractal import BasinEntropy
from ._method import AbstractGlobalMethod, method_from_dict

__all__ = ["Attractor", "ChaoticSaddle", "GlobalResult", "LabelUncertainty", "SINK", "UNRESOLVED", "LABEL_MEANINGS"]

SINK = -1
"""Label of cells whose orbits leave the region or blow up (Hsu's sink cell; outcome
``Status.ESCAPED``)."""
UNRESOLVED = -2
"""Label of cells whose fate was not decided in the allowed time (``Status.UNRESOLVED``)."""
LABEL_MEANINGS = {SINK: "sink (left the region or blew up)", UNRESOLVED: "unresolved"}


@dataclasses.dataclass(frozen=True, kw_only=True)
class Attractor:
    """One attractor found by the global analysis (paper §4.2: a P-k motion and its domain).

    Points are in state units (dimensionless ``b_c``, ``b_c omega_n`` for the gear
    models, model document §3) at forcing phase 0.

    Attributes:
        id: its label in :attr:`GlobalResult.labels`.
        period: k of P-k on the stroboscopic map (minimal); 0 for an attractor that repeats
            no point (quasi-periodic or chaotic: found by recurrences on a fine partition).
        points: ``(k, dim)`` stroboscopic points (state at phase 0 of k successive
            periods); for period 0 a cloud of a few thousand points on the attractor.
        section_points: ``(m, dim)`` crossings of Σ over the k periods (empty when the
            method has no section).
        cell_count: cells in its domain of attraction (including its periodic cells).
        share: ``cell_count / n_cells``.
        residual: ``max_i |P^k(p_i) - p_i|`` of the reported points (integration-level).
        periodic_cells: indices of the cells of its periodic group(s) (cell methods).
        multiplier: the largest modulus of its Floquet multipliers (paper §4.1: the
            cycle is asymptotically stable when it is below 1), the eigenvalues of the
            product of the one-period Jacobians (autodiff) along the cycle; NaN for period 0.
        kind: its :class:`~jaxgear.AttractorType` (periodic, quasi-periodic, chaotic), from
            its period and Lyapunov exponents (-1, unknown, where not measured).
        exponents: ``(n,)`` its largest Lyapunov exponents of the stroboscopic map, per
            forcing period (:func:`~jaxgear.lyapunov_spectrum`; NaN where not measured);
            per unit time they are these divided by the forcing period.
        exponent_errors: ``(n,)`` their standard errors (spread over independent stretches).
        kaplan_yorke: the Kaplan-Yorke dimension of the attractor of the map (0 for a
            stable cycle; NaN where not measured).
    """

    id: int
    period: int
    points: np.ndarray = array_field(("point", "state"))
    section_points: np.ndarray = array_field(("crossing", "state"))
    cell_count: int = 0
    share: float = 0.0
    residual: float = float("nan")
    periodic_cells: np.ndarray = array_field(("cycle_cell",), default_factory=lambda: np.zeros(0, np.int64))
    multiplier: float = later_field(float("nan"))
    kind: int = later_field(-1)
    exponents: np.ndarray = array_field(("exponent",), later=True, default_factory=lambda: np.zeros(0))
    exponent_errors: np.ndarray = array_field(("exponent",), later=True, default_factory=lambda: np.zeros(0))
    kaplan_yorke: float = later_field(float("nan"))

    @property
    def type(self) -> AttractorType:
        """Its :class:`~jaxgear.AttractorType`."""
        return AttractorType(int(self.kind))

    @property
    def largest_exponent(self) -> float:
        """Its largest Lyapunov exponent per forcing period (NaN where not measured)."""
        return float(self.exponents[0]) if len(self.exponents) else float("nan")

    @property
    def label(self) -> str:
        """``"P-k"``, ``"quasi-periodic"``, ``"chaotic"`` or ``"undetermined"``
        (``"aperiodic"`` for period 0 of unknown type)."""
        return attractor_label(self.period, self.kind)

    @property
    def type_reason(self) -> str:
        """Why it has its type: the test of :func:`~jaxgear.classify_attractor` with its
        numbers (:func:`~jaxgear.type_reason`)."""
        return type_reason(self.type, self.exponents, self.exponent_errors, self.period)

    def summary(self) -> dict[str, Any]:
        """JSON-able description (points as lists)."""
        return dict(id=self.id, period=self.period, label=self.label, type=self.type.name.lower(),
                    type_reason=self.type_reason,
                    exponents=np.asarray(self.exponents).tolist(),
                    exponent_errors=np.asarray(self.exponent_errors).tolist(), kaplan_yorke=self.kaplan_yorke,
                    cell_count=self.cell_count,
                    share=self.share, residual=self.residual, multiplier=self.multiplier,
                    points=np.asarray(self.points).tolist(),
                    section_points=np.asarray(self.section_points).tolist(),
                    n_periodic_cells=int(len(self.periodic_cells)))


def _exponent_text(a: Attractor) -> str:
    """``lambda_1 +- error`` per forcing period, ``-`` where not measured."""
    lam = a.largest_exponent
    if not np.isfinite(lam):
        return "-"
    err = float(a.exponent_errors[0]) if len(a.exponent_errors) else float("nan")
    if a.period > 0 and err == 0.0:  # a cycle's, from its Floquet multipliers
        return f"{lam:+.4f} (Floquet)"
    return f"{lam:+.4f}" + (f" +- {err:.1e}" if np.isfinite(err) else "")


@dataclasses.dataclass(frozen=True, kw_only=True)
class ChaoticSaddle:
    """A long chaotic transient the analysis met: a set on which states wander like on a
    chaotic attractor before they leave it for an attractor (Lai & Tél, *Transient Chaos*,
    2011). It labels no cell; its cells are labelled with where they went (they may run up
    to ``saddle_periods``).

    Attributes:
        points: ``(m, dim)`` a cloud of stroboscopic points on it.
        lifetime: the transient's mean lifetime ``1 / kappa`` in forcing periods, from the
            escape rate ``kappa`` of ``starts`` of its points continued ``periods`` periods
            (inf when none of them left after the first eighth, NaN when all had left
            within it: too short to measure).
        lifetime_error: its standard error (NaN where not measurable).
        starts, periods: the points continued and for how long.
        left: the share of them that left within ``periods``.
    """

    points: np.ndarray = array_field(("saddle_point", "state"))
    lifetime: float = float("nan")
    lifetime_error: float = float("nan")
    starts: int = 0
    periods: int = 0
    left: float = float("nan")

    def describe(self) -> str:
        """One line: the mean lifetime and how it was measured."""
        if np.isnan(self.lifetime):
            life = f"a mean lifetime below about {self.periods // 8} periods"
        elif not np.isfinite(self.lifetime):
            life = f"a mean lifetime beyond about {self.periods} periods"
        else:
            life = f"a mean lifetime of {self.lifetime:,.0f} +- {self.lifetime_error:,.0f} periods"
        return (f"chaotic saddle (a long chaotic transient, no attractor): {life} "
                f"({100 * self.left:.0f} % of {self.starts} of its points left it within {self.periods} periods)")


@dataclasses.dataclass(frozen=True, kw_only=True)
class LabelUncertainty:
    """How far a result's labels can be trusted (:func:`~jaxgear.analysis.label_uncertainty`).

    A random sample of cells is labelled again by direct integration, once with a finer
    integrator and once from starts moved inside their cells; the shares of sampled
    cells whose label changes bound the labels' error from the integration and from the
    cell discretisation (paper §3: a cell stands for every state in it).

    Attributes:
        samples: cells sampled.
        step: share of them whose label changes with ``refined_integrator``.
        start: share of them whose label changes when the start moves by up to
            ``perturbation`` cell sizes along each grid axis.
        perturbation: the start's largest move, in cell sizes.
        refined_integrator: the finer integrator (``integrator.refined()`` of the method's).
        perturbations: the start moves measured (cell sizes, the first is ``perturbation``)
            and ``start_fractions`` the share of sampled cells whose label changes at each:
            the uncertain fraction ``f(eps)`` of Grebogi, McDonald, Ott & Yorke (1983).
        alpha, alpha_error: the uncertainty exponent, ``f(eps) ~ eps**alpha``, from a
            log-log fit of those fractions over their scaling range
            (:func:`~jaxgear.scaling_range`) and its standard error: 1 for a smooth basin
            boundary, below 1 for a fractal one (NaN where there is no scaling range).
        alpha_range: the smallest and the largest start move of that range (cell sizes;
            ``None`` where there is none, and in files written before the range was chosen,
            whose ``alpha`` is fitted to every fraction above zero).
        alpha_chi2: the fit's reduced ``chi^2`` over the range (NaN where none).
        alpha_reason: ``None``, or why there is no exponent (``"no scaling range: ..."``).
    """

    samples: int
    step: float
    start: float
    perturbation: float
    refined_integrator: AbstractIntegrator = custom_field(lambda i: i.to_dict(), integrator_from_dict)
    perturbations: tuple[float, ...] = ()
    start_fractions: tuple[float, ...] = ()
    alpha: float = float("nan")
    alpha_error: float = float("nan")
    alpha_range: tuple[float, float] | None = later_field(None)
    alpha_chi2: float = later_field(float("nan"))
    alpha_reason: str | None = later_field(None)

    def alpha_text(self) -> str:
        """The uncertainty exponent in words: its value, error, range and fit quality, or
        why there is none (``""`` where not measured)."""
        if np.isfinite(self.alpha):
            text = f"alpha = {self.alpha:.2f} +- {self.alpha_error:.2f}"
            if self.alpha_range is not None:
                text += (f" over start moves {self.alpha_range[0]:.0e} to {self.alpha_range[1]:.0e} cell "
                         f"(reduced chi^2 {self.alpha_chi2:.2f})")
            return text
        return self.alpha_reason or ""

    def describe(self) -> str:
        """One line for the printed table."""
        r = self.refined_integrator
        refined = (f"halved step ({r.steps_per_period} steps/period)" if isinstance(r, AbstractFixedStep)
                   else "16x smaller integration error")
        line = (f"label uncertainty ({self.samples} sampled cells): {_percent(self.step, self.samples)} change with a "
                f"{refined}, {_percent(self.start, self.samples)} when the start moves by {self.perturbation:g} cell")
        if self.alpha_text():
            line += f"\nuncertainty exponent: {self.alpha_text()}" + (" (1: smooth boundary)" if np.isfinite(self.alpha)
                                                                       else "")
        return line


def _percent(share: float, samples: int) -> str:
    """A sampled share in percent with its binomial standard error ``sqrt(p (1 - p) / n)``."""
    se = np.sqrt(share * (1.0 - share) / max(int(samples), 1))
    return f"{100 * share:.1f} % +- {100 * se:.1f}"


def _uncertainty_summary(u: LabelUncertainty) -> dict[str, Any]:
    return dict(samples=u.samples, step=u.step, start=u.start, perturbation=u.perturbation,
                refined_integrator=u.refined_integrator.to_dict(), perturbations=list(u.perturbations),
                start_fractions=list(u.start_fractions), alpha=u.alpha, alpha_error=u.alpha_error,
                alpha_range=None if u.alpha_range is None else list(u.alpha_range), alpha_chi2=u.alpha_chi2,
                alpha_reason=u.alpha_reason)


def _grid_dims(r: GlobalResult) -> tuple[str, ...]:
    return r.grid.axis_names


@result_type
@dataclasses.dataclass(frozen=True, kw_only=True)
class GlobalResult:
    """Outcome of :func:`jaxgear.analyze_global` (paper §4).

    Attributes:
        labels: int array of shape ``grid.counts``: attractor id, ``SINK`` (-1) or
            ``UNRESOLVED`` (-2) for every cell.
        attractors: tuple of :class:`Attractor`, sorted by decreasing share.
        grid: the :class:`~jaxgear.CellGrid`.
        method: the method object that produced it, with every option and its
            integrator (a :class:`~jaxgear.Direct`, :class:`~jaxgear.PoincareCellMap`,
            :class:`~jaxgear.StroboscopicCellMap`, ...; saved as
            :meth:`~jaxgear.AbstractGlobalMethod.to_dict`, so it can be re-run from its file).
        params: the full canonical parameter set (model document §4 names) as a dict.
        system: the system's name; state_names: its coordinate names.
        n_sink, n_unresolved: cell counts.
        runtime_s: wall time of the analysis; version: jaxgear version.
        mean_periods: mean number of forcing periods integrated per cell.
        uncertainty: the label uncertainty, a :class:`LabelUncertainty`; None when not
            measured.
        basin_entropy: the basin entropy ``S_b`` and boundary basin entropy ``S_bb`` of the
            labels (:func:`~jaxgear.basin_entropy`, boxes of 5 cells a side; Daza et al.,
            Sci. Rep. 6, 31416, 2016; sink and unresolved cells count as outcomes).
        saddles: the chaotic saddles (long chaotic transients) the cells met, each a
            :class:`ChaoticSaddle` with its mean lifetime (direct method).
    """

    labels: np.ndarray = array_field(_grid_dims)
    attractors: tuple[Attractor, ...] = items_field("attractor")
    grid: CellGrid = None  # type: ignore[assignment]
    method: AbstractGlobalMethod = custom_field(lambda m: m.to_dict(), method_from_dict)
    params: dict = dataclasses.field(default_factory=dict)
    system: str = ""
    state_names: tuple[str, ...] = ()
    n_sink: int = 0
    n_unresolved: int = 0
    runtime_s: float = float("nan")
    version: str = ""
    mean_periods: float = float("nan")
    uncertainty: LabelUncertainty | None = None
    basin_entropy: BasinEntropy | None = None
    saddles: tuple[ChaoticSaddle, ...] = items_field("saddle", later=True, default=())

    @property
    def n_cells(self) -> int:
        """Number of cells of the grid."""
        return self.grid.n_cells

    @property
    def shares(self) -> dict[str, float]:
        """Share of each attractor (by id) plus ``sink`` and ``unresolved``; sums to 1."""
        out = {str(a.id): a.share for a in self.attractors}
        out["sink"] = self.n_sink / self.n_cells
        out["unresolved"] = self.n_unresolved / self.n_cells
        return out

    def table(self) -> str:
        """Printable table of attractors: id, period, cells, share, one representative point."""
        rows = []
        for a in self.attractors:
            p = np.asarray(a.points)[0] if len(a.points) else np.full(len(self.state_names), np.nan)
            rows.append((a.id, a.label, a.cell_count, f"{100 * a.share:.2f} %",
                         "[" + ", ".join(f"{v:.4f}" for v in p) + "]",
                         "-" if np.isnan(a.residual) else f"{a.residual:.1e}",
                         "-" if np.isnan(a.multiplier) else f"{a.multiplier:.4f}", _exponent_text(a)))
        rows.append(("sink", "-", self.n_sink, f"{100 * self.n_sink / self.n_cells:.2f} %",
                     "left the region/blew up", "", "", ""))
        if self.n_unresolved:
            rows.append(("unresolved", "-", self.n_unresolved, f"{100 * self.n_unresolved / self.n_cells:.2f} %",
                         "fate not decided", "", "", ""))
        head = ("id", "type", "cells", "share", "stroboscopic point (" + ", ".join(self.state_names) + ")",
                "residual", "max |mu|", "lambda_1 /period")
        table = format_table(rows, head)
        if self.basin_entropy is not None and np.isfinite(self.basin_entropy.S_b):
            e = self.basin_entropy
            bb = "no boundary boxes" if not np.isfinite(e.S_bb) else (
                f"boundary S_bb = {e.S_bb:.3f} ({'above' if e.fractal else 'not above'} log 2: "
                f"{'a fractal boundary' if e.fractal else 'no proof of a fractal boundary'})")
            table += f"\nbasin entropy S_b = {e.S_b:.3f} ({e.box}^{len(self.grid.axes)}-cell boxes), {bb}"
        for saddle in self.saddles:
            table += "\n" + saddle.describe()
        return table if self.uncertainty is None else table + "\n" + self.uncertainty.describe()

    def summary(self) -> dict[str, Any]:
        """Everything but the per-cell labels, JSON-able (written as ``summary.json``)."""
        return dict(
            method=self.method.name, system=self.system, state_names=list(self.state_names),
            grid=self.grid.to_dict(), n_cells=self.n_cells, settings=self.method.to_dict(), params=self.params,
            attractors=[a.summary() for a in self.attractors], n_sink=self.n_sink,
            n_unresolved=self.n_unresolved, shares=self.shares, runtime_s=self.runtime_s,
            mean_periods=self.mean_periods,
            uncertainty=None if self.uncertainty is None else _uncertainty_summary(self.uncertainty),
            basin_entropy=None if self.basin_entropy is None else dict(
                S_b=self.basin_entropy.S_b, S_bb=self.basin_entropy.S_bb, box=self.basin_entropy.box,
                fractal=self.basin_entropy.fractal, n_boundary_boxes=self.basin_entropy.n_boundary_boxes),
            saddles=[dict(lifetime=c.lifetime, lifetime_error=c.lifetime_error, starts=c.starts, periods=c.periods,
                          left=c.left) for c in self.saddles],
            version=self.version,
        )

    # ------------------------------------------------------------------ I/O
    def _coords(self) -> dict:
        g = self.grid
        coords = {name: (name, g.axis_centres(j), {"long_name": f"cell centre {name}"})
                  for j, name in enumerate(g.axis_names)}
        coords["state"] = ("state", list(self.state_names))
        return coords

    def _attrs(self) -> dict:
        return dict(title="jaxgear global analysis",
                    labels_meaning="attractor id of each cell; -1 sink, -2 unresolved",
                    units=("dimensionless: lengths in b_c, time in 1/omega_n (model document §3)"
                           if self.system.startswith("planetary") else "the system's own units"))

    def save(self, path):
        """Write the result to a netCDF file atomically; reload with :func:`jaxgear.load`,
        open with ``xarray.open_dataset``."""
        return save_result(self, path)

    def write_summary(self, path):
        """Write ``summary.json`` (everything but the per-cell labels; strict JSON)."""
        return write_json(self.summary(), path)
