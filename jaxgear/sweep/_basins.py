"""Basin shares across a parameter: the global analysis at every value, attractors matched.

At each value the global analysis runs on the grid (one after another, or with
``batched=True`` and the direct method all values of a block in one lane pool over
(value, cell) pairs, :func:`~jaxgear.analysis.analyze_global_values`); the attractors of
neighbouring values are matched (:func:`jaxgear._matching.match_attractors`, the idea of
global continuation of attractors, Datseris & Wagemakers 2022): cycles by the Hausdorff
distance of their stroboscopic point sets, quasi-periodic and chaotic attractors by the
overlap of the boxes their clouds of points occupy, so each keeps a global identity;
shares, types and largest Lyapunov exponents per value and global attractor, plus the
sink.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .._cells import CellGrid
from .._checks import check_int, with_changes
from .._codec import array_field, custom_field, later_field, result_type
from .._devices import values_over_processes
from .._format import format_table
from .._io import save_result
from .._lyapunov import AttractorType
from .._matching import match_attractors
from .._model import REDUCED
from .._params import params_to_dict
from .._presets import paper_params
from .._system import ForcedSystem
from .._version import __version__
from ..analysis import (
    AbstractGlobalMethod,
    analyze_global,
    analyze_global_values,
    default_method,
    method_from_dict,
    method_from_name,
)
from ..analysis._uncertainty import DEFAULT_SAMPLES
from ._bifurcation import read_only
from ._classify import carry_decided_types, type_label
from ._options import BasinOptions
from ._physical import axis_label, physical_summary, resolve_gear_set, sweep_axis
from ._runner import Runner, sweep_runner
from ._values import apply_values, check_values, coord_name

__all__ = ["BasinSweep", "GlobalShares", "basin_sweep", "match_across_values"]


def match_across_values(results, match_tol: float) -> list[np.ndarray]:
    """Global id of every attractor of every value: ``[ (A_i,) int array ]``.

    Attractors of value i are matched to those of value i-1
    (:func:`jaxgear._matching.match_attractors`: cycles whose point sets are farther than
    ``match_tol`` apart are not matched, clouds (period 0) that share less than half of
    their boxes of edge ``match_tol / 2`` are not; a cycle never matches a cloud); an
    unmatched attractor gets a new global id (numbered in order of first appearance).
    """
    out, prev, nxt = [], [], 0  # prev: [(gid, points, period)]
    for r in results:
        cur = [(np.asarray(a.points), a.period) for a in r.attractors]
        j = match_attractors([(p, k) for _, p, k in prev], cur, match_tol)
        gid = np.array([prev[i][0] if i >= 0 else -1 for i in j], dtype=np.int64)
        for i in range(len(cur)):
            if gid[i] < 0:
                gid[i] = nxt
                nxt += 1
        out.append(gid)
        prev = [(int(g), p, k) for g, (p, k) in zip(gid, cur)]
    return out


def _at(*tail):
    """Dimensions of a per-value array: the result's parameter dimensions, then ``tail``."""
    return lambda r: (*r.value_dims, *tail)


@dataclasses.dataclass(frozen=True, kw_only=True)
class GlobalShares:
    """What a basin sweep and a basin map share: per parameter value (the ``...`` axes,
    named by :attr:`value_dims`) the shares ``(..., G)``, periods, multipliers, types,
    largest Lyapunov exponents and points of global attractors (absent: period -1, share
    0, type -1, NaN), the sink and unresolved shares, every cell's global label, the
    label uncertainty, and the common options. Fields added after files were first
    written (``multiplier``, ``uncertainty_step``, ``uncertainty_start``,
    ``largest_exponent``, ``exponent_error``) load as NaN from those files, ``attractor_type`` as
    -1 (unknown) where the attractor is present and its period says nothing more."""

    shares: np.ndarray = array_field(_at("attractor"))
    sink_share: np.ndarray = array_field(_at())
    unresolved_share: np.ndarray = array_field(_at())
    period: np.ndarray = array_field(_at("attractor"))
    multiplier: np.ndarray | None = array_field(_at("attractor"), later=True, default=None)
    points: np.ndarray = array_field(_at("attractor", "point", "state"))
    n_points: np.ndarray = array_field(_at("attractor"))
    labels: np.ndarray = array_field(lambda r: (*r.value_dims, *r.grid.axis_names))
    uncertainty_step: np.ndarray | None = array_field(_at(), later=True, default=None)
    uncertainty_start: np.ndarray | None = array_field(_at(), later=True, default=None)
    attractor_type: np.ndarray | None = array_field(_at("attractor"), later=True, default=None)
    largest_exponent: np.ndarray | None = array_field(_at("attractor"), later=True, default=None)
    exponent_error: np.ndarray | None = array_field(_at("attractor"), later=True, default=None)
    basin_entropy: np.ndarray | None = array_field(_at(), later=True, default=None)
    boundary_basin_entropy: np.ndarray | None = array_field(_at(), later=True, default=None)
    uncertainty_exponent: np.ndarray | None = array_field(_at(), later=True, default=None)
    uncertainty_exponent_error: np.ndarray | None = array_field(_at(), later=True, default=None)
    uncertainty_exponent_low: np.ndarray | None = array_field(_at(), later=True, default=None)
    uncertainty_exponent_high: np.ndarray | None = array_field(_at(), later=True, default=None)
    uncertainty_exponent_chi2: np.ndarray | None = array_field(_at(), later=True, default=None)
    grid: CellGrid = None  # type: ignore[assignment]
    method: AbstractGlobalMethod = custom_field(lambda m: m.to_dict(), method_from_dict)
    match_tol: float = 0.0
    uncertainty_samples: int = DEFAULT_SAMPLES
    system: str = ""
    state_names: tuple[str, ...] = ()
    params: dict = dataclasses.field(default_factory=dict)
    version: str = ""

    def __post_init__(self):
        self._unmeasured_as_nan()
        for f in ("shares", "sink_share", "unresolved_share", "period", "multiplier", "points", "n_points", "labels",
                  "uncertainty_step", "uncertainty_start", "attractor_type", "largest_exponent", "exponent_error",
                  *_MEASURES):
            object.__setattr__(self, f, read_only(getattr(self, f)))

    @property
    def value_dims(self) -> tuple[str, ...]:
        """Names of the parameter dimensions in the saved file (set by each result type)."""
        raise NotImplementedError

    @property
    def n_attractors(self) -> int:
        """Number of global attractors."""
        return int(self.shares.shape[-1])

    @property
    def present(self) -> np.ndarray:
        """``(..., G)`` bool: the attractor exists at the parameter value."""
        return self.period >= 0

    def _unmeasured_as_nan(self) -> None:
        """The label uncertainties and multipliers of a file written before they were
        recorded: NaN."""
        for f in ("uncertainty_step", "uncertainty_start", *_MEASURES):
            if getattr(self, f) is None:
                object.__setattr__(self, f, np.full(np.shape(self.sink_share), np.nan))
        if self.multiplier is None:
            object.__setattr__(self, "multiplier", np.full(np.shape(self.shares), np.nan))
        for f in ("largest_exponent", "exponent_error"):
            if getattr(self, f) is None:
                object.__setattr__(self, f, np.full(np.shape(self.shares), np.nan))
        if self.attractor_type is None:  # a cycle is periodic; the type of a cloud was not recorded
            object.__setattr__(self, "attractor_type", np.where(np.asarray(self.period) > 0, int(AttractorType.PERIODIC),
                                                      int(AttractorType.UNKNOWN)).astype(np.int64))

    @property
    def coexisting(self) -> np.ndarray:
        """``(...)``: how many attractors of any type (cycles, quasi-periodic, chaotic)
        coexist at each parameter value."""
        return self.present.sum(axis=-1)

    def coexisting_of(self, kind) -> np.ndarray:
        """``(...)``: how many attractors of type ``kind`` (an
        :class:`~jaxgear.AttractorType`) coexist at each parameter value."""
        return (self.present & (self.attractor_type == int(AttractorType(int(kind))))).sum(axis=-1)

    @property
    def dominant(self) -> np.ndarray:
        """``(...)``: the global attractor (of any type) with the largest share at each
        value; -1 where the sink holds more cells than any attractor, -2 where the
        unresolved cells (no attractor found: a motion too long to resolve, or slow
        transients) hold more than the sink and any attractor."""
        top = np.argmax(self.shares, axis=-1) if self.n_attractors else np.zeros(self.sink_share.shape, int)
        best = np.take_along_axis(self.shares, top[..., None], -1)[..., 0] if self.n_attractors else 0.0
        other = np.where(self.unresolved_share > self.sink_share, -2, -1)
        return np.where(best > np.maximum(self.sink_share, self.unresolved_share), top, other)

    def labels_at(self, g: int) -> np.ndarray:
        """``(...)`` str: the label of global attractor ``g`` at each value (``"P-4"``,
        ``"chaotic"``, ``"quasi-periodic"``, ``"aperiodic"`` for period 0 of unknown type;
        ``""`` where absent)."""
        per, kind = np.asarray(self.period[..., g]), np.asarray(self.attractor_type[..., g])
        out = np.array([type_label(int(k), int(t)) if k >= 0 else "" for k, t in zip(per.ravel(), kind.ravel())],
                       dtype=object)
        return out.reshape(per.shape)

    def uncertainty_note(self, where: str = "values") -> str:
        """One line: the largest label uncertainties over the parameter ``where`` (values,
        points) ("" when none was measured)."""
        step, start = np.asarray(self.uncertainty_step), np.asarray(self.uncertainty_start)
        if not np.isfinite(step).any():
            return ""
        return (f"label uncertainty: at most {100 * np.nanmax(step):.1f} % of the sampled cells change label with "
                f"a refined step, {100 * np.nanmax(start):.1f} % when their start moves (mean "
                f"{100 * np.nanmean(step):.1f} % and {100 * np.nanmean(start):.1f} % over the "
                f"{int(np.isfinite(step).sum())} {where} measured)")

    def _per_value_summary(self) -> dict[str, list]:
        """The per-value arrays of :meth:`summary` (shares, multipliers, sink and
        unresolved shares, label uncertainties) as nested lists."""
        return {f: getattr(self, f).tolist() for f in (*_MEASURES, "shares", "multiplier", "attractor_type",
                                                        "largest_exponent",
                                                        "exponent_error", "sink_share", "unresolved_share",
                                                        "uncertainty_step", "uncertainty_start")}

    def settings_summary(self) -> dict[str, Any]:
        """The method's options (its integrator included) and the label-uncertainty
        samples, JSON-able (the ``settings`` of :meth:`summary`)."""
        return dict(method=self.method.to_dict(), uncertainty_samples=self.uncertainty_samples)

    def _cell_coords(self, coords: dict) -> dict:
        """``coords`` (the parameters') with the attractor, state and cell-centre coordinates."""
        coords.update(attractor=("attractor", np.arange(self.n_attractors)), state=("state", list(self.state_names)))
        for j, name in enumerate(self.grid.axis_names):
            coords[name] = (name, self.grid.axis_centres(j), {"long_name": f"cell centre {name}"})
        return coords

    def save(self, path):
        """Write to netCDF atomically; reload with :func:`jaxgear.load`."""
        return save_result(self, path)


@result_type
@dataclasses.dataclass(frozen=True, kw_only=True)
class BasinSweep(GlobalShares):
    """Result of :func:`basin_sweep`: basin shares of globally identified attractors.

    Attributes:
        param, fields, values ``(V,)``: the swept name as given, the dimensionless fields
            it sets, its values (in ``unit`` when ``physical``: a
            :class:`~jaxgear.GearSet` field swept with ``gear_set=``).
        unit, physical: the unit of ``values`` and whether they are physical (``""``
            and ``False`` for a dimensionless sweep).
        field_values: ``(V, len(fields))`` the dimensionless value of each field at each
            value (``values`` repeated for a dimensionless sweep).
        shares: ``(V, G)`` share of the grid in the domain of global attractor g at each
            value (0 where it does not exist); sink_share, unresolved_share: ``(V,)``.
        period: ``(V, G)`` its period there (k, 0 aperiodic), -1 where it does not exist.
        attractor_type: ``(V, G)`` its type there (an :class:`~jaxgear.AttractorType` value:
            periodic 0, quasi-periodic 1, chaotic 2, undetermined 3; -1 where absent or
            unknown); where the test left it undetermined, the type decided for the same
            attractor at the nearest value (:func:`~jaxgear.sweep._classify.carry_decided_types`).
        largest_exponent, exponent_error: ``(V, G)`` its largest Lyapunov exponent of the
            stroboscopic map per forcing period and the exponent's standard error (NaN
            where absent or not measured, and in older files).
        multiplier: ``(V, G)`` the largest modulus of its Floquet multipliers there (below 1:
            stable; it nears 1 at a bifurcation), NaN where it does not exist or is
            aperiodic (and in files written before it was recorded).
        points: ``(V, G, K, dim)`` its stroboscopic points (NaN padded), n_points ``(V, G)``.
        labels: ``(V, *grid.counts)`` int16: global attractor id of every cell, -1 sink,
            -2 unresolved.
        uncertainty_step, uncertainty_start: ``(V,)`` the label uncertainty of each value's
            analysis (:func:`~jaxgear.analysis.label_uncertainty`: the share of the sampled
            cells whose label changes with a refined integration step, and with the start
            moved by 1e-3 cell); NaN where not measured (``uncertainty=0``, or a file
            written before it was recorded).
        grid: the cell grid of every analysis; method: the global-analysis method object
            (every option, the integrator); match_tol: the relative distance under which
            attractors at two values are the same; uncertainty_samples: cells sampled
            for each label uncertainty (0: none measured).
        system, state_names, params (the base parameter set), version.
    """

    param: str
    fields: tuple[str, ...]
    values: np.ndarray = array_field(lambda b: (b.param_coord,))
    unit: str = later_field("")
    physical: bool = later_field(False)
    field_values: np.ndarray | None = array_field(lambda b: (b.param_coord, "field"), later=True, default=None)

    def __post_init__(self):
        super().__post_init__()
        if self.field_values is None:  # a dimensionless sweep (or a file written before physical sweeps)
            object.__setattr__(self, "field_values", np.repeat(np.asarray(self.values, float)[:, None],
                                                               len(self.fields), axis=1))
        for f in ("values", "field_values"):
            object.__setattr__(self, f, read_only(getattr(self, f)))

    @property
    def axis_label(self) -> str:
        """The swept parameter with its unit (``"b_sp [µm, half]"``) or the fields it sets."""
        return axis_label(self.param, self.fields, self.unit, self.physical)

    @property
    def value_dims(self) -> tuple[str, ...]:
        return (self.param_coord,)

    def attractor_label(self, g: int) -> str:
        """``"P-4"``, ``"chaotic"``, ``"quasi-periodic"``, or ``"P-4/P-8"`` when its label
        changes along the sweep."""
        ks = []
        for lab in self.labels_at(g).tolist():
            if lab and (not ks or ks[-1] != lab):
                ks.append(lab)
        return "/".join(ks) or "-"

    def events(self, share_step: float = 0.05) -> list[dict]:
        """Where attractors appear, vanish, change period or type (``"period change"``:
        P-4 -> P-8, P-8 -> chaotic, quasi-periodic -> chaotic, ...), or their share moves
        by at least ``share_step`` between neighbouring values."""
        ev = []
        pres = self.present
        labs = [self.labels_at(g) for g in range(self.n_attractors)]
        for g in range(self.n_attractors):
            if pres[0, g]:
                ev.append(dict(index=0, value=float(self.values[0]), id=g, event="present",
                               detail=f"{labs[g][0]}, share {100 * self.shares[0, g]:.1f} %"))
        for i in range(1, len(self.values)):
            for g in range(self.n_attractors):
                a, b = pres[i - 1, g], pres[i, g]
                e = None
                if b and not a:
                    e = ("appears", f"{labs[g][i]}, share {100 * self.shares[i, g]:.1f} %")
                elif a and not b:
                    e = ("vanishes", f"was {labs[g][i - 1]}, share {100 * self.shares[i - 1, g]:.1f} %")
                elif a and b and labs[g][i] != labs[g][i - 1]:
                    e = ("period change", f"{labs[g][i - 1]} -> {labs[g][i]}")
                elif a and b and abs(self.shares[i, g] - self.shares[i - 1, g]) >= share_step:
                    e = ("share change", f"{100 * self.shares[i - 1, g]:.1f} % -> {100 * self.shares[i, g]:.1f} %")
                if e:
                    ev.append(dict(index=i, value=float(self.values[i]), id=g, event=e[0], detail=e[1]))
        return ev

    def table(self, share_step: float = 0.05) -> str:
        """Printable table of the events (appear / vanish / period change / share change)."""
        rows = [(f"{e['value']:.5g}", e["id"], self.attractor_label(e["id"]), e["event"], e["detail"])
                for e in self.events(share_step)]
        return format_table(rows, (self._head(), "attractor", "label", "event", "detail"))

    def shares_table(self) -> str:
        """Shares (percent) of every global attractor and the sink at every value, and the
        label uncertainties (percent of the sampled cells) where measured."""
        unres = bool(np.any(self.unresolved_share > 0))
        unc = bool(np.isfinite(self.uncertainty_step).any())
        fractal = bool(np.isfinite(self.boundary_basin_entropy).any() or np.isfinite(self.uncertainty_exponent).any())
        head = ((self._head(),) + tuple(f"{g}: {self.attractor_label(g)}" for g in range(self.n_attractors))
                + ("sink",) + (("unresolved",) if unres else ()) + (("unc. step", "unc. start") if unc else ())
                + (("S_bb", "alpha", "alpha moves") if fractal else ()))

        def pct(x):
            return "-" if np.isnan(x) else f"{100 * x:.1f}"

        rows = [(f"{v:.5g}",) + tuple(f"{100 * s:.1f}" if self.present[i, g] else "-"
                                      for g, s in enumerate(self.shares[i])) + (f"{100 * self.sink_share[i]:.1f}",)
                + ((f"{100 * self.unresolved_share[i]:.1f}",) if unres else ())
                + ((pct(self.uncertainty_step[i]), pct(self.uncertainty_start[i])) if unc else ())
                + ((_num(self.boundary_basin_entropy[i]),) + self._alpha_cells(i) if fractal else ())
                for i, v in enumerate(self.values)]
        return format_table(rows, head)

    def _alpha_cells(self, i: int) -> tuple[str, str]:
        """The uncertainty exponent at value ``i`` and the start moves of its scaling range
        (cell sizes), ``"none"`` where the label uncertainty found no scaling range."""
        a, lo, hi = self.uncertainty_exponent[i], self.uncertainty_exponent_low[i], self.uncertainty_exponent_high[i]
        if np.isfinite(a):
            return _num(a), (f"{lo:.0e}-{hi:.0e}" if np.isfinite(lo) else "-")
        return ("none", "no scaling range") if np.isfinite(self.uncertainty_start[i]) else ("-", "-")

    def summary(self) -> dict[str, Any]:
        return dict(kind="basins", param=self.param, fields=list(self.fields), values=self.values.tolist(),
                    **physical_summary(self.unit, self.physical, self.field_values),
                    method=self.method.name, grid=self.grid.to_dict(), match_tol=self.match_tol, system=self.system,
                    params=self.params, settings=self.settings_summary(), version=self.version,
                    attractors=[dict(id=g, label=self.attractor_label(g),
                                     first=float(self.values[self.present[:, g]][0]),
                                     last=float(self.values[self.present[:, g]][-1]),
                                     max_share=float(self.shares[:, g].max())) for g in range(self.n_attractors)],
                    **self._per_value_summary(), events=self.events())

    def _head(self) -> str:
        return self.axis_label if self.physical else self.param

    @property
    def param_coord(self) -> str:
        """Name of the parameter's coordinate in the saved file."""
        return coord_name(self.param, list(self.state_names) + list(self.grid.axis_names)
                          + ["attractor", "point", "state", "field"])

    def _coords(self) -> dict:
        c = self.param_coord
        return self._cell_coords({c: (c, np.asarray(self.values), {"long_name": self.param,
                                                                    "sets": ",".join(self.fields),
                                                                    **({"units": self.unit} if self.physical else {})})})

    def _attrs(self) -> dict:
        return dict(title="jaxgear basin shares across a parameter",
                    labels_meaning="global attractor id of each cell; -1 sink, -2 unresolved")


BLOCK_CELLS = 1 << 20
"""Cells (values x grid cells) one lane pool of a basin sweep takes at most: the values
of a block run together, and the block is what a killed sweep loses."""


def _analyze_values(system, params_list, grid, method, batched: bool = False, uncertainty: int = DEFAULT_SAMPLES):
    """The global analysis at several parameter values, with the label uncertainty of
    ``uncertainty`` sampled cells: in one lane pool (``batched``) or one analysis after
    another (a hook for progress and tests)."""
    if batched:
        return analyze_global_values(system, params_list, grid, method, progress=False, uncertainty=uncertainty)
    return [analyze_global(system, p, grid, method, progress=False, uncertainty=uncertainty) for p in params_list]


def basin_sweep(system: ForcedSystem | None, params, param: str, values, grid: CellGrid | None = None, *,
                method: AbstractGlobalMethod | str | None = None, options: BasinOptions | None = None,
                runner: Runner | None = None, gear_set=None, **changes) -> BasinSweep:
    """Basin shares across a parameter, attractors continued from value to value.

    At each value :func:`~jaxgear.analyze_global` runs ``method`` on ``grid`` (default:
    the method's grid; for the gear model the paper's region D), values in blocks of at
    most :data:`BLOCK_CELLS` cells (``batched``: each block in one lane pool,
    :func:`~jaxgear.analysis.analyze_global_values`). The attractors of every type
    each analysis finds (cycles, and the quasi-periodic and chaotic attractors that
    repeat no point, period 0, with their clouds of points and Lyapunov exponents) are
    matched from value to value (the idea of global continuation of attractors,
    Datseris & Wagemakers 2022): cycles by the Hausdorff distance of their stroboscopic
    point sets (cyclic-shift invariant), pairs farther than ``match_tol`` not matched
    (default: 5 % of the diagonal of the grid's box over its gridded axes); clouds by
    the overlap of the boxes of edge ``match_tol / 2`` they occupy (matched when they
    share at least half of the boxes of the one with fewer), not by point distance; a
    cycle never matches a cloud (``match_tol``, ``batched`` and ``uncertainty`` are the
    fields of ``options``). Greedily, closest pairs first. An attractor that
    appears gets a new global id; one that vanishes keeps its id (it is not matched
    again later). Per value and global attractor the result records its type
    (``attractor_type``) and largest Lyapunov exponent with its error.

    Args:
        param, values: as in :func:`~jaxgear.bifurcation_diagram`.
        method: a global-analysis method object (default :class:`~jaxgear.Direct`) or
            its name; it carries every option (integrator, ``max_period``, ...).
        options: :class:`~jaxgear.BasinOptions`; ``None``: the defaults. Its fields:
            ``match_tol`` (``None``: 5 % of the grid's diagonal); ``batched``: run the
            values of a block in one lane pool over (value, cell) pairs
            (:func:`~jaxgear.analysis.analyze_global_values`) instead of one analysis
            after another, with the same attractors and labels: a value whose pilot did
            not find all of its attractors (an attractor found later changes the capture
            radius at a moment of the pool that depends on the other values: 1 of 5,760
            cells differed at one point of a benchmark map), or where the pool met an
            attractor of boxes or a chaotic saddle (when a candidate's boxes enter the
            table depends on them too) or left cells unresolved, is analysed again alone.
            Off by default: on the 2-core CPU of the
            benchmarks it is about as fast (0.9 to 1.05x, ``benchmarks/sweep_scale.py``:
            the cells' integration dominates, and what one pool saves, the pilot's and
            the tail's draining, is a small part of each analysis), while a sweep value by
            value saves and reports each value as it ends; one pool saves more on a GPU,
            whose pools drain with most lanes idle. ``uncertainty``: cells sampled at each
            value for its label uncertainty (:func:`~jaxgear.analysis.label_uncertainty`,
            kept as ``uncertainty_step`` and ``uncertainty_start``); 0 skips it. On a small
            grid it is a large part of the sweep (40 % on 20 x 12 x 24 cells, about 5 % on
            the paper's 90,000).
        runner: a :class:`~jaxgear.Runner`: its output folder, resume and progress bar
            (``None``: ``Runner()``, nothing written). With a folder ``DIR``, each value's
            :class:`~jaxgear.GlobalResult` is saved to ``DIR/parts/value_00000.nc`` when
            done, and the sweep to ``DIR/basins.nc``.
        gear_set: a :class:`~jaxgear.GearSet`: ``param`` is then one of its fields (or
            ``b``, ``e_amp``, ``k_amp``: both meshes) and ``values`` are in its physical
            units (µm, N/m, rpm, N m, ...); each value sets the dimensionless fields its
            conversion changes (:func:`~jaxgear.sweep.sweep_axis`, docs/model.md §3-§4)
            on ``params`` (default: the gear set's own conversion).
        **changes: fields of ``options`` to change, e.g. ``uncertainty=0``.

    Every analysis splits its cells over the local devices (:mod:`jaxgear._devices`). Run
    as several JAX processes (:func:`jaxgear._devices.initialize`, e.g. one per host
    under Slurm), process ``p`` of ``P`` computes the values ``i`` with ``i % P == p``
    into the runner's folder (required then, a folder every process sees), every process
    assembles the sweep from the parts, and only process 0 writes ``basins.nc``: the file
    of one process. A killed process loses the value it was computing; the same command
    rerun resumes from the parts.
    Returns:
        :class:`BasinSweep`.
    """
    runner = sweep_runner(runner, changes, "basin_sweep")
    opts = with_changes(options, BasinOptions, changes)
    if gear_set is not None:
        params = resolve_gear_set(gear_set, params, system is None or system is REDUCED)
    system, params, method, grid, opts = resolve_basin_options(system, params, method, grid, opts)
    axis = sweep_axis(params, param, values, gear_set)
    names, rows = axis.applied()
    check_values(system, params, names, rows)
    settings = dict(kind="basins", system=system.name, param=param, values=axis.values.tolist(),
                    **({"physical": axis.unit} if axis.physical else {}),
                    params=params_to_dict(params), grid=grid.to_dict(), method=method.to_dict(),
                    match_tol=float(opts.match_tol), **uncertainty_setting(opts.uncertainty), version=__version__)
    results = analyses_at(system, [apply_values(params, names, r) for r in rows], grid, method, opts, settings, runner)
    sweep = _assemble_basins(results, param, axis.values, grid, method, opts, system, params, axis)
    runner.write(sweep, "basins.nc")
    return sweep


def uncertainty_setting(uncertainty) -> dict:
    """The sweep settings entry of its label-uncertainty samples (checked): none for the
    default, so that a resume folder begun before the option existed (whose analyses
    measured the default) still matches its settings."""
    check_int(uncertainty, "uncertainty", 0)
    return {} if int(uncertainty) == DEFAULT_SAMPLES else {"uncertainty": int(uncertainty)}


def resolve_basin_options(system, params, method, grid, options: BasinOptions):
    """The defaults and checks shared by :func:`basin_sweep` and
    :func:`~jaxgear.basin_map`: ``(system, params, method, grid, options)`` (the reduced
    model and the paper's parameters, the default method and its grid, and ``match_tol``
    5 % of the grid's diagonal when not given)."""
    if system is None:
        system = REDUCED
    if params is None:
        if system is not REDUCED:
            raise ValueError("pass the parameters of your system.")
        params = paper_params()
    if method is None:
        method = default_method()
    elif isinstance(method, str):
        method = method_from_name(method)
    elif not isinstance(method, AbstractGlobalMethod):
        raise ValueError(f"method must be a global-analysis method object or name, got {type(method).__name__}.")
    grid = method.default_grid(system) if grid is None else grid
    if not isinstance(grid, CellGrid):
        raise ValueError(f"grid must be a CellGrid, got {type(grid).__name__}.")
    if grid.dim != system.dim:
        raise ValueError(f"the grid has {grid.dim} coordinates, the system {system.dim}.")
    method.check(system, grid)
    if options.match_tol is None:
        diagonal = float(np.linalg.norm(np.asarray(grid.upper) - np.asarray(grid.lower)))
        options = dataclasses.replace(options, match_tol=0.05 * diagonal)
    return system, params, method, grid, options


def analyses_at(system, params_list, grid, method, options: BasinOptions, settings: dict, runner: Runner) -> list:
    """The global analysis at every parameter set of ``params_list`` (with the label
    uncertainty of ``options.uncertainty`` sampled cells, in one lane pool per block when
    ``options.batched``), in blocks of at most :data:`BLOCK_CELLS` cells, resumable and
    split over processes by ``runner`` (:meth:`~jaxgear.Runner.values`; ``settings``: the
    manifest's, of ``kind`` ``"basins"`` or ``"basin_map"``)."""
    kind = settings["kind"]
    label = (f"basins {settings['param']}" if kind == "basins"
             else f"basin map {settings['param_x']} x {settings['param_y']}")

    def compute(block):
        with values_over_processes():  # this process's values: each analysis on this process's devices
            return _analyze_values(system, [params_list[i] for i in block], grid, method, options.batched,
                                   options.uncertainty)

    return runner.values(settings, len(params_list), compute, max(1, BLOCK_CELLS // grid.n_cells), label,
                         "GlobalResult")


def _num(x) -> str:
    return "-" if not np.isfinite(x) else f"{x:.3f}"


_MEASURES = ("basin_entropy", "boundary_basin_entropy", "uncertainty_exponent", "uncertainty_exponent_error",
             "uncertainty_exponent_low", "uncertainty_exponent_high", "uncertainty_exponent_chi2")
"""The fractal basin measures of each value ``(V,)`` (NaN where not measured): basin
entropy ``S_b`` and boundary basin entropy ``S_bb`` (:func:`~jaxgear.basin_entropy`) and
the uncertainty exponent ``alpha`` with its error, the smallest and largest start move of
its scaling range and the fit's reduced chi^2 (:class:`~jaxgear.analysis.LabelUncertainty`;
``alpha`` NaN where there is no scaling range)."""


def global_arrays(results, gids, grid: CellGrid, dim: int) -> dict[str, np.ndarray]:
    """The per-result arrays of a sweep or map from the analyses ``results`` and the global
    ids of their attractors ``gids`` (:func:`match_across_values`): ``shares``, ``period``
    (-1 where absent), ``multiplier`` (NaN where absent), ``points`` (NaN padded),
    ``n_points`` (each ``(n, G, ...)``),
    ``labels`` ``(n, *grid.counts)`` int16 (global ids, -1 sink, -2 unresolved),
    ``sink_share``, ``unresolved_share``, ``uncertainty_step`` and ``uncertainty_start``
    ``(n,)`` (NaN where not measured), and each attractor's type ``attractor_type`` (an
    :class:`~jaxgear.AttractorType` value, -1 where absent or unknown),
    ``largest_exponent`` and its ``exponent_error`` (per forcing period, NaN where absent
    or not measured) ``(n, G)``, and the fractal basin measures :data:`_MEASURES` ``(n,)``."""
    n = len(results)
    G = int(max([g.max(initial=-1) for g in gids] + [-1])) + 1
    K = max([len(a.points) for r in results for a in r.attractors] + [1])
    out = dict(shares=np.zeros((n, G)), period=np.full((n, G), -1, dtype=np.int64), multiplier=np.full((n, G), np.nan),
               points=np.full((n, G, K, dim), np.nan), n_points=np.zeros((n, G), dtype=np.int64),
               labels=np.empty((n, *grid.counts), dtype=np.int16), sink_share=np.empty(n),
               unresolved_share=np.empty(n), uncertainty_step=np.full(n, np.nan), uncertainty_start=np.full(n, np.nan),
               attractor_type=np.full((n, G), int(AttractorType.UNKNOWN), dtype=np.int64), largest_exponent=np.full((n, G), np.nan),
               exponent_error=np.full((n, G), np.nan), **{f: np.full(n, np.nan) for f in _MEASURES})
    for i, (r, g) in enumerate(zip(results, gids)):
        lut = np.full(len(r.attractors) + 2, -1, dtype=np.int64)  # index local id + 2
        lut[0], lut[1] = -2, -1
        for a, gg in zip(r.attractors, g):
            pts = np.asarray(a.points)
            out["shares"][i, gg], out["period"][i, gg], out["n_points"][i, gg] = a.share, a.period, len(pts)
            out["multiplier"][i, gg] = a.multiplier
            out["attractor_type"][i, gg] = a.kind
            out["largest_exponent"][i, gg] = a.largest_exponent
            out["exponent_error"][i, gg] = a.exponent_errors[0] if len(a.exponent_errors) else np.nan
            out["points"][i, gg, : len(pts)] = pts
            lut[a.id + 2] = gg
        out["labels"][i] = lut[np.asarray(r.labels) + 2].reshape(grid.counts)
        out["sink_share"][i] = r.n_sink / r.n_cells
        out["unresolved_share"][i] = r.n_unresolved / r.n_cells
        if r.uncertainty is not None:
            out["uncertainty_step"][i], out["uncertainty_start"][i] = r.uncertainty.step, r.uncertainty.start
            out["uncertainty_exponent"][i] = r.uncertainty.alpha
            out["uncertainty_exponent_error"][i] = r.uncertainty.alpha_error
            out["uncertainty_exponent_chi2"][i] = r.uncertainty.alpha_chi2
            if r.uncertainty.alpha_range is not None:
                out["uncertainty_exponent_low"][i], out["uncertainty_exponent_high"][i] = r.uncertainty.alpha_range
        if r.basin_entropy is not None:
            out["basin_entropy"][i], out["boundary_basin_entropy"][i] = r.basin_entropy.S_b, r.basin_entropy.S_bb
    return out


def _assemble_basins(results, param: str, values, grid, method, options: BasinOptions, system, params,
                     axis=None) -> BasinSweep:
    """The :class:`BasinSweep` of the analyses ``results`` at ``values`` of ``param`` (of
    ``axis``, a :class:`~jaxgear.sweep.SweepAxis`, for a physical sweep), their attractors
    matched from value to value (``options.match_tol`` resolved)."""
    axis = sweep_axis(params, param, values) if axis is None else axis
    arrays = global_arrays(results, match_across_values(results, options.match_tol), grid, system.dim)
    arrays["attractor_type"] = carry_decided_types(arrays["attractor_type"])
    return BasinSweep(param=axis.name, fields=axis.fields, values=axis.values, unit=axis.unit,
                      physical=axis.physical, field_values=axis.rows, **arrays, grid=grid,
                      method=method, match_tol=float(options.match_tol), uncertainty_samples=options.uncertainty,
                      system=system.name, state_names=tuple(system.state_names), params=params_to_dict(params),
                      version=__version__)
