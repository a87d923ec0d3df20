"""Where a lane pool runs: one device, a mesh of local devices, and several processes.

A placement is a strategy object with one interface (:class:`OneDevice`,
:class:`DeviceMesh`): ``start`` the pool over one queue block per device, ``run`` rounds,
``resize`` it, ``collect`` each block's labels and tables. Each of its steps is one
``jax.jit`` (compiled on its first call, from the real arrays); the host makes the
data-dependent decisions from the progress rows (:func:`jaxgear.analysis._pool.drive`).

On a mesh the blocks run in one SPMD program: a ``jax.jit`` of a ``jax.shard_map`` over
the 1-D mesh of the devices (:func:`jaxgear._devices.batch_mesh`), each device's pool
state a block along a leading device axis; each device runs the pool of one device on
its block (its own ``while_loop`` and attractor table, no collectives). The blocks are
padded to one shape; a block's real length is a per-device operand, so the padding
never enters a lane.

:func:`run_blocks` cuts a queue into one block per device of every process, runs this
process's blocks, exchanges them between processes (:func:`jaxgear._devices.allgather`)
and merges the attractors the blocks registered (:func:`jaxgear._matching.same_attractor`).
The merged table lists, per value, the known attractors (in their order) and then the
attractors found later in the order of the first cell of the queue they label: an order
that does not depend on the number of devices.
"""

from __future__ import annotations

import functools

import jax
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from .._batching import pad_rows, power_of_two_at_least
from .._devices import BATCH, allgather, batch_mesh, cell_processes, local_devices, put, split_rows
from .._matching import same_attractor
from ._lanes import (
    AttractorTable,
    SlotKind,
    candidate_of,
    characterise,
    init_pool,
    resize,
    run_rounds,
    slot_code,
    slot_kind,
    table_slots,
    with_candidate,
)
from ._pool_options import PoolOptions

__all__ = ["OneDevice", "DeviceMesh", "run_blocks", "MIN_BLOCK_CELLS", "queue_length"]

MIN_BLOCK_CELLS = 16
"""Fewest cells a device's block holds (smaller queues run on the first device alone)."""

QUEUE_STEP = 1024
"""Queues are padded to the next power of two (at least :data:`QUEUE_MIN`) up to this
length, to a multiple of it above."""

QUEUE_MIN = 64
"""Shortest padded queue: an analysis of a few cells and its label uncertainty share a pool."""


def queue_length(n: int) -> int:
    """The length a queue of ``n`` cells is padded to (the padding never enters a lane;
    the real length is a traced operand): queues of nearby lengths, such as an analysis and
    its label uncertainty, share one compiled pool."""
    if n <= QUEUE_STEP:
        return power_of_two_at_least(n, QUEUE_MIN)
    return -(-int(n) // QUEUE_STEP) * QUEUE_STEP


# ----------------------------------------------------------------------------- one device
@functools.partial(jax.jit, static_argnums=(0, 1))
def _init_one(L: int, M: int, X, Xrow, n_real, boxes, attractors: AttractorTable):
    return init_pool(L, M, X, Xrow, attractors, boxes, n_real=n_real)


@functools.partial(jax.jit, static_argnames=("system", "integrator", "o", "L_min"), donate_argnums=(0,))
def _run_one(s, system, params, integrator, o: PoolOptions, boxes, X, Xrow, n_real, L_min: int, rounds):
    return run_rounds(s, system, params, integrator, o, boxes, X, Xrow, n_real, L_min, rounds)


_resize_one = jax.jit(resize, static_argnames=("L", "A"))


@functools.partial(jax.jit, static_argnames=("system", "integrator", "o"))
def _characterise_one(c, system, params, integrator, o: PoolOptions, boxes):
    return characterise(system, params, integrator, o, boxes, c)


class OneDevice:
    """The pool of one queue on one device (``None``: the default device, uncommitted)."""

    def __init__(self, device=None):
        self.device = device

    def start(self, params, boxes, X_blocks, row_blocks, L: int, M: int, attractors: AttractorTable,
              queue: int = 0):
        """The pool over the one queue block ``X (n, dim)`` (rows ``(n,)``), padded to
        :func:`queue_length` (or to ``queue`` when longer: the shape of another pool whose
        compiled program this one shares), starting from the attractor tables
        ``attractors``, and the arrays it reads."""
        (X,), (Xrow,) = X_blocks, row_blocks
        self.n_real = len(X)
        n = max(queue_length(len(X)), int(queue))
        data = put((params, boxes, pad_rows(X, n), pad_rows(Xrow, n), np.int32(len(X))), self.device)
        return _init_one(L, M, data[2], data[3], data[4], data[1], put(attractors, self.device)), data

    def run(self, s, data, system, integrator, o: PoolOptions, L_min: int, rounds):
        params, boxes, X, Xrow, n_real = data
        s, info = _run_one(s, system, params, integrator, o, boxes, X, Xrow, n_real, L_min, rounds)
        return s, np.asarray(info).reshape(1, -1)

    def characterise(self, s, data, system, integrator, o: PoolOptions):
        """The pool with the candidate its round stopped at characterised."""
        params, boxes = data[:2]
        return with_candidate(s, _characterise_one(candidate_of(s), system, params, integrator, o, boxes))

    def resize(self, s, L=None, A=None):
        return _resize_one(s, L=L, A=A)

    def collect(self, s) -> list[tuple]:
        """``[(labels, used, attractor tables)]`` of the one block (numpy)."""
        lab, use, tables = jax.tree.map(np.asarray, jax.device_get((s.labels, s.used, s.attractors)))
        return [(lab[:self.n_real], use[:self.n_real], tables)]


# ----------------------------------------------------------------------------- a mesh of devices
def _local(tree):
    """A device's block of ``tree`` (inside ``shard_map``), without its device axis."""
    return jax.tree.map(lambda a: a[0], tree)


def _stacked(tree):
    """``tree`` as a device's block along the leading device axis."""
    return jax.tree.map(lambda a: a[None], tree)


def _per_device(mesh, body, replicated=()):
    """``body`` as one ``shard_map`` over ``mesh``: the arguments (but those at the
    positions ``replicated``) and the outputs split along their leading device axis. No
    collectives: ``check_vma`` off, as in :func:`jaxgear._devices.shard_rows`."""
    def specs(*args):
        return tuple(P() if i in replicated else P(BATCH) for i in range(len(args)))

    return lambda *args: jax.shard_map(body, mesh=mesh, in_specs=specs(*args), out_specs=P(BATCH),
                                       check_vma=False)(*args)


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _init_mesh(mesh, L: int, M: int, X, Xrow, n_real, boxes, attractors: AttractorTable):
    def body(X, Xrow, n_real, boxes, attractors):
        return _stacked(init_pool(L, M, X[0], Xrow[0], _local(attractors), boxes, n_real=n_real[0]))

    return _per_device(mesh, body, replicated=(3,))(X, Xrow, n_real, boxes, attractors)


@functools.partial(jax.jit, static_argnames=("mesh", "system", "integrator", "o", "L_min"), donate_argnums=0)
def _run_mesh(s, system, params, integrator, o: PoolOptions, boxes, X, Xrow, n_real, L_min: int, rounds, mesh):
    def body(s, params, boxes, X, Xrow, n_real, rounds):
        s, info = run_rounds(_local(s), system, params, integrator, o, boxes, X[0], Xrow[0], n_real[0], L_min,
                             rounds)
        return _stacked((s, info))

    return _per_device(mesh, body, replicated=(1, 2, 6))(s, params, boxes, X, Xrow, n_real, rounds)


@functools.partial(jax.jit, static_argnames=("mesh", "system", "integrator", "o"))
def _characterise_mesh(c, system, params, integrator, o: PoolOptions, boxes, mesh):
    def body(c, params, boxes):  # a block without a candidate passes unchanged
        return _stacked(characterise(system, params, integrator, o, boxes, _local(c)))

    return _per_device(mesh, body, replicated=(1, 2))(c, params, boxes)


@functools.partial(jax.jit, static_argnames=("mesh", "L", "A"))
def _resize_mesh(s, mesh, L: int | None = None, A: int | None = None):
    return _per_device(mesh, lambda s: _stacked(resize(_local(s), L=L, A=A)))(s)


class DeviceMesh:
    """One pool per device of ``mesh`` (a 1-D mesh of local devices), one block of the
    queue each, in one sharded program."""

    def __init__(self, mesh):
        self.mesh = mesh

    def start(self, params, boxes, X_blocks, row_blocks, L: int, M: int, attractors: AttractorTable,
              queue: int = 0):
        """The pools over the blocks ``[X (n_d, dim)]`` (rows ``[(n_d,)]``), padded to one
        shape (:func:`queue_length` of the longest, or ``queue`` when longer) with copies of
        each block's first entry (never taken into a lane), each starting from the
        attractor tables ``attractors``."""
        D = len(X_blocks)
        n_real = np.array([len(b) for b in X_blocks], np.int32)
        n = max(queue_length(int(n_real.max())), int(queue))
        split, rep = NamedSharding(self.mesh, P(BATCH)), NamedSharding(self.mesh, P())

        def padded(blocks):
            return jax.device_put(np.stack([pad_rows(b, n) for b in blocks]), split)

        data = (jax.device_put(params, rep), jax.device_put(boxes, rep), padded(X_blocks), padded(row_blocks),
                jax.device_put(n_real, split))
        tables = jax.device_put(jax.tree.map(lambda a: np.broadcast_to(a, (D, *a.shape)), attractors), split)
        self.n_real = n_real
        return _init_mesh(self.mesh, L, M, data[2], data[3], data[4], data[1], tables), data

    def run(self, s, data, system, integrator, o: PoolOptions, L_min: int, rounds):
        params, boxes, X, Xrow, n_real = data
        s, info = _run_mesh(s, system, params, integrator, o, boxes, X, Xrow, n_real, L_min, rounds, self.mesh)
        return s, np.asarray(info).reshape(-1, 6)

    def characterise(self, s, data, system, integrator, o: PoolOptions):
        """The pools with the candidates their rounds stopped at characterised."""
        params, boxes = data[:2]
        return with_candidate(s, _characterise_mesh(candidate_of(s), system, params, integrator, o, boxes, self.mesh))

    def resize(self, s, L=None, A=None):
        return _resize_mesh(s, self.mesh, L=L, A=A)

    def collect(self, s) -> list[tuple]:
        """``[(labels, used, attractor tables)]`` of each device's block (numpy)."""
        lab, use, tables = jax.tree.map(np.asarray, jax.device_get((s.labels, s.used, s.attractors)))
        return [(lab[d, :m], use[d, :m], jax.tree.map(lambda a, d=d: a[d], tables)) for d, m in enumerate(self.n_real)]


# ----------------------------------------------------------------------------- blocks and processes
def _my_blocks(n: int):
    """The blocks ``(start, stop)`` a queue of ``n`` cells is cut into for the local devices
    of every process, the indices of this process's blocks, and its placement for them
    (:class:`OneDevice` for one block, :class:`DeviceMesh` for several, ``None``)."""
    devices = local_devices()
    me, procs = cell_processes()
    blocks = split_rows(n, max(1, min(procs * len(devices), n // MIN_BLOCK_CELLS)))
    mine = [i for i in range(len(blocks)) if i % procs == me]
    if not mine:
        return blocks, mine, None
    if len(mine) == 1:
        return blocks, mine, OneDevice(devices[0])
    return blocks, mine, DeviceMesh(batch_mesh(tuple(devices[:len(mine)])))


def run_blocks(drive, X: np.ndarray, rows: np.ndarray, attractors: AttractorTable, merge_tol: float,
               partition=None, like: int = 0):
    """Label the queue ``X (n, dim)`` (value rows ``rows (n,)``) in one pool per device of
    every process (``drive(placement, X_blocks, row_blocks) -> [(labels, used, attractor
    tables)]`` runs this process's blocks), starting from the attractor tables
    ``attractors`` (numpy). Returns ``(labels (n,), periods used (n,), merged tables)``
    (numpy), the whole queue's in every process. ``partition``: the fine partition of the
    pool's attractors of boxes (blocks' clouds that share boxes are one attractor).
    ``like``: the length of another queue whose blocks' pool shapes these share when
    they are no longer (``drive``'s ``queue``)."""
    me, procs = cell_processes()
    blocks, mine, placement = _my_blocks(len(X))
    queue = queue_length(-(-int(like) // len(blocks))) if like > len(X) else 0
    local = drive(placement, [X[blocks[i][0]:blocks[i][1]] for i in mine],
                  [rows[blocks[i][0]:blocks[i][1]] for i in mine], queue=queue) if mine else []
    results = dict(zip(mine, local))
    if procs > 1:
        results = _exchange(blocks, results, me, procs, len(local_devices()))
    labels, tables = _merge(attractors.counts, [(rows[a:b], results[i]) for i, (a, b) in enumerate(blocks)],
                            merge_tol, partition)
    used = np.concatenate([results[i][1] for i in range(len(blocks))])
    return labels, used, tables


def _exchange(blocks, local: dict, me: int, P: int, D: int) -> dict:
    """Every block's ``(labels, used, attractor tables)`` in every process, from each
    process's own blocks (``local``; block ``i`` is process ``i % P``'s slot ``i // P``)."""
    longest = max(b - a for a, b in blocks)
    some = next(iter(local.values()), None)
    A = int(allgather(np.array([some[2].n_slots if some is not None else 0])).max())
    shapes = allgather(np.array(some[2].points.shape if some is not None else (0, 0, 0, 0)))
    V, _, M, dim = (int(x) for x in shapes.max(axis=0))
    Q = int(allgather(np.array([some[2].clouds.shape[2] if some is not None else 0])).max())
    lab = np.full((D, longest), -9, np.int64)
    use = np.zeros((D, longest), np.int64)
    tables = AttractorTable(points=np.full((D, V, A, M, dim), np.nan),
                            codes=np.full((D, V, A), slot_code(SlotKind.EMPTY, M), np.int32),
                            counts=np.zeros((D, V), np.int32), clouds=np.full((D, V, A, Q, dim), np.nan))
    for i, (labels, used, t) in local.items():
        j = i // P
        lab[j, : len(labels)], use[j, : len(used)] = labels, used
        tables.points[j, :, : t.n_slots], tables.codes[j, :, : t.n_slots], tables.counts[j] = t.points, t.codes, t.counts
        tables.clouds[j, :, : t.n_slots] = t.clouds
    lab, use, tables = allgather(lab), allgather(use), jax.tree.map(allgather, tables)
    out = {}
    for i, (a, b) in enumerate(blocks):
        p, j = i % P, i // P
        out[i] = (lab[p, j, : b - a], use[p, j, : b - a], jax.tree.map(lambda x, p=p, j=j: x[p, j], tables))
    return out


def _box_set(partition, cloud) -> set:
    """The boxes (integer coordinate tuples) of the finite points of ``cloud (Q, dim)``."""
    lo, width = np.asarray(partition.lo), np.asarray(partition.width)
    pts = cloud[np.all(np.isfinite(cloud), axis=1)]
    return set(map(tuple, np.floor((pts - lo) / width).astype(np.int64)))


def same_boxes(partition, a, b, share: float = 0.5) -> bool:
    """Whether the clouds ``a, b (Q, dim)`` are one attractor of boxes: at least ``share`` of
    the boxes of the smaller lie among the other's."""
    A, B = _box_set(partition, a), _box_set(partition, b)
    if not A or not B:
        return False
    return len(A & B) >= share * min(len(A), len(B))


def _merge(n0, blocks, merge_tol: float, partition=None):
    """Merge the attractor tables of the blocks ``[(rows (n_b,), (labels, used, attractor
    tables))]`` (in queue order), which share their first ``n0[v]`` entries per value: the
    labels of the whole queue and the merged :class:`~jaxgear.analysis._lanes.AttractorTable`
    (see the module). Cycles are the same by their points, attractors of boxes by their
    boxes."""
    V, _, M, dim = blocks[0][1][2].points.shape
    Q = blocks[0][1][2].clouds.shape[2]
    luts = [np.tile(np.arange(t.n_slots, dtype=np.int64), (V, 1)) for _, (_, _, t) in blocks]
    tables: list[list] = []
    for v in range(V):
        first = blocks[0][1][2]
        reps = [(first.points[v, a], int(first.codes[v, a]), first.clouds[v, a]) for a in range(int(n0[v]))]
        cands, offset = [], 0
        for b, (rows, (lab, _, t)) in enumerate(blocks):
            for a in range(int(n0[v]), int(t.counts[v])):
                hit = np.flatnonzero((rows == v) & (lab == a))
                cands.append((offset + int(hit[0]) if len(hit) else np.inf, b, a))
            offset += len(lab)
        for _, b, a in sorted(cands):
            t = blocks[b][1][2]
            pts, k, cloud = t.points[v, a], int(t.codes[v, a]), t.clouds[v, a]
            kind = slot_kind(k, M)
            if kind == SlotKind.BOXES:
                same = [g for g, (_, kk, c) in enumerate(reps)
                        if slot_kind(kk, M) == SlotKind.BOXES and same_boxes(partition, cloud, c)]
            elif kind == SlotKind.CYCLE:
                same = [g for g, (p, kk, _) in enumerate(reps)
                        if slot_kind(kk, M) == SlotKind.CYCLE and same_attractor(pts[:k], k, p[:kk], kk, merge_tol)]
            else:  # a repeller or a chaotic saddle is never the same
                same = []
            if same:
                luts[b][v, a] = same[0]
            else:
                luts[b][v, a] = len(reps)
                reps.append((pts, k, cloud))
        tables.append(reps)
    A = table_slots(max(len(t) for t in tables))
    pts = np.full((V, A, M, dim), np.nan)
    ks = np.full((V, A), slot_code(SlotKind.EMPTY, M), np.int32)
    clouds = np.full((V, A, Q, dim), np.nan)
    for v, reps in enumerate(tables):
        for a, (p, k, c) in enumerate(reps):
            pts[v, a], ks[v, a], clouds[v, a] = p, k, c
    labels = np.concatenate([np.where(lab >= 0, lut[rows, np.maximum(lab, 0)], lab)
                             for (rows, (lab, *_)), lut in zip(blocks, luts)])
    return labels, AttractorTable(points=pts, codes=ks, counts=np.array([len(t) for t in tables], np.int32),
                                  clouds=clouds)
