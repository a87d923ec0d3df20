"""Compiling ahead: a side thread traces and compiles a computation while the device
works on something else (an analysis's pilot, its main pool), so that the compilation
does not add to the wall time of the call that needs it.

:func:`compile_ahead` starts a job under a key; the code about to call the computation
calls :func:`wait_for` with the same key first, so nothing compiles twice. A job that
fails is forgotten: the real call then reports what is wrong. The same thread takes
other one-time preparations in their turn (the command line imports the libraries it
saves with there, after the compilations).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from concurrent.futures import Future, ThreadPoolExecutor

__all__ = ["compile_ahead", "wait_for", "wait_all"]

_COMPILER = ThreadPoolExecutor(max_workers=1, thread_name_prefix="jaxgear-compile")
_PENDING: dict[Hashable, Future] = {}
_STARTED: set = set()  # every key ever submitted: a computation is compiled ahead once
_LOCK = threading.Lock()


def compile_ahead(key: Hashable, job: Callable[[], object]) -> None:
    """Run ``job`` (typically ``f.lower(...).compile()`` of a jitted ``f`` on abstract
    arguments) on the side thread, unless a job with this key was started before. Jobs
    run one at a time, in the order they were started."""
    with _LOCK:
        if key not in _STARTED:
            _STARTED.add(key)
            _PENDING[key] = _COMPILER.submit(job)


def wait_for(key: Hashable) -> None:
    """Wait until the job started under ``key`` (if any) has finished."""
    with _LOCK:
        fut = _PENDING.pop(key, None)
    if fut is not None:
        try:
            fut.result()
        except Exception:  # the call itself will raise what is wrong
            pass


def wait_all() -> None:
    """Wait until every job started so far has finished (a process about to exit without
    its interpreter's teardown must not cut a compilation, or its cache entry, short)."""
    with _LOCK:
        futures = list(_PENDING.values())
    for fut in futures:
        try:
            fut.result()
        except Exception:
            pass
