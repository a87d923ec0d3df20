"""Simple cell mapping: the paper's Poincaré-like cell map and Hsu's stroboscopic cell map.

- :class:`PoincareCellMap` — the paper's method (§3, eq. 9): each cell centre, on the
  section Σ at forcing phase 0, is integrated ``l`` forcing periods and on to the next
  crossing of Σ; the image cell is where that crossing lies.
- :class:`StroboscopicCellMap` — Hsu's simple cell mapping of the exact stroboscopic
  map ``x -> P^l(x)`` on a grid over all state coordinates.

The cell map's periodic groups and domains come from :func:`analyze_cell_map`; each
group is then followed on the stroboscopic map at point level to read its period P-k
(the cycle length of the cell map depends on ``l``), and groups that reach the same
attractor are merged (:func:`jaxgear._matching.group_attractors`).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._batching import DEFAULT_CHUNK_CELLS, chunks, equal_chunk_size, pad_rows, progress_bar
from .._cells import PAPER_REGION, CellGrid
from .._checks import check_choice, check_int
from .._devices import local_devices, shard_rows
from .._matching import group_attractors
from .._model import REDUCED
from .._poincare import check_section, section_kernel
from .._status import Status
from ._graph import analyze_cell_map
from ._method import AbstractGlobalMethod, Classification, register_method
from ._orbits import advance_state_rows, follow, refine_orbits
from ._result import SINK

__all__ = ["PoincareCellMap", "StroboscopicCellMap", "cell_images"]


class _AbstractCellMap(AbstractGlobalMethod):
    """Options of the cell methods: those every method has (:class:`AbstractGlobalMethod`:
    ``max_period``, ``period_tol``, ``merge_tol``, ``chunk_size``, declared here), and in
    each method ``mapping_steps`` (``l``, forcing periods per cell-map step) and
    ``settle_periods`` (periods each periodic group is followed before its period is read)."""

    max_period: int = eqx.field(static=True, default=16)
    period_tol: float = eqx.field(static=True, default=1e-6)
    merge_tol: float = eqx.field(static=True, default=1e-4)
    chunk_size: int = eqx.field(static=True, default=DEFAULT_CHUNK_CELLS)

    def __check_init__(self):
        check_int(self.settle_periods, "settle_periods", 0)

    def images(self, system, params, grid: CellGrid, progress: bool) -> np.ndarray:
        """Image cell of every cell: ``(n_cells,)`` ints, the sink is ``n_cells``.

        In chunks of at most ``chunk_size`` cells per local device, each chunk sharded
        over the devices (:func:`jaxgear._devices.shard_rows`; each cell's image alone:
        no dependence on the devices)."""
        n = grid.n_cells
        D = len(local_devices())
        size = equal_chunk_size(n, D * min(self.chunk_size, -(-n // D)))
        images = np.empty(n, dtype=np.int64)
        bar = progress_bar(n, f"{self.name} map", progress)
        for a, b in chunks(n, size):
            X = pad_rows(grid.centres(np.arange(a, b)), size)
            images[a:b] = grid.locate(self._map(system, params, X)[: b - a])
            bar.update(b - a)
        bar.close()
        return images

    def classify(self, system, params, grid: CellGrid, progress: bool) -> Classification:
        images = self.images(system, params, grid, progress)
        labels, atts, cycles = _classify_groups(system, params, grid, images, self)
        return Classification(labels, atts, cycles, float(self.mapping_steps))


@register_method
class PoincareCellMap(_AbstractCellMap):
    """The paper's Poincaré-like cell-to-cell map (paper §3, eq. 9; Levitas et al. 1994).

    Each cell centre lies on Σ = {x_section_index = 0} at forcing phase 0; it is
    integrated ``mapping_steps`` (``l``) forcing periods, then on to the next crossing of
    Σ in ``direction``; the image cell holds that crossing. The map restarts every image
    at phase 0 although the crossing happened at another phase (model document §6).

    Attributes:
        mapping_steps: ``l`` (default 50, the paper's).
        direction: crossing direction of Σ (+1: ``x_i`` increasing, -1, 0: either).
        section_index: the section coordinate (default the system's).
        settle_periods, integrator, max_period, period_tol, merge_tol, chunk_size:
            see :class:`AbstractGlobalMethod`.
    """

    name: ClassVar[str] = "poincare-like"
    mapping_steps: int = eqx.field(static=True, default=50)
    settle_periods: int = eqx.field(static=True, default=400)
    direction: int = eqx.field(static=True, default=1)
    section_index: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        check_int(self.mapping_steps, "mapping_steps", 0)
        check_choice(self.direction, "direction", (1, -1, 0))
        if self.section_index is not None:
            check_int(self.section_index, "section_index", 0)

    def check(self, system, grid: CellGrid) -> None:
        idx = check_section(system, self.section_index, self.direction)
        if idx in grid.axes:
            raise ValueError(f"the Poincaré-like map needs cell centres on Σ = {{x_{idx} = 0}}: the grid must not "
                             f"cover coordinate {idx} (it covers {grid.axes}).")
        if grid.base[idx] != 0:
            raise ValueError(f"cell centres must lie on Σ: grid.base[{idx}] must be 0.")

    def _map(self, system, params, X):
        idx = check_section(system, self.section_index, self.direction)
        Yc, _, _, status = shard_rows(section_kernel, system, params, np.ascontiguousarray(X.T), jnp.asarray(0.0),
                                      int(self.mapping_steps), idx, int(self.direction), 4.0, self.integrator,
                                      batch=2, axis=1, out_axes=(1, 0, 0, 0))
        Y = np.array(Yc.T)
        Y[np.asarray(status) != Status.CONVERGED] = np.nan
        return Y


@register_method
class StroboscopicCellMap(_AbstractCellMap):
    """Hsu's simple cell mapping of the exact stroboscopic map ``x -> P^l(x)`` (Hsu 1980).

    The grid must cover every state coordinate. Attributes: ``mapping_steps`` (``l``,
    default 1) and those of :class:`AbstractGlobalMethod`.
    """

    name: ClassVar[str] = "stroboscopic"
    mapping_steps: int = eqx.field(static=True, default=1)
    settle_periods: int = eqx.field(static=True, default=400)

    def __check_init__(self):
        check_int(self.mapping_steps, "mapping_steps", 1)

    def check(self, system, grid: CellGrid) -> None:
        if sorted(grid.axes) != list(range(system.dim)):
            raise ValueError(
                f"the stroboscopic cell map needs a grid over every state coordinate (0..{system.dim - 1}); "
                f"this grid covers {grid.axes}. Use CellGrid.box(bounds, counts) with {system.dim} axes.")

    def default_grid(self, system) -> CellGrid:
        """For the gear model: the paper's region D extended by ``x4`` in [-12, 12],
        25 x 15 x 30 x 12 cells."""
        if system is not REDUCED:
            raise ValueError("analyze_global: pass a CellGrid over every coordinate of your system.")
        return CellGrid.box(PAPER_REGION + ((-12.0, 12.0),), (25, 15, 30, 12), axes=(0, 1, 2, 3),
                            base=(0.0,) * 4, names=REDUCED.state_names)

    @property
    def section_index(self) -> int | None:
        return None

    def _map(self, system, params, X):
        return shard_rows(advance_state_rows, system, params, np.asarray(X, np.float64), int(self.mapping_steps),
                          self.integrator, batch=2)


def cell_images(system, params, grid: CellGrid, method: _AbstractCellMap | None = None, *,
                progress: bool = True) -> np.ndarray:
    """Image cell of every cell (paper eq. 9): an int array ``(n_cells,)``; the sink is ``n_cells``.

    ``method``: a :class:`PoincareCellMap` (default) or :class:`StroboscopicCellMap`.
    Work is done in chunks of ``method.chunk_size`` cells (one compiled shape; memory
    bounded by the chunk, not the grid); the images do not depend on the chunk size.
    """
    method = PoincareCellMap() if method is None else method
    if not isinstance(method, _AbstractCellMap):
        raise ValueError(f"cell_images needs a cell method (PoincareCellMap or StroboscopicCellMap), got {method!r}.")
    method.check(system, grid)
    return method.images(system, params, grid, progress)


def _classify_groups(system, params, grid, images, method: _AbstractCellMap):
    """Cell-map groups -> attractors at point level; returns (labels (n,), [(points, period,
    residual)], cycles)."""
    n = grid.n_cells
    cm = analyze_cell_map(images, n)
    groups = cm["groups"]
    group_of_cell = cm["group"]
    labels = np.full(n, SINK, dtype=np.int64)
    if len(groups) == 0:
        return labels, [], []
    # Follow one representative (the group's smallest periodic cell) per group at point level.
    reps = grid.centres(groups)
    M = int(method.max_period)
    periods = np.empty(len(groups), dtype=np.int64)
    orbits = np.empty((len(groups), 2 * M + 2, system.dim))
    for a, b in chunks(len(groups), method.chunk_size):
        periods[a:b], orbits[a:b] = follow(system, params, reps[a:b], method.integrator, method.settle_periods, M,
                                           method.period_tol)
    # Groups that reach the same attractor are one attractor (escaped groups: the sink).
    keep = np.nonzero(periods >= 0)[0]
    sets = [(orbits[g, -max(int(periods[g]), 1):], int(periods[g])) for g in keep]
    ids = group_attractors(sets, method.merge_tol)
    group_label = np.full(len(groups), SINK, dtype=np.int64)
    group_label[keep] = ids
    pos = np.clip(np.searchsorted(groups, group_of_cell), 0, len(groups) - 1)
    labels = np.where(groups[pos] == group_of_cell, group_label[pos], SINK)
    out, cycles = [], []
    periodic = cm["periodic"]
    firsts = [keep[np.argmax(ids == a)] for a in range(int(ids.max(initial=-1)) + 1)]
    to_refine = [(orbits[f, -1], int(periods[f])) for f in firsts if int(periods[f]) > 0]
    refined = iter(refine_orbits(system, params, to_refine, method.integrator, max_period=M))
    for a, first in enumerate(firsts):
        k = int(periods[first])
        pts, res = next(refined) if k > 0 else (orbits[first, -1:], np.nan)
        out.append((pts, k, res))
        cycles.append(np.nonzero(periodic & np.isin(group_of_cell, groups[group_label == a]))[0])
    return labels, out, cycles
