"""The direct method's lane pool on several devices.

After the pilot (:func:`jaxgear.analysis._pool.run_pools`, on the first device), the
queue of the other cells is cut into one contiguous block per local device
(:func:`jaxgear._devices.split_rows`); each device runs its own pool over its block (the
same ``_drive`` as one device, its inputs committed to that device, one host thread per
device), seeded with the pilot's attractor table. Afterwards the attractors each block
registered are merged (:func:`jaxgear._matching.same_attractor`) and every block's
labels remapped. The merged table lists, per value, the pilot's attractors (in their
order) and then the attractors found later in the order of the first cell of the queue
they label: an order that does not depend on the number of devices (with one device the
same rule orders the one block's attractors).

A cell's label depends only on its own trajectory and on the attractor table it is
decided against, so the labels are those of one device whenever the pilot knows every
attractor the cells reach; an attractor found only later can change the automatic
capture radius for the cells decided after it (on one device for every later cell, on
several only for those of the block that found it): a cell then may be captured a
round earlier or later (its periods used), on the same attractor.
"""

from __future__ import annotations

import jax
import numpy as np

from .._devices import allgather, cell_processes, local_devices, on_devices, put, split_rows
from .._matching import same_attractor

__all__ = ["drive_blocks", "block_pools", "MIN_BLOCK_CELLS"]

MIN_BLOCK_CELLS = 16
"""Fewest cells a device's block holds (smaller queues run on the first device alone)."""


def drive_blocks(system, params, integrator, o, X: np.ndarray, rows: np.ndarray, L: int, att, bar,
                 devices=None):
    """Label the queue ``X (n, dim)`` (parameter rows ``rows (n,)``) in one pool per device,
    each with at most ``L`` lanes, starting from the attractor tables ``att = (points
    (V, A, M, dim), periods (V, A), counts (V,))``. Returns ``(labels (n,), periods used
    (n,), merged tables)`` as numpy arrays.

    With several processes (:func:`jaxgear._devices.cell_processes`) the queue is cut into
    blocks for every device of every process (process ``p`` takes the blocks ``i`` with
    ``i % P == p``), and the blocks' results are exchanged, so every process returns the
    whole queue's."""
    from ._pool import _drive

    devices = local_devices() if devices is None else list(devices)
    att = tuple(np.asarray(a) for a in jax.device_get(att))
    me, P = cell_processes()
    D = len(devices)
    blocks, mine = _blocks(len(X), D)

    def run(i, dev):
        a, b = blocks[i]
        s = _drive(system, put(params, dev), integrator, o, put(X[a:b], dev),
                   put(rows[a:b], dev), max(1, min(int(L), b - a)), put(att, dev), bar, device=dev)
        return tuple(np.asarray(v) for v in jax.device_get((s.labels, s.used, s.att_pts, s.att_k, s.n_att)))

    local = on_devices(run, mine, devices[:len(mine)]) if mine else []
    results = dict(zip(mine, local)) if P == 1 else _exchange(blocks, dict(zip(mine, local)), me, P, D)
    labels, tables = _merge(att[2], [(rows[a:b], results[i]) for i, (a, b) in enumerate(blocks)], o.merge_tol)
    used = np.concatenate([results[i][1] for i in range(len(blocks))])
    return labels, used, tables


def _blocks(n: int, D: int) -> tuple[list[tuple[int, int]], list[int]]:
    """The blocks ``(start, stop)`` a queue of ``n`` cells is cut into for ``D`` local
    devices in every process, and the indices of this process's blocks."""
    me, P = cell_processes()
    blocks = split_rows(n, max(1, min(P * D, n // MIN_BLOCK_CELLS)))
    return blocks, [i for i in range(len(blocks)) if i % P == me]


def block_pools(n: int, L: int, devices=None) -> list[tuple[int, int, object]]:
    """The ``(cells, lanes, device)`` of the pools :func:`drive_blocks` runs in this
    process for a queue of ``n`` cells and pools of at most ``L`` lanes (each distinct
    one once): what to compile ahead."""
    devices = local_devices() if devices is None else list(devices)
    blocks, mine = _blocks(n, len(devices))
    pools = {}
    for i, dev in zip(mine, devices):
        a, b = blocks[i]
        pools[(b - a, max(1, min(int(L), b - a)), dev.id)] = dev
    return [(n_b, L_b, dev) for (n_b, L_b, _), dev in pools.items()]


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
            same = [g for g, (p, kk) in enumerate(reps) if same_attractor(pts[:k], k, p[:kk], kk, merge_tol)]
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
