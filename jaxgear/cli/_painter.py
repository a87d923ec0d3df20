"""The figures of a command, drawn beside its computation.

matplotlib is pure Python for the most part: drawn on a thread of the computing process,
the figures hold the interpreter while the analysis needs it to drive the device, and
both slow down. On Linux, where JAX's runtime has not started yet (a command-line run,
before its first computation), a :class:`Painter` forks a worker process that imports
matplotlib at once and draws when it receives the result; elsewhere (macOS and Windows,
where forking a process that loaded system libraries is unsafe or impossible, or JAX
already running, e.g. the CLI called from a notebook) it draws on a thread of this
process.
"""

from __future__ import annotations

import multiprocessing
import sys
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

__all__ = ["Painter"]


def _jax_running() -> bool:
    """Whether JAX's runtime (its backends and their threads) has started in this process;
    ``True`` when that cannot be told (then no fork)."""
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except Exception:
        return True


def _work(conn, other, prepare: Callable[[], None], draw: Callable) -> None:
    """The worker process: import what the figures need, wait for ``(result, folder)``
    and answer ``("ok", names)`` or ``("error", text)``; ``None`` (or the parent gone)
    ends it."""
    other.close()  # the parent's end: the parent's death then reads as EOF here
    try:
        prepare()
        job = conn.recv()
    except (EOFError, OSError, KeyboardInterrupt):
        return
    if job is None:
        return
    try:
        conn.send(("ok", draw(*job)))
    except Exception:
        conn.send(("error", traceback.format_exc(limit=3)))


class Painter:
    """Draws ``draw(result, folder) -> [file names]`` once, beside the computation.

    Create it before the first JAX computation of the process (so a worker process can be
    forked cleanly); :meth:`submit` hands it the result, :meth:`names` waits for the files,
    :meth:`close` (or leaving a ``with`` block) ends the worker.
    """

    def __init__(self, prepare: Callable[[], None], draw: Callable):
        self._draw, self._conn, self._proc, self._thread, self._future = draw, None, None, None, None
        if sys.platform.startswith("linux") and not _jax_running():
            ctx = multiprocessing.get_context("fork")
            self._conn, child = ctx.Pipe()
            self._proc = ctx.Process(target=_work, args=(child, self._conn, prepare, draw), daemon=True,
                                     name="jaxgear-figures")
            self._proc.start()
            child.close()
        else:
            self._thread = ThreadPoolExecutor(1, thread_name_prefix="jaxgear-figures")
            self._thread.submit(prepare)

    @property
    def forked(self) -> bool:
        """Whether the figures are drawn by a worker process."""
        return self._proc is not None

    def submit(self, result, folder: Path) -> None:
        """Start drawing the figures of ``result`` into ``folder``."""
        if self._proc is not None:
            self._conn.send((result, str(folder)))
        else:
            self._future = self._thread.submit(self._draw, result, str(folder))

    def names(self) -> list[str]:
        """The files drawn (waits for them); raises what drawing raised."""
        if self._proc is None:
            return self._future.result()
        try:
            status, value = self._conn.recv()
        except EOFError:
            raise RuntimeError(f"the figure process ended without drawing (exit code {self._proc.exitcode})") from None
        if status != "ok":
            raise RuntimeError(f"drawing the figures failed:\n{value}")
        return value

    def close(self) -> None:
        if self._proc is not None:
            if self._proc.is_alive():
                try:
                    self._conn.send(None)
                except OSError:
                    pass
                self._proc.join(5)
                if self._proc.is_alive():
                    self._proc.terminate()
                    self._proc.join()
            self._conn.close()
        elif self._thread is not None:
            self._thread.shutdown(wait=True)

    def __enter__(self) -> Painter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
