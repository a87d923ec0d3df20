"""``jaxgear analyze``: the paper's global analysis (the main job).

Defaults: the ``paper`` preset, the reduced 2-DOF model, region D with 50 × 30 × 60
cells on Σ = {x4 = 0}, the kink-aware RK4 with 200 steps per period. Prints the attractor table
and the labels' uncertainty,
writes ``result.nc``, ``summary.json`` and figures into ``--out``.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from .._io import save_figure, write_json
from .._outdir import OutputFolder, check_output_folder
from .common import (
    add_param_options,
    add_system_option,
    cell_bytes,
    check_counts,
    check_options,
    check_pool_history,
    check_region,
    check_work,
    escape_bound,
    int_arg,
    parse_counts,
    parse_ranges,
    resolve_cli_system,
    with_uncertainty_line,
)

OWNED = ("result.nc", "summary.json", "compare.json", "domains.png", "shares.png", "domains_3d.png",
         "attractors.png", "basin_measures.png", "gear_view_*.nc")
"""Files ``jaxgear analyze`` writes into ``--out`` (replaced as a whole by the next run)."""


def add_parser(sub) -> None:
    from ..analysis import DEFAULT_METHOD, METHODS, Direct, PoincareCellMap
    from ..analysis._uncertainty import DEFAULT_SAMPLES
    from ..integrate import DEFAULT_STEPS_PER_PERIOD

    p = sub.add_parser(
        "analyze", help="global analysis: every coexisting attractor, its period and domain (the main job)",
        description="Global analysis by cell mapping (paper §3-§4). Defaults reproduce the paper's analysis: "
        "the 'paper' preset, region D = [-25,25]x[-10,20]x[-10,50] on the section x4 = 0, 50x30x60 cells, "
        f"classified by the {DEFAULT_METHOD} method (--method poincare-like is the paper's own map with l = 50). "
        "Writes result.nc (open with xarray), summary.json and PNG figures into --out.",
    )
    add_param_options(p)
    add_system_option(p)
    p.add_argument("--method", default=DEFAULT_METHOD, choices=tuple(METHODS),
                   help=f"{DEFAULT_METHOD} (default): integrate every cell centre until its attractor is recognised; "
                   "poincare-like: the paper's map (l periods, then the next crossing of x4 = 0, restarted at "
                   "phase 0: it loses the forcing phase, see docs/methods/global-analysis.md); "
                   "stroboscopic: Hsu's simple cell mapping of the stroboscopic map (grid over x1..x4)")
    p.add_argument("--grid", type=parse_counts, default=None, metavar="N1,N2,N3[,N4]",
                   help="cells per axis (default 50,30,60; stroboscopic default 25,15,30,12; with --system the "
                   "object's GRID, else 40 per axis on two axes, 20 on three)")
    p.add_argument("--region", type=parse_ranges, default=None, metavar="LO:HI,...",
                   help="box bounds per gridded axis (default the paper's D: -25:25,-10:20,-10:50; "
                   "stroboscopic adds x4 in -12:12; with --system the object's REGION: one range per coordinate, "
                   "or per coordinate but the section coordinate for cells on the section)")
    p.add_argument("--mapping-steps", type=int_arg, default=None, metavar="L",
                   help=f"cell methods: forcing periods per cell-map step l (default "
                   f"{PoincareCellMap.mapping_steps} poincare-like, 1 stroboscopic)")
    p.add_argument("--steps-per-period", type=int_arg, default=None, metavar="N",
                   help=f"fixed steps per forcing period (default {DEFAULT_STEPS_PER_PERIOD})")
    p.add_argument("--direction", type=int_arg, default=None, choices=(-1, 0, 1),
                   help="used by --method poincare-like only: crossing direction of the section x4 = 0 "
                   "(default 1: increasing x4; -1 decreasing; 0 both)")
    p.add_argument("--max-period", type=int_arg, default=None, metavar="K",
                   help=f"largest period P-k detected (default {Direct.max_period})")
    p.add_argument("--chunk-size", type=int_arg, default=None, metavar="N",
                   help=f"cells per batch (bounds memory; default {Direct.chunk_size})")
    p.add_argument("--uncertainty-samples", type=int_arg, default=DEFAULT_SAMPLES, metavar="N",
                   help=f"cells sampled for the label uncertainty (default {DEFAULT_SAMPLES}; 0 skips it): the "
                   "share whose label changes with a halved step, and with the start moved by 1e-3 cell")
    p.add_argument("--compare", nargs="?", type=int_arg, const=500, default=None, metavar="N",
                   help="also run the direct method on N >= 1 random cells (500 if N is left out) and report "
                   "agreement")
    p.add_argument("--out", default="jaxgear-out", metavar="DIR",
                   help="output folder (default jaxgear-out), replaced as a whole at the end of the run")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--distributed", action="store_true",
                   help="run as one process of a multi-process JAX program (jax.distributed.initialize: detects "
                   "Slurm and Open MPI, or reads JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID); "
                   "the cells split over every process's devices, process 0 writes --out")
    p.set_defaults(func=run)


OPTIONS = (("mapping_steps", "--mapping-steps", int, 1), ("steps_per_period", "--steps-per-period", int, 1),
           ("max_period", "--max-period", int, 1), ("chunk_size", "--chunk-size", int, 1),
           ("uncertainty_samples", "--uncertainty-samples", int, 0), ("compare", "--compare", int, 1))


def build_method(args):
    """The method object the command-line options describe (unset options at their defaults)."""
    from ..analysis import method_from_name
    from ..integrate import default_integrator

    opts = {"integrator": default_integrator(args.steps_per_period)}
    for name, value in (("max_period", args.max_period), ("chunk_size", args.chunk_size),
                        ("mapping_steps", args.mapping_steps), ("direction", args.direction)):
        if value is not None:
            if name in ("mapping_steps", "direction") and args.method == "direct":
                raise ValueError(f"--{name.replace('_', '-')} applies to the cell methods, not to --method direct.")
            if name == "direction" and args.method != "poincare-like":
                raise ValueError("--direction applies to --method poincare-like only.")
            opts[name] = value
    return method_from_name(args.method, **opts)


def run(args) -> int:

    if args.distributed:  # before any JAX computation
        from .._devices import initialize

        initialize()
    # every option is checked before any integration and before --out is touched
    check_options(args, OPTIONS)
    check_output_folder(args.out)
    return _run_checked(args)


def _check_work(args, method, counts, system=None) -> None:
    """The cells (and a lane's history of states) fit in memory, before anything is
    allocated (``system``: the gear model where ``None``)."""
    import math

    from .._model import REDUCED

    dim = (system or REDUCED).dim
    n_cells = math.prod(counts)
    check_work("--grid", ",".join(map(str, counts)), n_cells, cell_bytes(dim), "cells")
    if hasattr(method, "round_periods"):  # the lane pool: a history of 2 K + 1 states per lane (K = --max-period)
        check_pool_history("--max-period", int(method.max_period), min(int(method.chunk_size), n_cells), dim)


def _run_checked(args) -> int:
    from .._cells import CellGrid
    from .._model import REDUCED
    from .._presets import resolve_params

    user = resolve_cli_system(args)
    if user is not None:
        return _run_user(args, user)
    gear_set, params = resolve_params(args.preset, args.overrides)
    if params.N and not params.is_uniform:
        raise ValueError("analyze uses the reduced 2-DOF model, which needs identical planets; "
                         "the given parameters differ per planet.")
    params = params.uniform()
    method = build_method(args)
    default = method.default_grid(REDUCED)
    region = args.region or tuple(zip(default.lower, default.upper))
    counts = args.grid or default.counts
    n_axes = len(default.axes)
    where = f"(--method {args.method} grids {', '.join(default.axis_names)})"
    check_region(region, f"--region {where}", n_axes, default.axis_names, escape_bound(method),
                 [b for i, b in enumerate(default.base) if i not in default.axes])
    check_counts(counts, f"--grid {where}", n_axes, default.axis_names)
    _check_work(args, method, counts)
    grid = CellGrid.box(region, counts, axes=default.axes, base=default.base, names=REDUCED.state_names)
    method.check(REDUCED, grid)

    head = f"preset {args.preset}, Omega={float(params.Omega):.4g}"
    return _run_on(args, REDUCED, params, grid, method, head, gear_set)


def _run_user(args, user) -> int:
    """``--system``: the analysis of the user's system on its region (or ``--region``)."""
    from ._system_spec import user_grid

    system = user.system
    method = build_method(args)
    grid = user_grid(user, args.region, args.grid, args.method)
    names = grid.axis_names
    check_region(tuple(zip(grid.lower, grid.upper)), "--region", len(names), names, escape_bound(method))
    check_counts(grid.counts, "--grid")
    _check_work(args, method, grid.counts, system)
    method.check(system, grid)
    return _run_on(args, system, user.params, grid, method, f"system {user.spec} ({system.name})")


def _run_on(args, system, params, grid, method, head: str, gear_set=None) -> int:
    """Run the checked analysis and write ``--out`` (``head`` describes the system in the
    first line printed; ``gear_set``: the preset's physical set, for the mesh lines in µm)."""
    if args.distributed:
        from .._devices import process_index

        if process_index() != 0:  # the same computations (they exchange blocks), nothing written or printed
            import contextlib
            import io

            args.no_figures, args.quiet = True, True
            with contextlib.redirect_stdout(io.StringIO()):
                _analyze(args, system, params, grid, method, None, gear_set)
            return 0
    with OutputFolder(args.out, OWNED) as out:  # --out held by this run from here on
        print(f"jaxgear analyze: {args.method}, {grid.n_cells} cells, {head}")
        written = _analyze(args, system, params, grid, method, out, gear_set)
    print(f"\nwrote {', '.join(written)} to {args.out}/")
    return 0


def _analyze(args, system, params, grid, method, out: Path | None, gear_set=None) -> list[str]:
    """The analysis, its report and its files (written into the staging folder ``out``,
    none when ``out`` is ``None``: a process of a multi-process run other than 0)."""
    import numpy as np

    from ..analysis import analyze_global, compare_with_direct

    t0 = time.perf_counter()
    result = analyze_global(system, params, grid, method, progress=not args.quiet,
                            uncertainty=args.uncertainty_samples)
    result = dataclasses.replace(result, runtime_s=time.perf_counter() - t0)
    print(f"done in {result.runtime_s:.1f} s (mean {result.mean_periods:.1f} periods per cell)\n")
    print(with_uncertainty_line(result.table(), result))
    views = _print_meshes(result, system, params, gear_set)
    written = []
    if out is not None:
        result.save(out / "result.nc")
        summary = result.summary()
        if views:
            summary["gear_views"] = [v.summary() for v in views]
        write_json(summary, out / "summary.json")
        written += ["result.nc", "summary.json"]
        for v in views:  # the whole gear view of each attractor, spectra included
            v.save(out / f"gear_view_{v.attractor_id}.nc")
            written.append(f"gear_view_{v.attractor_id}.nc")
        if not args.no_figures:
            written += _figures(result, out)
    if args.compare:
        rep = compare_with_direct(result, system, params, n_samples=args.compare, progress=not args.quiet)
        if out is not None:
            write_json(rep, out / "compare.json")
            written.append("compare.json")
        print(f"\nagreement with the direct method on {rep['n_samples']} random cells: "
              f"{100 * rep['agreement']:.1f} %")
        for aid, d in rep["per_attractor"].items():
            print(f"  attractor {aid}: {d['agree']}/{d['cells']} cells agree ({100 * d['fraction']:.1f} %)")
        for d in rep["direct_only"]:
            print(f"  found only by direct integration: P-{d['period']} at {np.round(d['point'], 4).tolist()} "
                  f"({d['cells']} of the sampled cells)")
    return written


def _print_meshes(result, system, params, gear_set) -> list:
    """One line per attractor and mesh: contact regime, RMS transmission error and dynamic
    factor (:func:`jaxgear.gear_views`, every attractor in one batch; in µm with the
    preset's gear set). Nothing for a system without switching functions; one line saying
    why for a system whose switching functions are not pairs ``X - b, X + b``. Returns the
    views (none where nothing is shown)."""
    from .._contact import gear_views

    if not result.attractors or system.switching is None:  # no switching functions: no meshes
        return []
    print("\nmeshes (jaxgear.gear_view" + (", physical units" if gear_set is not None else "") + "):")
    try:
        views = gear_views(system, params, result.attractors, gear_set)
    except ValueError as exc:  # a user system whose switching functions are not meshes
        print(f"  not shown: {exc}")
        return []
    for view in views:
        for line in view.lines():
            print(f"  {line}")
    return views


def _figures(result, out) -> list[str]:
    """Draw the analysis's figures into ``out``: the names of the files written."""
    from ..analysis import PoincareCellMap
    from ..plotting import plot_attractors, plot_basin_measures, plot_domains, plot_domains_3d, plot_shares

    out = Path(out)
    figures = [("domains.png", lambda: plot_domains(result, axis=-1, n_slices=4))]
    if len(result.grid.axes) >= 3:
        figures.append(("domains_3d.png", lambda: plot_domains_3d(result)))
    figures.append(("shares.png", lambda: plot_shares(result)))
    dim = result.grid.dim
    if result.attractors and dim >= 2:  # the first two or three coordinates (a --system may have fewer than 4)
        figures.append(("attractors.png", lambda: plot_attractors(result, coords=tuple(range(min(dim, 3))),
                                                                  section=isinstance(result.method, PoincareCellMap))))
    u = result.uncertainty
    if u is not None and any(f > 0 for f in u.start_fractions):  # the uncertain fraction, its fit where it scales
        figures.append(("basin_measures.png", lambda: plot_basin_measures(result)))
    names = []
    for name, plot in figures:
        save_figure(plot(), out / name, dpi=120)
        names.append(name)
    return names
