"""The direct method's lane pool on several devices.

After the pilot (:func:`jaxgear.analysis._pool.run_pools`, on the first device), the
queue of the other cells is cut into one contiguous block per local device
(:func:`jaxgear._devices.split_rows`); each device runs its own pool over its block,
seeded with the pilot's attractor table, all of them in one SPMD program: a ``jax.jit``
of a ``jax.shard_map`` over the 1-D mesh of the devices
(:func:`jaxgear._devices.batch_mesh`), each device's pool state a block along a leading
device axis (``NamedSharding(mesh, P("batch"))``). Each device runs the pool's loop of
one device on its block (its own ``while_loop`` and attractor table, no collectives), and
the host makes one device's decisions from the devices' progress rows
(:func:`jaxgear.analysis._pool._steer`). The blocks are padded to one shape; a block's
real length is a per-device operand, so the padding never enters a lane. Afterwards the
attractors each block registered are merged (:func:`jaxgear._matching.same_attractor`)
and every block's labels remapped. The merged table lists, per value, the pilot's
attractors (in their order) and then the attractors found later in the order of the
first cell of the queue they label: an order that does not depend on the number of
devices (with one device the same rule orders the one block's attractors).

A cell's label depends only on its own trajectory and on the attractor table it is
decided against, so the labels are those of one device whenever the pilot knows every
attractor the cells reach; an attractor found only later can change the automatic
capture radius for the cells decided after it (on one device for every later cell, on
several only for those of the block that found it): a cell then may be captured a
round earlier or later (its periods used), on the same attractor.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from .._devices import BATCH, allgather, batch_mesh, cell_processes, local_devices, put, split_rows
from .._matching import same_attractor
from ._pool import _drive, _init, _next_pool, _ready, _resize, _rounds, _steer

__all__ = ["drive_blocks", "block_pool", "compile_blocks", "MIN_BLOCK_CELLS"]

MIN_BLOCK_CELLS = 16
"""Fewest cells a device's block holds (smaller queues run on the first device alone)."""


def drive_blocks(system, params, integrator, o, X: np.ndarray, rows: np.ndarray, L: int, att, bar):
    """Label the queue ``X (n, dim)`` (parameter rows ``rows (n,)``) in one pool per device,
    each with at most ``L`` lanes, starting from the attractor tables ``att = (points
    (V, A, M, dim), periods (V, A), counts (V,))``. Returns ``(labels (n,), periods used
    (n,), merged tables)`` as numpy arrays.

    With several processes (:func:`jaxgear._devices.cell_processes`) the queue is cut into
    blocks for every device of every process (process ``p`` takes the blocks ``i`` with
    ``i % P == p``, on its own devices; a short queue leaves some processes none), and
    the blocks' results are exchanged, so every process returns the whole queue's."""
    att = tuple(np.asarray(a) for a in jax.device_get(att))
    me, procs = cell_processes()
    blocks, mine, where = _my_blocks(len(X))
    spans = [blocks[i] for i in mine]
    if not mine:
        local = []
    elif len(mine) == 1:  # one device: the plain pool
        (a, b), dev = spans[0], where
        s = _drive(system, put(params, dev), integrator, o, put(X[a:b], dev), put(rows[a:b], dev),
                   max(1, min(int(L), b - a)), put(att, dev), bar, device=dev)
        local = [tuple(np.asarray(v) for v in jax.device_get((s.labels, s.used, s.att_pts, s.att_k, s.n_att)))]
    else:
        local = _drive_sharded(system, params, integrator, o, X, rows, spans, L, att, bar, where)
    results = dict(zip(mine, local))
    if procs > 1:
        results = _exchange(blocks, results, me, procs, len(local_devices()))
    labels, tables = _merge(att[2], [(rows[a:b], results[i]) for i, (a, b) in enumerate(blocks)], o.merge_tol)
    used = np.concatenate([results[i][1] for i in range(len(blocks))])
    return labels, used, tables


def _my_blocks(n: int) -> tuple[list[tuple[int, int]], list[int], object]:
    """The blocks ``(start, stop)`` a queue of ``n`` cells is cut into for the local devices
    of every process, the indices of this process's blocks, and where they run: its first
    device (one block), the mesh of its first devices (one block each), or ``None``."""
    devices = local_devices()
    me, procs = cell_processes()
    blocks = split_rows(n, max(1, min(procs * len(devices), n // MIN_BLOCK_CELLS)))
    mine = [i for i in range(len(blocks)) if i % procs == me]
    where = None if not mine else devices[0] if len(mine) == 1 else batch_mesh(tuple(devices[:len(mine)]))
    return blocks, mine, where


def block_pool(n: int, L: int) -> tuple[int, int, object] | None:
    """The ``(cells, lanes, device or mesh)`` of the pool :func:`drive_blocks` runs in this
    process for a queue of ``n`` cells and pools of at most ``L`` lanes (on several
    devices, the sharded pool's block shape), or ``None`` (no block here): what to
    compile ahead."""
    blocks, mine, where = _my_blocks(n)
    if not mine:
        return None
    n_b = max(blocks[i][1] - blocks[i][0] for i in mine)
    return n_b, max(1, min(int(L), n_b)), where


# ------------------------------------------------------------------ the sharded pool
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


@functools.partial(jax.jit, static_argnums=(0, 1, 2, 3, 4))
def _init_blocks(mesh, n: int, L: int, dim: int, M: int, X, Xrow, n_real, att_pts, att_k, n_att):
    """``_init`` of each device's pool over its block ``X[d, :n_real[d]]`` (blocks padded
    to ``n`` states): the padding stays out of the lanes."""
    def body(X, Xrow, n_real, *att):
        s = _init(n, L, dim, M, X[0], Xrow[0], *_local(att))
        take = jnp.minimum(L, n_real[0]).astype(jnp.int32)
        keep = jnp.arange(L, dtype=jnp.int32) < take
        s = s._replace(Y=jnp.where(keep[None], s.Y, 0.0), cell=jnp.where(keep, s.cell, -1).astype(jnp.int32),
                       row=jnp.where(keep, s.row, 0).astype(jnp.int32), next_cell=take, n_active=take)
        return _stacked(s)

    return _per_device(mesh, body)(X, Xrow, n_real, att_pts, att_k, n_att)


@functools.partial(jax.jit, static_argnames=("mesh", "system", "integrator", "o", "L_min"), donate_argnums=0)
def _run_blocks(s, system, params, integrator, o, X, Xrow, n_real, L_min: int, rounds, mesh):
    """``_run`` of every device's pool on its block (queue ``X[d, :n_real[d]]``): each
    device runs its own rounds; the ``info`` rows stacked ``(devices, 5)``."""
    def body(s, params, X, Xrow, n_real, rounds):
        s, info = _rounds(_local(s), system, params, integrator, o, X[0], Xrow[0], n_real[0], L_min, rounds)
        return _stacked((s, info))

    return _per_device(mesh, body, replicated=(1, 5))(s, params, X, Xrow, n_real, rounds)


@functools.partial(jax.jit, static_argnames=("mesh", "L", "A"))
def _resize_blocks(s, mesh, L: int | None = None, A: int | None = None):
    """``_resize`` of every device's pool."""
    return _per_device(mesh, lambda s: _stacked(_resize(_local(s), L=L, A=A)))(s)


def _drive_sharded(system, params, integrator, o, X, rows, spans, L: int, att, bar, mesh) -> list[tuple]:
    """Run the pools of the blocks ``X[a:b]`` (``spans``, one per device of ``mesh``) as one
    sharded pool until every one is decided: each block's ``(labels, used, points,
    periods, counts)``."""
    D = len(spans)
    n_real = np.array([b - a for a, b in spans], np.int32)
    n = int(n_real.max())
    L = max(1, min(int(L), n))
    split, rep = NamedSharding(mesh, P(BATCH)), NamedSharding(mesh, P())

    def blocks(A):  # padded with copies of each block's last entry (never taken into a lane)
        return jax.device_put(np.stack([np.concatenate([A[a:b], np.repeat(A[b - 1:b], n - (b - a), axis=0)])
                                        for a, b in spans]), split)

    Xs, Rs = blocks(X), blocks(rows)
    ns = jax.device_put(n_real, split)
    atts = jax.device_put(tuple(np.broadcast_to(a, (D, *a.shape)) for a in att), split)
    params = jax.device_put(params, rep)
    _ready(system, integrator, o, n, L, att[1].shape, mesh)
    s = _init_blocks(mesh, n, L, X.shape[1], o.M, Xs, Rs, ns, *atts)
    s = _steer(s, lambda s, L_min, rounds: _run_blocks(s, system, params, integrator, o, Xs, Rs, ns, L_min, rounds,
                                                       mesh),
               functools.partial(_resize_blocks, mesh=mesh), n_real, bar,
               lambda L: _ready(system, integrator, o, n, L, att[1].shape, mesh))
    lab, use, pts, ks, cnt = (np.asarray(v) for v in jax.device_get((s.labels, s.used, s.att_pts, s.att_k, s.n_att)))
    return [(lab[d, :m], use[d, :m], pts[d], ks[d], cnt[d]) for d, m in enumerate(n_real)]


def compile_blocks(system, params, integrator, o, n: int, size: int, L: int, dim: int, V: int, A: int, mesh):
    """Compile the sharded pool's ``_init_blocks`` and ``_run_blocks`` for ``size`` lanes
    (of a pool started at ``L``) over blocks of ``n`` states, their inputs placed as
    :func:`_drive_sharded` places them (the call then hits JAX's caches)."""
    D = mesh.size
    split = NamedSharding(mesh, P(BATCH))

    def spec(*shape, dtype=jnp.float64):
        return jax.ShapeDtypeStruct((D, *shape), dtype, sharding=split)

    X, Xrow, n_real = spec(n, dim), spec(n, dtype=jnp.int32), spec(dtype=jnp.int32)
    att = (spec(V, A, o.M, dim), spec(V, A, dtype=jnp.int32), spec(V, dtype=jnp.int32))
    params = jax.device_put(params, NamedSharding(mesh, P()))
    if size == L:
        _init_blocks.lower(mesh, n, L, dim, o.M, X, Xrow, n_real, *att).compile()
    s = jax.eval_shape(functools.partial(_init_blocks, mesh, n, size, dim, o.M), X, Xrow, n_real, *att)
    s = jax.tree.map(lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=split), s)
    _run_blocks.lower(s, system, params, integrator, o, X, Xrow, n_real, _next_pool(size), np.int32(1), mesh).compile()


def _exchange(blocks, local: dict, me: int, P: int, D: int) -> dict:
    """Every block's ``(labels, used, points, periods, counts)`` in every process, from
    each process's own blocks (``local``; block ``i`` is process ``i % P``'s slot ``i // P``)."""
    longest = max(b - a for a, b in blocks)
    some = next(iter(local.values()), None)
    A = int(allgather(np.array([some[2].shape[1] if some is not None else 0])).max())
    shapes = allgather(np.array(some[2].shape if some is not None else (0, 0, 0, 0)))
    V, _, M, dim = (int(x) for x in shapes.max(axis=0))
    lab = np.full((D, longest), -9, np.int64)
    use = np.zeros((D, longest), np.int64)
    pts = np.full((D, V, A, M, dim), np.nan)
    ks = np.zeros((D, V, A), np.int32)
    ns = np.zeros((D, V), np.int32)
    for i, r in local.items():
        j = i // P
        lab[j, : len(r[0])], use[j, : len(r[1])] = r[0], r[1]
        pts[j, :, : r[2].shape[1]], ks[j, :, : r[3].shape[1]], ns[j] = r[2], r[3], r[4]
    lab, use, pts, ks, ns = (allgather(x) for x in (lab, use, pts, ks, ns))
    out = {}
    for i, (a, b) in enumerate(blocks):
        p, j = i % P, i // P
        out[i] = (lab[p, j, : b - a], use[p, j, : b - a], pts[p, j], ks[p, j], ns[p, j])
    return out


def _merge(n0, blocks, merge_tol: float):
    """Merge the attractor tables of the blocks ``[(rows (n_b,), (labels, used, points,
    periods, counts))]`` (in queue order), which share their first ``n0[v]`` entries per
    value: the labels of the whole queue and the merged tables (see the module)."""
    V, _, M, dim = blocks[0][1][2].shape
    luts = [np.tile(np.arange(r[2].shape[1], dtype=np.int64), (V, 1)) for _, r in blocks]
    tables: list[list] = []
    for v in range(V):
        reps = [(blocks[0][1][2][v, a], int(blocks[0][1][3][v, a])) for a in range(int(n0[v]))]
        cands, offset = [], 0
        for b, (rows, (lab, *_, n)) in enumerate(blocks):
            for a in range(int(n0[v]), int(n[v])):
                hit = np.flatnonzero((rows == v) & (lab == a))
                cands.append((offset + int(hit[0]) if len(hit) else np.inf, b, a))
            offset += len(lab)
        for _, b, a in sorted(cands):
            pts, k = blocks[b][1][2][v, a], int(blocks[b][1][3][v, a])
            same = [g for g, (p, kk) in enumerate(reps)  # (a repeller, kk < 0, is never the same)
                    if kk > 0 and same_attractor(pts[:k], k, p[:kk], kk, merge_tol)]
            if same:
                luts[b][v, a] = same[0]
            else:
                luts[b][v, a] = len(reps)
                reps.append((pts, k))
        tables.append(reps)
    most = max(len(t) for t in tables)
    A = max(8, 1 << max(0, most - 1).bit_length())
    pts = np.full((V, A, M, dim), np.nan)
    ks = np.zeros((V, A), np.int32)
    for v, reps in enumerate(tables):
        for a, (p, k) in enumerate(reps):
            pts[v, a], ks[v, a] = p, k
    labels = np.concatenate([np.where(lab >= 0, lut[rows, np.maximum(lab, 0)], lab)
                             for (rows, (lab, *_)), lut in zip(blocks, luts)])
    return labels, (pts, ks, np.array([len(t) for t in tables], np.int32))
