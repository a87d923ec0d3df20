"""Options shared by several sub-commands."""

from __future__ import annotations

import argparse


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
