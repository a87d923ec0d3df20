"""``jaxgear shoot``: periodic orbits of the gear model by shooting, with Floquet multipliers.

The paper's local method (§4.1): damped Newton on ``P^k(x) - x = 0`` for the
stroboscopic map of the reduced 2-DOF model, from user points (``--from``), from a
cell-mapping result (``--seeds-from``) or from random points of a box (``--random``).
Prints each distinct orbit: its points, minimal period, Floquet multipliers,
stability and kind of instability; ``--verify`` adds the paper's check by direct
integration; ``--json`` prints one JSON object (with the full parameter set);
``--out DIR`` writes ``orbits.nc`` (open with ``jaxgear.load`` or xarray),
``orbits.json`` (the ``--json`` object) and figures (``orbit_N.png``, ``multipliers.png``).
"""

from __future__ import annotations

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
        description="Shooting method (paper §4.1): damped Newton on P^k(x) - x = 0 for the stroboscopic map "
        "of the reduced 2-DOF gear model (state x1..x4 at forcing phase 0), Jacobian by automatic "
        "differentiation through the RK4 integrator. Prints every distinct orbit found, its minimal period, "
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
    p.add_argument("--random", type=int, metavar="N",
                   help="N random seeds in --region (with --periods, also together with --seeds-from)")
    p.add_argument("--region", type=parse_ranges, default=None, metavar="LO:HI,...",
                   help="box for --random, one LO:HI per coordinate (default the paper's D with x4 in [-5,5]: "
                   "-25:25,-10:20,-10:50,-5:5; with --system the object's REGION if it has one per coordinate)")
    p.add_argument("--seed", type=int, default=0, help="random seed for --random (default 0)")
    p.add_argument("--period", type=int, action="append", metavar="K",
                   help="shoot for P-K orbits (fixed points of P^K); repeatable (default 1, or the attractors' "
                   "periods with --seeds-from)")
    p.add_argument("--periods", type=_parse_periods, default=None, metavar="K1-K2",
                   help="search every period in K1..K2 (e.g. 1-8) with the search settings below: transient, "
                   "deflation, multiple shooting, polishing with the integrator and verification of each orbit "
                   "by direct integration; seeds from --random, plus the attractors of --seeds-from")
    p.add_argument("--solver", default=None, choices=("newton", "dogleg", "levenberg-marquardt", "damped-newton"),
                   help="nonlinear solver (default damped-newton, the hand-written "
                   "single-shooting Newton with backtracking)")
    p.add_argument("--segments", type=int, default=None, metavar="M",
                   help="multiple shooting with M segments per orbit (default 1; needs an optimistix --solver)")
    p.add_argument("--deflation-rounds", type=int, default=None, metavar="R",
                   help="deflated rounds after the plain one (default 0; needs an optimistix --solver)")
    p.add_argument("--transient", type=int, default=None, metavar="PERIODS",
                   help="map each seed PERIODS forcing periods forward before shooting (default 0; with --periods 40)")
    p.add_argument("--steps-per-period", type=int, default=None, metavar="N",
                   help=f"fixed steps per forcing period (default {DEFAULT_STEPS_PER_PERIOD})")
    p.add_argument("--tol", type=float, default=1e-10, help="Newton tolerance on ||P^K(x) - x|| (default 1e-10)")
    p.add_argument("--max-iter", type=int, default=40, help="Newton iteration limit (default 40)")
    p.add_argument("--verify", type=int, default=None, metavar="PERIODS",
                   help="check each orbit by direct integration over PERIODS >= 1 periods from a perturbed start")
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
        a, b = int(lo), int(hi or lo)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--periods expects K1-K2 (e.g. 1-8), got {text!r}") from None
    if not 1 <= a <= b <= INT_MAX:
        raise argparse.ArgumentTypeError(f"--periods needs 1 <= K1 <= K2 <= {INT_MAX}, got {text!r}")
    try:
        check_work("--periods", text, b - a + 1, SHOT_BYTES, "periods per seed")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return list(range(a, b + 1))


# Settings of a --periods search, chosen by measurement (benchmarks/shooting.py, table in
# benchmarks/RESULTS.md; paper preset, 64 seeds over region D, periods 1, 2, 4, 8):
# - transient 40: it alone lifts the converged fraction from 1-2 % to 76-84 % for every solver;
# - solver damped-newton: with the transient it converges as often as the best optimistix
#   solver (84 % vs Dogleg 84 %, Newton 76 %, Levenberg-Marquardt 78 %) and is the fastest
#   (13 s vs 20-59 s). This is the benchmark row that keeps the hand-written loop; the
#   optimistix solvers stay available (--solver) and are needed for segments and deflation;
# - one segment: 4 segments lift Newton from 76 % to 83 %, no more than damped Newton's
#   single shooting, at 1.6x Newton's time;
# - no deflated round: two rounds found no orbit that the plain round had not (the same five
#   orbits) at 2.7x the time, and they halve the fraction per run.
SEARCH_DEFAULTS = dict(solver="damped-newton", segments=1, deflation_rounds=0, transient=40)


def _load_seeds(path: str, system=None):
    """The saved result ``path`` and its attractors' points by period; ``ValueError`` when it
    holds a result of another system than ``system`` (the gear model where ``None``)."""
    from .._io import load
    from .._model import REDUCED as GEAR
    from ..shooting import seeds_from_result

    REDUCED = system or GEAR  # noqa: N806

    result = load(path, expected="GlobalResult")
    system = getattr(result, "system", None)
    if system and system != REDUCED.name:  # "" in files written before the name was saved
        raise ValueError(f"--seeds-from {path} holds a result of another system ({system!r}); jaxgear shoot "
                         f"shoots on the gear model ({REDUCED.name!r}): give a result of jaxgear analyze.")
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


def run(args) -> int:
    from .._checks import check_int
    from .._model import REDUCED
    from .._params import GearParams, params_to_dict
    from .._presets import resolve_params
    from ..integrate import default_integrator
    from ..shooting import find_periodic_orbits, seeds_in_box, verify_orbit

    # every option is checked before any integration and before --out is touched
    check_options(args, OPTIONS)
    user = resolve_cli_system(args)  # --system: its ForcedSystem replaces the gear model below
    if user is not None:
        REDUCED = user.system  # noqa: N806
    if args.region is None:
        args.region = DEFAULT_REGION if user is None else user.region
        if user is not None and args.random is not None and len(args.region or ()) != REDUCED.dim:
            raise ValueError(f"--random needs a box over every coordinate: give --region with {REDUCED.dim} LO:HI "
                             f"ranges ({', '.join(REDUCED.state_names)}); --system {user.spec} gives "
                             + (f"{len(args.region)}." if args.region else "none."))
    periods = args.period
    for k in periods or ():
        check_int(k, "--period", 1, INT_MAX)
    if args.points:
        for pt in args.points:
            check_point(pt, "--from", REDUCED.dim)
    if args.random is not None:
        check_region(args.region, "--region", REDUCED.dim, REDUCED.state_names)
    if args.out is not None:
        check_output_folder(args.out)
    if args.periods is not None:
        if periods is not None:
            raise ValueError("give either --period (repeatable) or --periods K1-K2, not both.")
        periods = args.periods
    check_shoot_work(args, periods)
    if not (args.points or args.seeds_from or args.random is not None):
        raise ValueError("give seeds: --from, --seeds-from or --random N.")
    if args.random is not None and (args.points or (args.seeds_from and args.periods is None)):
        raise ValueError("--random cannot be combined with --from, nor with --seeds-from outside a --periods search.")
    source = None
    if args.seeds_from:
        result, groups = _load_seeds(args.seeds_from, REDUCED)
        if user is not None:
            params, source = user.params, f"system {user.spec}"
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
    else:
        params = resolve_params(args.preset, args.overrides)[1] if user is None else user.params
        if user is not None:
            source = f"system {user.spec}"
        if args.points:
            seeds = np.asarray(args.points, dtype=float)
        else:
            region = np.asarray(args.region, dtype=float)
            seeds = seeds_in_box(args.random, region[:, 0], region[:, 1], seed=args.seed)
    if user is None:
        if not params.is_uniform:
            raise ValueError("shoot uses the reduced 2-DOF model, which needs identical planets; "
                             "the given parameters differ per planet.")
        params = params.uniform()
    integ = default_integrator(args.steps_per_period)
    search_mode = args.periods is not None
    opt = {name: getattr(args, name) for name in SEARCH_DEFAULTS}
    for name, value in opt.items():
        if value is None:
            opt[name] = SEARCH_DEFAULTS[name] if search_mode else {"solver": "damped-newton", "segments": 1,
                                                                    "deflation_rounds": 0, "transient": 0}[name]
    extra = {}
    if search_mode:
        if isinstance(seeds, dict):  # --seeds-from: the attractors' points seed every period
            seeds = np.concatenate(list(seeds.values()))
        if args.seeds_from and args.random:
            region = np.asarray(args.region, dtype=float)
            seeds = np.concatenate([seeds, seeds_in_box(args.random, region[:, 0], region[:, 1], seed=args.seed)])
        from ..integrate import RK4

        # rounds with classical RK4 (its jacfwd is far cheaper than the kink-aware steps'), every
        # orbit then re-converged with the default integrator (measured: benchmarks/shooting.py)
        extra = dict(search_integrator=RK4(integ.steps_per_period), verify=args.verify or 300)
    search = find_periodic_orbits(REDUCED, params, seeds, period=periods or [1], integrator=integ,
                                  tol=args.tol, max_iter=args.max_iter, progress=not (args.quiet or args.json),
                                  **opt, **extra)
    n_seeds = search.n_seeds
    checks = []
    if args.verify and not search.checks:
        checks = [verify_orbit(REDUCED, params, o, periods=args.verify, integrator=integ) for o in search.orbits]

    if args.json or args.out:
        orbits = []
        for i, o in enumerate(search.orbits):
            d = o.to_dict()
            if checks:
                c = checks[i]
                d["verification"] = {"periods": args.verify, "kept": c.kept, "left_at": c.left_at.tolist(),
                                     "final_points": np.where(np.isfinite(c.final_points[:, -1]),
                                                              c.final_points[:, -1], None).tolist()}
            orbits.append(d)
        out = {
            "command": "shoot", "system": REDUCED.name, "state_names": list(REDUCED.state_names),
            "params": params_to_dict(params),
            "settings": {"periods_tried": sorted(search.shots), "n_seeds": n_seeds,
                         "integrator": integ.to_dict(), "tol": args.tol, "max_iter": args.max_iter,
                         "t0": 0.0, "seeds_from": args.seeds_from, "random": args.random, "seed": args.seed},
            "status_counts": search.status_counts, "convergence": search.convergence, "checks": search.checks,
            "orbits": orbits, "version": search.version, "runtime_s": search.runtime_s,
        }
        if args.json:
            print(json.dumps(out))
    written = _write_outputs(search, out, args) if args.out else []
    if args.json:
        return 0

    names = " ".join(f"{n:>11s}" for n in REDUCED.state_names)
    print(f"jaxgear shoot: {REDUCED.name} model, {source or 'preset ' + args.preset}, "
          + (f"Omega={float(params.Omega):.4g}, " if user is None else "") + f"{n_seeds} seed run{'s' if n_seeds != 1 else ''}, P^K for K in {sorted(search.shots)}, "
          f"{integ.name} {integ.steps_per_period} steps/period, tol {args.tol:g}")
    print("Newton: " + ", ".join(f"{v} {k}" for k, v in search.status_counts.items()))
    if search_mode:
        st = search.settings
        print(f"search: {st['solver']}, {st['segments']} segment(s), {st['deflation_rounds']} deflated round(s), "
              f"transient {st['transient']} periods, rounds with {st['search_integrator']['type']}; "
              f"{search.runtime_s:.1f} s")
        print(search.convergence_table())
    if not search.orbits:
        print("no periodic orbit converged from these seeds.")
        return 0
    for i, o in enumerate(search.orbits):
        kind = "stable" if o.stable else f"unstable ({o.instability})"
        print(f"\norbit {i + 1}: P-{o.period}, {kind}, max |multiplier| {o.max_multiplier:.4f}, "
              f"residual {o.residual:.1e}, from {o.n_seeds} seed(s)")
        print("  |multipliers|: " + " ".join(f"{abs(z):.4f}" for z in o.multipliers))
        print("  multipliers:   " + " ".join(f"{z.real:+.4f}{z.imag:+.4f}j" for z in o.multipliers))
        print(f"  points (phase 0): {names}")
        for pt in o.points:
            print("                   " + " ".join(f"{v:11.5f}" for v in pt))
        if search.checks:
            c = search.checks[str(i)]
            left = "stays on the orbit" if c["kept"] else f"leaves the orbit after {c['left_at']} period(s)"
            print(f"  direct integration ({c['periods']} periods): {left}"
                  + ("" if c["consistent"] else " (INCONSISTENT with the multipliers)"))
        if checks:
            c = checks[i]
            if c.kept:
                print(f"  direct integration ({args.verify} periods): stays on the orbit")
            else:
                first = int(np.min(c.left_at[c.left_at > 0]))
                ends = c.final_points[:, -1]
                print(f"  direct integration ({args.verify} periods): leaves the orbit after {first} period(s); "
                      f"ends at " + "; ".join("diverged" if not np.all(np.isfinite(e)) else
                                               "[" + ", ".join(f"{v:.4f}" for v in e) + "]" for e in ends))
    if written:
        print(f"\nwrote {', '.join(written)} to {args.out}/")
    return 0


def _write_outputs(search, summary: dict, args) -> list[str]:
    """``orbits.nc``, ``orbits.json`` and (unless ``--no-figures``) PNG figures in ``--out``."""
    with OutputFolder(args.out, OWNED) as out:
        return _write_files(search, summary, args, out)


def _write_files(search, summary: dict, args, out: Path) -> list[str]:
    search.save(out / "orbits.nc")
    write_json(summary, out / "orbits.json")
    written = ["orbits.nc", "orbits.json"]
    if not args.no_figures and search.orbits:
        from ..plotting import plot_multipliers, plot_orbit

        figs = {f"orbit_{i + 1}_P-{o.period}.png": plot_orbit(search, i, coords=(0, 1, 2))
                for i, o in enumerate(search.orbits)}
        figs["multipliers.png"] = plot_multipliers(search)
        for name, fig in figs.items():
            save_figure(fig, out / name, dpi=110)
        written += list(figs)
    return written
