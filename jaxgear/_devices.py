"""Past one device: batches split over every local device, and the multi-process runtime.

Every batch axis of jaxgear (the cells of the direct analysis, the seeds of shooting, the
values of a sweep) is cut into one contiguous block per local device
(:func:`local_devices`: every GPU of this process, or the CPU devices that
``XLA_FLAGS=--xla_force_host_platform_device_count=N`` makes). Each block runs the same
compiled program a single device runs, its inputs committed to its device
(``jax.device_put``), driven from one Python thread per device: JAX dispatch is
thread-safe and asynchronous, so the devices work at the same time. Per-device programs
rather than one partitioned program (``NamedSharding`` / ``shard_map``) because the
direct method's pool takes data-dependent host decisions per block, and because the
integrator's compiled CPU kernel (an XLA FFI custom call) has no sharding rule: each
lane computes exactly what it computes on one device, so results do not depend on the
device count.

Several processes (one per host or GPU, :func:`initialize`): an analysis splits its
cells over the devices of every process (the direct method's blocks are exchanged with
:func:`allgather`, every process returns the whole result); a basin sweep splits its
values instead: process ``p`` of ``P`` computes the values ``i`` with ``i % P == p``,
saves each to the sweep's checkpoint folder (shared by the processes), and process 0
assembles the parts and writes the result file (:func:`wait_for_parts`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import contextvars
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import numpy as np

__all__ = ["local_devices", "on_devices", "put", "split_rows", "map_rows", "initialize", "process_index",
           "process_count", "wait_for_parts", "cell_processes", "values_over_processes", "allgather"]


def local_devices() -> list:
    """The devices this process computes on (all of the default backend's local devices)."""
    return list(jax.local_devices())


def put(tree, device):
    """``tree`` with its JAX and numpy array leaves committed to ``device`` (other leaves
    kept as they are). With one device in all, the leaves are placed there uncommitted:
    the same device, and calls then share their compiled computations with the calls
    of the rest of the library (a computation compiles once per input placement)."""
    single = jax.device_count() == 1

    def one(a):
        if not isinstance(a, (jax.Array, np.ndarray)):
            return a
        return jax.device_put(a) if single else jax.device_put(a, device)

    return jax.tree.map(one, tree)


def on_devices(fn: Callable, jobs: Sequence, devices: Sequence | None = None) -> list:
    """``[fn(job, device)]`` for each job and its device (``jobs[i]`` on ``devices[i]``),
    one thread per device so that the devices compute at the same time."""
    devices = local_devices() if devices is None else list(devices)
    if len(jobs) > len(devices):
        raise ValueError(f"{len(jobs)} jobs for {len(devices)} devices")
    if len(jobs) == 1:
        return [fn(jobs[0], devices[0])]
    with concurrent.futures.ThreadPoolExecutor(max_workers=len(jobs)) as pool:
        futures = [pool.submit(fn, job, dev) for job, dev in zip(jobs, devices)]
        return [f.result() for f in futures]


def split_rows(n: int, parts: int) -> list[tuple[int, int]]:
    """``(start, stop)`` of ``parts`` contiguous blocks of near-equal size covering
    ``range(n)`` (the first ``n % parts`` one row longer; empty blocks dropped)."""
    size, extra = divmod(int(n), int(parts))
    out, start = [], 0
    for p in range(int(parts)):
        stop = start + size + (p < extra)
        if stop > start:
            out.append((start, stop))
        start = stop
    return out


def map_rows(fn: Callable, X: np.ndarray, devices: Sequence | None = None, min_rows: int = 1) -> list:
    """``fn(rows, device)`` on one block of the rows of ``X`` per device (blocks of at
    least ``min_rows`` rows; one block on the first device when ``X`` is smaller), in
    device order: the list of what it returns for each block, whose rows concatenated are
    ``X``'s."""
    devices = local_devices() if devices is None else list(devices)
    D = max(1, min(len(devices), len(X) // max(1, int(min_rows))))
    blocks = split_rows(len(X), D)
    return on_devices(lambda ab, dev: fn(X[ab[0]:ab[1]], dev), blocks, devices[:len(blocks)])


# ------------------------------------------------------------------ several processes
_VALUES_SPLIT = contextvars.ContextVar("jaxgear_values_over_processes", default=False)


@contextlib.contextmanager
def values_over_processes():
    """Inside this block each process computes its own values (a sweep split over the
    processes): an analysis then splits its cells over this process's devices only."""
    token = _VALUES_SPLIT.set(True)
    try:
        yield
    finally:
        _VALUES_SPLIT.reset(token)


def cell_processes() -> tuple[int, int]:
    """``(index, count)`` of the processes an analysis splits its cells over: all the
    processes of the JAX program, or this one alone inside :func:`values_over_processes`."""
    if _VALUES_SPLIT.get():
        return 0, 1
    return process_index(), process_count()


def allgather(x: np.ndarray) -> np.ndarray:
    """``x`` of every process, stacked in process order: ``(processes, *x.shape)`` (each
    process passes an array of the same shape and dtype)."""
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(np.asarray(x)))


def initialize(coordinator_address: str | None = None, num_processes: int | None = None,
               process_id: int | None = None) -> None:
    """Start JAX's multi-process runtime (``jax.distributed.initialize``): without
    arguments it detects Slurm and Open MPI (or reads ``JAX_COORDINATOR_ADDRESS``,
    ``JAX_NUM_PROCESSES``, ``JAX_PROCESS_ID``); call it once, first, in every process."""
    env = os.environ
    coordinator_address = coordinator_address or env.get("JAX_COORDINATOR_ADDRESS")
    if num_processes is None and "JAX_NUM_PROCESSES" in env:
        num_processes = int(env["JAX_NUM_PROCESSES"])
    if process_id is None and "JAX_PROCESS_ID" in env:
        process_id = int(env["JAX_PROCESS_ID"])
    jax.config.update("jax_cpu_collectives_implementation", "gloo")  # CPU processes exchange results
    jax.distributed.initialize(coordinator_address=coordinator_address, num_processes=num_processes,
                               process_id=process_id)


def process_index() -> int:
    """This process's index (0 when JAX runs as one process)."""
    return int(jax.process_index())


def process_count() -> int:
    """Number of processes of the JAX program (1 unless :func:`initialize` started several)."""
    return int(jax.process_count())


def wait_for_parts(paths: Sequence[Path], timeout: float | None = None, poll: float = 0.2) -> None:
    """Wait until every file of ``paths`` exists (the parts other processes write;
    ``timeout`` seconds at most, then ``TimeoutError`` naming the first missing)."""
    t0 = time.monotonic()
    while True:
        missing = [p for p in paths if not Path(p).is_file()]
        if not missing:
            return
        if timeout is not None and time.monotonic() - t0 > timeout:
            raise TimeoutError(f"{len(missing)} parts still missing after {timeout:.0f} s, e.g. {missing[0]}")
        time.sleep(poll)
