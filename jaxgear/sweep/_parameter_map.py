"""Two-parameter maps: the period reached from a fixed start, or the number of attractors."""

from __future__ import annotations

import dataclasses
import enum
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._checks import check_enum, with_changes
from .._codec import array_field, plain, result_type
from .._format import format_table
from .._io import save_result
from .._params import param_targets, params_to_dict
from .._system import ForcedSystem, check_system
from .._version import __version__
from ..integrate import AbstractIntegrator, resolve_integrator
from ._bifurcation import SequenceSettings, _Run, check_common, read_only
from ._classify import classify_sequences, group_starts, label_order, period_label
from ._kernels import independent_points
from ._options import SequenceOptions
from ._runner import Runner, sweep_runner
from ._values import apply_values, check_starts, check_values, coord_name, sorted_values

__all__ = ["ParameterMap", "parameter_map", "MapQuantity"]


class MapQuantity(enum.StrEnum):
    """What a :class:`ParameterMap` shows (its :attr:`~ParameterMap.data` and figure). A
    ``StrEnum``: each member equals its text (``"period"``, ``"n_attractors"``), which
    :func:`parameter_map` also accepts and files hold."""

    PERIOD = "period"
    """The period reached from the first start."""
    N_ATTRACTORS = "n_attractors"
    """The number of distinct attractors reached from the starts."""


@result_type
@dataclasses.dataclass(frozen=True, kw_only=True)
class ParameterMap:
    """Result of :func:`parameter_map` (a grid of two parameters).

    Attributes:
        param_x, fields_x, values_x ``(nx,)``; param_y, fields_y, values_y ``(ny,)``.
        starts: ``(S, dim)`` initial states (the same for every grid point).
        quantity: a :class:`MapQuantity`, ``PERIOD`` or ``N_ATTRACTORS`` (what :attr:`data`
            and the figure show).
        period: ``(ny, nx, S)`` period code reached from each start (k, 0 aperiodic, -1 escaped).
        attractor: ``(ny, nx, S)`` distinct-attractor id per grid point (-1 escaped).
        n_attractors: ``(ny, nx)`` number of distinct attractors reached (escape not counted).
        last_point: ``(ny, nx, S, dim)`` the last recorded stroboscopic point.
        system, state_names, params (the base parameter set), settings (a
        :class:`~jaxgear.sweep.SequenceSettings`), version.
    """

    param_x: str
    fields_x: tuple[str, ...]
    values_x: np.ndarray = array_field(lambda m: (m.coords_xy[0],))
    param_y: str = ""
    fields_y: tuple[str, ...] = ()
    values_y: np.ndarray = array_field(lambda m: (m.coords_xy[1],))
    starts: np.ndarray = array_field(("start", "state"))
    quantity: MapQuantity = MapQuantity.PERIOD
    period: np.ndarray = array_field(lambda m: (m.coords_xy[1], m.coords_xy[0], "start"))
    attractor: np.ndarray = array_field(lambda m: (m.coords_xy[1], m.coords_xy[0], "start"))
    n_attractors: np.ndarray = array_field(lambda m: (m.coords_xy[1], m.coords_xy[0]))
    last_point: np.ndarray = array_field(lambda m: (m.coords_xy[1], m.coords_xy[0], "start", "state"))
    system: str = ""
    state_names: tuple[str, ...] = ()
    params: dict = dataclasses.field(default_factory=dict)
    settings: SequenceSettings
    version: str = ""

    def __post_init__(self):
        object.__setattr__(self, "quantity", check_enum(self.quantity, "quantity", MapQuantity))
        for f in ("values_x", "values_y", "starts", "period", "attractor", "n_attractors", "last_point"):
            object.__setattr__(self, f, read_only(getattr(self, f)))

    @property
    def data(self) -> np.ndarray:
        """``(ny, nx)``: the period reached from the first start, or the number of attractors."""
        return self.period[:, :, 0] if self.quantity == MapQuantity.PERIOD else self.n_attractors

    def table(self) -> str:
        """Share of the grid per period (from the first start) and per number of attractors."""
        n = self.period[:, :, 0].size
        rows = []
        for k in sorted(np.unique(self.period[:, :, 0]).tolist(), key=lambda k: label_order(period_label(k))):
            c = int((self.period[:, :, 0] == k).sum())
            rows.append(("period from start 0", period_label(k), c, f"{100 * c / n:.1f} %"))
        for m in np.unique(self.n_attractors).tolist():
            c = int((self.n_attractors == m).sum())
            rows.append(("attractors reached", str(m), c, f"{100 * c / n:.1f} %"))
        return format_table(rows, ("quantity", "value", "grid points", "share"))

    def summary(self) -> dict[str, Any]:
        return dict(kind="parameter_map", param_x=self.param_x, values_x=self.values_x.tolist(),
                    param_y=self.param_y, values_y=self.values_y.tolist(), quantity=self.quantity.value,
                    n_starts=int(len(self.starts)), system=self.system, params=self.params, settings=plain(self.settings),
                    version=self.version,
                    period_counts={period_label(k): int((self.period[:, :, 0] == k).sum())
                                   for k in np.unique(self.period[:, :, 0]).tolist()},
                    n_attractors_counts={str(m): int((self.n_attractors == m).sum())
                                         for m in np.unique(self.n_attractors).tolist()})

    @property
    def coords_xy(self) -> tuple[str, str]:
        """Names of the two parameter coordinates in the saved file."""
        taken = list(self.state_names) + ["start", "state"]
        cx = coord_name(self.param_x, taken)
        cy = coord_name(self.param_y, taken + [cx])
        return cx, (f"{cy}_y" if cy == cx else cy)

    def _coords(self) -> dict:
        cx, cy = self.coords_xy
        return {cx: (cx, np.asarray(self.values_x), {"long_name": self.param_x, "sets": ",".join(self.fields_x)}),
                cy: (cy, np.asarray(self.values_y), {"long_name": self.param_y, "sets": ",".join(self.fields_y)}),
                "state": ("state", list(self.state_names))}

    def _attrs(self) -> dict:
        return dict(title="jaxgear two-parameter map")

    def save(self, path):
        """Write to netCDF atomically; reload with :func:`jaxgear.load`."""
        return save_result(self, path)


def parameter_map(system: ForcedSystem | None, params, param_x: str, values_x, param_y: str, values_y, x0s, *,
                  quantity: MapQuantity | str = MapQuantity.PERIOD, integrator: AbstractIntegrator | None = None,
                  options: SequenceOptions | None = None, runner: Runner | None = None, **changes) -> ParameterMap:
    """Two-parameter map: the period of the attractor reached from a fixed initial state
    (``quantity="period"``, :attr:`MapQuantity.PERIOD`: from ``x0s[0]``) or the number of
    distinct attractors reached from several starts (``"n_attractors"``), on the grid
    ``values_y x values_x``; ``quantity`` is a :class:`MapQuantity` or its text.

    Every (grid point, start) runs as in :func:`bifurcation_diagram` with
    ``direction="independent"`` and the :class:`~jaxgear.SequenceOptions` ``options``
    (``transient`` periods, then ``record`` points, ``None``: ``2 max_period + 2``), all
    batched with ``vmap`` in blocks of ``chunk_size`` trajectories; ``**changes``: fields
    of ``options`` to change. Both period codes and attractor counts are always computed.
    ``runner``: a :class:`~jaxgear.Runner`, its output folder ``DIR`` (kill-and-resume,
    and the final ``DIR/parameter_map.nc``) and progress bar (``None``: ``Runner()``,
    nothing written).

    Several JAX processes (:func:`jaxgear._devices.initialize`), each calling this with
    the same arguments, split every block of grid points over the processes and
    exchange the parts: every process returns the whole, identical map, and only
    process 0 keeps the runner's folder and writes the file.
    """
    runner = sweep_runner(runner, changes, "parameter_map")
    quantity = check_enum(quantity, "quantity", MapQuantity)
    opts = with_changes(options, SequenceOptions, changes)
    opts = opts.with_record(2 * opts.max_period + 2)
    system, params = check_common(system, params)
    param_targets(params, param_x)
    param_targets(params, param_y)
    if set(param_targets(params, param_x)) & set(param_targets(params, param_y)):
        raise ValueError(f"param_x={param_x!r} and param_y={param_y!r} set the same field.")
    vx, vy = sorted_values(values_x, param_x), sorted_values(values_y, param_y)
    X0 = check_starts(system, x0s)
    names = (param_x, param_y)
    VV = np.stack(np.meshgrid(vx, vy, indexing="xy"), axis=-1).reshape(-1, 2)  # (ny*nx, 2), y major
    check_system(system, apply_values(params, names, VV[0]), X0[0])
    check_values(system, params, names, VV)
    integrator = resolve_integrator(integrator)
    S, n = len(X0), len(VV)
    B = max(1, min(n, opts.chunk_size // S))
    settings = dict(kind="parameter_map", system=system.name, param_x=param_x, values_x=vx.tolist(),
                    param_y=param_y, values_y=vy.tolist(), starts=X0.tolist(), params=params_to_dict(params),
                    transient=opts.transient, record=opts.record, integrator=integrator.to_dict(),
                    max_period=opts.max_period, tol=float(opts.tol), merge_tol=float(opts.merge_tol),
                    escape_bound=float(opts.escape_bound), block_points=int(B), version=__version__)
    ck = runner.blocks("parameter_map", settings)
    run = _Run(system, params, names, VV, X0, opts, integrator)
    period, attractor, last = _map_blocks(run, B, ck, runner.bar(n, f"map {param_x} x {param_y}", unit="point"))
    ny, nx = len(vy), len(vx)
    n_att = attractor.max(axis=1, initial=-1) + 1
    pmap = ParameterMap(
        param_x=param_x, fields_x=param_targets(params, param_x), values_x=vx, param_y=param_y,
        fields_y=param_targets(params, param_y), values_y=vy, starts=X0, quantity=quantity,
        period=period.reshape(ny, nx, S), attractor=attractor.reshape(ny, nx, S),
        n_attractors=n_att.reshape(ny, nx).astype(np.int64), last_point=last.reshape(ny, nx, S, system.dim),
        system=system.name, state_names=tuple(system.state_names), params=params_to_dict(params),
        settings=SequenceSettings(options=opts, integrator=integrator), version=__version__,
    )
    runner.write(pmap, "parameter_map.nc")
    return pmap




def _map_blocks(run: _Run, B: int, ck, bar):
    """The grid points ``run.values (n, 2)`` in blocks of ``B`` (each saved to and resumed
    from ``ck``, counted on the progress bar ``bar``): the period code and attractor id
    per (point, start), ``(n, S)``, and the last recorded point ``(n, S, dim)``."""
    (n, _), (S, dim) = run.values.shape, run.starts.shape
    opts, X0, M = run.options, jnp.asarray(run.starts), run.options.max_period
    period = np.empty((n, S), dtype=np.int64)
    attractor = np.empty((n, S), dtype=np.int64)
    last = np.empty((n, S, dim))
    for bi, a in enumerate(range(0, n, B)):
        b = min(a + B, n)

        def compute(a=a, b=b):
            pts = independent_points(run.system, run.params, run.names, run.values[a:b], B, X0, opts.transient,
                                     opts.record, run.integrator)
            per = classify_sequences(pts, M, float(opts.tol), float(opts.escape_bound))
            return dict(period=per, attractor=group_starts(pts[..., -M:, :], per, float(opts.merge_tol)),
                        last=pts[:, :, -1])

        like = dict(period=((b - a, S), np.int64), attractor=((b - a, S), np.int64), last=((b - a, S, dim), float))
        z = ck.block(f"map_{bi:05d}.npz", compute, like)
        period[a:b], attractor[a:b], last[a:b] = z["period"], z["attractor"], z["last"]
        bar.update(b - a)
    bar.close()
    return period, attractor, last
