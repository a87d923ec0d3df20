"""Options shared by several sub-commands."""

from __future__ import annotations

import argparse

from .._checks import check_int, check_number


def add_param_options(p: argparse.ArgumentParser) -> None:
    """``--preset`` and repeatable ``--set NAME=VALUE``."""
    p.add_argument("--preset", default="paper", help="gear-set preset (default: paper, the set of paper §4.1)")
    p.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE",
        help="override a parameter: a physical GearSet field (face_width=0.03, input_rpm=3000, "
        "k_sp_amp=2e8, ...) or a canonical dimensionless name (Omega=0.9, b_sp=4, "
        "kappa_sp_amp=0.3, ...); per-planet values as comma lists; repeatable",
    )


def parse_ranges(text: str) -> tuple[tuple[float, float], ...]:
    """``--region`` value ``LO:HI,LO:HI,...`` -> ``((lo, hi), ...)``, one pair per coordinate."""
    out = []
    for part in text.split(","):
        lo, sep, hi = part.partition(":")
        try:
            if not sep:
                raise ValueError
            out.append((float(lo), float(hi)))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"--region expects LO:HI per coordinate, comma-separated (e.g. -25:25,-10:20,-10:50), got {text!r}"
            ) from None
    return tuple(out)


def parse_point(text: str) -> tuple[float, ...]:
    """``--from`` value ``x1,x2,...`` -> a state tuple."""
    try:
        return tuple(float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--from expects comma-separated numbers like 5.4,-0.2,8.3,-0.8, got {text!r}") from None


def parse_counts(text: str) -> tuple[int, ...]:
    """``--grid`` value ``N1,N2,...`` (or ``N1xN2x...``) -> positive cell counts per axis."""
    try:
        vals = tuple(int(t) for t in text.replace("x", ",").split(",") if t.strip())
    except ValueError:
        vals = ()
    if not vals or min(vals) < 1:
        raise argparse.ArgumentTypeError(f"--grid expects positive counts like 50,30,60, got {text!r}")
    return vals


def check_options(args, spec) -> None:
    """Check numeric options before any work: ``spec`` rows ``(dest, flag, kind, minimum)``
    with ``kind`` ``int`` or ``float`` (``float`` minimums are exclusive); options left
    unset (``None``) are skipped. ``ValueError`` names the option, its value and the range."""
    for dest, flag, kind, minimum in spec:
        value = getattr(args, dest, None)
        if value is None:
            continue
        if kind is int:
            check_int(value, flag, minimum)
        else:
            check_number(value, flag, minimum, strict_min=minimum is not None)


def check_region(region, flag: str, n_axes: int, names) -> None:
    """``--region`` ranges: ``n_axes`` of them, finite, ``LO < HI``."""
    import math

    if len(region) != n_axes:
        raise ValueError(f"{flag} needs {n_axes} LO:HI ranges ({', '.join(names)}), got {len(region)}.")
    for name, (lo, hi) in zip(names, region):
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ValueError(f"{flag}: the range of {name} is {lo:g}:{hi:g}; it must be finite with LO < HI.")


def check_point(point, flag: str, dim: int) -> None:
    """A ``--from`` state: ``dim`` finite numbers."""
    import math

    if len(point) != dim:
        raise ValueError(f"{flag} needs {dim} coordinates x1,...,x{dim}; got {len(point)}: "
                         f"{','.join(f'{v:g}' for v in point)}.")
    if not all(math.isfinite(v) for v in point):
        raise ValueError(f"{flag}={','.join(f'{v:g}' for v in point)} must hold finite numbers.")


def check_counts(counts, flag: str, n_axes: int, names) -> None:
    """``--grid`` counts: ``n_axes`` of them (each >= 1 already)."""
    if len(counts) != n_axes:
        raise ValueError(f"{flag} needs {n_axes} counts ({', '.join(names)}), got {len(counts)}: "
                         f"{','.join(map(str, counts))}.")
