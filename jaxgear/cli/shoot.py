"""``jaxgear shoot``: periodic orbits of the gear model by shooting, with Floquet multipliers.

The paper's local method (§4.1): a Newton-type solve of ``P^k(x) - x = 0`` for the
stroboscopic map of the reduced 2-DOF model, from user points (``--from``), from a
cell-mapping result (``--seeds-from``) or from random points of a box (``--random``).
``--period K`` and ``--periods K1-K2`` run the same search
(:func:`~jaxgear.find_periodic_orbits`) with the same options. Prints each distinct
orbit: its points, minimal period, Floquet multipliers, stability, kind of instability
and the paper's check by direct integration (``--verify``); ``--json`` prints one JSON
object (with the full parameter set);
``--out DIR`` writes ``orbits.nc`` (open with ``jaxgear.load`` or xarray),
``orbits.json`` (the ``--json`` object) and figures (``orbit_N.png``, ``multipliers.png``).
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np

from .._io import save_figure, write_json
from .._outdir import OutputFolder, check_output_folder
from .common import (
    INT_MAX,
    SHOT_BYTES,
    add_param_options,
    add_system_option,
    check_options,
    check_point,
    check_region,
    check_shoot_work,
    check_work,
    float_arg,
    int_arg,
    number,
    parse_point,
    parse_ranges,
    resolve_cli_system,
)

# The paper's region D (x1, x2, x3) with x4 in [-5, 5].
DEFAULT_REGION = ((-25.0, 25.0), (-10.0, 20.0), (-10.0, 50.0), (-5.0, 5.0))

OWNED = ("orbits.nc", "orbits.json", "orbit_*.png", "multipliers.png")
"""Files ``jaxgear shoot --out`` writes (replaced as a whole by the next run)."""

OPTIONS = (("random", "--random", int, 1), ("steps_per_period", "--steps-per-period", int, 1),
           ("tol", "--tol", float, 0.0), ("max_iter", "--max-iter", int, 1), ("verify", "--verify", int, 1),
           ("seed", "--seed", int, 0), ("segments", "--segments", int, 1),
           ("deflation_rounds", "--deflation-rounds", int, 0), ("transient", "--transient", int, 0))


def add_parser(sub) -> None:
    from ..integrate import DEFAULT_STEPS_PER_PERIOD

    p = sub.add_parser(
        "shoot", help="periodic orbits by shooting: points, minimal period, Floquet multipliers, stability",
        description="Shooting method (paper §4.1): Levenberg-Marquardt (optimistix) on P^k(x) - x = 0 for the "
        "stroboscopic map of the reduced 2-DOF gear model (state x1..x4 at forcing phase 0), Jacobian by automatic "
        "differentiation through the kink-aware RK4 integrator. Prints every distinct orbit found, its minimal period, "
        "Floquet multipliers, stability and how an unstable orbit is unstable (fold: real multiplier > 1; "
        "flip: real multiplier < -1; neimark-sacker: complex pair outside the unit circle).",
    )
    add_param_options(p)
    add_system_option(p)
    src = p.add_mutually_exclusive_group(required=False)
    src.add_argument("--from", dest="points", type=parse_point, action="append", metavar="x1,x2,x3,x4",
                     help="a seed point (repeatable)")
    src.add_argument("--seeds-from", metavar="RESULT",
                     help="a saved global-analysis result (jaxgear analyze): every point of each P-k attractor "
                     "seeds a P-k orbit; the result's own parameters are used (--set overrides canonical names)")
    p.add_argument("--random", type=int_arg, metavar="N",
                   help="N random seeds in --region (with --periods, also together with --seeds-from)")
    p.add_argument("--region", type=parse_ranges, default=None, metavar="LO:HI,...",
                   help="box for --random, one LO:HI per coordinate (default the paper's D with x4 in [-5,5]: "
                   "-25:25,-10:20,-10:50,-5:5)")
    p.add_argument("--seed", type=int_arg, default=0, help="random seed for --random (default 0)")
    p.add_argument("--period", type=int_arg, action="append", metavar="K",
                   help="shoot for P-K orbits (fixed points of P^K); repeatable (default 1, or the attractors' "
                   "periods with --seeds-from)")
    p.add_argument("--periods", type=_parse_periods, default=None, metavar="K1-K2",
                   help="search every period in K1..K2 (e.g. 1-8): the search of --period for each K; seeds from "
                   "--random, plus the attractors of --seeds-from")
    p.add_argument("--solver", default=None, choices=tuple(SOLVERS),
                   help="nonlinear solver, an optimistix one (default: the library's choice, levenberg-marquardt)")
    p.add_argument("--segments", type=int_arg, default=None, metavar="M",
                   help="multiple shooting with M segments per orbit (default 1)")
    p.add_argument("--deflation-rounds", type=int_arg, default=None, metavar="R",
                   help="deflated rounds after the plain one (default 0)")
    p.add_argument("--transient", type=int_arg, default=None, metavar="PERIODS",
                   help=f"map each seed PERIODS forcing periods forward before shooting (default {RANDOM_TRANSIENT} "
                   "with --random, else 0)")
    p.add_argument("--steps-per-period", type=int_arg, default=None, metavar="N",
                   help=f"fixed steps per forcing period (default {DEFAULT_STEPS_PER_PERIOD})")
    p.add_argument("--tol", type=float_arg, default=1e-10, help="Newton tolerance on ||P^K(x) - x|| (default 1e-10)")
    p.add_argument("--max-iter", type=int_arg, default=40, help="Newton iteration limit (default 40)")
    p.add_argument("--verify", type=int_arg, default=None, metavar="PERIODS",
                   help="check each orbit by direct integration over PERIODS >= 1 periods from a perturbed start "
                   f"(default {VERIFY_PERIODS})")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="also write DIR/orbits.nc (every orbit and every shot; open with jaxgear.load or "
                   "xarray.open_dataset), DIR/orbits.json (the --json object) and PNG figures")
    p.add_argument("--no-figures", action="store_true", help="with --out: skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _parse_periods(text: str) -> list[int]:
    """``"1-8"`` -> ``[1, ..., 8]``; ``"4"`` -> ``[4]`` (``argparse.ArgumentTypeError``, a
    one-line refusal naming ``--periods``, for anything else)."""
    import argparse

    try:
        lo, _, hi = text.partition("-")
        a, b = number(lo, int), number(hi or lo, int)
    except ValueError as exc:
        if "'_'" in str(exc):
            raise argparse.ArgumentTypeError(f"--periods={text}: {exc}") from None
        raise argparse.ArgumentTypeError(f"--periods expects K1-K2 (e.g. 1-8), got {text!r}") from None
    if not 1 <= a <= b <= INT_MAX:
        raise argparse.ArgumentTypeError(f"--periods needs 1 <= K1 <= K2 <= {INT_MAX}, got {text!r}")
    try:
        check_work("--periods", text, b - a + 1, SHOT_BYTES, "periods per seed")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return list(range(a, b + 1))


# Settings of every search (--period and --periods alike), chosen by measurement
# (benchmarks/shooting.py, table in benchmarks/RESULTS.md; paper preset, 64 random seeds over
# region D): a transient of 40 periods for random seeds lifts the converged fraction from 1-2 %
# to about 80 % for every solver; the rounds run with classical RK4 (its jacfwd is far cheaper
# than the kink-aware steps'), every orbit is then re-converged with the default integrator;
# one segment and no deflated round (4 segments or two deflated rounds found no orbit more).
RANDOM_TRANSIENT = 40
VERIFY_PERIODS = 300


def _solvers():
    import optimistix as optx

    from ..shooting._options import STEP_ATOL, STEP_RTOL

    return {"newton": optx.Newton(rtol=STEP_RTOL, atol=STEP_ATOL), "dogleg": optx.Dogleg(rtol=STEP_RTOL, atol=STEP_ATOL),
            "levenberg-marquardt": optx.LevenbergMarquardt(rtol=STEP_RTOL, atol=STEP_ATOL)}


SOLVERS = ("newton", "dogleg", "levenberg-marquardt")
"""``--solver`` names, mapped to optimistix solver objects by :func:`_solvers` (names exist only here)."""


def _load_seeds(path: str, system):
    """The saved result ``path`` and its attractors' points by period; ``ValueError`` when it
    holds a result of another system than ``system``."""
    from .._io import load
    from ..shooting import seeds_from_result

    result = load(path, expected="GlobalResult")
    saved = getattr(result, "system", None)
    if saved and saved != system.name:  # "" in files written before the name was saved
        raise ValueError(f"--seeds-from {path} holds a result of another system ({saved!r}); jaxgear shoot "
                         f"shoots on {system.name!r}: give a result of jaxgear analyze on that system.")
    return result, seeds_from_result(result)


def _canonical_overrides(overrides) -> dict:
    from .._params import PARAM_NAMES
    from .._presets import parse_value

    out = {}
    for item in overrides:
        if "=" not in item:
            raise ValueError(f"--set expects NAME=VALUE, got {item!r}")
        k, v = (s.strip() for s in item.split("=", 1))
        k = k.removeprefix("dimless.")
        if k not in PARAM_NAMES or k == "N":
            raise ValueError(f"with --seeds-from only canonical dimensionless names can be overridden "
                             f"({', '.join(PARAM_NAMES[1:])}); got {k!r}")
        out[k] = parse_value(v)
    return out


def _check_args(args, system, user) -> list[int] | None:
    """Check every option before any integration and before ``--out`` is touched; return the
    periods asked for (``None``: one per attractor period of ``--seeds-from``, else ``[1]``)."""
    from .._checks import check_int

    if args.region is None:
        args.region = DEFAULT_REGION if user is None else user.region
        if user is not None and args.random is not None and len(args.region or ()) != system.dim:
            raise ValueError(f"--random needs a box over every coordinate: give --region with {system.dim} LO:HI "
                             f"ranges ({', '.join(system.state_names)}); --system {user.spec} gives "
                             + (f"{len(args.region)}." if args.region else "none."))
    for k in args.period or ():
        check_int(k, "--period", 1, INT_MAX)
    for pt in args.points or ():
        check_point(pt, "--from", system.dim)
    if args.random is not None:
        check_region(args.region, "--region", system.dim, system.state_names)
    if args.out is not None:
        check_output_folder(args.out)
    if args.periods is not None and args.period is not None:
        raise ValueError("give either --period (repeatable) or --periods K1-K2, not both.")
    periods = args.periods if args.periods is not None else args.period
    check_shoot_work(args, periods)
    if not (args.points or args.seeds_from or args.random is not None):
        raise ValueError("give seeds: --from, --seeds-from or --random N.")
    if args.random is not None and (args.points or (args.seeds_from and periods is None)):
        raise ValueError("--random cannot be combined with --from, nor with --seeds-from unless periods are given "
                         "(--period or --periods).")
    return periods


def _check_verify(args, periods, seeds_from=None) -> None:
    """The check by direct integration (``--verify``) runs at least as many periods as the
    longest orbit shot (it compares the orbit's points over one whole orbit at least)."""
    longest = max(int(k) for k in periods)
    verify = VERIFY_PERIODS if args.verify is None else args.verify
    if longest > verify:
        given = f"--verify={verify}" if args.verify is not None else f"--verify (default {verify})"
        source = (f"the attractors of --seeds-from {seeds_from} have" if seeds_from
                  else "--period/--periods asks for")
        raise ValueError(f"{given} is shorter than the longest orbit: {source} period {longest}; give "
                         f"--verify {longest} or more (periods of direct integration per check).")


def _random_seeds(args):
    from ..shooting import seeds_in_box

    region = np.asarray(args.region, dtype=float)
    return seeds_in_box(args.random, region[:, 0], region[:, 1], seed=args.seed)


def _params_and_seeds(args, periods, system, user):
    """The parameters (the uniform gear parameters, or those of ``--system``), the seeds (an
    array, or ``{k: seeds}`` from ``--seeds-from`` when no period is given) and where the
    parameters came from."""
    from .._params import GearParams
    from .._presets import resolve_params

    source = None if user is None else f"system {user.spec}"
    if args.seeds_from:
        result, groups = _load_seeds(args.seeds_from, system)
        if user is not None:
            params = user.params
        elif getattr(result, "params", None):
            params = GearParams.from_dict(result.params)
            if args.overrides:
                params = params.replace(**_canonical_overrides(args.overrides))
            source = f"parameters of {args.seeds_from}"
        else:
            params = resolve_params(args.preset, args.overrides)[1]
        if not groups:
            raise ValueError(f"{args.seeds_from} has no periodic attractor to seed shooting from.")
        seeds = groups if periods is None else np.concatenate(list(groups.values()))
        if args.random:
            seeds = np.concatenate([seeds, _random_seeds(args)])
    else:
        params = resolve_params(args.preset, args.overrides)[1] if user is None else user.params
        seeds = np.asarray(args.points, dtype=float) if args.points else _random_seeds(args)
    if user is not None:
        return params, seeds, source
    if not params.is_uniform:
        raise ValueError("shoot uses the reduced 2-DOF model, which needs identical planets; "
                         "the given parameters differ per planet.")
    return params.uniform(), seeds, source


def _search_options(args, integ):
    """The :class:`~jaxgear.SearchOptions` of the command line (the same for --period and --periods)."""
    from ..integrate import RK4
    from ..shooting import SearchOptions

    transient = args.transient if args.transient is not None else (RANDOM_TRANSIENT if args.random else 0)
    return SearchOptions(
        solver=None if args.solver is None else _solvers()[args.solver], tol=args.tol, max_iter=args.max_iter,
        segments=args.segments or 1, deflation_rounds=args.deflation_rounds or 0, transient=transient,
        search_integrator=RK4(integ.steps_per_period), verify=args.verify or VERIFY_PERIODS)


def run(args) -> int:
    from .._model import REDUCED
    from ..integrate import default_integrator
    from ..shooting import find_periodic_orbits

    check_options(args, OPTIONS)
    user = resolve_cli_system(args)  # --system: its ForcedSystem replaces the gear model
    system = REDUCED if user is None else user.system
    periods = _check_args(args, system, user)
    _check_verify(args, periods or [1])
    params, seeds, source = _params_and_seeds(args, periods, system, user)
    if isinstance(seeds, dict):  # the periods of the --seeds-from attractors
        _check_verify(args, list(seeds), args.seeds_from)
    integ = default_integrator(args.steps_per_period)
    held = OutputFolder(args.out, OWNED) if args.out else contextlib.nullcontext()
    with held as out:  # --out held by this run before the search
        search = find_periodic_orbits(system, params, seeds, period=periods or [1], integrator=integ,
                                      options=_search_options(args, integ), progress=not (args.quiet or args.json))
        summary = _summary(search, system, params, args) if (args.json or args.out) else {}
        written = _write_files(search, summary, args, out) if args.out else []
    if args.json:
        print(json.dumps(summary))
    else:
        _print_search(search, system, params, args, source)
        if written:
            print(f"\nwrote {', '.join(written)} to {args.out}/")
    return 0


def _summary(search, system, params, args) -> dict:
    """The ``--json`` object (also ``orbits.json``)."""
    from .._params import params_to_dict

    st = search.settings.to_dict()
    return {
        "command": "shoot", "system": system.name, "state_names": list(system.state_names),
        "params": params_to_dict(params),
        "settings": {"periods_tried": sorted(search.shots), "n_seeds": search.n_seeds, "integrator": st["integrator"],
                     "tol": args.tol, "max_iter": args.max_iter, "t0": 0.0, "seeds_from": args.seeds_from,
                     "random": args.random, "seed": args.seed, "search": st},
        "status_counts": search.status_counts,
        "convergence": {str(c.period): c.to_dict() for c in search.convergence},
        "checks": {str(c.orbit): c.to_dict() for c in search.checks},
        "orbits": [o.to_dict() for o in search.orbits], "version": search.version, "runtime_s": search.runtime_s,
    }


def _print_search(search, system, params, args, source) -> None:
    """The text report: the search's settings, its convergence per period, every orbit."""
    st = search.settings.to_dict()
    n = search.n_seeds
    omega = f"Omega={float(params.Omega):.4g}, " if hasattr(params, "Omega") else ""
    print(f"jaxgear shoot: {system.name} model, {source or 'preset ' + args.preset}, "
          f"{omega}{n} seed run{'s' if n != 1 else ''}, P^K for K in {sorted(search.shots)}, "
          f"{st['integrator']['type']} {st['integrator']['steps_per_period']} steps/period, tol {args.tol:g}")
    print("solver: " + ", ".join(f"{v} {k}" for k, v in search.status_counts.items()))
    print(f"search: {st['solver']['type']}, {st['segments']} segment(s), {st['deflation_rounds']} deflated round(s), "
          f"transient {st['transient']} periods, rounds with {st['search_integrator']['type']}; "
          f"{search.runtime_s:.1f} s")
    print(search.convergence_table())
    if not search.orbits:
        print("no periodic orbit converged from these seeds.")
    for i, o in enumerate(search.orbits):
        _print_orbit(i, o, search.verification_of(i), system)


def _print_orbit(i: int, o, check, system) -> None:
    names = " ".join(f"{n:>11s}" for n in system.state_names)
    kind = "stable" if o.stable else f"unstable ({o.instability})"
    print(f"\norbit {i + 1}: P-{o.period}, {kind}, max |multiplier| {o.max_multiplier:.4f}, "
          f"residual {o.residual:.1e}, from {o.n_seeds} seed(s)")
    print("  |multipliers|: " + " ".join(f"{abs(z):.4f}" for z in o.multipliers))
    print("  multipliers:   " + " ".join(f"{z.real:+.4f}{z.imag:+.4f}j" for z in o.multipliers))
    print(f"  points (phase 0): {names}")
    for pt in o.points:
        print("                   " + " ".join(f"{v:11.5f}" for v in pt))
    if check is not None:
        left = "stays on the orbit" if check.kept else f"leaves the orbit after {check.left_at} period(s)"
        print(f"  direct integration ({check.periods} periods): {left}"
              + ("" if check.consistent else " (INCONSISTENT with the multipliers)"))


def _write_files(search, summary: dict, args, out: Path) -> list[str]:
    """``orbits.nc``, ``orbits.json`` and (unless ``--no-figures``) PNG figures in the
    staging folder ``out`` of ``--out``."""
    search.save(out / "orbits.nc")
    write_json(summary, out / "orbits.json")
    written = ["orbits.nc", "orbits.json"]
    if not args.no_figures and search.orbits:
        from ..plotting import plot_multipliers, plot_orbit

        coords = tuple(range(min(3, len(search.state_names))))
        figs = {f"orbit_{i + 1}_P-{o.period}.png": plot_orbit(search, i, coords=coords)
                for i, o in enumerate(search.orbits)}
        figs["multipliers.png"] = plot_multipliers(search)
        for name, fig in figs.items():
            save_figure(fig, out / name, dpi=110)
        written += list(figs)
    return written
