"""``jaxgear sweep``: how the motion changes with one parameter of the gear model.

``--kind bifurcation`` (default): stroboscopic points of several starts per value,
classified by period, swept up and down (hysteresis); ``--kind basins``: the global
analysis at every value with attractors matched across values (basin shares), or, with
``--param2``/``--values2``, at every point of a grid of two parameters (a basin map);
``--kind continuation``: one periodic orbit followed by pseudo-arclength continuation
with its Floquet multipliers. Writes the result file, ``summary.json`` and PNG figures
into ``--out``; an interrupted bifurcation or basin sweep started again with the same
command resumes where it stopped.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any, NamedTuple

from .._io import save_figure, write_json
from .._outdir import OutputFolder, check_output_folder
from ..sweep import Runner, SweepDirection
from .common import (
    ESCAPE_BOUND,
    add_param_options,
    add_system_option,
    cell_bytes,
    check_counts,
    check_options,
    check_point,
    check_pool_history,
    check_region,
    check_resume,
    check_work,
    escape_bound,
    int_arg,
    number,
    parse_counts,
    parse_point,
    parse_ranges,
    resolve_cli_system,
    shares_uncertainty_line,
    with_uncertainty_line,
)

KINDS = ("bifurcation", "basins", "continuation")

OWNED = ("bifurcation.nc", "basins.nc", "basin_map.nc", "branch.nc", "summary.json", "bifurcation.png",
         "bifurcation_x3.png", "shares.png", "regimes.png", "basin_map.png", "basin_map_shares.png", "branch.png")
"""Files ``jaxgear sweep`` writes into ``--out`` (replaced as a whole by the next run; the
resume state ``parts/`` and ``manifest.json`` is kept)."""

OPTIONS = (("starts", "--starts", int, 1), ("seed", "--seed", int, 0), ("period", "--period", int, 1),
           ("max_steps", "--max-steps", int, 1), ("transient", "--transient", int, 0),
           ("record", "--record", int, 2), ("steps_per_period", "--steps-per-period", int, 1),
           ("max_period", "--max-period", int, 1), ("uncertainty_samples", "--uncertainty-samples", int, 0))

SECTION_COUNTS = (20, 12, 24)
STROBOSCOPIC_COUNTS = (10, 6, 12, 6)


def _range(text: str, flag: str = "--values") -> tuple[float, float, int]:
    """``START:STOP:COUNT`` -> ``(START, STOP, COUNT)``, checked (``ValueError`` with the
    reason, naming the option ``flag``); no value is made yet."""
    import numpy as np

    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"{flag} expects START:STOP:COUNT (e.g. 3:7:41), got {text!r}.")
    try:
        start, stop = number(parts[0]), number(parts[1])
    except ValueError as exc:
        if "'_'" in str(exc):
            raise ValueError(f"{flag}={text}: {exc}") from None
        raise ValueError(f"{flag} expects numbers in START:STOP:COUNT, got {text!r}.") from None
    try:
        count = number(parts[2], int)
    except ValueError as exc:
        if "'_'" in str(exc):
            raise ValueError(f"{flag}={text}: {exc}") from None
        raise ValueError(f"{flag}: COUNT must be an integer, got {parts[2]!r} in {text!r}.") from None
    if not (np.isfinite(start) and np.isfinite(stop)):
        raise ValueError(f"{flag}: START and STOP must be finite, got {text!r}.")
    if count < 2:
        raise ValueError(f"{flag}: COUNT must be >= 2 (got {count}); a sweep needs at least two values.")
    if start == stop:
        raise ValueError(f"{flag}: the range {start:g}:{stop:g} is empty (START = STOP).")
    check_work(flag, text, count, 8 * 8, "values")  # the values and their per-value results, at the least
    return start, stop, count


def add_parser(sub) -> None:
    from ..analysis import DEFAULT_METHOD, METHODS
    from ..integrate import DEFAULT_STEPS_PER_PERIOD

    p = sub.add_parser(
        "sweep", help="parameter sweeps: bifurcation diagrams, basin shares, orbit continuation",
        description="Sweep one parameter of the reduced gear model (any canonical name: b_sp, kappa_sp_amp, "
        "Omega, c_sp, f_D, e_sp_amp, ...; or b = b_sp and b_rp, kappa_amp = both stiffness amplitudes, "
        "e_amp = both error amplitudes; or a field of the preset's physical gear set in its units, see jaxgear "
        "params: k_sp_amp [N/m], input_rpm, T_D [N m], ..., and gear.NAME for the names both share, e.g. "
        "gear.b_sp [um], gear.b = both half backlashes), or, with --kind basins and --param2, two (a basin map). "
        "Writes the "
        "result (bifurcation.nc, basins.nc, basin_map.nc or branch.nc), "
        "summary.json and figures into --out. Run the same command again after an interruption to resume.",
    )
    add_param_options(p)
    add_system_option(p)
    p.add_argument("--param", required=True, metavar="NAME",
                   help="the parameter to sweep: a dimensionless name, or a physical gear-set field in its units "
                   "(a name only the gear set has, such as input_rpm, k_sp_amp, T_D, or gear.NAME for any: "
                   "gear.b_sp, gear.b, gear.Omega); with --system a field of the system's parameters")
    p.add_argument("--values", required=True, metavar="START:STOP:COUNT",
                   help="COUNT evenly spaced values from START to STOP (COUNT >= 2), in the parameter's units")
    p.add_argument("--param2", default=None, metavar="NAME",
                   help="basins: a second parameter; the global analysis then runs at every point of the grid "
                   "--values2 x --values (a basin map, basin_map.nc)")
    p.add_argument("--values2", default=None, metavar="START:STOP:COUNT", help="the values of --param2")
    p.add_argument("--kind", default="bifurcation", choices=KINDS, help="what to compute (default bifurcation)")
    p.add_argument("--direction", default=SweepDirection.ALL.value, choices=[d.value for d in SweepDirection],
                   help="bifurcation: independent (every value from the starts: all coexisting attractors the "
                   "starts reach), up/down (state carried from value to value: a branch is followed until it "
                   "vanishes), both (up and down: hysteresis shows where they differ), all (default: the three)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--starts", type=int_arg, default=None, metavar="N",
                     help="bifurcation: N random starts in the paper's region D on x4 = 0 (jaxgear.seeds_in_box over x1, x2, x3 with --seed; default 16)")
    src.add_argument("--from", dest="points", type=parse_point, action="append", metavar="x1,x2,x3,x4",
                     help="a start (repeatable; continuation: the point on or near the orbit to follow)")
    p.add_argument("--seed", type=int_arg, default=0, help="random seed of --starts (default 0)")
    p.add_argument("--grid", type=parse_counts, default=None, metavar="N1,N2,N3[,N4]",
                   help="basins: cells over x1, x2, x3 on x4 = 0 (default 20,12,24); with --method "
                   "stroboscopic over x1..x4 (default 10,6,12,6)")
    p.add_argument("--region", type=parse_ranges, default=None, metavar="LO:HI,...",
                   help="basins: box over x1, x2, x3 (default the paper's D: -25:25,-10:20,-10:50; "
                   "--method stroboscopic adds x4 in -12:12); bifurcation: the box of the random starts")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=tuple(METHODS),
                   help=f"basins: the global-analysis method (default {DEFAULT_METHOD})")
    p.add_argument("--period", type=int_arg, default=1, metavar="K", help="continuation: period of the orbit (default 1)")
    p.add_argument("--max-steps", type=int_arg, default=500, help="continuation: step limit (default 500)")
    p.add_argument("--transient", type=int_arg, default=400, help="bifurcation: periods dropped per value (default 400)")
    p.add_argument("--record", type=int_arg, default=64,
                   help="bifurcation: stroboscopic points kept (default 64; at least 2 --max-period + 1)")
    p.add_argument("--steps-per-period", type=int_arg, default=None, metavar="N",
                   help=f"fixed steps per forcing period (default {DEFAULT_STEPS_PER_PERIOD})")
    p.add_argument("--max-period", type=int_arg, default=16, help="largest period P-k detected (default 16)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (also holds the resume parts)")
    p.add_argument("--restart", action="store_true", help="discard a previous sweep of other settings in --out")
    p.add_argument("--uncertainty-samples", type=int_arg, default=None, metavar="N",
                   help="basins: cells sampled at each value for its label uncertainty (default 1024; 0 skips it, "
                   "which on a small grid saves much of the time): the share whose label changes with a refined "
                   "step, and with the start moved by 1e-3 cell")
    p.add_argument("--one-pool", action="store_true",
                   help="basins, direct method: run the values in one lane pool over (value, cell) pairs instead of "
                   "one analysis after another (the same attractors and, but for the odd boundary cell, labels; a killed sweep "
                   "loses the values of the pool)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--distributed", action="store_true",
                   help="basins, bifurcation: run as one process of a multi-process JAX program "
                   "(jax.distributed.initialize: detects Slurm and Open MPI, or reads JAX_COORDINATOR_ADDRESS, "
                   "JAX_NUM_PROCESSES, JAX_PROCESS_ID); every process takes a share of the values, process 0 "
                   "writes --out")
    p.set_defaults(func=run)


class _Plan(NamedTuple):
    """A checked ``jaxgear sweep`` command: the system (``user`` for ``--system``, else None),
    its parameters, the range of ``--values`` and the values (``values2`` of ``--values2``),
    the integrator, and for ``--kind basins`` the grid and the method."""

    user: Any
    system: Any
    params: Any
    start: float
    stop: float
    count: int
    values: Any
    values2: Any
    integ: Any
    grid: Any = None
    method: Any = None
    param: str = ""
    param2: str | None = None
    gear_set: Any = None


def run(args) -> int:
    if args.distributed:  # before any JAX computation
        from .._devices import initialize

        if args.kind not in ("basins", "bifurcation"):
            raise ValueError("--distributed runs --kind basins and bifurcation (continuation runs in one process).")
        initialize()
    plan = _plan(args)  # every option is checked before any integration and before --out is touched
    if args.kind != "continuation" and not args.restart:  # a sweep of other settings in --out: refused now
        check_resume(args.out, _resume_settings(args, plan))
    head = _head(args, plan)
    # the sweep resumes from and saves its parts in --out; this command writes the result with its summary and figures
    runner = Runner(out=Path(args.out), restart=args.restart, progress=not args.quiet, save=False)
    if args.distributed:
        from .._devices import process_index

        if process_index() != 0:  # its share of the values (exchanged, or parts in --out); process 0 writes
            _share(args, plan, dataclasses.replace(runner, progress=False))
            return 0
    if args.kind != "continuation":  # Ctrl-C: the boundary of the command line says what a rerun resumes from
        args.interrupt_note = lambda: _resume_note(args, plan)
    with OutputFolder(args.out, OWNED, create=True) as work:
        t0 = time.perf_counter()
        if args.kind == "continuation":
            files = _continuation(args, plan, work, head)
        else:
            files = _sweep(args, plan, work, head, t0, runner)
    print(f"\nwrote {', '.join(files)} to {args.out}/")
    return 0


def _resume_note(args, plan: _Plan) -> str:
    """What an interrupted bifurcation or basin sweep keeps: ``the sweep resumes from N of
    M values`` (the values, or for a bifurcation sweep the (direction, value) pairs, saved
    in ``--out/parts`` with these settings)."""
    import numpy as np

    from ..sweep._checkpoint import saved_parts

    done = 0
    for part in saved_parts(args.out):
        if part.suffix == ".npz":  # a block of a bifurcation pass: points (values, directions, ...)
            try:
                with np.load(part) as z:
                    shape = z["points"].shape
                done += int(shape[0]) * int(shape[1])
            except Exception:  # unreadable: computed again
                continue
        else:
            done += 1
    total = plan.count * (1 if plan.values2 is None else len(plan.values2))
    if args.kind == "bifurcation":
        total *= len(SweepDirection(args.direction).sweeps)
    return (f"the sweep resumes from {done} of {total} values (run the same command again)" if done
            else "no value was finished; the previous result is unchanged")


def _plan(args) -> _Plan:
    """Every option checked (before any integration and before ``--out`` is touched) and
    the sweep it asks for."""
    import numpy as np

    from .._model import REDUCED
    from ..integrate import default_integrator

    start, stop, count = _range(args.values)
    check_options(args, OPTIONS)
    user = resolve_cli_system(args)
    system = REDUCED if user is None else user.system
    count2 = _check_flags(args, user, system, start, stop)
    grid = _user_grid(args, user) if user is not None and args.kind == "basins" else None
    _check_work(args, user, system, grid, count, count2)
    values = np.linspace(start, stop, count)
    values2 = None if args.values2 is None else np.linspace(*_range(args.values2, "--values2"))
    check_output_folder(args.out)
    params = _cli_params(args, user)
    param, param2, gear_set = _names(args, user, params)  # unknown name -> the list of valid ones
    plan = _Plan(user, system, params, start, stop, count, values, values2, default_integrator(args.steps_per_period),
                 grid, param=param, param2=param2, gear_set=gear_set)
    return _check_values(args, plan)


PHYSICAL_PREFIX = "gear."
"""``--param gear.NAME``: the gear set's physical field NAME (needed for the names the
physical and the dimensionless tables share: ``b_sp``, ``e_sp_amp``, ``Omega``, ...)."""


def _names(args, user, params) -> tuple[str, str | None, Any]:
    """``--param`` and ``--param2`` as the sweep functions take them, and the gear set when
    they are physical (:func:`jaxgear.sweep.sweep_axis`): a dimensionless name (or alias)
    of ``params``; a field only the gear set has (``input_rpm``, ``k_sp_amp``, ``T_D``); or
    ``gear.NAME`` for any gear-set field. ``ValueError`` listing the valid names, for a
    physical name with ``--system`` or next to a dimensionless one, and for a physical
    sweep of a field that a dimensionless ``--set`` overrides."""
    from .._params import param_names
    from .._presets import resolve_params
    from ..sweep import physical_names

    given = [n for n in (args.param, args.param2) if n is not None]
    kinds = []
    for n in given:
        physical_only = user is None and n not in param_names(params) and n in physical_names()
        if n.startswith(PHYSICAL_PREFIX) or physical_only:  # a user system's unknown name is just unknown
            if user is not None:
                raise ValueError(f"--param {n}: physical gear-set names need the gear model (no --system {user.spec}).")
            name = n.removeprefix(PHYSICAL_PREFIX)
            if name not in physical_names():
                raise ValueError(f"unknown gear-set parameter {name!r}; physical names (gear.NAME): "
                                 f"{', '.join(physical_names())}.")
            kinds.append((name, True))
        elif n in param_names(params):
            kinds.append((n, False))
        else:
            extra = "" if user is not None else f"; physical gear-set names: {', '.join(physical_names())}"
            raise ValueError(f"unknown parameter {n!r}; valid names: dimensionless {', '.join(param_names(params))}"
                             f"{extra}.")
    if len({k for _, k in kinds}) > 1:
        raise ValueError(f"--param {args.param} and --param2 {args.param2}: give both in physical units (gear.NAME) "
                         "or both dimensionless.")
    names = [k for k, _ in kinds] + [None]
    if not kinds[0][1]:
        return names[0], names[1], None
    gear_set, _ = resolve_params(args.preset, args.overrides)
    return names[0], names[1], gear_set


def _axes(args, plan: _Plan):
    """The parameter(s) as the sweep functions apply them: ``(axes, names, rows)`` (the
    :class:`~jaxgear.sweep.SweepAxis` of ``--param`` and of ``--param2``, the fields set and
    one row of values per value or map point); ``ValueError`` where a dimensionless ``--set``
    overrides a field the physical sweep sets."""
    import numpy as np

    from ..sweep import sweep_axis
    from ..sweep._physical import joint_rows

    axes = [sweep_axis(plan.params, plan.param, plan.values, plan.gear_set)]
    if plan.values2 is not None:
        axes.append(sweep_axis(plan.params, plan.param2, plan.values2, plan.gear_set))
        if set(axes[0].fields) & set(axes[1].fields):
            raise ValueError(f"--param {args.param} and --param2 {args.param2} set the same field.")
    if plan.gear_set is not None:
        base = plan.gear_set.to_params().uniform()
        for ax in axes:
            kept = [f for f in ax.fields if not np.array_equal(np.asarray(getattr(base, f)),
                                                               np.asarray(getattr(plan.params, f)))]
            if kept:
                raise ValueError(f"--param {ax.name} sets {', '.join(kept)}, which --set overrides: give each "
                                 "parameter once.")
    if len(axes) == 1:
        return axes, *axes[0].applied()
    VV = np.stack(np.meshgrid(axes[0].values, axes[1].values), axis=-1).reshape(-1, 2)
    if plan.gear_set is not None:
        return axes, axes[0].fields + axes[1].fields, joint_rows(plan.gear_set, tuple(axes), VV)
    return axes, (plan.param, plan.param2), VV


def _check_flags(args, user, system, start: float, stop: float) -> int | None:
    """The options that must go together or not at all; the count of ``--values2`` (None without it)."""
    if args.kind != "continuation" and start > stop:
        raise ValueError(f"--values={args.values}: START must be < STOP for --kind {args.kind} (the values are "
                         "swept up and down by --direction); only --kind continuation runs from START to STOP.")
    if (args.param2 is None) != (args.values2 is None):
        raise ValueError("--param2 NAME and --values2 START:STOP:COUNT go together (a basin map over two "
                         "parameters).")
    count2 = None
    if args.param2 is not None:
        if args.kind != "basins":
            raise ValueError(f"--param2 makes a basin map: it needs --kind basins (got --kind {args.kind}).")
        start2, stop2, count2 = _range(args.values2, "--values2")
        if start2 > stop2:
            raise ValueError(f"--values2={args.values2}: START must be < STOP.")
    if args.uncertainty_samples is not None and args.kind != "basins":
        raise ValueError(f"--uncertainty-samples measures the label uncertainty of a basin sweep: it needs --kind "
                         f"basins (got --kind {args.kind}).")
    for pt in args.points or ():
        check_point(pt, "--from", system.dim)
    return count2


def _check_work(args, user, system, grid, count: int, count2: int | None) -> None:
    """The starts' box of a bifurcation sweep, and the memory the sweep keeps."""
    from .._model import REDUCED

    if args.kind == "bifurcation" and args.region is not None:
        if user is None:
            check_region(args.region, "--region (the box of the starts)", 3, REDUCED.state_names[:3], ESCAPE_BOUND)
        else:
            _user_starts_box(args, user)
    if args.kind == "bifurcation":
        _check_bifurcation_work(args, count, system.dim)
    elif args.kind == "continuation":
        per_step = 8 * system.dim * (args.period + 4) * 4  # points of the orbit, multipliers, tangent
        check_work("--max-steps", args.max_steps, args.max_steps, per_step, "continuation steps")
    else:  # the grid as given or the method's default (checked against the method below)
        counts = (grid.counts if user is not None else args.grid
                  or (STROBOSCOPIC_COUNTS if args.method == "stroboscopic" else SECTION_COUNTS))
        _check_basins_work(args, counts, count * (1 if count2 is None else count2), system.dim)


def _cli_params(args, user):
    """The parameters: the ``--system`` object's, or the preset with ``--set`` (identical planets)."""
    from .._presets import resolve_params

    if user is not None:
        return user.params
    _, params = resolve_params(args.preset, args.overrides)
    if not params.is_uniform:
        raise ValueError("sweep uses the reduced 2-DOF model, which needs identical planets; "
                         "the given parameters differ per planet.")
    return params.uniform()


def _check_values(args, plan: _Plan) -> _Plan:
    """The values of the parameter(s) checked for the kind of sweep; for ``--kind basins``
    the plan with its grid and method."""
    import numpy as np

    from .._checks import check_int
    from ..sweep import check_values

    system, params = plan.system, plan.params
    if args.kind == "continuation":
        if not args.points or len(args.points) != 1:
            raise ValueError("--kind continuation needs one --from x1,x2,x3,x4: a point on or near the P-K orbit "
                             "at the start value (e.g. from jaxgear shoot).")
        if plan.gear_set is not None:
            from ..sweep import sweep_axis

            fields = sweep_axis(params, plan.param, [plan.start, plan.stop], plan.gear_set).fields
            raise ValueError(f"--kind continuation follows one dimensionless parameter; {args.param} sets "
                             f"{', '.join(fields)}: continue in {fields[0]} (jaxgear params shows the conversion).")
        check_values(system, params, (plan.param,), np.array([[plan.start], [plan.stop]]))
        return plan
    if args.kind == "bifurcation":
        check_int(args.record, "--record", 2 * args.max_period + 1)
        _, names, rows = _axes(args, plan)
        check_values(system, params, names, rows)
        return plan
    grid, method = _basins_grid(args, plan)
    if hasattr(method, "round_periods"):  # the direct method's lane pool (analyze checks the same)
        check_pool_history("--max-period", int(method.max_period), min(int(method.chunk_size), grid.n_cells),
                           system.dim)
    method.check(system, grid)
    _, names, rows = _axes(args, plan)
    check_values(system, params, names, rows)
    return plan._replace(grid=grid, method=method)


def _basins_grid(args, plan: _Plan):
    """``--kind basins``: the grid (the ``--system`` one, or ``--region``/``--grid`` over the
    method's default) and the method with ``--max-period`` and the integrator."""
    from .._cells import CellGrid
    from .._model import REDUCED
    from ..analysis import method_from_name

    method = method_from_name(args.method, integrator=plan.integ, max_period=args.max_period)
    if plan.user is not None:
        grid = plan.grid
        names = grid.axis_names
        check_region(tuple(zip(grid.lower, grid.upper)), "--region", len(names), names, escape_bound(method))
        check_counts(grid.counts, "--grid")
        return grid, method
    default = method.default_grid(REDUCED)
    names = default.axis_names
    where = f"(--method {args.method} grids {', '.join(names)})"
    region = args.region or tuple(zip(default.lower, default.upper))
    counts = args.grid or (STROBOSCOPIC_COUNTS if len(names) == 4 else SECTION_COUNTS)
    check_region(region, f"--region {where}", len(names), names, escape_bound(method),
                 [b for i, b in enumerate(default.base) if i not in default.axes])
    check_counts(counts, f"--grid {where}", len(names), names)
    return CellGrid.box(region, counts, axes=default.axes, base=default.base, names=REDUCED.state_names), method


def _head(args, plan: _Plan) -> str:
    """The first line the command prints."""
    from .._model import REDUCED

    axes = _axes(args, plan)[0] if args.kind != "continuation" else []

    def span(name, lo, hi, count, i):
        if i >= len(axes) or not axes[i].physical:
            return f"{name} = {lo:g} .. {hi:g} ({count} values)"
        ax = axes[i]  # physical: the unit, and the dimensionless fields it sets
        dims = ", ".join(f"{f} = {ax.rows[0, j]:.4g} .. {ax.rows[-1, j]:.4g}" for j, f in enumerate(ax.fields))
        return f"{name} = {lo:g} .. {hi:g} {ax.unit} ({count} values; {dims})"

    head = f"jaxgear sweep: {args.kind} in " + span(plan.param, plan.start, plan.stop, plan.count, 0)
    if plan.values2 is not None:
        v2 = plan.values2
        head += " x " + span(plan.param2, v2[0], v2[-1], len(v2), 1)
    return head + (f", preset {args.preset}, {REDUCED.name} model" if plan.user is None
                   else f", system {plan.user.spec} ({plan.system.name})")


def _sequence_options(args):
    """The :class:`~jaxgear.SequenceOptions` of ``--transient``, ``--record`` and ``--max-period``."""
    from ..sweep import SequenceOptions

    return SequenceOptions(transient=args.transient, record=args.record, max_period=args.max_period)


def _diagram(args, plan: _Plan, runner: Runner):
    """The bifurcation diagram, resumable in ``--out`` by ``runner`` (the result file is
    written by the caller)."""
    from ..sweep import bifurcation_diagram

    return bifurcation_diagram(plan.system, plan.params, plan.param, plan.values, _starts(args, plan.user),
                               direction=args.direction, integrator=plan.integ, options=_sequence_options(args),
                               runner=runner, gear_set=plan.gear_set)


def _share(args, plan: _Plan, runner: Runner) -> None:
    """A process other than 0 of a ``--distributed`` sweep: its share of the values."""
    (_basins if args.kind == "basins" else _diagram)(args, plan, runner)


def _user_grid(args, user):
    """``--system`` basin sweep: the cells of the user's region (or ``--region``)."""
    from ._system_spec import user_grid

    return user_grid(user, args.region, args.grid, args.method)


def _user_starts_box(args, user):
    """``--system`` bifurcation: the box of the random starts (``--region`` or the
    object's region, over every coordinate or every one but the section coordinate) and
    its coordinates; ``ValueError`` where there is none."""
    from ._system_spec import axes_of

    region = args.region or user.region
    if region is None:
        raise ValueError(f"--system {user.spec}: --kind bifurcation needs starts: give --from x1,..., or a box "
                         "for --starts N: --region LO:HI,... or REGION in the module (region in the object).")
    axes, _ = axes_of(user.system, len(region), "--region (the box of the starts)")
    names = [user.system.state_names[i] for i in axes]
    check_region(region, "--region (the box of the starts)", len(axes), names, ESCAPE_BOUND)
    return region, axes


def _check_bifurcation_work(args, count: int, dim: int = 4) -> None:
    """The points a bifurcation sweep keeps (values x starts x record x directions) fit in
    memory (``dim`` coordinates per point)."""
    n_dirs = len(SweepDirection(args.direction).sweeps)
    starts = len(args.points) if args.points else (16 if args.starts is None else args.starts)
    point = 8 * dim * n_dirs  # one recorded point of one start at one value, every direction
    flag, value = ("--from", f"{starts} points") if args.points else ("--starts", starts)
    checks = {  # option: (its count over a typical one, the check with the others as given)
        "--values": (count / 41, lambda: check_work(
            "--values", args.values, count, point * starts * args.record,
            f"values ({starts:,} starts x {args.record:,} recorded points x {n_dirs} direction(s))")),
        flag: (starts / 16, lambda: check_work(flag, value, starts, point * count * args.record,
                                               f"starts ({count:,} values x {args.record:,} recorded points)")),
        "--record": (args.record / 64, lambda: check_work(
            "--record", args.record, args.record, point * count * starts,
            f"recorded points ({count:,} values x {starts:,} starts)")),
    }
    for _, check in sorted(checks.values(), key=lambda c: -c[0]):  # the most unusual count is named
        check()


def _check_basins_work(args, counts, n_values: int, dim: int = 4) -> None:
    """The cells of one analysis, and the labels kept for every value (every cell of every
    value at once with --one-pool), fit in memory (``dim`` state coordinates)."""
    import math

    n_cells = math.prod(counts)
    check_work("--grid", ",".join(map(str, counts)), n_cells, cell_bytes(dim), "cells per value")
    per_value = n_cells * (cell_bytes(dim) if args.one_pool else 16)
    flag, text = ("--values2", args.values2) if args.values2 is not None else ("--values", args.values)
    check_work(flag, text, n_values, per_value, f"values of {n_cells:,} cells"
               + (" in one pool" if args.one_pool else "") + (" (both parameters)" if args.values2 else ""))


def _resume_settings(args, plan: _Plan) -> dict:
    """The settings of the sweep this command would resume that the command line decides
    alone (as the sweep functions record them in the manifest of --out), for
    :func:`~jaxgear.cli.common.check_resume`; the sweep functions compare every setting
    again when they open the folder."""
    from .._params import params_to_dict
    from ..sweep._basins import uncertainty_setting

    s = {"system": plan.system.name, "params": params_to_dict(plan.params)}
    values, values2 = plan.values, plan.values2
    if plan.gear_set is not None:  # as the sweep functions record a physical sweep
        axes = _axes(args, plan)[0]
        s["physical"] = axes[0].unit if len(axes) == 1 else [ax.unit for ax in axes]
    if args.kind == "bifurcation":
        s.update(kind="bifurcation", param=plan.param, values=values.tolist(),
                 starts=_starts(args, plan.user).tolist(), transient=int(args.transient), record=int(args.record),
                 direction=args.direction, max_period=int(args.max_period), integrator=plan.integ.to_dict())
        return s
    s.update(grid=plan.grid.to_dict(), method=plan.method.to_dict())
    if args.uncertainty_samples is not None:
        s.update(uncertainty_setting(args.uncertainty_samples))
    if values2 is None:
        s.update(kind="basins", param=plan.param, values=values.tolist())
    else:
        s.update(kind="basin_map", param_x=plan.param, values_x=values.tolist(), param_y=plan.param2,
                 values_y=values2.tolist())
    return s


def _starts(args, user=None):
    """The starts of a bifurcation sweep: ``--from`` points, or ``--starts`` seeded points of
    the region on the section x4 = 0 (the same on every process); with ``--system`` (``user``)
    seeded points of its box, over every coordinate or on its section."""
    import numpy as np

    from .._cells import PAPER_REGION
    from ..shooting import seeds_in_box

    if args.points:
        return np.asarray(args.points, dtype=float)
    n = 16 if args.starts is None else args.starts
    if user is not None:
        region, axes = _user_starts_box(args, user)
        region = np.asarray(region, dtype=float)
        X0 = np.zeros((n, user.system.dim))  # the coordinate left out (the section's) is 0
        X0[:, list(axes)] = seeds_in_box(n, region[:, 0], region[:, 1], seed=args.seed)
        return X0
    region = np.asarray(args.region or PAPER_REGION, dtype=float)
    X0 = np.zeros((n, 4))  # on the section x4 = 0, like the paper's cells
    X0[:, :3] = seeds_in_box(n, region[:, 0], region[:, 1], seed=args.seed)
    return X0


def _basins(args, plan: _Plan, runner: Runner):
    """The basin sweep over ``--param`` (no ``--values2``) or the basin map over ``--param``
    x ``--param2``, resumable in ``--out`` by ``runner`` (the result file is written by the
    caller)."""
    from ..sweep import BasinOptions, basin_map, basin_sweep

    samples = {} if args.uncertainty_samples is None else {"uncertainty": args.uncertainty_samples}
    opts = BasinOptions(batched=args.one_pool, **samples)
    kw = dict(method=plan.method, options=opts, runner=runner, gear_set=plan.gear_set)
    if plan.values2 is None:
        return basin_sweep(plan.system, plan.params, plan.param, plan.values, plan.grid, **kw)
    return basin_map(plan.system, plan.params, plan.param, plan.values, plan.param2, plan.values2, plan.grid, **kw)


def _sweep(args, plan: _Plan, work: Path, head: str, t0: float, runner: Runner) -> list[str]:
    """A bifurcation or basin sweep (or map) of the gear model or of the ``--system``:
    resume parts in ``--out`` (``runner``), its files into ``work``."""
    if args.kind == "bifurcation":
        print(head + f", {len(_starts(args, plan.user))} starts, direction {args.direction}")
        result = _diagram(args, plan, runner)
        print(f"done in {time.perf_counter() - t0:.1f} s\n")
        name, figs, extra = "bifurcation.nc", _report_diagram(args, plan, result), {}
    else:
        print(head + f", {args.method} on {plan.grid.n_cells} cells per value")
        result = _basins(args, plan, runner)
        print(f"done in {time.perf_counter() - t0:.1f} s\n")
        name, figs, extra = _report_basins(args, plan, result)
    result.save(work / name)
    summary = {**result.summary(), **extra}
    summary["runtime_s"] = time.perf_counter() - t0  # in summary.json only, never in the result file
    write_json(summary, work / "summary.json", indent=1)
    for fname, fig in figs.items():
        save_figure(fig, work / fname, dpi=120)
    return [name, "summary.json"] + list(figs)


def _report_diagram(args, plan: _Plan, result) -> dict:
    """Print the diagram's table and hysteresis; its figures ``{file name: figure}``."""
    print(result.table())
    if SweepDirection.UP in result.directions and SweepDirection.DOWN in result.directions:
        diff = result.values[result.differs(SweepDirection.UP, SweepDirection.DOWN)]
        print(f"\nup and down sweeps differ (hysteresis) at {result.axis_label} = "
              + (", ".join(f"{v:.5g}" for v in diff) if len(diff) else "none of the values"))
    if args.no_figures:
        return {}
    from ..plotting import plot_bifurcation

    if plan.user is None:
        return {"bifurcation.png": plot_bifurcation(result, "x1"), "bifurcation_x3.png": plot_bifurcation(result, "x3")}
    return {"bifurcation.png": plot_bifurcation(result, plan.system.state_names[0])}  # the system's first coordinate


def _report_basins(args, plan: _Plan, result) -> tuple[str, dict, dict]:
    """Print the basin sweep's (or map's) tables; its file name, figures and what the
    summary adds (the contact regimes' shares)."""
    if plan.values2 is not None:
        print(with_uncertainty_line(result.table(), result, "points"))
        regimes = _regimes(plan, result)
        extra = {} if regimes is None else {"contact_regimes": regimes.summary()}
        if args.no_figures:
            return "basin_map.nc", {}, extra
        from ..plotting import plot_basin_map, plot_regime_map

        figs = {"basin_map.png": plot_basin_map(result), "basin_map_shares.png": plot_basin_map(result, "all")}
        if regimes is not None:
            figs["regimes.png"] = plot_regime_map(regimes)
        return "basin_map.nc", figs, extra
    print(result.shares_table())
    print()
    print(with_uncertainty_line(result.table(), result))
    if shares_uncertainty_line(result):
        print(shares_uncertainty_line(result))
    regimes = _regimes(plan, result)
    extra = {} if regimes is None else {"contact_regimes": regimes.summary()}
    if args.no_figures:
        return "basins.nc", {}, extra
    from ..plotting import plot_basin_shares, plot_regime_shares

    figs = {"shares.png": plot_basin_shares(result)}
    if regimes is not None:
        figs["regimes.png"] = plot_regime_shares(regimes)
    return "basins.nc", figs, extra


def _regimes(plan: _Plan, result):
    """Print the share of the cells in each contact regime per mesh and value, or over the
    points of a map (:func:`jaxgear.regime_shares`); ``None`` (nothing printed) for a
    system without meshes."""
    from .._contact import regime_shares

    if plan.system.switching is None:
        return None
    try:
        regimes = regime_shares(result, plan.system, plan.params)
    except ValueError as exc:  # a user system whose switching functions are not meshes
        print(f"\ncontact regimes not shown: {exc}")
        return None
    print("\nshare of the cells in each contact regime (jaxgear.regime_shares):")
    print(regimes.table())
    return regimes


def _continuation(args, plan: _Plan, out: Path, head: str) -> list[str]:
    """The branch of the ``--from`` orbit from START to STOP (the step: the spacing of
    ``--values``), its table, file, summary and figure."""
    import numpy as np

    from .._params import params_to_dict, with_param
    from ..continuation import ContinuationOptions, continue_orbit

    x0 = np.asarray(args.points[0], dtype=float)
    start, stop, params = plan.start, plan.stop, plan.params
    p0 = with_param(params, plan.param, start)
    ds = abs(stop - start) / (plan.count - 1)
    print(head + f", P-{args.period} orbit from {x0.tolist()}, step {ds:g}")
    t0 = time.perf_counter()
    branch = continue_orbit(plan.system, p0, x0, param=plan.param, stop=stop, period=args.period,
                            integrator=plan.integ, options=ContinuationOptions(ds=ds, max_steps=args.max_steps),
                            progress=not args.quiet)
    print(f"done in {time.perf_counter() - t0:.1f} s\n")
    table = branch.table()
    print(table)
    branch.save(out / "branch.nc")
    summary = dict(kind="continuation", param=plan.param, start=start, stop=stop, ds=ds, period=args.period,
                   seed_point=x0.tolist(), params=params_to_dict(params), table=table,
                   runtime_s=time.perf_counter() - t0)
    if hasattr(branch, "summary"):
        summary["branch"] = branch.summary()
    write_json(summary, out / "summary.json", indent=1)
    files = ["branch.nc", "summary.json"]
    if not args.no_figures:
        from ..plotting import plot_branch

        save_figure(plot_branch(branch), out / "branch.png", dpi=120)
        files.append("branch.png")
    return files
