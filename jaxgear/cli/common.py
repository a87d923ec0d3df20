"""Options shared by several sub-commands."""

from __future__ import annotations

import argparse
import math

from .._checks import check_int, check_memory, check_number


def add_param_options(p: argparse.ArgumentParser) -> None:
    """``--preset`` and repeatable ``--set NAME=VALUE``."""
    p.add_argument("--preset", default="paper", help="gear-set preset (default: paper, the set of paper §4.1)")
    p.add_argument(
        "--set", dest="overrides", action=SetOnce, default=[], metavar="NAME=VALUE",
        help="override a parameter: a physical GearSet field (face_width=0.03, input_rpm=3000, "
        "k_sp_amp=2e8, ...) or a canonical dimensionless name (Omega=0.9, b_sp=4, "
        "kappa_sp_amp=0.3, ...); per-planet values as comma lists; repeatable, each parameter once",
    )


def add_system_option(p: argparse.ArgumentParser) -> None:
    """``--system MODULE:ATTRIBUTE``: run the command on a user's ``ForcedSystem``
    (:mod:`jaxgear.cli._system_spec` says what the attribute may be)."""
    p.add_argument(
        "--system", default=None, metavar="MODULE:ATTRIBUTE",
        help="run on your own jaxgear.ForcedSystem instead of the gear model: MODULE is a module in the current "
        "folder or on PYTHONPATH, or a file path/to/model.py; ATTRIBUTE a ForcedSystem (parameters, region and "
        "cell counts from the module's PARAMS, REGION, GRID), an object or dict with 'system' and optional "
        "'params', 'region', 'grid', or a function returning either; --set then sets fields of its parameters, "
        "--region and --grid replace its region and counts",
    )


def resolve_cli_system(args):
    """The :class:`~jaxgear.cli._system_spec.UserSystem` of ``--system`` with the
    ``--set`` overrides applied, or ``None`` without ``--system``; ``ValueError`` for a
    ``--preset`` other than the default next to ``--system`` (a preset is a gear set)."""
    spec = getattr(args, "system", None)
    if spec is None:
        return None
    if getattr(args, "preset", "paper") != "paper":
        raise ValueError(f"--preset {args.preset} is a gear set; with --system {spec} the parameters come from "
                         "the system's object (change them with --set NAME=VALUE).")
    from ._system_spec import resolve_system

    return resolve_system(spec, getattr(args, "overrides", ()) or ())


def _set_fields(item: str) -> set[str]:
    """The parameter fields a ``--set NAME=VALUE`` item sets (an alias sets several)."""
    from .._params import PARAM_ALIASES

    name = item.split("=", 1)[0].strip().removeprefix("dimless.")
    return set(PARAM_ALIASES.get(name, (name,))) if "=" in item and name else set()


class SetOnce(argparse.Action):
    """``--set NAME=VALUE``, repeatable, each parameter at most once: a second value for
    a parameter (directly or through an alias: ``b`` sets ``b_sp`` and ``b_rp``) is
    refused instead of silently replacing the first."""

    def __call__(self, parser, namespace, value, option_string=None):
        items = list(getattr(namespace, self.dest, None) or [])
        if "=" in value:  # the value (a number or a comma list of them): no '_' (names have them)
            try:
                for t in value.split("=", 1)[1].split(","):
                    if "_" in t:
                        number(t)
            except ValueError as exc:
                raise argparse.ArgumentError(self, f"{value.strip()}: {exc}") from None
        new = _set_fields(value)
        for old in items:
            both = sorted(_set_fields(old) & new)
            if both:
                raise argparse.ArgumentError(
                    self, f"{', '.join(both)} is set twice ({old.strip()} and {value.strip()}); give each "
                    "parameter once")
        setattr(namespace, self.dest, [*items, value])


def number(text: str, kind=float):
    """The number written in ``text`` (``kind`` ``float`` or ``int``), as the command line
    reads every number: ``ValueError`` for what is not one, also for digits grouped with
    ``_`` (``0_9``, which Python would read as 9: a typo for 0.9 more often than not)."""
    if "_" in text:
        raise ValueError(f"numbers are written without '_' (got {text.strip()!r}); did you mean "
                         f"{text.strip().replace('_', '.', 1)!r}?")
    return kind(text)


def _argument_type(kind):
    """An ``argparse`` type reading a ``kind`` with :func:`number` (a one-line refusal
    naming the option for ``0_9``; argparse's own for what is no number)."""

    def parse(text: str):
        if "_" in text:
            try:
                number(text, kind)
            except ValueError as exc:
                raise argparse.ArgumentTypeError(str(exc)) from None
        return kind(text)

    parse.__name__ = kind.__name__  # argparse names it in "invalid int value: 'x'"
    return parse


int_arg = _argument_type(int)
"""``type=`` of the integer options (``int`` without ``_``)."""
float_arg = _argument_type(float)
"""``type=`` of the real-number options (``float`` without ``_``)."""


def parse_ranges(text: str) -> tuple[tuple[float, float], ...]:
    """``--region`` value ``LO:HI,LO:HI,...`` -> ``((lo, hi), ...)``, one pair per coordinate."""
    out = []
    for part in text.split(","):
        lo, sep, hi = part.partition(":")
        try:
            if not sep:
                raise ValueError
            out.append((number(lo), number(hi)))
        except ValueError as exc:
            if "'_'" in str(exc):
                raise argparse.ArgumentTypeError(str(exc)) from None
            raise argparse.ArgumentTypeError(
                f"--region expects LO:HI per coordinate, comma-separated (e.g. -25:25,-10:20,-10:50), got {text!r}"
            ) from None
    return tuple(out)


def parse_point(text: str) -> tuple[float, ...]:
    """``--from`` value ``x1,x2,...`` -> a state tuple."""
    try:
        return tuple(number(t) for t in text.split(","))
    except ValueError as exc:
        if "'_'" in str(exc):
            raise argparse.ArgumentTypeError(str(exc)) from None
        raise argparse.ArgumentTypeError(
            f"--from expects comma-separated numbers like 5.4,-0.2,8.3,-0.8, got {text!r}") from None


def parse_counts(text: str) -> tuple[int, ...]:
    """``--grid`` value ``N1,N2,...`` (or ``N1xN2x...``) -> positive cell counts per axis."""
    try:
        vals = tuple(number(t, int) for t in text.replace("x", ",").split(",") if t.strip())
    except ValueError as exc:
        if "'_'" in str(exc):
            raise argparse.ArgumentTypeError(str(exc)) from None
        vals = ()
    if not vals or min(vals) < 1:
        raise argparse.ArgumentTypeError(f"--grid expects positive counts like 50,30,60, got {text!r}")
    return vals


INT_MAX = 2**31 - 1
"""Largest value of an integer option (counts, steps, periods, seeds): the compiled
kernels count their loops and draw their seeds in 32-bit integers."""


def check_options(args, spec) -> None:
    """Check numeric options before any work: ``spec`` rows ``(dest, flag, kind, minimum)``
    with ``kind`` ``int`` (at most :data:`INT_MAX`) or ``float`` (``float`` minimums are
    exclusive); options left unset (``None``) are skipped. ``ValueError`` names the
    option, its value and the range."""
    for dest, flag, kind, minimum in spec:
        value = getattr(args, dest, None)
        if value is None:
            continue
        if kind is int:
            check_int(value, flag, minimum, INT_MAX)
        else:
            check_number(value, flag, minimum, strict_min=minimum is not None)


ESCAPE_BOUND = 1e6
"""Norm of the state beyond which the analyses and sweeps count a motion as escaped (the
default ``escape_bound`` of :class:`jaxgear.Direct` and of the sweeps)."""


def check_region(region, flag: str, n_axes: int, names, escape_bound: float | None = None, base=()) -> None:
    """``--region`` ranges: ``n_axes`` of them, finite, ``LO < HI``; with ``escape_bound``,
    the farthest corner of the box (with the fixed coordinates ``base``) lies within it,
    since a start beyond the bound counts as escaped at once (every such cell would go
    to the sink)."""
    if len(region) != n_axes:
        raise ValueError(f"{flag} needs {n_axes} LO:HI ranges ({', '.join(names)}), got {len(region)}.")
    for name, (lo, hi) in zip(names, region):
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ValueError(f"{flag}: the range of {name} is {lo:g}:{hi:g}; it must be finite with LO < HI.")
    if escape_bound is not None:
        far = math.hypot(*(max(abs(lo), abs(hi)) for lo, hi in region), *base)
        if not far <= escape_bound:
            raise ValueError(f"{flag}: the box {','.join(f'{lo:g}:{hi:g}' for lo, hi in region)} reaches |x| = {far:.3g}, "
                             f"beyond the escape bound {escape_bound:g} (a state farther out counts as escaped): "
                             f"keep the box within |x| <= {escape_bound:g}.")


def check_point(point, flag: str, dim: int) -> None:
    """A ``--from`` state: ``dim`` finite numbers."""
    import math

    if len(point) != dim:
        raise ValueError(f"{flag} needs {dim} coordinates x1,...,x{dim}; got {len(point)}: "
                         f"{','.join(f'{v:g}' for v in point)}.")
    if not all(math.isfinite(v) for v in point):
        raise ValueError(f"{flag}={','.join(f'{v:g}' for v in point)} must hold finite numbers.")


MIN_CELLS = 2
"""Fewest cells per axis of an analysed grid: the result's basin entropy counts the labels
in boxes of at least 2 x 2 cells (:func:`jaxgear.basin_entropy`)."""


def check_counts(counts, flag: str, n_axes: int | None = None, names=()) -> None:
    """``--grid`` counts: ``n_axes`` of them (unless ``None``), each at least :data:`MIN_CELLS`."""
    if n_axes is not None and len(counts) != n_axes:
        raise ValueError(f"{flag} needs {n_axes} counts ({', '.join(names)}), got {len(counts)}: "
                         f"{','.join(map(str, counts))}.")
    if min(counts) < MIN_CELLS:
        raise ValueError(f"{flag} needs at least {MIN_CELLS} cells on every axis (the basin entropy of the result "
                         f"counts labels in boxes of {MIN_CELLS} cells a side or more), got {','.join(map(str, counts))}.")


def check_work(flag: str, value, count: int, unit_bytes: float, what: str) -> None:
    """Refuse before any work an option whose ``count`` units of ``what`` (values, seeds,
    cells) would need about ``count * unit_bytes`` bytes, more than the machine can hold
    (:func:`jaxgear._checks.check_memory`); the message names ``flag``, its ``value``
    and the largest count that fits."""
    check_memory(flag, value, count, unit_bytes, what)


def check_pool_history(flag: str, max_period: int, lanes: int, dim: int) -> None:
    """The direct method's lane pool keeps, per lane, a ring of its last ``2 K + 1``
    states and a streak per period ``k <= K`` (``K = max_period``), and each round tests
    its :data:`~jaxgear.analysis._recurrence.CANDIDATE_POOL` oldest undecided lanes for a
    cycle by comparing their last ``2 K`` points at every lag ``k <= K``: ``K x K`` states
    at once, which is what outgrows memory for a large ``K``. Refuse (naming ``flag``)
    a ``K`` whose arrays do not fit."""
    from ..analysis._recurrence import CANDIDATE_POOL

    candidates = min(CANDIDATE_POOL, lanes)

    def history(k: int) -> float:
        return 2.0 * lanes * (2 * dim * 8 + 8) * k + 8.0 * (dim + 1) * candidates * float(k) * k

    check_memory(flag, max_period, int(max_period), 0, "periods (a cycle test of K periods holds K x K states)",
                 history)


def cell_bytes(dim: int) -> int:
    """Memory estimate per cell of an analysis of a ``dim``-dimensional state: about eight
    float64 states (the centre, its image or lane state, the pool's lane buffers, the
    labels and the result's arrays)."""
    return 64 * int(dim)


def escape_bound(method) -> float:
    """The escape bound of an analysis method (:data:`ESCAPE_BOUND` where it has none)."""
    bound = getattr(method, "escape_bound", None)
    return ESCAPE_BOUND if bound is None else float(bound)


NOT_MEASURED = "label uncertainty: not measured: no resolved cells"
"""Printed instead of a label uncertainty where no cell was resolved (0 % would read as
certainty: the sampled cells stay unresolved with any step)."""


def shares_uncertainty_line(result, where: str = "values") -> str:
    """The label-uncertainty line of a basin sweep or map over the ``where`` (values,
    points) with resolved cells only; :data:`NOT_MEASURED` where none has any; "" where
    none was measured."""
    import numpy as np

    step = np.asarray(result.uncertainty_step, dtype=float).reshape(-1)
    start = np.asarray(result.uncertainty_start, dtype=float).reshape(-1)
    unresolved = np.asarray(result.unresolved_share, dtype=float).reshape(-1)
    measured = np.isfinite(step)
    if not measured.any():
        return ""
    ok = measured & (unresolved < 1.0)
    if not ok.any():
        return NOT_MEASURED
    line = (f"label uncertainty: at most {100 * step[ok].max():.1f} % of the sampled cells change label with a "
            f"refined step, {100 * start[ok].max():.1f} % when their start moves (mean {100 * step[ok].mean():.1f} "
            f"% and {100 * start[ok].mean():.1f} % over the {int(ok.sum())} {where} with resolved cells)")
    skipped = int((measured & ~ok).sum())
    return line + (f"; not measured at {skipped} {where}: no resolved cells" if skipped else "")


def with_uncertainty_line(text: str, result, where: str = "values") -> str:
    """``text``, a result's table that may end in its label-uncertainty line, with that
    line replaced: for a :class:`~jaxgear.GlobalResult` without resolved cells (every
    cell unresolved) by :data:`NOT_MEASURED`; for a basin sweep or map by
    :func:`shares_uncertainty_line`."""
    if hasattr(result, "uncertainty_note"):  # a basin sweep or map: one measurement per value
        note = result.uncertainty_note(where)
        if not note or not text.endswith("\n" + note):
            return text
        return text[: len(text) - len(note)] + shares_uncertainty_line(result, where)
    u = getattr(result, "uncertainty", None)
    note = u.describe() if u is not None else ""
    if note and int(result.n_unresolved) >= int(result.n_cells) and text.endswith(note):
        return text[: len(text) - len(note)] + NOT_MEASURED
    return text


def check_resume(out, now: dict) -> None:
    """Refuse, before the command's header, to resume the sweep saved in ``out`` (its
    ``manifest.json``) when one of the settings in ``now`` differs from the saved one;
    the message names every differing field with both values. Settings not in ``now``,
    and a missing or unreadable manifest, are left to the sweep functions."""
    import json
    from pathlib import Path

    from ..sweep._checkpoint import diff_settings, mismatch_message

    man = Path(out) / "manifest.json"
    try:
        saved = json.loads(man.read_text())
    except (OSError, ValueError):
        return
    if not isinstance(saved, dict) or not isinstance(saved.get("settings"), dict):
        return
    old = {k: v for k, v in saved["settings"].items() if k in now}
    diff = diff_settings(old, {k: v for k, v in now.items() if k in old})
    if old and diff != "format":
        raise ValueError(mismatch_message(Path(out), saved.get("kind", "?"), diff, "--restart"))


SHOT_BYTES = 8 * 8 * (4 + 4 * 4)
"""Memory estimate of one seed shot for one period (``jaxgear shoot``): about eight
float64 copies of the state and its 4 x 4 Jacobian (Newton's iterate, step and trial,
the saved shot)."""
VERIFY_TRIALS = 4
"""Perturbed starts of each orbit's check by direct integration (``verify_orbit``'s default)."""


def check_shoot_work(args, periods) -> None:
    """``jaxgear shoot``: the seeds (``--random``, ``--from``) times the periods shot from
    each, and the periods of ``--verify``, fit in memory (``--seeds-from`` seeds come from
    a result that was itself held in memory)."""
    from .._model import REDUCED

    periods = list(periods or [1])
    per_seed = len(periods) * SHOT_BYTES + 8 * REDUCED.dim * sum(periods)  # + the orbits' points
    if args.random is not None:
        check_work("--random", args.random, args.random, per_seed, f"seeds ({len(periods):,} period(s) each)")
    if args.points:
        check_work("--from", f"{len(args.points)} points", len(args.points), per_seed, "seeds")
    if args.verify is not None:  # each check keeps the trajectories of its trials, one point per period
        check_work("--verify", args.verify, args.verify, VERIFY_TRIALS * REDUCED.dim * 8 * 4, "periods")
