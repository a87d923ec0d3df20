"""The runner of the sweeps: their output folder, kill-and-resume checkpoints and progress.

The sweep functions (:func:`~jaxgear.bifurcation_diagram`, :func:`~jaxgear.basin_sweep`,
:func:`~jaxgear.basin_map`, :func:`~jaxgear.parameter_map`) compute and return their
results; a :class:`Runner` holds every file of theirs (the folder ``out`` with its
``manifest.json``, ``parts/`` and the final result file, written by
:mod:`._checkpoint`), the split of a basin sweep's values over processes through that
folder, and the progress bars. The command line builds one runner per command.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from .._batching import progress_bar
from .._checks import article, check_bool
from .._devices import cell_processes, process_count, process_index, wait_for_parts
from .._io import load
from ._checkpoint import Checkpoint, checkpoint_on_zero, open_shared_checkpoint

__all__ = ["Runner", "MOVED", "sweep_runner"]

MOVED = ("out", "restart", "progress", "save")
"""The keywords the sweep functions took before the runner held them (each now a field of
:class:`Runner`)."""


@dataclasses.dataclass(frozen=True)
class Runner:
    """Where a sweep's files go and how it reports: output folder, checkpoints, resume, progress.

    ``Runner()`` writes nothing and shows progress bars. With ``out=DIR`` a sweep saves
    every finished block to ``DIR/parts`` as it ends (a bifurcation diagram's or parameter
    map's block of values ``NAME_NNNNN.npz``, a basin sweep's or map's analysis at one
    value ``value_NNNNN.nc``), each tagged with the settings, under ``DIR/manifest.json``
    (the settings and their hash); the same call rerun after a kill resumes from the
    parts, and a bifurcation diagram whose file is already whole in ``DIR`` is read, not
    computed. At the end it writes the result into ``DIR`` (``bifurcation.nc``,
    ``basins.nc``, ``basin_map.nc`` or ``parameter_map.nc``).

    Attributes:
        out: the kill-and-resume folder (``None``: nothing written, every block computed).
        restart: discard a folder of a sweep with other settings (without it, such a folder
            raises ``ValueError`` naming every differing setting).
        progress: show progress bars.
        save: write the result file into ``out``; ``False``: only the parts (the command
            line writes the result with its summary and figures as one set).

    Run one sweep with ``runner.run(jaxgear.basin_sweep, system, params, "b", values,
    grid)``, or pass ``runner=`` to the sweep function.

    Run as several JAX processes (:func:`jaxgear._devices.initialize`): process ``p`` of
    ``P`` of a basin sweep or map computes the values ``i % P == p`` into ``out``
    (required then, a folder every process sees) and reads the others' parts; the
    processes of a bifurcation diagram or parameter map compute every block together,
    and process 0 alone keeps ``out`` (it need not be shared). Only process 0 writes the
    result file.
    """

    out: str | os.PathLike | None = None
    restart: bool = False
    progress: bool = True
    save: bool = True

    def __post_init__(self):
        if self.out is not None and not (isinstance(self.out, os.PathLike) or (isinstance(self.out, str) and self.out)):
            raise ValueError(f"out={self.out!r} must be a folder (a str or os.PathLike) or None (nothing written).")
        for name in ("restart", "progress", "save"):
            check_bool(getattr(self, name), name)

    def run(self, sweep, *args, **kwargs):
        """``sweep(*args, runner=self, **kwargs)``: one sweep function run by this runner."""
        return sweep(*args, runner=self, **kwargs)

    def bar(self, total: int, label: str, unit: str = "value"):
        """A progress bar of ``total`` steps (hidden without ``progress``)."""
        return progress_bar(total, label, self.progress, unit=unit)

    def blocks(self, kind: str, settings: dict) -> Checkpoint:
        """The checkpoint of a ``kind`` sweep whose processes compute every block together
        (:func:`._checkpoint.checkpoint_on_zero`: process 0 keeps ``out``); its
        :meth:`Checkpoint.block` gives each block, saved or computed."""
        return checkpoint_on_zero(self.out, kind, settings, self.restart)

    def values(self, settings: dict, n: int, compute, per_block: int, label: str, expected: str) -> list:
        """The results of ``n`` values (``compute(indices)``: the results of a block of at
        most ``per_block`` indices; ``expected``: their type in :func:`jaxgear.load`),
        resumable: each result is saved to ``out/parts/value_NNNNN.nc`` (``NNNNN`` its
        index) as its block ends, and a rerun loads the saved ones (``settings``: the
        manifest's, with its ``kind``). With several JAX processes, process ``p`` of ``P``
        computes the indices ``i % P == p`` (``out`` required,
        :func:`._checkpoint.open_shared_checkpoint`) and reads the others' parts. A
        progress bar ``label`` counts the finished ones."""
        kind = settings["kind"]
        n_proc, me = process_count(), process_index()
        if n_proc > 1 and self.out is None:
            raise ValueError(f"{article(kind)} sweep over {n_proc} processes needs an output folder, "
                             "jaxgear.Runner(out=...) (a folder every process can read): each process saves its "
                             "values there and process 0 assembles them.")
        ck = open_shared_checkpoint(self.out, kind, settings, self.restart)

        def read(i):
            return ck.load_result(f"value_{i:05d}.nc", lambda path: load(path, expected=expected))

        results: list = [None] * n
        bar = self.bar(n, label)
        todo = []
        for i in range(n):
            results[i] = read(i) if ck.has(f"value_{i:05d}.nc") else None
            if results[i] is None:
                if i % n_proc == me:  # this process's share of the values
                    todo.append(i)
            else:
                bar.update(1)
        for b in range(0, len(todo), per_block):
            block = todo[b:b + per_block]
            for i, r in zip(block, compute(block)):
                if ck.dir is not None:
                    r.save(ck.path(f"value_{i:05d}.nc"))
                results[i] = r
            bar.update(len(block))
        bar.close()
        if n_proc > 1:  # the other processes' values, from their parts
            missing = [i for i in range(n) if results[i] is None]
            wait_for_parts([ck.path(f"value_{i:05d}.nc") for i in missing])
            for i in missing:
                results[i] = read(i)
                if results[i] is None:
                    raise RuntimeError(f"the part of value {i} written by another process is unreadable; rerun.")
        return results

    def finished(self, name: str, expected: str, same):
        """The result saved as ``out/name`` (of type ``expected``) when ``same(result)``
        says it is the one asked for, else ``None`` (no ``out``, ``restart``, no such file,
        an unreadable one or another result: computed again and replaced)."""
        if self.out is None or self.restart or not (Path(self.out) / name).is_file():
            return None
        try:
            result = load(Path(self.out) / name, expected=expected)
        except (OSError, ValueError):
            return None
        return result if same(result) else None

    def write(self, result, name: str) -> None:
        """Write ``result`` as ``out/name`` (with ``out`` and ``save``; process 0 alone)."""
        if self.out is not None and self.save and cell_processes()[0] == 0:
            result.save(Path(self.out) / name)


def _shown(value) -> str:
    return repr(os.fspath(value)) if isinstance(value, os.PathLike) else repr(value)


def sweep_runner(runner: Runner | None, changes: dict, sweep: str) -> Runner:
    """The runner of a call of the sweep function ``sweep`` (``None``: ``Runner()``);
    ``TypeError`` pointing to :class:`Runner` where its keyword arguments ``changes`` hold
    one of :data:`MOVED`."""
    moved = [k for k in MOVED if k in changes]
    if moved:
        fields = ", ".join(f"{k}={_shown(changes[k])}" for k in moved)
        raise TypeError(f"{sweep}() no longer takes {', '.join(k + '=' for k in moved)}: output folders, "
                        f"checkpoints, resume and progress bars moved to jaxgear.Runner; pass "
                        f"runner=jg.Runner({fields}), or call jg.Runner({fields}).run(jg.{sweep}, ...).")
    if runner is None:
        return Runner()
    if not isinstance(runner, Runner):
        raise ValueError(f"runner={runner!r} must be a jaxgear.Runner (or None: nothing written, progress shown).")
    return runner
