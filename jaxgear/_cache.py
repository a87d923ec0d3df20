"""Where jaxgear keeps what it builds once per machine.

One root folder, ``$JAXGEAR_CACHE_DIR`` (default ``~/.cache/jaxgear``), holds

- ``xla/``: JAX's persistent compilation cache, switched on by the command line through
  JAX's public configuration (a repeated command loads its compiled computations
  instead of compiling them again). It holds data that JAX itself reads and checks;
  nothing in it is executed as Python.

``JAXGEAR_CACHE_DIR=off`` turns the compilation cache off.

The compiled CPU kernel of the gear models (:mod:`jaxgear.integrate._native`) is not kept
there: it is code, and that folder may be shared by the processes of a run. It lives in
the user's private :func:`native_dir`, whatever ``JAXGEAR_CACHE_DIR`` says.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

__all__ = ["cache_root", "native_dir", "enable_compilation_cache"]

_OFF = ("", "0", "off", "none", "false", "no")


def _default_root() -> Path:
    return Path(os.path.expanduser("~")) / ".cache" / "jaxgear"


def cache_root() -> Path | None:
    """The cache folder, or ``None`` when ``JAXGEAR_CACHE_DIR`` turns caching off."""
    value = os.environ.get("JAXGEAR_CACHE_DIR")
    if value is None:
        return _default_root()
    return None if value.strip().lower() in _OFF else Path(value)


def native_dir() -> Path:
    """Folder of the compiled CPU kernel: ``$XDG_CACHE_HOME/jaxgear/native`` (default
    ``~/.cache/jaxgear/native``), private to the user (created 0700; the kernel refuses it
    when others can write it). It does not follow ``JAXGEAR_CACHE_DIR``: the kernel is built
    once per user and machine, and never loaded from a folder a run shares."""
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    base = Path(xdg) if os.path.isabs(xdg) else Path(os.path.expanduser("~")) / ".cache"
    return base / "jaxgear" / "native"


def enable_compilation_cache() -> Path | None:
    """Keep every XLA computation jaxgear compiles in ``<cache root>/xla``, so that a new
    Python process (a restarted notebook kernel, a repeated command) loads them instead of
    compiling them again: call it once, before the first analysis.

    What it changes in the process: JAX's public settings ``jax_compilation_cache_dir``
    (that folder), ``jax_persistent_cache_min_compile_time_secs`` and
    ``jax_persistent_cache_min_entry_size_bytes`` (both 0: a global analysis compiles a
    dozen computations of under a second each, which together cost seconds). Every JAX
    computation of the process is then cached there, not only jaxgear's. The root is
    ``$JAXGEAR_CACHE_DIR`` (default ``~/.cache/jaxgear``; ``off`` turns the cache off).

    The folder holds data that JAX itself reads and checks, nothing executed as Python;
    it is created private to the user (0700) and not used when others can write to it.

    Returns:
        The folder, or ``None`` (with one warning, and nothing changed) when caching is
        off, the folder cannot be created, others can write to it, or its path is not
        valid text.

    JAX writes entries from process 0 of a multi-process run only; on CPUs the other
    processes' keys name their own devices, so they compile their computations at each
    start (the price of using JAX's cache as JAX defines it)."""
    root = cache_root()
    if root is None:
        return None
    import jax

    path = root / "xla"
    try:
        str(path).encode("utf-8")
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
        if path.stat().st_mode & 0o022:
            warnings.warn(f"jaxgear: compilation cache not used: others can write to {path} "
                          "(set JAXGEAR_CACHE_DIR to a private folder).", stacklevel=2)
            return None
        jax.config.update("jax_compilation_cache_dir", str(path))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except UnicodeError:
        warnings.warn(f"jaxgear: compilation cache not used: its folder {path!r} is not valid text "
                      "(set JAXGEAR_CACHE_DIR to another folder).", stacklevel=2)
        return None
    except (OSError, AttributeError) as exc:  # read-only home or an older jax: run without the cache
        warnings.warn(f"jaxgear: compilation cache not used: {path} cannot be created "
                      f"({getattr(exc, 'strerror', None) or exc}).", stacklevel=2)
        return None
    return path

