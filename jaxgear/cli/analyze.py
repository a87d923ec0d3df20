"""``jaxgear analyze``: the paper's global analysis (the main job).

Defaults: the ``paper`` preset, the reduced 2-DOF model, region D with 50 × 30 × 60
cells on Σ = {x4 = 0}, RK4 with 200 steps per period. Prints the attractor table,
writes ``result.nc``, ``summary.json`` and figures into ``--out``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from .common import add_param_options, parse_counts, parse_ranges


def add_parser(sub) -> None:
    p = sub.add_parser(
        "analyze", help="global analysis: every coexisting attractor, its period and domain (the main job)",
        description="Global analysis by cell mapping (paper §3-§4). Defaults reproduce the paper's analysis: "
        "the 'paper' preset, region D = [-25,25]x[-10,20]x[-10,50] on the section x4 = 0, 50x30x60 cells, "
        "classified by direct integration on the stroboscopic map (--method poincare-like is the paper's own "
        "map with l = 50). Writes result.nc (open with xarray), summary.json and PNG "
        "figures into --out.",
    )
    add_param_options(p)
    p.add_argument("--method", default="direct", choices=("poincare-like", "stroboscopic", "direct"),
                   help="direct (default): integrate every cell centre until its attractor is recognised; "
                   "poincare-like: the paper's map (l periods, then the next crossing of x4 = 0, restarted at "
                   "phase 0: it loses the forcing phase, see README); "
                   "stroboscopic: Hsu's simple cell mapping of the stroboscopic map (grid over x1..x4)")
    p.add_argument("--grid", type=parse_counts, default=None, metavar="N1,N2,N3[,N4]",
                   help="cells per axis (default 50,30,60; stroboscopic default 25,15,30,12)")
    p.add_argument("--region", type=parse_ranges, default=None, metavar="LO:HI,...",
                   help="box bounds per gridded axis (default the paper's D: -25:25,-10:20,-10:50; "
                   "stroboscopic adds x4 in -12:12)")
    p.add_argument("--mapping-steps", type=int, default=None, metavar="L",
                   help="forcing periods per cell-map step l (default 50 poincare-like, 1 stroboscopic)")
    p.add_argument("--steps-per-period", type=int, default=200, help="RK4 steps per forcing period (default 200)")
    p.add_argument("--direction", type=int, default=1, choices=(-1, 0, 1),
                   help="crossing direction of the section x4 = 0 (+1 increasing, -1 decreasing, 0 both)")
    p.add_argument("--max-period", type=int, default=16, help="largest period P-k detected (default 16)")
    p.add_argument("--chunk-size", type=int, default=131072, help="cells per batch (bounds memory; default %(default)s)")
    p.add_argument("--compare", nargs="?", type=int, const=500, default=None, metavar="N",
                   help="also run the direct method on N random cells (default 500) and report agreement")
    p.add_argument("--out", default="jaxgear-out", help="output folder (default jaxgear-out)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args) -> int:
    import numpy as np

    from .. import REDUCED, CellGrid, PAPER_REGION, analyze_global, compare_with_direct
    from .._params import resolve_params

    gear_set, params = resolve_params(args.preset, args.overrides)
    if params.N and not params.is_uniform:
        raise ValueError("analyze uses the reduced 2-DOF model, which needs identical planets; "
                         "the given parameters differ per planet.")
    params = params.uniform()
    names = REDUCED.state_names
    if args.method == "stroboscopic":
        region = args.region or PAPER_REGION + ((-12.0, 12.0),)
        counts = args.grid or (25, 15, 30, 12)
        if len(region) != 4 or len(counts) != 4:
            raise ValueError("the stroboscopic method grids all four coordinates: give 4 counts and 4 ranges.")
        grid = CellGrid.box(region, counts, axes=(0, 1, 2, 3), base=(0.0,) * 4, names=names)
    else:
        region = args.region or PAPER_REGION
        counts = args.grid or (50, 30, 60)
        if len(region) != 3 or len(counts) != 3:
            raise ValueError("the poincare-like and direct methods grid x1, x2, x3 on x4 = 0: give 3 counts and 3 ranges.")
        grid = CellGrid.box(region, counts, axes=(0, 1, 2), base=(0.0,) * 4, names=names)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"jaxgear analyze: {args.method}, {grid.n_cells} cells, preset {args.preset}, Omega={float(params.Omega):.4g}")
    t0 = time.perf_counter()
    result = analyze_global(REDUCED, params, grid, method=args.method, mapping_steps=args.mapping_steps,
                            steps_per_period=args.steps_per_period, direction=args.direction,
                            max_period=args.max_period, chunk_size=args.chunk_size, progress=not args.quiet)
    print(f"done in {time.perf_counter() - t0:.1f} s (mean {result.mean_periods:.1f} periods per cell)\n")
    print(result.table())
    result.save(out / "result.nc")
    result.write_summary(out / "summary.json")
    written = ["result.nc", "summary.json"]
    if args.compare:
        rep = compare_with_direct(result, REDUCED, params, n_samples=args.compare, progress=not args.quiet)
        (out / "compare.json").write_text(json.dumps(rep, indent=2))
        written.append("compare.json")
        print(f"\nagreement with the direct method on {rep['n_samples']} random cells: "
              f"{100 * rep['agreement']:.1f} %")
        for aid, d in rep["per_attractor"].items():
            print(f"  attractor {aid}: {d['agree']}/{d['cells']} cells agree ({100 * d['fraction']:.1f} %)")
        for d in rep["direct_only"]:
            print(f"  found only by direct integration: P-{d['period']} at {np.round(d['point'], 4).tolist()} "
                  f"({d['cells']} of the sampled cells)")
    if not args.no_figures:
        written += _figures(result, out)
    print(f"\nwrote {', '.join(written)} to {out}/")
    return 0


def _figures(result, out: Path) -> list[str]:
    from .. import plotting

    figs = {
        "domains.png": plotting.plot_domains(result, axis=-1, n_slices=4),
        "shares.png": plotting.plot_shares(result),
    }
    if len(result.grid.axes) >= 3:
        figs["domains_3d.png"] = plotting.plot_domains_3d(result)
    if result.attractors:
        figs["attractors.png"] = plotting.plot_attractors(result, section=result.method == "poincare-like")
    for name, fig in figs.items():
        fig.savefig(out / name, dpi=120)
    return list(figs)
