"""The ``jaxgear`` command line: one sub-module per sub-command.

``jaxgear params`` (parameter tables), ``jaxgear analyze`` (the paper's global
analysis, the main job), ``jaxgear shoot`` (periodic orbits and Floquet
multipliers), ``jaxgear sweep`` (bifurcation diagrams, basin shares, continuation).
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import warnings

from .._cache import enable_compilation_cache

# (sub-command, module under jaxgear.cli) — each module defines add_parser(subparsers).
COMMANDS = (
    ("params", "params"),
    ("analyze", "analyze"),
    ("shoot", "shoot"),
    ("sweep", "sweep"),
)


class Parser(argparse.ArgumentParser):
    """``argparse`` parser that takes a value beginning with ``-`` (``--region -25:25,...``,
    ``--from -5,0,8,0``, ``--values -0.1:0.1:3``, ``--tol -inf``, ``--out -dash``) as the
    option's value, not as an unknown option, unless it names an option of the command
    (``--out -h``: the message says to write ``--out=-h``). Sub-command parsers inherit
    the class."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self._negative_number_matcher = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)

    def _parse_optional(self, arg_string):
        """A word beginning with ``-`` that names no option of this parser (``-dash``,
        ``-o``) is a value (``--out -dash``), not an unknown option; alone, it is still
        refused as an unrecognised argument."""
        found = super()._parse_optional(arg_string)
        # Python < 3.12.7: None or one (action, ...) tuple; later: None or a list of them
        options = found if isinstance(found, list) else [found] if found is not None else []
        if options and all(o[0] is None for o in options) and arg_string.startswith("-"):
            return None
        return found

    def error(self, message):
        """One line: what is wrong and where the usage is (not the whole usage text)."""
        m = re.match(r"argument (--[\w-]+)(?:/[^:]*)?: expected one argument$", message)
        if m:  # the value is missing, or begins with '-' and is an option's name (--out -h)
            message += f" (write a value that begins with '-' as {m.group(1)}=-VALUE)"
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from .._version import __version__

    parser = Parser(
        prog="jaxgear",
        description="Global analysis of nonlinear planetary gear trains: every coexisting periodic "
        "motion and its domain of attraction (cell mapping, shooting, sweeps).",
    )
    parser.add_argument("--version", action="version", version=f"jaxgear {__version__}")
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


def _one_line_warnings(command: str):
    """``warnings.showwarning`` printing ``jaxgear COMMAND: warning: message`` (no source line)."""

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        print(f"jaxgear {command}: warning: {text}", file=file or sys.stderr)

    return show


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    enable_compilation_cache()
    previous = warnings.showwarning
    warnings.showwarning = _one_line_warnings(args.command)
    try:
        return int(args.func(args) or 0)
    except ValueError as exc:  # bad input: a clear message, no traceback
        text = " ".join(str(exc).split())
        print(f"jaxgear {args.command}: error: {text}", file=sys.stderr)
        return 2
    except OSError as exc:  # a file could not be written (disk full, permissions)
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(f"jaxgear {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1
    finally:
        warnings.showwarning = previous


def console() -> None:
    """The ``jaxgear`` command (and ``python -m jaxgear``): :func:`main` and its exit code."""
    sys.exit(main())


if __name__ == "__main__":
    console()
