"""Past one device: batches split over every local device, and the multi-process runtime.

Every batch axis of jaxgear (the cells of an analysis, the seeds of shooting, the values
of a sweep) is split over the local devices (:func:`local_devices`: every GPU of this
process, or the CPU devices that ``XLA_FLAGS=--xla_force_host_platform_device_count=N``
makes), in one of two ways:

- stateless batched maps (the values of an independent sweep, the seeds of shooting, the
  cell images of the cell maps) run as one ``jax.jit`` of a ``jax.shard_map`` over a 1-D
  mesh of the local devices (:func:`shard_rows`): the batch is sharded
  (``NamedSharding(mesh, P("batch"))``), everything else replicated, and each device runs
  the kernel of one device on its local block. The per-device body sees local shapes
  only, so the integrator's compiled CPU kernel (an XLA FFI custom call, which has no
  sharding rule) runs in it unchanged;
- the direct method's lane pools run one pool per device over one block of the rows
  (:func:`split_rows`), also as one ``jax.jit`` of a ``jax.shard_map`` over the mesh: each
  device runs the pool's loop of one device on its block, and the host makes the
  data-dependent decisions (stop, grow the attractor tables, shrink the pools) from the
  devices' progress rows (:mod:`jaxgear.analysis._placement`).

Either way each row is computed alone by the kernel of one device, so results do not
depend on the device count (bit for bit where the batch shape a device runs does not
change the kernel's round-off, see :func:`shard_rows`).

Several processes (one per host or GPU, :func:`initialize`): an analysis splits its
cells over the devices of every process (the direct method's blocks are exchanged with
:func:`allgather`, every process returns the whole result); a bifurcation diagram or a
parameter map splits each block of its independent values over the processes and
exchanges the parts with :func:`allgather`; a basin sweep splits its values instead:
process ``p`` of ``P`` computes the values ``i`` with ``i % P == p``, saves each to the
sweep's checkpoint folder (shared by the processes), and process 0 assembles the parts
and writes the result file (:func:`wait_for_parts`).
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from ._batching import pad_rows

__all__ = ["local_devices", "put", "placement", "split_rows", "shard_rows", "batch_mesh",
           "initialize", "process_index", "process_count", "wait_for_parts", "cell_processes",
           "values_over_processes", "allgather", "rows_over_processes"]

BATCH = "batch"  # the name of the mesh axis the batches are sharded over


def local_devices() -> list:
    """The devices this process computes on (all of the default backend's local devices)."""
    return list(jax.local_devices())


def put(tree, device):
    """``tree`` with its JAX and numpy array leaves committed to ``device`` (other leaves
    kept as they are). With one device in all, the leaves are placed there uncommitted:
    the same device, and calls then share their compiled computations with the calls
    of the rest of the library (a computation compiles once per input placement)."""
    sharding = placement(device)

    def one(a):
        if not isinstance(a, (jax.Array, np.ndarray)):
            return a
        return jax.device_put(a) if sharding is None else jax.device_put(a, sharding)

    return jax.tree.map(one, tree)


def placement(device):
    """The sharding :func:`put` commits arrays to on ``device``: ``None`` (uncommitted)
    when there is no device or one device in all."""
    if device is None or jax.device_count() == 1:
        return None
    return jax.sharding.SingleDeviceSharding(device)


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


# ------------------------------------------------------------------ one program, sharded
@functools.cache
def batch_mesh(devices: tuple) -> Mesh:
    """The 1-D mesh (axis ``"batch"``) of ``devices``, in their order."""
    return Mesh(np.array(devices, dtype=object), (BATCH,))


def _spec(axis: int) -> P:
    """The partition spec of an array whose axis ``axis`` is the batch."""
    return P(*([None] * int(axis)), BATCH)


@eqx.filter_jit
def _sharded_call(kernel, mesh, batch, axis, out_axes, args):
    """``kernel(*args)`` as one ``shard_map`` over ``mesh``: ``args[batch]`` split along
    ``axis``, the other array leaves replicated, the outputs concatenated along
    ``out_axes``. The non-array leaves of ``args`` are static, as in ``kernel``'s own jit."""
    dyn, static = eqx.partition(args, eqx.is_array)
    rest = dyn[:batch] + (None,) + dyn[batch + 1:]

    def body(x, rest):
        a = list(eqx.combine(rest, static))
        a[batch] = x
        return kernel(*a)

    # check_vma off: the body has no collectives and every output is sharded (a loop whose
    # carry starts from replicated values only would otherwise need jax.lax.pcast)
    return jax.shard_map(body, mesh=mesh, in_specs=(_spec(axis), P()), out_specs=jax.tree.map(_spec, out_axes),
                         check_vma=False)(dyn[batch], rest)


@eqx.filter_jit
def _partitioned_call(kernel, mesh, batch, axis, out_axes, args):
    """``kernel(*args)`` partitioned by XLA (no ``shard_map``): ``args[batch]`` arrives
    split along ``axis`` and the outputs leave split along ``out_axes``."""
    out = kernel(*args)
    return jax.tree.map(lambda ax, sub: jax.tree.map(
        lambda a: jax.lax.with_sharding_constraint(a, NamedSharding(mesh, _spec(ax))), sub), out_axes, out)


def shard_rows(kernel: Callable, *args, batch: int = 0, axis: int = 0, out_axes=0, per_device: int | None = None,
               partitioned_by_xla: bool = False):
    """``kernel(*args)`` with the batch ``args[batch]`` split over the local devices: the
    outputs as numpy arrays (a pytree like ``kernel``'s).

    ``kernel`` is a jitted computation (``eqx.filter_jit``) that treats the entries along
    axis ``axis`` of ``args[batch]`` independently; ``out_axes`` (an int, or a prefix of
    the output's pytree of ints) is the batch axis of each output. The batch is cut into
    one block per device: ``per_device`` entries each (the batch then holds at most one
    block per local device), or else ``n`` entries split evenly over ``D = min(devices,
    n)`` devices (padded to a multiple of ``D`` by repeating its first entry). The batch
    is placed with ``NamedSharding(mesh, P("batch"))``, every other array replicated
    (``P()``), one ``jax.jit`` of a ``jax.shard_map`` runs ``kernel`` on each device's
    block, and the padding is stripped from the outputs. A device computes what one
    device computes on a batch of its block's shape: with ``per_device`` set to the chunk
    of one device the results are those of one device bit for bit. An even split changes
    the batch shape; the results are still bit for bit those of one device when the
    kernel's round-off does not depend on its batch shape (true of the integrators,
    checked in ``tests/test_devices.py``; not of the shooting kernel). With one block
    this is the plain call ``kernel(*args)``.

    ``partitioned_by_xla``: one ``jax.jit`` whose batch XLA partitions over the devices
    instead of a ``shard_map``, for kernels that hold lineax solves (the shooting kernel:
    lineax 0.1 refuses its own operators inside ``shard_map``, whose values carry the
    manual mesh in their shapes). The results are still those of one device bit for bit
    (``tests/test_devices.py``).
    """
    X = args[batch]
    n = int(X.shape[axis])
    local = local_devices()
    per = -(-n // max(1, min(len(local), n))) if per_device is None else int(per_device)
    D = max(1, -(-n // per))
    if D > len(local):
        raise ValueError(f"{n} entries in blocks of {per} need {D} devices; there are {len(local)}.")
    if D == 1:
        return jax.tree.map(np.asarray, kernel(*args))
    mesh = batch_mesh(tuple(local[:D]))
    Xp = pad_rows(np.asarray(X), D * per, axis)
    rep = NamedSharding(mesh, P())
    args = tuple(jax.device_put(Xp, NamedSharding(mesh, _spec(axis))) if i == batch
                 else jax.tree.map(lambda a: jax.device_put(a, rep) if eqx.is_array(a) else a, a)
                 for i, a in enumerate(args))
    call = _partitioned_call if partitioned_by_xla else _sharded_call
    out = call(kernel, mesh, int(batch), int(axis), out_axes, args)
    strip = lambda ax, sub: jax.tree.map(lambda a: np.asarray(a)[(slice(None),) * ax + (slice(0, n),)], sub)
    return jax.tree.map(strip, out_axes, out)


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
    """``(index, count)`` of the processes an analysis splits its cells (a sweep its
    independent values, :func:`rows_over_processes`) over: all the processes of the JAX
    program, or this one alone inside :func:`values_over_processes`."""
    if _VALUES_SPLIT.get():
        return 0, 1
    return process_index(), process_count()


def allgather(x: np.ndarray) -> np.ndarray:
    """``x`` of every process, stacked in process order: ``(processes, *x.shape)`` (each
    process passes an array of the same shape and dtype)."""
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(np.asarray(x)))


def rows_over_processes(fn: Callable, X: np.ndarray) -> np.ndarray:
    """``fn(X)`` for every row of ``X`` with the rows split over the processes
    (:func:`cell_processes`): process ``p`` of ``P`` runs ``fn`` on the ``p``-th contiguous
    block of ``ceil(n / P)`` rows (padded with ``X``'s first row: the same shape on every
    process), and the blocks are exchanged (:func:`allgather`), so every process returns
    the whole, identical array (``fn`` returns one array whose axis 0 are its rows, each
    row computed alone). One process: ``fn(X)``."""
    me, count = cell_processes()
    if count == 1:
        return fn(X)
    n = len(X)
    sub = -(-n // count)
    mine = X[min(me * sub, n): min((me + 1) * sub, n)]
    mine = np.concatenate([mine, np.repeat(X[:1], sub - len(mine), axis=0)], axis=0)
    every = allgather(np.asarray(fn(mine)))  # (processes, sub, ...)
    return np.concatenate([every[q, : max(0, min((q + 1) * sub, n) - q * sub)] for q in range(count)], axis=0)


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
