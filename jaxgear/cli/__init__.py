"""The ``jaxgear`` command line: one sub-module per sub-command.

``jaxgear params`` (parameter tables), ``jaxgear analyze`` (the paper's global
analysis, the main job), ``jaxgear shoot`` (periodic orbits and Floquet
multipliers), ``jaxgear sweep`` (bifurcation diagrams, basin shares, continuation).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .._cache import enable_compilation_cache

# (sub-command, module under jaxgear.cli) — each module defines add_parser(subparsers).
COMMANDS = (
    ("params", "params"),
    ("analyze", "analyze"),
    ("shoot", "shoot"),
    ("sweep", "sweep"),
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxgear",
        description="Global analysis of nonlinear planetary gear trains: every coexisting periodic "
        "motion and its domain of attraction (cell mapping, shooting, sweeps).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for _name, module in COMMANDS:
        try:
            mod = importlib.import_module(f"jaxgear.cli.{module}")
        except ModuleNotFoundError as exc:
            if exc.name == f"jaxgear.cli.{module}":
                continue  # sub-command not installed in this build
            raise
        mod.add_parser(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    enable_compilation_cache()
    try:
        return int(args.func(args) or 0)
    except ValueError as exc:  # bad input: a clear message, no traceback
        print(f"jaxgear {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
