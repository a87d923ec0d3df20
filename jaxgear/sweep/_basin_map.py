"""Basin shares over two parameters: the global analysis at every point of a parameter grid.

The map over ``values_y x values_x`` runs :func:`~jaxgear.analyze_global` at every grid
point (resumable and split over processes as in :func:`~jaxgear.basin_sweep`, whose
machinery it shares), then gives the attractors global identities across the map: the
attractors of a point are matched (:func:`jaxgear._matching.match_attractors`: cycles by the Hausdorff
distance of their stroboscopic point sets, cyclic-shift invariant; quasi-periodic and
chaotic attractors by the overlap of the boxes their clouds occupy) to those of its left
neighbour ``(iy, ix - 1)`` and its lower neighbour ``(iy - 1, ix)``, the same global
continuation of attractors as along one parameter, carried over a grid in rows.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .._cells import CellGrid
from .._checks import with_changes
from .._codec import array_field, later_field, result_type
from .._format import format_table
from .._matching import match_attractors
from .._model import REDUCED
from .._params import params_to_dict
from .._system import ForcedSystem
from .._version import __version__
from ..analysis import AbstractGlobalMethod
from ._basins import GlobalShares, analyses_at, global_arrays, resolve_basin_options, uncertainty_setting
from ._bifurcation import read_only
from ._classify import label_order
from ._options import BasinOptions
from ._physical import axis_label, joint_rows, physical_summary, resolve_gear_set, sweep_axis
from ._runner import Runner, sweep_runner
from ._values import apply_values, check_values, coord_name

__all__ = ["BasinMap", "basin_map", "match_on_grid"]


@result_type
@dataclasses.dataclass(frozen=True, kw_only=True)
class BasinMap(GlobalShares):
    """Result of :func:`basin_map`: basin shares of globally identified attractors over a
    grid of two parameters (``y`` rows, ``x`` columns).

    Attributes:
        param_x, fields_x, values_x ``(nx,)``; param_y, fields_y, values_y ``(ny,)``:
            each parameter as given, the dimensionless fields it sets and its values (in
            ``unit_x`` / ``unit_y`` when ``physical_x`` / ``physical_y``: a
            :class:`~jaxgear.GearSet` field swept with ``gear_set=``).
        field_values_x, field_values_y: ``(nx, len(fields_x))``, ``(ny, len(fields_y))``
            the dimensionless value of each field at each value (the values repeated for a
            dimensionless parameter).
        shares: ``(ny, nx, G)`` share of the cell grid in the domain of global attractor
            g at each parameter point (0 where it does not exist); sink_share,
            unresolved_share: ``(ny, nx)``.
        period: ``(ny, nx, G)`` its period there (k, 0 aperiodic), -1 where it does not exist.
        attractor_type, largest_exponent, exponent_error: ``(ny, nx, G)`` its type there (an
            :class:`~jaxgear.AttractorType` value, -1 where absent or unknown), its largest
            Lyapunov exponent per forcing period and that exponent's error (NaN where
            absent or not measured).
        multiplier: ``(ny, nx, G)`` the largest modulus of its Floquet multipliers there
            (NaN where it does not exist or is aperiodic, and in older files).
        points: ``(ny, nx, G, K, dim)`` its stroboscopic points (NaN padded), n_points
            ``(ny, nx, G)``.
        labels: ``(ny, nx, *grid.counts)`` int16: global attractor id of every cell, -1
            sink, -2 unresolved.
        uncertainty_step, uncertainty_start: ``(ny, nx)`` the label uncertainty of each
            point's analysis (as in :class:`~jaxgear.sweep.BasinSweep`); NaN where not
            measured.
        grid: the cell grid of every analysis; method: the global-analysis method object
            (every option, the integrator); match_tol: the relative distance under which
            attractors at two values are the same; uncertainty_samples: cells sampled
            for each label uncertainty (0: none measured).
        system, state_names, params (the base parameter set), version.
    """

    param_x: str
    fields_x: tuple[str, ...]
    values_x: np.ndarray = array_field(lambda m: (m.coords_xy[0],))
    param_y: str = ""
    fields_y: tuple[str, ...] = ()
    values_y: np.ndarray = array_field(lambda m: (m.coords_xy[1],))
    unit_x: str = later_field("")
    unit_y: str = later_field("")
    physical_x: bool = later_field(False)
    physical_y: bool = later_field(False)
    field_values_x: np.ndarray | None = array_field(lambda m: (m.coords_xy[0], "field_x"), later=True, default=None)
    field_values_y: np.ndarray | None = array_field(lambda m: (m.coords_xy[1], "field_y"), later=True, default=None)

    def __post_init__(self):
        super().__post_init__()
        for a in ("x", "y"):  # a dimensionless parameter (or a file written before physical sweeps)
            if getattr(self, f"field_values_{a}") is None:
                v, fields = np.asarray(getattr(self, f"values_{a}"), float), getattr(self, f"fields_{a}")
                object.__setattr__(self, f"field_values_{a}", np.repeat(v[:, None], len(fields), axis=1))
        for f in ("values_x", "values_y", "field_values_x", "field_values_y"):
            object.__setattr__(self, f, read_only(getattr(self, f)))

    @property
    def axis_labels(self) -> tuple[str, str]:
        """The two parameters with their units (``"T_D [N m]"``) or the fields they set."""
        return (axis_label(self.param_x, self.fields_x, self.unit_x, self.physical_x),
                axis_label(self.param_y, self.fields_y, self.unit_y, self.physical_y))

    def point_rows(self) -> np.ndarray:
        """``(ny, nx, len(fields_x) + len(fields_y))``: the dimensionless values every point
        sets on ``fields_x + fields_y``."""
        ny, nx = len(self.values_y), len(self.values_x)
        return np.concatenate([np.broadcast_to(self.field_values_x[None], (ny, nx, len(self.fields_x))),
                               np.broadcast_to(self.field_values_y[:, None], (ny, nx, len(self.fields_y)))], axis=-1)

    @property
    def value_dims(self) -> tuple[str, ...]:
        return self.coords_xy[::-1]

    def attractor_label(self, g: int) -> str:
        """``"P-4"``, ``"chaotic"``, ``"quasi-periodic"``, or ``"P-4/P-8"`` when its label
        differs across the map."""
        labs = sorted({lab for lab in self.labels_at(g).ravel().tolist() if lab}, key=label_order)
        return "/".join(labs) or "-"

    def table(self) -> str:
        """Printable table: per global attractor its period(s), where it exists and its shares."""
        n = self.sink_share.size
        rows = []
        for g in range(self.n_attractors):
            here = self.present[..., g]
            s = self.shares[..., g][here]
            rows.append((g, self.attractor_label(g), f"{int(here.sum())}/{n}", f"{int((self.dominant == g).sum())}",
                         f"{100 * s.min():.1f}", f"{100 * s.mean():.1f}", f"{100 * s.max():.1f}"))
        for name, share, code in (("sink", self.sink_share, -1), ("unresolved", self.unresolved_share, -2)):
            if code == -1 or np.any(share > 0):
                rows.append((name, "-", f"{int((share > 0).sum())}/{n}", f"{int((self.dominant == code).sum())}",
                             f"{100 * share.min():.1f}", f"{100 * share.mean():.1f}", f"{100 * share.max():.1f}"))
        note = self.uncertainty_note("points")
        return format_table(rows, ("attractor", "label", "present at", "largest at", "min %", "mean %", "max %")) + (
            "\n" + note if note else "")

    def summary(self) -> dict[str, Any]:
        return dict(kind="basin_map", param_x=self.param_x, fields_x=list(self.fields_x),
                    values_x=self.values_x.tolist(), param_y=self.param_y, fields_y=list(self.fields_y),
                    values_y=self.values_y.tolist(),
                    **physical_summary(self.unit_x, self.physical_x, self.field_values_x, "_x"),
                    **physical_summary(self.unit_y, self.physical_y, self.field_values_y, "_y"),
                    method=self.method.name, grid=self.grid.to_dict(),
                    match_tol=self.match_tol, system=self.system, params=self.params,
                    settings=self.settings_summary(),
                    version=self.version,
                    attractors=[dict(id=g, label=self.attractor_label(g), present_at=int(self.present[..., g].sum()),
                                     max_share=float(self.shares[..., g].max())) for g in range(self.n_attractors)],
                    coexisting_counts={str(m): int((self.coexisting == m).sum())
                                       for m in np.unique(self.coexisting).tolist()},
                    **self._per_value_summary())

    @property
    def coords_xy(self) -> tuple[str, str]:
        """Names of the two parameter coordinates in the saved file."""
        taken = list(self.state_names) + list(self.grid.axis_names) + ["attractor", "point", "state", "field_x",
                                                                          "field_y"]
        cx = coord_name(self.param_x, taken)
        cy = coord_name(self.param_y, taken + [cx])
        return cx, (f"{cy}_y" if cy == cx else cy)

    def _coords(self) -> dict:
        cx, cy = self.coords_xy
        return self._cell_coords({
            cx: (cx, np.asarray(self.values_x), {"long_name": self.param_x, "sets": ",".join(self.fields_x),
                                                 **({"units": self.unit_x} if self.physical_x else {})}),
            cy: (cy, np.asarray(self.values_y), {"long_name": self.param_y, "sets": ",".join(self.fields_y),
                                                 **({"units": self.unit_y} if self.physical_y else {})})})

    def _attrs(self) -> dict:
        return dict(title="jaxgear basin shares over two parameters",
                    labels_meaning="global attractor id of each cell; -1 sink, -2 unresolved")


def match_on_grid(results, ny: int, nx: int, match_tol: float) -> list[np.ndarray]:
    """Global id of every attractor at every point of a ``ny x nx`` parameter grid:
    ``[(A_i,) int array]`` for the results listed row by row (``i = iy * nx + ix``).

    Point by point in that order, the attractors are matched
    (:func:`jaxgear._matching.match_attractors`: cycles farther than ``match_tol`` apart,
    or clouds sharing less than half of their boxes of edge ``match_tol / 2``, not
    matched) to those of the left neighbour and of the lower neighbour together (each
    global id once); an unmatched attractor gets a new global id (numbered in order of
    first appearance).
    """
    out: list = [None] * (ny * nx)
    nxt = 0
    for i in range(ny * nx):
        iy, ix = divmod(i, nx)
        prev, seen = [], set()
        for j in ([i - 1] if ix > 0 else []) + ([i - nx] if iy > 0 else []):
            for a, g in zip(results[j].attractors, out[j]):
                if int(g) not in seen:
                    seen.add(int(g))
                    prev.append((int(g), np.asarray(a.points), a.period))
        cur = [(np.asarray(a.points), a.period) for a in results[i].attractors]
        j = match_attractors([(p, k) for _, p, k in prev], cur, match_tol)
        gid = np.array([prev[m][0] if m >= 0 else -1 for m in j], dtype=np.int64)
        for a in range(len(cur)):
            if gid[a] < 0:
                gid[a] = nxt
                nxt += 1
        out[i] = gid
    return out


def basin_map(system: ForcedSystem | None, params, param_x: str, values_x, param_y: str, values_y,
              grid: CellGrid | None = None, *, method: AbstractGlobalMethod | str | None = None,
              options: BasinOptions | None = None, runner: Runner | None = None, gear_set=None,
              **changes) -> BasinMap:
    """Basin shares over a grid of two parameters, attractors identified across the grid.

    At every point of ``values_y x values_x`` :func:`~jaxgear.analyze_global` runs
    ``method`` on ``grid`` (default: the method's grid; for the gear model the paper's
    region D). The attractors of every type (cycles, and quasi-periodic and chaotic
    attractors with their clouds) are given global ids by :func:`match_on_grid`: matched
    to those of the left and lower neighbours, cycles by the Hausdorff distance of their
    stroboscopic point sets, pairs farther than ``options.match_tol`` not matched (default: 5 %
    of the diagonal of the grid's box), clouds by the overlap of the boxes they occupy
    (as in :func:`~jaxgear.basin_sweep`). ``dominant`` and ``coexisting`` count
    attractors of every type (``coexisting_of`` one type). A map of ``ny x nx`` points costs ``ny * nx``
    global analyses: on the paper grid (90,000 cells) about 5 to 10 s each on a 2-core
    CPU.

    Args:
        param_x, values_x, param_y, values_y: two parameters (canonical or grouped names,
            as in :func:`~jaxgear.bifurcation_diagram`; they must set different fields)
            and their values (sorted, distinct).
        method: a global-analysis method object (default :class:`~jaxgear.Direct`) or
            its name.
        options: :class:`~jaxgear.BasinOptions` (as in :func:`~jaxgear.basin_sweep`:
            ``match_tol``; ``batched``, the points of a block in one lane pool;
            ``uncertainty``, cells sampled at each point for its label uncertainty, kept as
            ``uncertainty_step`` and ``uncertainty_start``, 0 skips it); ``None``: the defaults.
        runner: a :class:`~jaxgear.Runner`: its output folder, resume and progress bar
            (``None``: ``Runner()``, nothing written). With a folder ``DIR``, each point's
            :class:`~jaxgear.GlobalResult` is saved to ``DIR/parts/value_NNNNN.nc``
            (``NNNNN = iy * nx + ix``) when done, and the map to ``DIR/basin_map.nc``.
        gear_set: a :class:`~jaxgear.GearSet`: both parameters are then its fields (as
            in :func:`~jaxgear.basin_sweep`), in its physical units; each point sets the
            dimensionless fields both conversions change.
        **changes: fields of ``options`` to change.

    Run as several JAX processes (:func:`jaxgear._devices.initialize`), process ``p`` of
    ``P`` computes the points ``i % P == p`` into the runner's folder (required then),
    every process assembles the map from the parts, and only process 0 writes
    ``basin_map.nc``. A killed process loses the point it was computing; the same call
    rerun resumes.

    Returns:
        :class:`BasinMap`.
    """
    runner = sweep_runner(runner, changes, "basin_map")
    opts = with_changes(options, BasinOptions, changes)
    if gear_set is not None:
        params = resolve_gear_set(gear_set, params, system is None or system is REDUCED)
    system, params, method, grid, opts = resolve_basin_options(system, params, method, grid, opts)
    ax_x, ax_y = sweep_axis(params, param_x, values_x, gear_set), sweep_axis(params, param_y, values_y, gear_set)
    if set(ax_x.fields) & set(ax_y.fields):
        raise ValueError(f"param_x={param_x!r} and param_y={param_y!r} set the same field.")
    vx, vy = ax_x.values, ax_y.values
    VV = np.stack(np.meshgrid(vx, vy, indexing="xy"), axis=-1).reshape(-1, 2)  # (ny * nx, 2), y major
    if ax_x.physical:  # every point's dimensionless fields, checked against the gear set at both values
        names, rows = ax_x.fields + ax_y.fields, joint_rows(gear_set, (ax_x, ax_y), VV)
    else:
        names, rows = (param_x, param_y), VV
    check_values(system, params, names, rows)
    settings = dict(kind="basin_map", system=system.name, param_x=param_x, values_x=vx.tolist(), param_y=param_y,
                    values_y=vy.tolist(), **({"physical": [ax_x.unit, ax_y.unit]} if ax_x.physical else {}),
                    params=params_to_dict(params), grid=grid.to_dict(),
                    method=method.to_dict(), match_tol=opts.match_tol, **uncertainty_setting(opts.uncertainty),
                    version=__version__)
    results = analyses_at(system, [apply_values(params, names, v) for v in rows], grid, method, opts, settings, runner)
    ny, nx = len(vy), len(vx)
    arrays = global_arrays(results, match_on_grid(results, ny, nx, opts.match_tol), grid, system.dim)
    bmap = BasinMap(
        param_x=param_x, fields_x=ax_x.fields, values_x=vx, param_y=param_y, fields_y=ax_y.fields, values_y=vy,
        unit_x=ax_x.unit, unit_y=ax_y.unit, physical_x=ax_x.physical, physical_y=ax_y.physical,
        field_values_x=ax_x.rows, field_values_y=ax_y.rows,
        **{k: a.reshape(ny, nx, *a.shape[1:]) for k, a in arrays.items()}, grid=grid, method=method,
        match_tol=opts.match_tol, uncertainty_samples=opts.uncertainty, system=system.name,
        state_names=tuple(system.state_names), params=params_to_dict(params), version=__version__)
    runner.write(bmap, "basin_map.nc")
    return bmap
