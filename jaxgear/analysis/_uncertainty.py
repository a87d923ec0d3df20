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
  uncertainty at that scale. The same samples moved by :data:`EXPONENT_SCALES` times
  that (five decades below it, all in one pool) give the uncertain fraction ``f(eps)``
  and the uncertainty exponent ``alpha`` of ``f ~ eps**alpha`` (Grebogi, McDonald, Ott &
  Yorke, Phys. Lett. A 99, 415, 1983): 1 for a smooth basin boundary, below 1 for a
  fractal one. It is fitted over the scaling range of :func:`~jaxgear.scaling_range`
  (moves well below a cell, where ``f`` has not saturated), or not at all: NaN with the
  reason ``"no scaling range: ..."``.

The pools know every attractor of the result. Where the result has no attractor found by
its boxes (quasi-periodic, chaotic, or a cycle longer than ``max_period``) and no chaotic
saddle, they look for no new attractor of boxes (no lane becomes a candidate,
:func:`~jaxgear.analysis._lanes.characterise`): each candidate there is a slow
transient whose cloud is rejected, which changes no label but costs a cloud (about a
third of the pools' time on the paper preset).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._cells import CellGrid
from .._checks import check_int, check_number
from ._fractal import scaling_range
from ._pool import main_queue, run_pools
from ._result import LabelUncertainty

__all__ = ["label_uncertainty", "label_uncertainties", "DEFAULT_SAMPLES", "DEFAULT_PERTURBATION"]

DEFAULT_SAMPLES = 1024
"""Cells sampled for the estimate (the direct method's pilot size: the same compiled pool)."""
DEFAULT_PERTURBATION = 1e-3
"""Start perturbation, in cell widths."""
EXPONENT_SCALES = (1.0, 1e-1, 1e-2, 1e-3, 1e-4, 1e-5)
"""The start moves of the uncertainty exponent, in multiples of the perturbation (one a
decade, five decades: ``1e-8`` to ``1e-3`` cell with the default, well below the cell
size, where ``f(eps)`` saturates)."""


def label_uncertainty(system, params, grid: CellGrid, labels: np.ndarray, attractors, direct, *,
                      samples: int = DEFAULT_SAMPLES, perturbation: float = DEFAULT_PERTURBATION, seed: int = 0,
                      saddles=None, progress: bool = False) -> LabelUncertainty:
    """The label uncertainty of a result (see the module): a
    :class:`~jaxgear.analysis.LabelUncertainty` with ``samples``, ``step`` and ``start``
    (shares of the sampled cells whose label changes), ``perturbation`` (cell widths),
    ``refined_integrator``, and the uncertain fractions with their exponent over its
    scaling range (Grebogi et al. 1983).

    Args:
        labels: the result's labels (any shape with ``grid.n_cells`` entries): attractor
            id, ``SINK`` or ``UNRESOLVED``.
        attractors: the result's :class:`~jaxgear.analysis.Attractor` objects.
        direct: the :class:`~jaxgear.Direct` method whose pool and options are used (its
            integrator is the result's).
        saddles: the result's chaotic saddles (``GlobalResult.saddles``), or ``None`` (not
            known: new attractors of boxes are looked for, see the module).
    """
    return label_uncertainties(system, [params], grid, [labels], [attractors], direct, samples=samples,
                               perturbation=perturbation, seed=seed, saddles_list=None if saddles is None else [saddles],
                               progress=progress)[0]


def label_uncertainties(system, params_list, grid: CellGrid, labels_list, attractors_list, direct, *,
                        samples: int = DEFAULT_SAMPLES, perturbation: float = DEFAULT_PERTURBATION, seed: int = 0,
                        saddles_list=None, progress: bool = False) -> list[LabelUncertainty]:
    """:func:`label_uncertainty` of several results on one grid (one per parameter set of
    ``params_list``; ``saddles_list``: the saddles of each, or ``None``), each pool run once
    for all of them: one per result, each equal to :func:`label_uncertainty` of that result
    alone."""
    check_int(samples, "samples", 1)
    check_number(perturbation, "perturbation", 0)
    n = grid.n_cells
    S = min(int(samples), n)
    rng = np.random.default_rng(seed)
    cells = np.sort(rng.choice(n, size=S, replace=False))
    X = grid.centres(cells)
    direction = rng.uniform(-1.0, 1.0, (S, len(grid.axes)))
    scales = np.asarray(EXPONENT_SCALES) * perturbation  # the first is the perturbation itself
    moved = []
    for eps in scales:
        dX = np.zeros_like(X)
        dX[:, list(grid.axes)] = direction * eps * grid.cell_size
        moved.append(X + dX)
    refs = [np.asarray(labels).reshape(-1)[cells] for labels in labels_list]
    # every attractor is known to the pools: cycles by their points, attractors of boxes
    # (period 0) by their clouds, in the partition the analysis used
    knowns = [[(np.asarray(a.points), int(a.period)) for a in atts if 0 <= int(a.period) <= direct.max_period]
              for atts in attractors_list]
    idss = [np.array([a.id for a in atts if 0 <= int(a.period) <= direct.max_period], dtype=np.int64)
            for atts in attractors_list]
    boxes = direct.boxes(grid.centres())
    if boxes is not None and not _sets_of_boxes(attractors_list, saddles_list, direct.max_period):
        # no lane past max_periods is a candidate: none is (see the module)
        boxes = dataclasses.replace(boxes, options=dataclasses.replace(boxes.options,
                                                                       transient=direct.pool_options().max_periods))

    def relabel(X, integrator, name, like=0):
        """The labels of the states ``X`` under every value (one pool), in the result's ids."""
        pooled = run_pools(system, params_list, [X] * len(params_list), integrator, direct.pool_options(pilot=0),
                           boxes=boxes, attractors=knowns, progress=progress, label=name, like=like)
        outs = []
        for (lab, *_), ids in zip(pooled, idss):
            out = lab.copy()
            seeded = (lab >= 0) & (lab < len(ids))
            out[seeded] = ids[lab[seeded]]
            out[lab >= len(ids)] = np.iinfo(np.int64).max  # an attractor the result does not have
            outs.append(out)
        return outs

    fine = direct.integrator.refined()
    steps = relabel(X, fine, "uncertainty: step halved")
    # every start move in one pool (the samples moved by each scale, one after the other)
    # (in the shapes of the analysis's own pools, so it compiles none of its own)
    main = main_queue([n] * len(params_list), direct.pool_options().pilot)
    together = relabel(np.concatenate(moved), direct.integrator, "uncertainty: start moved", like=main)
    starts = [[lab[j * S:(j + 1) * S] for lab in together] for j in range(len(scales))]
    out = []
    for v, (step, ref) in enumerate(zip(steps, refs)):
        f = np.array([float(np.mean(starts[j][v] != ref)) for j in range(len(scales))])
        if perturbation > 0:
            s = scaling_range(scales, f, S)
            fit = dict(alpha=s.alpha, alpha_error=s.alpha_err, alpha_chi2=s.reduced_chi2, alpha_reason=s.reason,
                       alpha_range=None if s.reason else (s.eps_min, s.eps_max))
        else:
            fit = dict(alpha_reason="no scaling range: no start move (perturbation 0)")
        out.append(LabelUncertainty(samples=S, step=float(np.mean(step != ref)), start=float(f[0]),
                                    perturbation=float(perturbation), refined_integrator=fine,
                                    perturbations=tuple(float(e) for e in scales),
                                    start_fractions=tuple(float(x) for x in f), **fit))
    return out


def _sets_of_boxes(attractors_list, saddles_list, max_period: int) -> bool:
    """Whether a result may hold a set the pools find by its boxes: an attractor of period
    0 or above ``max_period`` (found by its boxes), a chaotic saddle, or saddles not known."""
    if saddles_list is None or any(len(s) for s in saddles_list):
        return True
    return any(int(a.period) == 0 or int(a.period) > max_period for atts in attractors_list for a in atts)
