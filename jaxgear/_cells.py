"""Cell space of the cell-to-cell mapping method (paper §3, Hsu 1980).

A :class:`CellGrid` is a box over some state coordinates divided into equal cells;
the other coordinates are held at fixed values (the paper's region D lies on
Σ = {x4 = 0}: 50 × 30 × 60 cells over x1, x2, x3 with x4 = 0). Cells are numbered in
C order over the grid axes; the number ``n_cells`` is the sink cell, where every
state outside the box or non-finite goes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from ._checks import check_int, check_number

__all__ = ["CellGrid", "PAPER_REGION"]

PAPER_REGION = ((-25.0, 25.0), (-10.0, 20.0), (-10.0, 50.0))
"""The paper's studied region D (eq. 10) over x1, x2, x3."""
MAX_CELLS = 2**62
"""Most cells a grid may have: cell numbers (and the sink, one more) are int64."""


@dataclasses.dataclass(frozen=True)
class CellGrid:
    """A box of cells over the state coordinates ``axes``.

    Attributes:
        axes: indices of the gridded state coordinates, e.g. ``(0, 1, 2)``.
        lower, upper: box bounds per gridded axis (state units).
        counts: number of cells per gridded axis.
        base: the full state ``(dim,)`` that supplies the non-gridded coordinates
            (e.g. ``x4 = 0`` on the paper's section).
        names: names of all state coordinates (for labelled results).
    """

    axes: tuple[int, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    counts: tuple[int, ...]
    base: tuple[float, ...]
    names: tuple[str, ...] = ()

    def __post_init__(self):
        k = len(self.axes)
        if not (len(self.lower) == len(self.upper) == len(self.counts) == k) or k == 0:
            raise ValueError("CellGrid: axes, lower, upper and counts must have the same (non-zero) length.")
        dim = len(self.base)
        if len(set(self.axes)) != k or not all(0 <= a < dim for a in self.axes):
            raise ValueError(f"CellGrid: axes {self.axes} must be distinct indices in 0..{dim - 1}.")
        for a, lo, hi, n in zip(self.axes, self.lower, self.upper, self.counts):
            if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
                raise ValueError(f"CellGrid: axis {a} needs finite bounds with upper > lower, got [{lo}, {hi}].")
            if int(n) != n or n < 1:
                raise ValueError(f"CellGrid: axis {a} needs a positive integer number of cells, got {n}.")
        if math.prod(int(n) for n in self.counts) > MAX_CELLS:
            raise ValueError(f"CellGrid: counts {tuple(int(n) for n in self.counts)} give "
                             f"{math.prod(int(n) for n in self.counts):.3g} cells; at most {MAX_CELLS:.3g} can be "
                             "numbered.")
        if not np.all(np.isfinite(self.base)):
            raise ValueError("CellGrid: base state must be finite.")
        if self.names and len(self.names) != dim:
            raise ValueError(f"CellGrid: names must name all {dim} coordinates.")

    # ------------------------------------------------------------------ build
    @classmethod
    def box(cls, bounds: Sequence[tuple[float, float]], counts: Sequence[int], *, axes: Sequence[int] | None = None,
            dim: int | None = None, base: Sequence[float] | None = None, names: Sequence[str] = ()) -> CellGrid:
        """A grid from ``bounds=[(lo, hi), ...]`` and ``counts`` over ``axes`` (default: the first ones)."""
        try:
            bounds = [tuple(b) for b in bounds]
            counts = list(counts)
        except TypeError:
            raise ValueError(f"CellGrid.box needs bounds=[(lo, hi), ...] and counts=[n, ...], got bounds={bounds!r}, "
                             f"counts={counts!r}.") from None
        if len(bounds) != len(counts) or not all(len(b) == 2 for b in bounds):
            raise ValueError(f"CellGrid.box needs one (lo, hi) pair and one count per axis, got bounds={bounds!r}, "
                             f"counts={counts!r}.")
        bounds = [(check_number(lo, f"bounds[{i}][0]"), check_number(hi, f"bounds[{i}][1]"))
                  for i, (lo, hi) in enumerate(bounds)]
        counts = [check_int(c, f"counts[{i}]", 1) for i, c in enumerate(counts)]
        axes = tuple(range(len(bounds))) if axes is None else tuple(check_int(a, "axes", 0) for a in axes)
        dim = dim if dim is not None else (len(base) if base is not None else (len(names) or max(axes) + 1))
        base = tuple(float(b) for b in (base if base is not None else np.zeros(dim)))
        return cls(axes=axes, lower=tuple(float(b[0]) for b in bounds), upper=tuple(float(b[1]) for b in bounds),
                   counts=tuple(int(c) for c in counts), base=base, names=tuple(names))

    @classmethod
    def paper(cls, counts: Sequence[int] = (50, 30, 60), bounds=PAPER_REGION) -> CellGrid:
        """The paper's region D on Σ = {x4 = 0} (eq. 10): 50 × 30 × 60 cells over x1, x2, x3."""
        return cls.box(bounds, counts, axes=(0, 1, 2), base=(0.0, 0.0, 0.0, 0.0), names=("x1", "x2", "x3", "x4"))

    # ------------------------------------------------------------------ geometry
    @property
    def dim(self) -> int:
        return len(self.base)

    @property
    def n_cells(self) -> int:
        """Number of regular cells; the sink cell is numbered ``n_cells``."""
        return math.prod(int(n) for n in self.counts)

    @property
    def sink(self) -> int:
        return self.n_cells

    @property
    def cell_size(self) -> np.ndarray:
        return (np.asarray(self.upper) - np.asarray(self.lower)) / np.asarray(self.counts)

    @property
    def axis_names(self) -> tuple[str, ...]:
        names = self.names or tuple(f"x{i + 1}" for i in range(self.dim))
        return tuple(names[a] for a in self.axes)

    def axis_centres(self, j: int) -> np.ndarray:
        """Cell-centre coordinates along gridded axis ``j`` (``counts[j]`` values)."""
        lo, h = self.lower[j], self.cell_size[j]
        return lo + h * (np.arange(self.counts[j]) + 0.5)

    def centres(self, cells: np.ndarray | None = None) -> np.ndarray:
        """Full states ``(n, dim)`` at the centres of ``cells`` (default: all, in index order).

        ``ValueError`` naming the grid's counts when the centres of every cell would not
        fit in memory (:func:`jaxgear._checks.check_memory`), before anything is allocated.
        """
        if cells is None:
            from ._checks import check_memory

            check_memory("CellGrid counts", self.counts, self.n_cells, 8 * (self.dim + len(self.axes) + 1),
                         "cell centres")
        cells = np.arange(self.n_cells) if cells is None else np.asarray(cells)
        multi = np.unravel_index(cells, self.counts)
        out = np.tile(np.asarray(self.base, dtype=float), (cells.size, 1))
        for j, a in enumerate(self.axes):
            out[:, a] = self.lower[j] + self.cell_size[j] * (multi[j] + 0.5)
        return out

    def locate(self, states: np.ndarray) -> np.ndarray:
        """Cell index of each state ``(..., dim)``; the sink for states outside or non-finite.

        Only the gridded coordinates decide the cell (the others are the section's or
        are held fixed by construction).
        """
        states = np.asarray(states, dtype=float)
        lead = states.shape[:-1]
        s = states.reshape(-1, self.dim)
        idx = np.zeros(s.shape[0], dtype=np.int64)
        inside = np.all(np.isfinite(s), axis=1)
        for j, a in enumerate(self.axes):
            q = np.floor((s[:, a] - self.lower[j]) / self.cell_size[j])
            ok = (q >= 0) & (q < self.counts[j])
            inside &= ok
            q = np.where(ok, q, 0).astype(np.int64)
            idx = idx * self.counts[j] + q
        return np.where(inside, idx, self.sink).reshape(lead)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d) -> CellGrid:
        return cls(**{k: tuple(v) for k, v in d.items()})
