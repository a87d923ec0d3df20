"""Agreement of a global-analysis result with direct integration on a sample of cells."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import check_int
from .._matching import same_attractor
from .._model import REDUCED
from .._params import GearParams
from ..integrate import AbstractIntegrator
from ._direct import Direct
from ._result import SINK, GlobalResult

__all__ = ["compare_with_direct"]


def compare_with_direct(result: GlobalResult, system=None, params=None, *, n_samples: int = 500, seed: int = 0,
                        integrator: AbstractIntegrator | None = None, match_tol: float = 1e-2,
                        progress: bool = True) -> dict[str, Any]:
    """Agreement report (``jaxgear analyze --compare``): the direct method on a random sample
    of cells, compared with the labels of ``result``.

    Checks a cell-mapping result (paper §3-§4) against direct integration of the same
    cell centres, the paper's verification by direct integration applied to domains.
    ``n_samples`` cells are drawn without replacement (``seed``); ``system`` and
    ``params`` default to the reduced gear model with ``result.params``; the integrator
    defaults to the result's. Direct attractors are matched to the result's attractors
    by :func:`jaxgear._matching.same_attractor` with the relative tolerance ``match_tol``.

    Returns:
        ``{"n_samples", "agreement" (overall fraction in [0, 1]), "per_attractor": {id:
        {"cells", "agree", "fraction"}}, "direct_only": [{"period", "point" (dim,), "cells"}]}``.
    """
    n_samples = check_int(n_samples, "n_samples", 1)
    system = REDUCED if system is None else system
    if params is None:
        if system is not REDUCED:
            raise ValueError("compare_with_direct: pass the parameters of your system (params=...).")
        params = GearParams.from_dict(result.params)
    if result.grid.dim != system.dim:
        raise ValueError(f"compare_with_direct: the result's grid has {result.grid.dim} coordinates, "
                         f"the system {system.dim}.")
    direct = Direct.like(result.method, integrator)
    rng = np.random.default_rng(seed)
    n = result.n_cells
    cells = rng.choice(n, size=min(n_samples, n), replace=False)
    labels, atts, _ = direct.label_states(system, params, result.grid.centres(cells), progress)
    mapping, direct_only = {}, []
    for i, (pts, k, _) in enumerate(atts):
        match = next((a.id for a in result.attractors if same_attractor(pts, k, a.points, a.period, match_tol)),
                     None)
        if match is not None:
            mapping[i] = match
        else:
            mapping[i] = -100 - i
            direct_only.append(dict(period=int(k), point=np.asarray(pts[0]).tolist(),
                                    cells=int((labels == i).sum())))
    direct_ids = np.array([mapping.get(int(lab), int(lab)) for lab in labels])
    cell_labels = result.labels.reshape(-1)[cells]
    per = {}
    for a in list(result.attractors) + [None]:
        aid = SINK if a is None else a.id
        sel = cell_labels == aid
        if sel.sum():
            agree = int((direct_ids[sel] == aid).sum())
            per[str(aid if a is not None else "sink")] = dict(cells=int(sel.sum()), agree=agree,
                                                             fraction=agree / int(sel.sum()))
    return dict(n_samples=int(len(cells)), agreement=float((direct_ids == cell_labels).mean()),
                per_attractor=per, direct_only=direct_only)
