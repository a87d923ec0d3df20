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

from .._ahead import compile_ahead, wait_for
from .._io import save_figure, write_json
from .._outdir import OutputFolder, check_output_folder
from ._painter import Painter
from .common import add_param_options, check_counts, check_options, check_region, parse_counts, parse_ranges

OWNED = ("result.nc", "summary.json", "compare.json", "domains.png", "shares.png", "domains_3d.png",
         "attractors.png")
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
    p.add_argument("--method", default=DEFAULT_METHOD, choices=tuple(METHODS),
                   help=f"{DEFAULT_METHOD} (default): integrate every cell centre until its attractor is recognised; "
                   "poincare-like: the paper's map (l periods, then the next crossing of x4 = 0, restarted at "
                   "phase 0: it loses the forcing phase, see README); "
                   "stroboscopic: Hsu's simple cell mapping of the stroboscopic map (grid over x1..x4)")
    p.add_argument("--grid", type=parse_counts, default=None, metavar="N1,N2,N3[,N4]",
                   help="cells per axis (default 50,30,60; stroboscopic default 25,15,30,12)")
    p.add_argument("--region", type=parse_ranges, default=None, metavar="LO:HI,...",
                   help="box bounds per gridded axis (default the paper's D: -25:25,-10:20,-10:50; "
                   "stroboscopic adds x4 in -12:12)")
    p.add_argument("--mapping-steps", type=int, default=None, metavar="L",
                   help=f"cell methods: forcing periods per cell-map step l (default "
                   f"{PoincareCellMap.mapping_steps} poincare-like, 1 stroboscopic)")
    p.add_argument("--steps-per-period", type=int, default=None, metavar="N",
                   help=f"fixed steps per forcing period (default {DEFAULT_STEPS_PER_PERIOD})")
    p.add_argument("--direction", type=int, default=None, choices=(-1, 0, 1),
                   help="used by --method poincare-like only: crossing direction of the section x4 = 0 "
                   "(default 1: increasing x4; -1 decreasing; 0 both)")
    p.add_argument("--max-period", type=int, default=None, metavar="K",
                   help=f"largest period P-k detected (default {Direct.max_period})")
    p.add_argument("--chunk-size", type=int, default=None, metavar="N",
                   help=f"cells per batch (bounds memory; default {Direct.chunk_size})")
    p.add_argument("--uncertainty-samples", type=int, default=DEFAULT_SAMPLES, metavar="N",
                   help=f"cells sampled for the label uncertainty (default {DEFAULT_SAMPLES}; 0 skips it): the "
                   "share whose label changes with a halved step, and with the start moved by 1e-3 cell")
    p.add_argument("--compare", nargs="?", type=int, const=500, default=None, metavar="N",
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


OPTIONS = (("mapping_steps", "--mapping-steps", int, 0), ("steps_per_period", "--steps-per-period", int, 1),
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
    # the figures' worker starts before the first JAX computation (see _painter)
    painter = None if args.no_figures or args.distributed else Painter(_import_plotting, _figures)
    try:
        return _run_checked(args, painter)
    finally:
        if painter is not None:
            painter.close()


def _run_checked(args, painter) -> int:
    from .._cells import CellGrid
    from .._model import REDUCED
    from .._presets import resolve_params

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
    check_region(region, f"--region {where}", n_axes, default.axis_names)
    check_counts(counts, f"--grid {where}", n_axes, default.axis_names)
    grid = CellGrid.box(region, counts, axes=default.axes, base=default.base, names=REDUCED.state_names)
    method.check(REDUCED, grid)
    # everything the run will compute compiles on a side thread, in order, from now on
    from ..analysis import prepare_analysis

    prepare_analysis(REDUCED, params, grid, method, args.uncertainty_samples)

    if args.distributed:
        from .._devices import process_index

        if process_index() != 0:  # the same computations (they exchange blocks), nothing written or printed
            import contextlib
            import io

            args.no_figures, args.quiet = True, True
            with contextlib.redirect_stdout(io.StringIO()):
                _analyze(args, params, grid, method, None, None)
            return 0
    print(f"jaxgear analyze: {args.method}, {grid.n_cells} cells, preset {args.preset}, Omega={float(params.Omega):.4g}")
    with OutputFolder(args.out, OWNED) as out:
        written = _analyze(args, params, grid, method, out, painter)
    print(f"\nwrote {', '.join(written)} to {args.out}/")
    return 0


def _analyze(args, params, grid, method, out: Path | None, painter) -> list[str]:
    """The analysis, its report and its files (written into the staging folder ``out``,
    none when ``out`` is ``None``: a process of a multi-process run other than 0; the
    figures by ``painter``, a :class:`~jaxgear.cli._painter.Painter`, or none)."""
    import numpy as np

    from .._model import REDUCED
    from ..analysis import analyze_global, compare_with_direct, with_label_uncertainty

    t0 = time.perf_counter()
    # xarray (for saving) is imported on the side thread after the compilations
    # (prepare_analysis), once the device is busy: imported at once, its quarter second
    # of Python would delay the first computations
    if out is not None:
        compile_ahead(_OUTPUT_LIBRARIES, _import_output_libraries)
    result = analyze_global(REDUCED, params, grid, method, progress=not args.quiet, uncertainty=0)
    if painter is not None:  # the figures are drawn while the label uncertainty is measured and the result saved
        painter.submit(result, out)
    if args.uncertainty_samples:
        result = with_label_uncertainty(result, REDUCED, params, method, args.uncertainty_samples,
                                        progress=not args.quiet)
    result = dataclasses.replace(result, runtime_s=time.perf_counter() - t0)
    print(f"done in {result.runtime_s:.1f} s (mean {result.mean_periods:.1f} periods per cell)\n")
    print(result.table())
    written = []
    if out is not None:
        wait_for(_OUTPUT_LIBRARIES)
        result.save(out / "result.nc")
        result.write_summary(out / "summary.json")
        written += ["result.nc", "summary.json"]
    figure_names = painter.names() if painter is not None else []
    if args.compare:
        rep = compare_with_direct(result, REDUCED, params, n_samples=args.compare, progress=not args.quiet)
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
    return written + figure_names


_OUTPUT_LIBRARIES = ("import", "xarray")
"""Key of the side thread's import of the saving libraries (:mod:`jaxgear._ahead`)."""


def _import_output_libraries() -> None:
    import xarray  # noqa: F401


def _import_plotting() -> None:
    """What the figure workers do before the result comes (the computing process has a
    core to spare while it starts): import the plotting module and draw a throwaway
    figure with a 3D axis into memory, so that what matplotlib loads on first use (fonts,
    the 3D toolkit, the PNG writer) is loaded then, not while the figures are drawn
    (about 0.13 s of the drawing)."""
    import io

    import matplotlib.pyplot as plt

    from .. import plotting  # noqa: F401

    fig = plt.figure(figsize=(2, 2))
    fig.add_subplot(121).plot([0, 1], [0, 1])
    fig.add_subplot(122, projection="3d").scatter([0], [0], [0])
    fig.savefig(io.BytesIO(), format="png", dpi=20)
    plt.close(fig)


def _figures(result, out, part: int = 0, parts: int = 1) -> list[str]:
    """Draw the analysis's figures into ``out``; with ``parts`` painters, the share
    ``part`` of them (the list is ordered so that alternate figures split the cost evenly:
    the slices and the 3D view cost the most)."""
    from ..analysis import PoincareCellMap
    from ..plotting import plot_attractors, plot_domains, plot_domains_3d, plot_shares

    out = Path(out)
    figures = [("domains.png", lambda: plot_domains(result, axis=-1, n_slices=4))]
    if len(result.grid.axes) >= 3:
        figures.append(("domains_3d.png", lambda: plot_domains_3d(result)))
    figures.append(("shares.png", lambda: plot_shares(result)))
    if result.attractors:
        figures.append(("attractors.png", lambda: plot_attractors(result, section=isinstance(result.method, PoincareCellMap))))
    names = []
    for name, plot in figures[part::parts]:
        save_figure(plot(), out / name, dpi=120)
        names.append(name)
    return names
