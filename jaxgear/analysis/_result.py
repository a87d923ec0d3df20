"""Result of a global analysis: attractors, their periods, domains and shares."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .._cells import CellGrid
from .._codec import array_field, items_field, later_field, result_type
from .._format import format_table
from .._io import save_result, write_json

__all__ = ["Attractor", "GlobalResult", "SINK", "UNRESOLVED", "LABEL_MEANINGS"]

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
        period: k of P-k on the stroboscopic map (minimal); 0 when no period <= the
            detection limit was found (quasi-periodic, chaotic or a very slow transient).
        points: ``(k, dim)`` stroboscopic points (state at phase 0 of k successive periods).
        section_points: ``(m, dim)`` crossings of Σ over the k periods (empty when the
            method has no section).
        cell_count: cells in its domain of attraction (including its periodic cells).
        share: ``cell_count / n_cells``.
        residual: ``max_i |P^k(p_i) - p_i|`` of the reported points (integration-level).
        periodic_cells: indices of the cells of its periodic group(s) (cell methods).
        multiplier: the largest modulus of its Floquet multipliers (paper §4.1: the
            cycle is asymptotically stable when it is below 1), from central differences
            of the k-fold stroboscopic map at its first point; NaN for period 0 (and in
            files written before it was recorded).
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

    @property
    def label(self) -> str:
        """``"P-k"``, or ``"non-periodic"`` for period 0."""
        return f"P-{self.period}" if self.period > 0 else "non-periodic"

    def summary(self) -> dict[str, Any]:
        """JSON-able description (points as lists)."""
        return dict(id=self.id, period=self.period, label=self.label, cell_count=self.cell_count,
                    share=self.share, residual=self.residual, multiplier=self.multiplier,
                    points=np.asarray(self.points).tolist(),
                    section_points=np.asarray(self.section_points).tolist(),
                    n_periodic_cells=int(len(self.periodic_cells)))


def describe_uncertainty(u: dict) -> str:
    """One line for the printed table."""
    if not u:
        return ""
    return (f"label uncertainty ({u['samples']} sampled cells): {100 * u['step']:.1f} % change with a "
            f"{_refined_name(u)}, {100 * u['start']:.1f} % when the start moves by {u['perturbation']:g} cell")


def _refined_name(u: dict) -> str:
    r = u.get("refined_integrator", {})
    if "steps_per_period" in r:
        return f"halved step ({r['steps_per_period']} steps/period)"
    return "16x smaller integration error"


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
        method: the method's name (``"direct"``, ``"poincare-like"``, ``"stroboscopic"``).
        settings: the method object's settings (:meth:`to_dict` of the method, with its
            integrator), JSON-able: :func:`jaxgear.analysis.method_from_dict` rebuilds it.
        params: the full canonical parameter set (model document §4 names) as a dict.
        system: the system's name; state_names: its coordinate names.
        n_sink, n_unresolved: cell counts.
        runtime_s: wall time of the analysis; version: jaxgear version.
        mean_periods: mean number of forcing periods integrated per cell.
        uncertainty: the label uncertainty (:func:`~jaxgear.analysis.label_uncertainty`):
            ``samples``, ``step`` and ``start`` (shares of sampled cells whose label
            changes with a halved step / a start moved by ``perturbation`` cells);
            empty when not measured.
    """

    labels: np.ndarray = array_field(_grid_dims)
    attractors: tuple[Attractor, ...] = items_field("attractor")
    grid: CellGrid = None  # type: ignore[assignment]
    method: str = ""
    settings: dict = dataclasses.field(default_factory=dict)
    params: dict = dataclasses.field(default_factory=dict)
    system: str = ""
    state_names: tuple[str, ...] = ()
    n_sink: int = 0
    n_unresolved: int = 0
    runtime_s: float = float("nan")
    version: str = ""
    mean_periods: float = float("nan")
    uncertainty: dict = dataclasses.field(default_factory=dict)

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
                         "[" + ", ".join(f"{v:.4f}" for v in p) + "]", f"{a.residual:.1e}",
                         "-" if np.isnan(a.multiplier) else f"{a.multiplier:.4f}"))
        rows.append(("sink", "-", self.n_sink, f"{100 * self.n_sink / self.n_cells:.2f} %",
                     "left the region/blew up", "", ""))
        if self.n_unresolved:
            rows.append(("unresolved", "-", self.n_unresolved, f"{100 * self.n_unresolved / self.n_cells:.2f} %",
                         "fate not decided", "", ""))
        head = ("id", "period", "cells", "share", "stroboscopic point (" + ", ".join(self.state_names) + ")",
                "residual", "max |mu|")
        note = describe_uncertainty(self.uncertainty)
        return format_table(rows, head) + ("\n" + note if note else "")

    def summary(self) -> dict[str, Any]:
        """Everything but the per-cell labels, JSON-able (written as ``summary.json``)."""
        return dict(
            method=self.method, system=self.system, state_names=list(self.state_names),
            grid=self.grid.to_dict(), n_cells=self.n_cells, settings=self.settings, params=self.params,
            attractors=[a.summary() for a in self.attractors], n_sink=self.n_sink,
            n_unresolved=self.n_unresolved, shares=self.shares, runtime_s=self.runtime_s,
            mean_periods=self.mean_periods, uncertainty=self.uncertainty, version=self.version,
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
