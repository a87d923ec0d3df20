"""The ``jaxgear`` command line: one sub-module per sub-command.

``jaxgear params`` (parameter tables), ``jaxgear analyze`` (the paper's global
analysis, the main job), ``jaxgear shoot`` (periodic orbits and Floquet
multipliers), ``jaxgear sweep`` (bifurcation diagrams, basin shares, continuation).
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
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


INTERRUPTED = 130
"""Exit status of a run stopped by Ctrl-C (SIGINT), as a shell reports it (128 + 2)."""


def main(argv=None) -> int:
    """Run the command ``argv`` (default ``sys.argv[1:]``): its exit status. The one error
    boundary of the command line: bad input (``ValueError``, status 2), a stop by Ctrl-C
    (status 130), a file that cannot be written (``OSError``: a full disk, a loop of links),
    memory exhausted (``MemoryError``, XLA's ``RESOURCE_EXHAUSTED``) (status 1) each print
    one line ``jaxgear COMMAND: ...`` instead of a traceback."""
    command = "jaxgear"
    previous = warnings.showwarning
    args = None
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "command", None):
            parser.print_help()
            return 2
        command = f"jaxgear {args.command}"
        warnings.showwarning = _one_line_warnings(args.command)  # before anything can warn
        enable_compilation_cache()
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        if sys.stderr.isatty():  # after a progress bar's unfinished line
            print(file=sys.stderr)
        note = getattr(args, "interrupt_note", None)
        try:
            text = note() if note is not None else ""
        except Exception:  # the note is a courtesy: never a traceback for it
            text = ""
        _say(command, f"interrupted; {text or 'the previous result is unchanged'}")
        return INTERRUPTED
    except ValueError as exc:  # bad input: a clear message, no traceback
        _say(command, f"error: {exc}")
        return 2
    except OSError as exc:  # a file could not be written (disk full, permissions, a loop of links)
        _say(command, f"error: {describe_os_error(exc)}")
        return 1
    except MemoryError as exc:
        _say(command, "error: out of memory" + (f" ({_first_line(str(exc))})" if str(exc) else "") + f"; {LESS_WORK}")
        return 1
    except Exception as exc:
        if "RESOURCE_EXHAUSTED" not in str(exc):
            raise
        _say(command, "error: out of memory on the device (XLA RESOURCE_EXHAUSTED: "
             f"{_first_line(str(exc).split('RESOURCE_EXHAUSTED', 1)[1].lstrip(': '))}); {LESS_WORK}")
        return 1
    finally:
        warnings.showwarning = previous


LESS_WORK = "ask for less work (fewer cells, values, starts or periods; a smaller --max-period or --chunk-size)."


def _first_line(text: str, limit: int = 200) -> str:
    line = " ".join(text.strip().splitlines()[0].split()) if text.strip() else ""
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _say(command: str, text: str) -> None:
    """One line on stderr: ``jaxgear COMMAND: text`` (white space folded)."""
    print(f"{command}: {' '.join(str(text).split())}", file=sys.stderr)


_H5_FILE = re.compile(r"filename = '([^']*)'")


def describe_os_error(exc: OSError) -> str:
    """What went wrong with a file, in a few words, and where: ``no space left on device
    (writing PATH)``, ``too many levels of symbolic links (PATH)``. HDF5 (h5py, netCDF4)
    reports a full disk in its own text, ``errno = 28`` among it: read as ENOSPC."""
    text = str(exc)
    code = exc.errno
    if code is None:
        m = re.search(r"errno = (\d+)", text)
        code = int(m.group(1)) if m else None
    where = exc.filename
    if where is None:
        m = _H5_FILE.search(text)
        where = m.group(1) if m else None
    where = os.fsdecode(where) if where is not None else None
    if code == errno.ENOSPC or "No space left on device" in text:
        return "no space left on device" + (f" (writing {where})" if where else "")
    if code is not None and code == getattr(errno, "EDQUOT", None):
        return "disk quota exceeded" + (f" (writing {where})" if where else "")
    reason = os.strerror(code) if code else (exc.strerror or _first_line(text))
    reason = reason[:1].lower() + reason[1:]
    return reason + (f" ({where})" if where else "")


def console() -> None:
    """The ``jaxgear`` command (and ``python -m jaxgear``): :func:`main` and its exit code."""
    sys.exit(main())


if __name__ == "__main__":
    console()
