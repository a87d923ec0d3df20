"""Result of a global analysis: attractors, their periods, domains and shares.

A :class:`GlobalResult` holds the label of every cell (an attractor id, ``SINK`` or
``UNRESOLVED``), one :class:`Attractor` per coexisting attractor (period P-k read
from the stroboscopic map, its k stroboscopic points, its Σ-crossing points, cell
count and share), the grid, the method and its settings, the full canonical
parameter set, the software version and the runtime. It saves to a netCDF file
(labelled arrays: open it with ``xarray.open_dataset``) and to ``summary.json``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from ._cells import CellGrid

__all__ = ["Attractor", "GlobalResult", "load_result", "SINK", "UNRESOLVED"]

SINK = -1
"""Label of cells whose orbits leave the region or blow up (Hsu's sink cell)."""
UNRESOLVED = -2
"""Label of cells whose fate was not decided within the allowed number of periods."""


@dataclasses.dataclass(frozen=True)
class Attractor:
    """One attractor found by the global analysis (paper §4.2: a P-k motion and its domain).

    Points are in state units (dimensionless ``b_c``, ``b_c omega_n`` for the gear
    models, MODEL.md §3) at forcing phase 0.

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
    """

    id: int
    period: int
    points: np.ndarray
    section_points: np.ndarray
    cell_count: int
    share: float
    residual: float
    periodic_cells: np.ndarray

    @property
    def label(self) -> str:
        return f"P-{self.period}" if self.period > 0 else "non-periodic"

    def summary(self) -> dict[str, Any]:
        return dict(id=self.id, period=self.period, label=self.label, cell_count=self.cell_count,
                    share=self.share, residual=self.residual, points=np.asarray(self.points).tolist(),
                    section_points=np.asarray(self.section_points).tolist(),
                    n_periodic_cells=int(len(self.periodic_cells)))


@dataclasses.dataclass(frozen=True)
class GlobalResult:
    """Outcome of :func:`jaxgear.analyze_global` (paper §4).

    Attributes:
        labels: int array of shape ``grid.counts``: attractor id, ``SINK`` (-1) or
            ``UNRESOLVED`` (-2) for every cell.
        attractors: tuple of :class:`Attractor`, sorted by decreasing share.
        grid: the :class:`CellGrid`.
        method: ``"poincare-like"``, ``"stroboscopic"`` or ``"direct"``.
        settings: mapping count, steps per period, tolerances, section, ... (JSON-able).
        params: the full canonical parameter set (MODEL.md §4 names) as a dict.
        system: the system's name; state_names: its coordinate names.
        n_sink, n_unresolved: cell counts.
        runtime_s: wall time of the analysis; version: jaxgear version.
        mean_periods: mean number of forcing periods integrated per cell.
    """

    labels: np.ndarray
    attractors: tuple[Attractor, ...]
    grid: CellGrid
    method: str
    settings: dict
    params: dict
    system: str
    state_names: tuple[str, ...]
    n_sink: int
    n_unresolved: int
    runtime_s: float
    version: str
    mean_periods: float = float("nan")

    @property
    def n_cells(self) -> int:
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
        from ._params import format_table

        rows = []
        for a in self.attractors:
            p = np.asarray(a.points)[0] if len(a.points) else np.full(len(self.state_names), np.nan)
            rows.append((a.id, a.label, a.cell_count, f"{100 * a.share:.2f} %",
                         "[" + ", ".join(f"{v:.4f}" for v in p) + "]", f"{a.residual:.1e}"))
        rows.append(("sink", "-", self.n_sink, f"{100 * self.n_sink / self.n_cells:.2f} %", "left the region/blew up", ""))
        if self.n_unresolved:
            rows.append(("unresolved", "-", self.n_unresolved, f"{100 * self.n_unresolved / self.n_cells:.2f} %",
                         "fate not decided", ""))
        head = ("id", "period", "cells", "share", "stroboscopic point (" + ", ".join(self.state_names) + ")",
                "residual")
        return format_table(rows, head)

    def summary(self) -> dict[str, Any]:
        """Everything but the per-cell labels, JSON-able (written as ``summary.json``)."""
        return dict(
            method=self.method, system=self.system, state_names=list(self.state_names),
            grid=self.grid.to_dict(), n_cells=self.n_cells, settings=self.settings, params=self.params,
            attractors=[a.summary() for a in self.attractors], n_sink=self.n_sink,
            n_unresolved=self.n_unresolved, shares=self.shares, runtime_s=self.runtime_s,
            mean_periods=self.mean_periods, version=self.version,
        )

    # ---------------------------------------------------------------- I/O
    def to_xarray(self):
        """The result as an ``xarray.Dataset`` (labelled arrays, metadata in attrs)."""
        import xarray as xr

        g = self.grid
        dims = g.axis_names
        coords = {name: (name, g.axis_centres(j), {"long_name": f"cell centre {name}"}) for j, name in enumerate(dims)}
        A = len(self.attractors)
        kmax = max([len(a.points) for a in self.attractors] + [1])
        mmax = max([len(a.section_points) for a in self.attractors] + [1])
        cmax = max([len(a.periodic_cells) for a in self.attractors] + [1])
        dim = len(self.state_names)
        pts = np.full((A, kmax, dim), np.nan)
        sec = np.full((A, mmax, dim), np.nan)
        cyc = np.full((A, cmax), -1, dtype=np.int64)
        for i, a in enumerate(self.attractors):
            pts[i, : len(a.points)] = a.points
            sec[i, : len(a.section_points)] = a.section_points
            cyc[i, : len(a.periodic_cells)] = a.periodic_cells
        data = {
            "labels": (dims, self.labels.astype(np.int64),
                       {"description": "attractor id of each cell; -1 sink, -2 unresolved"}),
            "attractor_id": ("attractor", np.array([a.id for a in self.attractors], dtype=np.int64)),
            "attractor_period": ("attractor", np.array([a.period for a in self.attractors], dtype=np.int64)),
            "attractor_cells": ("attractor", np.array([a.cell_count for a in self.attractors], dtype=np.int64)),
            "attractor_share": ("attractor", np.array([a.share for a in self.attractors], dtype=float)),
            "attractor_residual": ("attractor", np.array([a.residual for a in self.attractors], dtype=float)),
            "attractor_n_points": ("attractor", np.array([len(a.points) for a in self.attractors], dtype=np.int64)),
            "attractor_n_section": ("attractor", np.array([len(a.section_points) for a in self.attractors],
                                                          dtype=np.int64)),
            "attractor_n_cycle": ("attractor", np.array([len(a.periodic_cells) for a in self.attractors],
                                                        dtype=np.int64)),
            "points": (("attractor", "point", "state"), pts, {"description": "stroboscopic points (phase 0)"}),
            "section_points": (("attractor", "crossing", "state"), sec, {"description": "crossings of the section"}),
            "periodic_cells": (("attractor", "cycle_cell"), cyc, {"description": "cells of the periodic groups"}),
        }
        coords["state"] = ("state", list(self.state_names))
        attrs = dict(
            jaxgear_type="GlobalResult", title="jaxgear global analysis", method=self.method, system=self.system,
            grid=json.dumps(self.grid.to_dict()), settings=json.dumps(self.settings),
            params=json.dumps(self.params), n_sink=self.n_sink, n_unresolved=self.n_unresolved,
            runtime_s=self.runtime_s, mean_periods=self.mean_periods, version=self.version,
            units=("dimensionless: lengths in b_c, time in 1/omega_n (MODEL.md §3)"
                   if self.system.startswith("planetary") else "the system's own units"),
        )
        for k, v in self.params.items():
            if np.ndim(v) == 0:
                attrs[f"param_{k}"] = v
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path: str | Path) -> Path:
        """Write the result to a netCDF file (``.nc``, atomically); reload with
        :func:`load_result` or :func:`jaxgear.load`, open with ``xarray.open_dataset``."""
        from ._io import _write_netcdf

        return _write_netcdf(self.to_xarray(), path)

    def write_summary(self, path: str | Path) -> Path:
        """Write ``summary.json`` (everything but the per-cell labels)."""
        from ._io import _write_json

        return _write_json(self.summary(), path)


def load_result(path: str | Path) -> GlobalResult:
    """Load a :class:`GlobalResult` saved with :meth:`GlobalResult.save` (exact round trip:
    labels and points bit-for-bit, grid, settings and parameters equal).

    Raises ``FileNotFoundError`` without a file, ``ValueError`` when the file holds
    another result type (use :func:`jaxgear.load` for any type).

    Also reads files written before ``attrs["jaxgear_type"]`` existed.
    """
    from ._io import _check_type, _read_netcdf

    ds = _read_netcdf(path)
    _check_type(ds, "GlobalResult", path)
    grid = CellGrid.from_dict(json.loads(ds.attrs["grid"]))
    attractors = []
    for i in range(ds.sizes.get("attractor", 0)):
        k = int(ds["attractor_n_points"][i])
        m = int(ds["attractor_n_section"][i])
        c = int(ds["attractor_n_cycle"][i])
        attractors.append(Attractor(
            id=int(ds["attractor_id"][i]), period=int(ds["attractor_period"][i]),
            points=ds["points"].values[i, :k], section_points=ds["section_points"].values[i, :m],
            cell_count=int(ds["attractor_cells"][i]), share=float(ds["attractor_share"][i]),
            residual=float(ds["attractor_residual"][i]), periodic_cells=ds["periodic_cells"].values[i, :c],
        ))
    return GlobalResult(
        labels=ds["labels"].values.astype(np.int64), attractors=tuple(attractors), grid=grid,
        method=str(ds.attrs["method"]), settings=json.loads(ds.attrs["settings"]),
        params=json.loads(ds.attrs["params"]), system=str(ds.attrs["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), n_sink=int(ds.attrs["n_sink"]),
        n_unresolved=int(ds.attrs["n_unresolved"]), runtime_s=float(ds.attrs["runtime_s"]),
        version=str(ds.attrs["version"]), mean_periods=float(ds.attrs["mean_periods"]),
    )
