"""Where jaxgear keeps what it builds once per machine.

One root folder, ``$JAXGEAR_CACHE_DIR`` (default ``~/.cache/jaxgear``), holds

- ``xla/``: JAX's persistent compilation cache, enabled by the command line (a repeated
  command loads its compiled computations instead of compiling them again);
- ``kept/``: the lowered computations a command keeps for the next
  (:mod:`jaxgear._kept`: a warm command loads its lane pools instead of tracing them);

``JAXGEAR_CACHE_DIR=off`` turns the compilation cache and the kept computations off.

The compiled CPU kernel of the gear models (:mod:`jaxgear.integrate._native`) is not kept
there: it is code, and that folder may be shared by the processes of a run. It lives in
the user's private :func:`native_dir`, whatever ``JAXGEAR_CACHE_DIR`` says.
"""

from __future__ import annotations

import inspect
import os
from pathlib import Path

__all__ = ["cache_root", "native_dir", "enable_compilation_cache", "write_from_every_process"]

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
    """Keep every compiled XLA computation in ``<cache root>/xla`` (whatever its compile
    time: a run of the global analysis compiles a dozen computations of under a second
    each, which together cost seconds). Returns the folder, or ``None`` when caching is off
    or the folder cannot be created (then nothing changes)."""
    root = cache_root()
    if root is None:
        return None
    import jax

    path = root / "xla"
    try:
        path.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(path))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except (OSError, AttributeError):  # read-only home or an older jax: run without the cache
        return None
    return path


_WRITE_SIGNATURES = (
    ("cache_key", "compile_time_secs", "module_name", "backend", "executable", "host_callbacks"),  # jax <= 0.10
    ("cache_key", "compile_time_secs", "module_name", "backend", "executable"),  # later: callbacks are cacheable
)
"""The signatures of the JAX function :func:`write_from_every_process` replaces."""


def write_from_every_process() -> bool:
    """Let every process of a multi-process CPU program write its own entries into JAX's
    persistent compilation cache; returns whether it could.

    JAX writes cache entries from process 0 only (so that processes do not contend for
    the same entry on a shared file system). On CPUs the key of a computation holds the
    ids of the devices it runs on, so the other processes never find process 0's entries:
    without their own, they compile every computation again at every start (seconds per
    pool program on one core, more than the analysis of their share of the cells). Their
    keys differ from process 0's and from each other's, so writing them contends for
    nothing. Other platforms keep JAX's rule (GPU keys leave the devices out: process 0's
    entries serve every process). This reaches into JAX's compiler module; a JAX without
    the hook it replaces keeps its own behaviour (and this returns ``False``)."""
    try:
        from jax._src import compilation_cache, compiler, distributed
    except ImportError:
        return False
    own = getattr(compiler, "_cache_write", None)
    put = getattr(compilation_cache, "put_executable_and_time", None)
    if own is None or put is None:
        return False
    if getattr(own, "writes_from_every_process", False):
        return True
    signature = inspect.signature(own)
    if tuple(signature.parameters) not in _WRITE_SIGNATURES:  # another JAX: its own rule
        return False

    def write(*args, **kwargs):
        a = signature.bind(*args, **kwargs).arguments
        backend, seconds = a["backend"], a["compile_time_secs"]
        if distributed.global_state.process_id == 0 or getattr(backend, "platform", None) != "cpu":
            return own(*args, **kwargs)
        import jax

        if a.get("host_callbacks") or seconds < jax.config.jax_persistent_cache_min_compile_time_secs:
            return None  # JAX's other conditions for writing
        try:
            put(a["cache_key"], a["module_name"], a["executable"], backend, int(seconds))
        except Exception:  # a cache that cannot be written costs a compilation, nothing else
            pass
        return None

    write.writes_from_every_process = True
    compiler._cache_write = write
    return True
