"""Bifurcation diagrams: stroboscopic points against one parameter, classified by period and type.

From several initial states per value, a transient is dropped, stroboscopic points are
recorded and each (value, start) is classified as P-k (recurrence on the stroboscopic
map, paper §3), aperiodic (no period up to ``max_period``) or escaped; an aperiodic
attractor is then labelled chaotic or quasi-periodic by its largest Lyapunov exponent
(:func:`aperiodic_types`). Values and starts are batched (``direction="independent"``), or the state is
carried from one value to the next (``"up"``/``"down"``/``"both"``: a ``lax.scan`` over
values), so hysteresis shows; ``"all"`` does both kinds.

Parameters are named by a field of the parameter pytree or an alias (``b``,
``kappa_amp``, ``e_amp``: both meshes) and set with :func:`jaxgear.with_param`; values
enter the compiled kernels as array leaves, so nothing is recompiled per value. With a
:class:`~jaxgear.Runner` of an output folder every finished block is saved and an
interrupted sweep resumes.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._checks import check_enum, with_changes
from .._codec import array_field, custom_field, later_field, plain, result_type
from .._format import format_table
from .._io import save_result
from .._lyapunov import AttractorType, LyapunovSpectrum, kaplan_yorke
from .._model import REDUCED
from .._params import params_to_dict
from .._presets import paper_params
from .._status import Status
from .._system import ForcedSystem, check_system
from .._version import __version__
from ..analysis._global import LYAPUNOV_PERIODS, LYAPUNOV_STRETCHES, with_longer_look
from ..integrate import AbstractIntegrator, integrator_from_dict, resolve_integrator
from ._classify import APERIODIC, ESCAPED, classify_sequences, group_starts, label_order, type_label
from ._kernels import independent_points, sequential_points, values_exponent_estimates
from ._options import DIAGRAM_RECORD, SequenceOptions
from ._physical import axis_label, physical_summary, resolve_gear_set, sweep_axis
from ._runner import Runner, sweep_runner
from ._values import apply_values, check_starts, check_values, coord_name

__all__ = ["BifurcationDiagram", "SequenceSettings", "bifurcation_diagram", "SweepDirection", "DIRECTIONS",
           "check_common", "read_only"]


class SweepDirection(enum.StrEnum):
    """How a bifurcation diagram runs through the parameter values (:func:`bifurcation_diagram`'s
    ``direction``, :attr:`BifurcationDiagram.directions`). A ``StrEnum``: each member equals
    its text (``"up"``, ...), which the functions also accept and files hold.

    Not the crossing direction of a Poincaré section (``PoincareCellMap.direction``,
    :func:`~jaxgear.section_map`), which is a signed number (+1, -1, 0).
    """

    INDEPENDENT = "independent"
    """Every (value, start) from the starts, all batched."""
    UP = "up"
    """Values in increasing order, each from the state the previous one ended in."""
    DOWN = "down"
    """The same in decreasing order."""
    BOTH = "both"
    """The up and the down sweep, run together."""
    ALL = "all"
    """Independent, up and down."""

    @property
    def sweeps(self) -> tuple[SweepDirection, ...]:
        """The sweeps it runs, in the order of :attr:`BifurcationDiagram.directions`
        (``BOTH``: ``(UP, DOWN)``; ``ALL``: ``(INDEPENDENT, UP, DOWN)``)."""
        D = SweepDirection
        return {D.BOTH: (D.UP, D.DOWN), D.ALL: (D.INDEPENDENT, D.UP, D.DOWN)}.get(self, (self,))


DIRECTIONS = tuple(d.value for d in SweepDirection)
"""The texts of :class:`SweepDirection` (``"independent"``, ``"up"``, ``"down"``, ``"both"``, ``"all"``)."""


def read_only(a) -> np.ndarray:
    """``a`` as a numpy array that cannot be written to (results are immutable)."""
    a = np.asarray(a)
    a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, kw_only=True)
class SequenceSettings:
    """What a sweep that follows each start for a number of forcing periods and classifies
    the recorded stroboscopic points ran with (:func:`bifurcation_diagram`,
    :func:`~jaxgear.parameter_map`).

    Attributes:
        options: the :class:`~jaxgear.SequenceOptions` (``record`` as used, never ``None``).
        integrator: the integrator.
    """

    options: SequenceOptions
    integrator: AbstractIntegrator = custom_field(lambda i: i.to_dict(), integrator_from_dict)


@result_type
@dataclasses.dataclass(frozen=True, kw_only=True)
class BifurcationDiagram:
    """Result of :func:`bifurcation_diagram` (a one-parameter sweep).

    Attributes:
        param: the swept name as given (a field or an alias, or a
            :class:`~jaxgear.GearSet` field for a physical sweep); fields: the
            dimensionless fields it sets.
        values: ``(V,)`` parameter values, increasing (in ``unit`` when ``physical``).
        unit, physical: the unit of ``values`` and whether they are a gear set's
            physical values (``gear_set=``; ``""`` and ``False`` otherwise).
        field_values: ``(V, len(fields))`` the dimensionless value of each field at each
            value (``values`` repeated for a dimensionless sweep).
        directions: which sweeps (:class:`SweepDirection` members, equal to their texts):
            ``(INDEPENDENT,)``, ``(UP,)``, ``(DOWN,)``, ``(UP, DOWN)`` or
            ``(INDEPENDENT, UP, DOWN)`` (:attr:`SweepDirection.sweeps`).
        starts: ``(S, dim)`` initial states.
        points: ``(D, V, S, R, dim)`` recorded stroboscopic points (state at forcing phase
            0 of R successive periods after the transient), per direction, value, start.
        period: ``(D, V, S)`` minimal period k of P-k, ``APERIODIC`` (0) or ``ESCAPED`` (-1).
        attractor: ``(D, V, S)`` id of the distinct attractor reached, numbered per
            (direction, value) in order of first start; -1 escaped.
        attractor_type: ``(D, V, S)`` the type of the attractor reached (an
            :class:`~jaxgear.AttractorType` value): periodic for P-k, chaotic or
            quasi-periodic for an aperiodic one by its largest Lyapunov exponent, -1
            (unknown) where escaped or not measured (files written before it was).
        largest_exponent, exponent_error: ``(D, V, S)`` the largest Lyapunov exponent of
            the stroboscopic map per forcing period on an aperiodic attractor and its
            standard error (NaN for P-k and escaped lanes, and in older files).
        system, state_names, params (the base parameter set, canonical names), settings
        (a :class:`SequenceSettings`: the :class:`~jaxgear.SequenceOptions` and the
        integrator), version.
    """

    param: str
    fields: tuple[str, ...]
    values: np.ndarray = array_field(lambda d: (d.param_coord,))
    unit: str = later_field("")
    physical: bool = later_field(False)
    field_values: np.ndarray | None = array_field(lambda d: (d.param_coord, "field"), later=True, default=None)
    directions: tuple[SweepDirection, ...] = ()
    starts: np.ndarray = array_field(("start", "state"))
    points: np.ndarray = array_field(lambda d: ("direction", d.param_coord, "start", "record", "state"))
    period: np.ndarray = array_field(lambda d: ("direction", d.param_coord, "start"))
    attractor: np.ndarray = array_field(lambda d: ("direction", d.param_coord, "start"))
    attractor_type: np.ndarray | None = array_field(lambda d: ("direction", d.param_coord, "start"), later=True,
                                                    default=None)
    largest_exponent: np.ndarray | None = array_field(lambda d: ("direction", d.param_coord, "start"), later=True,
                                                      default=None)
    exponent_error: np.ndarray | None = array_field(lambda d: ("direction", d.param_coord, "start"), later=True,
                                                    default=None)
    system: str = ""
    state_names: tuple[str, ...] = ()
    params: dict = dataclasses.field(default_factory=dict)
    settings: SequenceSettings
    version: str = ""

    def __post_init__(self):
        object.__setattr__(self, "directions", tuple(check_enum(d, "direction", SweepDirection)
                                                     for d in self.directions))
        if self.attractor_type is None:  # a file written before types were recorded: cycles periodic, the rest unknown
            object.__setattr__(self, "attractor_type", np.where(np.asarray(self.period) > 0, int(AttractorType.PERIODIC),
                                                      int(AttractorType.UNKNOWN)).astype(np.int64))
        for f in ("largest_exponent", "exponent_error"):
            if getattr(self, f) is None:
                object.__setattr__(self, f, np.full(np.shape(self.period), np.nan))
        if self.field_values is None:  # a dimensionless sweep (or a file written before physical sweeps)
            object.__setattr__(self, "field_values", np.repeat(np.asarray(self.values, float)[:, None],
                                                               len(self.fields), axis=1))
        for f in ("values", "field_values", "starts", "points", "period", "attractor", "attractor_type", "largest_exponent", "exponent_error"):
            object.__setattr__(self, f, read_only(getattr(self, f)))

    @property
    def axis_label(self) -> str:
        """The swept parameter with its unit (``"b_sp [µm, half]"``) or the fields it sets."""
        return axis_label(self.param, self.fields, self.unit, self.physical)

    @property
    def param_coord(self) -> str:
        """Name of the parameter's coordinate in the saved file (the parameter's name
        unless it clashes with another dimension)."""
        return coord_name(self.param, list(self.state_names) + ["direction", "start", "record", "state", "field"])

    def _d(self, direction: SweepDirection | str | None) -> int:
        if direction is None:
            return 0
        if direction not in self.directions:
            raise ValueError(f"direction {direction!r} is not in this diagram; it has "
                             f"{', '.join(map(str, self.directions))}.")
        return self.directions.index(direction)

    def labels(self) -> np.ndarray:
        """``(D, V, S)`` str: the label of the attractor each start reached (``"P-4"``,
        ``"chaotic"``, ``"quasi-periodic"``, ``"aperiodic"`` of unknown type, ``"escaped"``)."""
        out = np.array([type_label(int(k), int(t)) for k, t in zip(self.period.ravel(), self.attractor_type.ravel())],
                       dtype=object)
        return out.reshape(self.period.shape)

    def attractors_at(self, index: int, direction: SweepDirection | str | None = None) -> list[dict]:
        """Distinct attractors at ``values[index]``: label (``"P-k"``, ``"chaotic"``,
        ``"quasi-periodic"``, ``"aperiodic"``), period, type, largest Lyapunov exponent and
        its error (per forcing period; NaN for P-k), number of starts, one point."""
        d = self._d(direction)
        ids, per, pts = self.attractor[d, index], self.period[d, index], self.points[d, index]
        out = []
        for a in range(int(ids.max(initial=-1)) + 1):
            lanes = np.nonzero(ids == a)[0]
            s, k = lanes[0], int(per[lanes[0]])
            t = int(self.attractor_type[d, index, s])
            out.append(dict(id=a, period=k, label=type_label(k, t), type=AttractorType(t).label,
                            largest_exponent=float(self.largest_exponent[d, index, s]),
                            exponent_error=float(self.exponent_error[d, index, s]), starts=int(len(lanes)),
                            point=pts[s, -1].tolist()))
        n_esc = int((ids < 0).sum())
        if n_esc:
            out.append(dict(id=-1, period=ESCAPED, label="escaped", type=AttractorType.UNKNOWN.label,
                            largest_exponent=float("nan"), exponent_error=float("nan"), starts=n_esc, point=None))
        return out

    def transitions(self, direction: SweepDirection | str | None = None) -> list[dict]:
        """Where the set of attractor labels changes: ``[{before, after, from, to}, ...]``."""
        d = self._d(direction)
        sets = [tuple(sorted({a["label"] for a in self.attractors_at(i, self.directions[d])},
                             key=label_order)) for i in range(len(self.values))]
        order = range(len(self.values)) if self.directions[d] != SweepDirection.DOWN else range(len(self.values) - 1, -1, -1)
        order = list(order)
        out = []
        for i, j in zip(order[:-1], order[1:]):
            if sets[i] != sets[j]:
                out.append({"before": float(self.values[i]), "after": float(self.values[j]),
                            "from": list(sets[i]), "to": list(sets[j])})
        return out

    def _attractor_sets(self, d: int, i: int) -> list[tuple[str, np.ndarray]]:
        """``[(label, points)]`` of the attractors at value ``i`` of direction ``d``."""
        ids, per, pts = self.attractor[d, i], self.period[d, i], self.points[d, i]
        out = []
        for a in range(int(ids.max(initial=-1)) + 1):
            s = int(np.argmax(ids == a))
            k = int(per[s])
            out.append((type_label(k, int(self.attractor_type[d, i, s])), pts[s, -k:] if k > 0 else pts[s, -1:]))
        if np.any(ids < 0):
            out.append(("escaped", np.zeros((0, pts.shape[-1]))))
        return out

    def differs(self, a: SweepDirection | str = SweepDirection.UP,
                b: SweepDirection | str = SweepDirection.DOWN) -> np.ndarray:
        """``(V,)`` bool: the sweeps ``a`` and ``b`` end on different sets of attractors at
        each value (same periods and point sets within ``merge_tol``, or aperiodic
        attractors of the same type, count as equal);
        for ``"up"`` and ``"down"`` this marks the hysteresis."""
        da, db = self._d(a), self._d(b)
        tol = self.settings.options.merge_tol
        out = np.zeros(len(self.values), dtype=bool)
        for i in range(len(self.values)):
            A, B = self._attractor_sets(da, i), self._attractor_sets(db, i)

            def same(x, y):
                if x[0] != y[0]:
                    return False
                if not x[0].startswith("P-"):
                    return True  # aperiodic sets of one type, escape
                scale = 1.0 + max(np.abs(x[1]).max(), np.abs(y[1]).max())
                d = np.linalg.norm(x[1][:, None] - y[1][None], axis=-1)
                return max(d.min(axis=0).max(), d.min(axis=1).max()) <= tol * scale

            out[i] = not (all(any(same(x, y) for y in B) for x in A) and all(any(same(y, x) for x in A) for y in B))
        return out

    def table(self, full: bool = False) -> str:
        """Printable table: runs of values with the same attractors (``full``: every value),
        each attractor with its share of the starts."""
        rows = []
        S = len(self.starts)
        for name in self.directions:
            runs = []
            for i in range(len(self.values)):
                atts = self.attractors_at(i, name)
                labels = tuple(sorted({a["label"] for a in atts}, key=label_order))
                cnt = {}
                for a in atts:
                    cnt[a["label"]] = cnt.get(a["label"], 0) + a["starts"]
                if runs and not full and runs[-1][1] == labels:
                    runs[-1][0].append(i)
                    for k, c in cnt.items():
                        runs[-1][2][k] += c
                else:
                    runs.append(([i], labels, dict(cnt)))
            for idx, labels, cnt in runs:
                lo, hi = self.values[idx[0]], self.values[idx[-1]]
                rng = f"{lo:.5g}" if len(idx) == 1 else f"{lo:.5g} .. {hi:.5g}"
                text = ", ".join(f"{lab} ({100 * cnt[lab] / (S * len(idx)):.0f} %)" for lab in labels)
                rows.append((rng, len(idx), name, text))
        head = (self.axis_label if self.physical else self.param, "values", "sweep", f"attractors (share of {S} starts)")
        return format_table(rows, head)

    def summary(self) -> dict[str, Any]:
        """JSON-able summary: settings, parameters and the attractors at every value."""
        return dict(
            kind="bifurcation", param=self.param, fields=list(self.fields), values=self.values.tolist(),
            **physical_summary(self.unit, self.physical, self.field_values),
            directions=[str(d) for d in self.directions], n_starts=int(len(self.starts)), system=self.system,
            state_names=list(self.state_names), params=self.params, settings=plain(self.settings), version=self.version,
            transitions={str(d): self.transitions(d) for d in self.directions},
            hysteresis=(self.values[self.differs()].tolist()
                        if SweepDirection.UP in self.directions and SweepDirection.DOWN in self.directions else None),
            attractors={str(d): [self.attractors_at(i, d) for i in range(len(self.values))] for d in self.directions},
        )

    def _coords(self) -> dict:
        return {"direction": ("direction", [str(d) for d in self.directions]),
                self.param_coord: (self.param_coord, np.asarray(self.values),
                                   {"long_name": self.param, "sets": ",".join(self.fields),
                                    **({"units": self.unit} if self.physical else {})}),
                "state": ("state", list(self.state_names))}

    def _attrs(self) -> dict:
        return dict(title="jaxgear bifurcation diagram",
                    units="dimensionless: lengths in b_c, time in 1/omega_n (model document §3) for the gear models")

    def save(self, path):
        """Write to netCDF atomically; reload with :func:`jaxgear.load`."""
        return save_result(self, path)


def check_common(system, params):
    """The defaults shared by the sweeps: the gear model and the paper preset."""
    if system is None:
        system = REDUCED
    if params is None:
        if system is not REDUCED:
            raise ValueError("pass the parameters of your system.")
        params = paper_params()
    return system, params


def bifurcation_diagram(system: ForcedSystem | None, params, param: str, values, x0s, *,
                        direction: SweepDirection | str = SweepDirection.INDEPENDENT,
                        integrator: AbstractIntegrator | None = None,
                        options: SequenceOptions | None = None, runner: Runner | None = None, gear_set=None,
                        **changes) -> BifurcationDiagram:
    """Bifurcation diagram: stroboscopic points against one parameter, classified by period.

    For each value of ``param`` and each initial state: ``transient`` forcing periods,
    then ``record`` stroboscopic points (paper §3: the state at forcing phase 0 of
    successive periods), classified as P-k (the smallest ``k <= max_period`` with
    ``|x_j - x_(j-k)| <= tol (1 + |x_j|)`` over the last k+1 points), aperiodic (none:
    quasi-periodic, chaotic or a slow transient) or escaped (non-finite, or a norm above
    ``escape_bound``); those are the fields of ``options``. Each aperiodic attractor (per direction and value) then gets its
    type, chaotic or quasi-periodic, from the largest Lyapunov exponent of the
    stroboscopic map (:func:`aperiodic_types`: a few hundred periods from its last
    point, every aperiodic attractor of the diagram in one batch; kept as
    ``attractor_type``, ``largest_exponent`` and ``exponent_error``).

    Args:
        system, params: the :class:`ForcedSystem` and its parameter pytree (defaults: the
            reduced gear model and the ``paper`` preset).
        param: a field of ``params`` (for :class:`GearParams` any canonical name but
            ``N``: ``b_sp``, ``kappa_sp_amp``, ``Omega``, ``c_sp``, ``f_D``, ``e_sp_amp``...)
            or an alias (``b``, ``kappa_amp``, ``e_amp``: both meshes together);
            per-planet fields are set for all planets.
        values: the parameter values (sorted increasing, distinct).
        x0s: initial states ``(S, dim)`` (or one ``(dim,)``).
        direction: a :class:`SweepDirection` or its text: ``"independent"`` — every
            (value, start) from ``x0s``, all batched; ``"up"`` — values in increasing
            order, each value starting from the state the previous value ended in (the
            first from ``x0s``), so a branch is followed until it vanishes; ``"down"`` —
            the same in decreasing order from ``x0s``; ``"both"`` — the up and the down
            sweep, each from ``x0s`` (run together); ``"all"`` — independent, up and down.
            A lane of a sweep that escapes restarts from its ``x0`` at the next value.
        integrator: default :func:`~jaxgear.integrate.default_integrator` (for a fixed-step
            integrator the step is ``h = T/steps`` per value).
        options: :class:`~jaxgear.SequenceOptions` (``transient``, ``record`` (``None``:
            :data:`DIAGRAM_RECORD`), ``max_period``, ``tol``, ``merge_tol``,
            ``escape_bound``, ``chunk_size``: trajectories per compiled batch, values per
            block ``chunk_size // S``, also the block the runner saves); ``None``: the defaults.
        runner: a :class:`~jaxgear.Runner`: its output folder, resume and progress bar
            (``None``: ``Runner()``, nothing written). With a folder ``DIR``: kill-and-resume
            (``DIR/parts``, ``DIR/manifest.json``) and the final ``DIR/bifurcation.nc``,
            read instead of computed when it holds this diagram.
        gear_set: a :class:`~jaxgear.GearSet`: ``param`` is then one of its fields (or
            ``b``, ``e_amp``, ``k_amp``: both meshes) and ``values`` are in its physical
            units; each value sets the dimensionless fields its conversion changes
            (:func:`~jaxgear.sweep.sweep_axis`, docs/model.md §3-§4) on ``params``
            (default: the gear set's own conversion).
        **changes: fields of ``options`` to change, e.g. ``transient=200, max_period=8``.

    Run as several JAX processes (:func:`jaxgear._devices.initialize`), every process
    calls this with the same arguments: each block of independent values is split over
    the processes (one contiguous part each, :func:`jaxgear._devices.rows_over_processes`)
    and the parts are exchanged, so every process returns the whole, identical diagram;
    the sequential sweeps (``"up"``, ``"down"``, ``"both"``: the state carried from
    value to value) run on process 0 alone and are sent to the others. Only process 0
    keeps the runner's folder (it need not be shared) and writes the file.
    Returns:
        :class:`BifurcationDiagram`.
    """
    runner = sweep_runner(runner, changes, "bifurcation_diagram")
    opts = with_changes(options, SequenceOptions, changes).with_record(DIAGRAM_RECORD)
    direction = check_enum(direction, "direction", SweepDirection)
    system, params, axis, X0, integrator = _check_diagram(system, params, param, values, x0s, integrator, gear_set)
    vals = axis.values
    passes, dirs, blocks = _passes(direction, len(vals), len(X0), opts.chunk_size)
    settings = dict(kind="bifurcation", system=system.name, param=param, values=vals.tolist(),
                    **({"physical": axis.unit} if axis.physical else {}),
                    starts=X0.tolist(), params=params_to_dict(params), transient=opts.transient, record=opts.record,
                    direction=direction.value, integrator=integrator.to_dict(), max_period=opts.max_period,
                    tol=float(opts.tol), merge_tol=float(opts.merge_tol), escape_bound=float(opts.escape_bound),
                    block_values=blocks, version=__version__)
    ck = runner.blocks("bifurcation", settings)
    done = runner.finished("bifurcation.nc", "BifurcationDiagram",
                           functools.partial(_is_diagram, axis, X0, dirs, params_to_dict(params),
                                             SequenceSettings(options=opts, integrator=integrator)))
    if done is not None:  # the same diagram, already whole in the runner's folder: nothing is recomputed
        return done
    run = _Run(system, params, *axis.applied(), X0, opts, integrator)
    points = _record_passes(run, passes, dirs, blocks, ck, runner.bar(len(dirs) * len(vals), f"sweep {param}"))
    period = classify_sequences(points, opts.max_period, float(opts.tol), float(opts.escape_bound))
    attractor = group_starts(points[..., -opts.max_period:, :], period, float(opts.merge_tol))
    kind, lam, err = aperiodic_types(run, points, period, attractor)
    diagram = BifurcationDiagram(
        param=param, fields=axis.fields, values=vals, unit=axis.unit, physical=axis.physical,
        field_values=axis.rows, directions=dirs, starts=X0, points=points,
        period=period, attractor=attractor, attractor_type=kind, largest_exponent=lam, exponent_error=err,
        system=system.name, state_names=tuple(system.state_names), params=params_to_dict(params),
        settings=SequenceSettings(options=opts, integrator=integrator), version=__version__,
    )
    runner.write(diagram, "bifurcation.nc")
    return diagram


def _is_diagram(axis, starts, directions, params: dict, settings: SequenceSettings, d) -> bool:
    """Whether the saved diagram ``d`` is the one these arguments ask for (same parameter,
    values, starts, directions, base parameters and settings; the checkpoint already
    refused a folder of other settings)."""
    return (d.param == axis.name and d.physical == axis.physical and np.array_equal(d.values, axis.values)
            and np.array_equal(d.starts, starts) and tuple(d.directions) == tuple(directions) and d.params == params
            and d.settings == settings)


def _check_diagram(system, params, param, values, x0s, integrator, gear_set=None):
    """The defaults and checks of :func:`bifurcation_diagram` (but its ``direction``'s):
    ``(system, params, axis (a SweepAxis: values sorted), starts (S, dim), integrator)``."""
    if gear_set is not None:
        params = resolve_gear_set(gear_set, params, system is None or system is REDUCED)
    system, params = check_common(system, params)
    axis = sweep_axis(params, param, values, gear_set)
    names, rows = axis.applied()
    X0 = check_starts(system, x0s)
    check_system(system, apply_values(params, names, rows[0]), X0[0])
    check_values(system, params, names, rows)
    return system, params, axis, X0, resolve_integrator(integrator)


def _passes(direction: SweepDirection, V: int, S: int, chunk_size: int):
    """The passes of a diagram: ``[(name of its parts, directions it computes together)]``
    (the up and the down sweep are one pass, named ``"both"``), the directions in order
    (:attr:`SweepDirection.sweeps`), and the values per block of each pass (independent:
    as many as ``chunk_size`` trajectories hold; sequential: the block only sets how often
    the sweep is saved)."""
    D = SweepDirection
    passes = {D.BOTH: [("both", (D.UP, D.DOWN))],
              D.ALL: [("independent", (D.INDEPENDENT,)), ("both", (D.UP, D.DOWN))]}.get(direction,
                                                                                       [(direction.value, (direction,))])
    dirs = tuple(d for _, ds in passes for d in ds)  # direction.sweeps
    blocks = {}
    for name, ds in passes:
        if name == "independent":
            blocks[name] = max(1, min(V, chunk_size // S))
        else:
            blocks[name] = max(1, min(V, chunk_size // (S * len(ds)), -(-V // 8)))
    return passes, dirs, blocks


@dataclasses.dataclass(frozen=True)
class _Run:
    """What every block of a sweep integrates with: the system, base parameters, swept
    names, and one row per value ``(V, len(names))`` (a diagram: the values in order) or
    per grid point (a parameter map), starts ``(S, dim)``, the options (``record`` set) and the integrator."""

    system: Any
    params: Any
    names: tuple[str, ...]
    values: np.ndarray
    starts: np.ndarray
    options: SequenceOptions
    integrator: Any


def _compute_block(run: _Run, name: str, B: int, orders, a: int, b: int, carry) -> dict:
    """Points of the values ``a:b`` of one pass (padded to ``B`` values), and the state
    carried out of the block (sequential passes; the carry in for independent ones)."""
    if name == "independent":
        pts = independent_points(run.system, run.params, run.names, run.values[a:b], B, jnp.asarray(run.starts),
                                 run.options.transient, run.options.record, run.integrator)[:, None]
    else:
        seq = np.stack([run.values[o[a:b]] for o in orders], axis=1)  # (n, nd, m)
        pts, carry = sequential_points(run.system, run.params, run.names, seq, B, jnp.asarray(run.starts), carry,
                                       run.options.transient, run.options.record, run.integrator,
                                       run.options.escape_bound)
    return dict(points=pts, carry=carry)


def _record_passes(run: _Run, passes, dirs, blocks, ck, bar) -> np.ndarray:
    """Every pass block by block (each saved to and resumed from ``ck``, counted on the
    progress bar ``bar``): the recorded points ``(D, V, S, R, dim)``."""
    V, (S, dim), R = len(run.values), run.starts.shape, run.options.record
    points = np.empty((len(dirs), V, S, R, dim))
    for name, ds in passes:
        B, nd = blocks[name], len(ds)
        rows = [dirs.index(d) for d in ds]
        orders = [np.arange(V)[::-1] if d == SweepDirection.DOWN else np.arange(V) for d in ds]
        carry = np.broadcast_to(run.starts, (nd, S, dim)).copy()
        for bi, a in enumerate(range(0, V, B)):
            b = min(a + B, V)
            like = dict(points=((b - a, nd, S, R, dim), float), carry=((nd, S, dim), float))
            z = ck.block(f"{name}_{bi:05d}.npz", functools.partial(_compute_block, run, name, B, orders, a, b, carry),
                         like, collective=name == "independent")
            pts, carry = z["points"], z["carry"]
            for j in range(nd):
                points[rows[j], orders[j][a:b]] = pts[:, j]
            bar.update(nd * (b - a))
    bar.close()
    return points


def aperiodic_types(run: _Run, points: np.ndarray, period: np.ndarray, attractor: np.ndarray):
    """Type and largest Lyapunov exponent of the attractor every (direction, value, start)
    reached: ``attractor_type`` (an :class:`~jaxgear.AttractorType` value: periodic for a P-k lane,
    unknown for an escaped one), ``largest_exponent`` and ``exponent_error`` (per forcing
    period; NaN where not measured), each ``(D, V, S)``.

    Of each aperiodic attractor (the aperiodic starts of one direction and value, one
    group of :func:`group_starts`) the exponents of the stroboscopic map are computed
    from the last recorded point of its first start (:data:`LYAPUNOV_PERIODS` periods in
    :data:`LYAPUNOV_STRETCHES` weighted stretches, as
    :func:`~jaxgear.lyapunov_spectrum`; all of the diagram's aperiodic attractors, each at
    its own value, in one batch) and classified (:func:`~jaxgear.classify_attractor`:
    chaotic when the largest exponent is positive beyond its error, quasi-periodic when
    it is zero within it, also over :data:`LYAPUNOV_RECHECK` times as many periods).
    """
    kind = np.where(period > 0, int(AttractorType.PERIODIC), int(AttractorType.UNKNOWN)).astype(np.int64)
    lam, err = np.full(period.shape, np.nan), np.full(period.shape, np.nan)
    first = np.argmax(period == APERIODIC, axis=-1)  # the first aperiodic start of each (direction, value)
    dd, vv = np.nonzero(np.any(period == APERIODIC, axis=-1))
    if len(dd) == 0:
        return kind, lam, err
    ss = first[dd, vv]
    k = min(2, run.system.dim)

    def measure(i, x, periods, stretches):  # each lane at its own value
        est, final = values_exponent_estimates(run.system, run.params, run.names, run.values[vv[i]], x,
                                               n_exponents=k, periods=periods, stretches=stretches,
                                               integrator=run.integrator, chunk_size=run.options.chunk_size)
        return exponent_spectrum(run, vv[i], est, final, periods=periods)

    first_look = measure(np.arange(len(vv)), points[dd, vv, ss, -1], LYAPUNOV_PERIODS, LYAPUNOV_STRETCHES)
    types, exps, errs, _ = with_longer_look(first_look, measure)
    lam1, err1 = exps[:, 0], errs[:, 0]
    here = (period[dd, vv] == APERIODIC) & (attractor[dd, vv] == attractor[dd, vv, ss][:, None])  # (n, S)
    for i, (d, v) in enumerate(zip(dd, vv)):
        kind[d, v, here[i]] = types[i]
        lam[d, v, here[i]] = lam1[i]
        err[d, v, here[i]] = err1[i]
    return kind, lam, err


def exponent_spectrum(run: _Run, vv: np.ndarray, est: np.ndarray, final: np.ndarray,
                      periods: int = LYAPUNOV_PERIODS) -> LyapunovSpectrum:
    """The :class:`~jaxgear.LyapunovSpectrum` of stretch estimates ``est (n, stretches, k)``
    (each lane at the value ``run.values[vv]``) and their final states: the mean of the
    stretches and its standard error, NaN and ``DIVERGED`` where a lane became non-finite
    (as :func:`~jaxgear.lyapunov_spectrum`)."""
    ok = np.all(np.isfinite(est), axis=(1, 2)) & np.all(np.isfinite(final), axis=1)
    est = np.where(ok[:, None, None], est, np.nan)
    lam = est.mean(axis=1)
    err = est.std(axis=1, ddof=1) / np.sqrt(est.shape[1])
    T = np.asarray([float(run.system.period(apply_values(run.params, run.names, v)))
                    for v in run.values[vv]])[:, None]
    return LyapunovSpectrum(
        exponents=jnp.asarray(lam), per_time=jnp.asarray(lam / T), errors=jnp.asarray(err),
        errors_per_time=jnp.asarray(err / T), stretch_exponents=jnp.asarray(est),
        kaplan_yorke=kaplan_yorke(jnp.asarray(lam)), final_state=jnp.asarray(final),
        status=jnp.asarray(np.where(ok, int(Status.CONVERGED), int(Status.DIVERGED)), jnp.int32),
        periods=periods, transient=0, weighted=True)
