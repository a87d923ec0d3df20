"""The figures of a command, drawn beside its computation.

matplotlib is pure Python for the most part: drawn on a thread of the computing process,
the figures hold the interpreter while the analysis needs it to drive the device, and
both slow down. On Linux, where JAX's runtime has not started yet (a command-line run,
before its first computation), a :class:`Painter` forks a worker process that imports
matplotlib at once; once that is done the worker forks the other workers (one per
core, at most one per figure group; they inherit the imported libraries), and each draws
its share of the figures when it receives the result. Elsewhere (macOS and Windows,
where forking a process that loaded system libraries is unsafe or impossible, or JAX
already running, e.g. the CLI called from a notebook) one thread of this process draws
them all.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

__all__ = ["Painter", "MAX_WORKERS"]

MAX_WORKERS = 2
"""Worker processes at most (the figures of an analysis split in two groups of about equal
cost; more workers would only import more)."""


def _jax_running() -> bool:
    """Whether JAX's runtime (its backends and their threads) has started in this process;
    ``True`` when that cannot be told (then no fork)."""
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except Exception:
        return True


def _serve(conn, part: int, parts: int, draw: Callable) -> None:
    """Wait for ``(result, folder)`` on ``conn`` and answer ``("ok", names)`` or
    ``("error", text)`` for the share ``part`` of ``parts``; ``None`` (or the parent
    gone) ends it."""
    try:
        job = conn.recv()
    except (EOFError, OSError, KeyboardInterrupt):
        return
    if job is None:
        return
    try:
        conn.send(("ok", draw(*job, part=part, parts=parts)))
    except Exception:
        conn.send(("error", traceback.format_exc(limit=3)))


def _work(conns, others, prepare: Callable[[], None], draw: Callable) -> None:
    """The first worker process: close the parent's ends (the parent's death then reads
    as EOF), import what the figures need, fork the other workers (each keeps its own
    connection), then serve the first share."""
    for other in others:
        other.close()
    try:
        prepare()
    except KeyboardInterrupt:
        return
    parts = len(conns)
    children = []
    for part in range(1, parts):
        pid = os.fork()
        if pid == 0:  # a further worker: only its own connection stays open
            code = 0
            try:
                for j, c in enumerate(conns):
                    if j != part:
                        c.close()
                _serve(conns[part], part, parts, draw)
            except BaseException:
                code = 1
            finally:
                os._exit(code)
        children.append(pid)
        conns[part].close()
    try:
        _serve(conns[0], 0, parts, draw)
    finally:
        for pid in children:  # reaped here, so their CPU time counts as the command's
            try:
                os.waitpid(pid, 0)
            except ChildProcessError:
                pass


class Painter:
    """Draws ``draw(result, folder, part=, parts=) -> [file names]`` once, beside the
    computation: with ``parts`` workers, worker ``part`` draws its share of the figures.

    Create it before the first JAX computation of the process (so the workers can be
    forked cleanly); :meth:`submit` hands them the result, :meth:`names` waits for the
    files (in the order of the shares), :meth:`close` (or leaving a ``with`` block) ends
    the workers.
    """

    def __init__(self, prepare: Callable[[], None], draw: Callable, workers: int | None = None):
        self._draw, self._conns, self._proc, self._thread, self._future = draw, [], None, None, None
        if workers is None:
            workers = min(MAX_WORKERS, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                          else os.cpu_count() or 1)
        if sys.platform.startswith("linux") and not _jax_running():
            ctx = multiprocessing.get_context("fork")
            pipes = [ctx.Pipe() for _ in range(max(1, int(workers)))]
            self._conns = [p[0] for p in pipes]
            children = [p[1] for p in pipes]
            self._proc = ctx.Process(target=_work, args=(children, self._conns, prepare, draw), daemon=True,
                                     name="jaxgear-figures")
            self._proc.start()
            for child in children:
                child.close()
        else:
            self._thread = ThreadPoolExecutor(1, thread_name_prefix="jaxgear-figures")
            self._thread.submit(prepare)

    @property
    def forked(self) -> bool:
        """Whether the figures are drawn by worker processes."""
        return self._proc is not None

    @property
    def workers(self) -> int:
        """How many workers share the figures (1: a thread of this process)."""
        return len(self._conns) if self._proc is not None else 1

    def submit(self, result, folder: Path) -> None:
        """Start drawing the figures of ``result`` into ``folder``."""
        if self._proc is not None:
            for conn in self._conns:
                conn.send((result, str(folder)))
        else:
            self._future = self._thread.submit(self._draw, result, str(folder), part=0, parts=1)

    def names(self) -> list[str]:
        """The files drawn (waits for them); raises what drawing raised."""
        if self._proc is None:
            return self._future.result()
        names, errors = [], []
        for conn in self._conns:
            try:
                status, value = conn.recv()
            except EOFError:
                raise RuntimeError(f"a figure process ended without drawing (exit code {self._proc.exitcode})"
                                   ) from None
            if status == "ok":
                names.extend(value)
            else:
                errors.append(value)
        if errors:
            raise RuntimeError("drawing the figures failed:\n" + "\n".join(errors))
        return names

    def close(self) -> None:
        if self._proc is not None:
            if self._proc.is_alive():
                for conn in self._conns:
                    try:
                        conn.send(None)
                    except OSError:
                        pass
                self._proc.join(5)
                if self._proc.is_alive():
                    self._proc.terminate()
                    self._proc.join()
            for conn in self._conns:
                conn.close()
        elif self._thread is not None:
            self._thread.shutdown(wait=True)

    def __enter__(self) -> Painter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
