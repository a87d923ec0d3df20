"""How far a global result's cell labels can be trusted: its label uncertainty.

Where basins interleave at the scale of a cell, integration error and the choice of a
cell's representative state show up as label noise while the shares hardly move. Two
numbers estimate it on a random sample of cells, each by running the direct method's
lane pool (:mod:`jaxgear.analysis._pool`) from the sampled cell centres with the
result's attractors as the known ones:

- ``step``: the share of sampled cells whose label changes when the integrator's error
  is made about 16 times smaller (:meth:`~jaxgear.AbstractIntegrator.refined`: half the
  step). For the direct method this is the integration error of the labels; for the
  cell methods it also holds their discretisation error (the label the cell's centre
  itself reaches against the label the cell map gave it).
- ``start``: the share whose label changes when the start moves by ``perturbation``
  cell widths (uniformly in that box along the gridded coordinates): the basin-boundary
  uncertainty at that scale.
"""

from __future__ import annotations

import numpy as np

from .._cells import CellGrid
from .._checks import check_int, check_number
from ._pool import run_pool

__all__ = ["label_uncertainty", "DEFAULT_SAMPLES", "DEFAULT_PERTURBATION"]

DEFAULT_SAMPLES = 1024
"""Cells sampled for the estimate (the direct method's pilot size: the same compiled pool)."""
DEFAULT_PERTURBATION = 1e-3
"""Start perturbation, in cell widths."""


def label_uncertainty(system, params, grid: CellGrid, labels: np.ndarray, attractors, direct, *,
                      samples: int = DEFAULT_SAMPLES, perturbation: float = DEFAULT_PERTURBATION, seed: int = 0,
                      progress: bool = False) -> dict:
    """The label uncertainty of a result (see the module): a JSON-able dict with
    ``samples``, ``step`` and ``start`` (shares of the sampled cells whose label
    changes), ``perturbation`` (cell widths) and ``refined_integrator``.

    Args:
        labels: the result's labels (any shape with ``grid.n_cells`` entries): attractor
            id, ``SINK`` or ``UNRESOLVED``.
        attractors: the result's :class:`~jaxgear.analysis.Attractor` objects.
        direct: the :class:`~jaxgear.Direct` method whose pool and options are used (its
            integrator is the result's).
    """
    check_int(samples, "samples", 1)
    check_number(perturbation, "perturbation", 0)
    labels = np.asarray(labels).reshape(-1)
    n = grid.n_cells
    S = min(int(samples), n)
    rng = np.random.default_rng(seed)
    cells = np.sort(rng.choice(n, size=S, replace=False))
    ref = labels[cells]
    X = grid.centres(cells)
    known = [(np.asarray(a.points), int(a.period)) for a in attractors if 0 < int(a.period) <= direct.max_period]
    ids = np.array([a.id for a in attractors if 0 < int(a.period) <= direct.max_period], dtype=np.int64)

    def relabel(X, integrator, name):
        lab, _, _ = run_pool(system, params, X, integrator, chunk=direct.chunk_size, R=direct.round_periods,
                             max_periods=direct.max_periods, max_period=direct.max_period, tol=direct.period_tol,
                             capture=direct.capture_radius, bound=direct.escape_bound, merge_tol=direct.merge_tol,
                             progress=progress, pilot=0, attractors=known, label=name)
        out = lab.copy()
        seeded = (lab >= 0) & (lab < len(ids))
        out[seeded] = ids[lab[seeded]]
        out[lab >= len(ids)] = np.iinfo(np.int64).max  # an attractor the result does not have
        return out

    fine = direct.integrator.refined()
    step = relabel(X, fine, "uncertainty: step halved")
    dX = np.zeros_like(X)
    dX[:, list(grid.axes)] = rng.uniform(-1.0, 1.0, (S, len(grid.axes))) * perturbation * grid.cell_size
    start = relabel(X + dX, direct.integrator, "uncertainty: start moved")
    return dict(samples=S, step=float(np.mean(step != ref)), start=float(np.mean(start != ref)),
                perturbation=float(perturbation), refined_integrator=fine.to_dict())
