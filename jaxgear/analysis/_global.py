"""Global analysis: every coexisting attractor in a region, its period and its domain.

:func:`analyze_global` runs a method object (:class:`~jaxgear.Direct`, the default;
:class:`~jaxgear.PoincareCellMap`, the paper's; :class:`~jaxgear.StroboscopicCellMap`,
Hsu's) and does what every method shares: periods reduced to the minimal one,
attractors that are the same merged, attractors sorted by decreasing share, their
section crossings, and the :class:`~jaxgear.GlobalResult`.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .._cells import CellGrid
from .._checks import check_bool, check_int
from .._lyapunov import (
    AttractorType,
    LyapunovOptions,
    classify_attractor,
    ensemble_spectrum,
    kaplan_yorke,
    lyapunov_spectrum,
)
from .._matching import group_attractors, minimal_cycle
from .._params import params_to_dict
from .._system import ForcedSystem, check_system
from .._version import __version__
from ._diagnostics import warn_if_unreliable
from ._direct import Direct
from ._fractal import basin_entropy
from ._method import AbstractGlobalMethod, method_from_name
from ._orbits import cycle_sections_and_multipliers, long_cycles
from ._result import SINK, UNRESOLVED, Attractor, GlobalResult
from ._tori import joined_tori
from ._uncertainty import DEFAULT_SAMPLES, label_uncertainties, label_uncertainty

__all__ = ["analyze_global", "analyze_global_values", "default_method", "DEFAULT_METHOD", "with_label_uncertainty"]

DEFAULT_METHOD = "direct"
"""Name of the default method: the library, the CLI and the README use the same."""


def default_method() -> AbstractGlobalMethod:
    """The default method object (:class:`~jaxgear.Direct` with its default options)."""
    return method_from_name(DEFAULT_METHOD)


def analyze_global(system: ForcedSystem | None = None, params=None, grid: CellGrid | None = None,
                   method: AbstractGlobalMethod | str | None = None, *, progress: bool = True,
                   uncertainty: int = DEFAULT_SAMPLES) -> GlobalResult:
    """Every coexisting attractor in a region, its period and its domain (paper §3-§4).

    Args:
        system: a :class:`~jaxgear.ForcedSystem` (default: the reduced gear model).
        params: its parameter pytree (default: the ``paper`` preset).
        grid: the :class:`~jaxgear.CellGrid` (default: the method's; for the gear model
            the paper's region D, 50 x 30 x 60 cells on Σ = {x4 = 0}).
        method: a method object — :class:`~jaxgear.Direct` (default),
            :class:`~jaxgear.PoincareCellMap` (the paper's map) or
            :class:`~jaxgear.StroboscopicCellMap` — holding all its options, or the name
            of one (``"direct"``, ``"poincare-like"``, ``"stroboscopic"``) for its defaults.
        progress: show progress bars (tqdm); ``False`` silences them.
        uncertainty: cells sampled for the result's label uncertainty (the share of
            them whose label changes with a halved step, and with a start moved by 1e-3
            cell: :func:`~jaxgear.analysis.label_uncertainty`); ``0`` skips it.
    Returns:
        :class:`~jaxgear.GlobalResult`. Warnings name what to change when the result looks
        unreliable: many sink cells or an attractor on the region's edge (enlarge the
        region), no period found or many unresolved cells (raise ``max_period`` /
        ``max_periods``), an attractor resolved by few cells (refine the grid).
    Raises:
        ValueError: bad input (the message names the argument and what is allowed),
            found before any integration.
    """
    from .._model import REDUCED
    from .._presets import paper_params

    t_start = time.perf_counter()
    check_bool(progress, "progress")
    check_int(uncertainty, "uncertainty", 0)
    system = REDUCED if system is None else system
    if not isinstance(system, ForcedSystem):
        raise ValueError(f"system must be a jaxgear.ForcedSystem, got {type(system).__name__}.")
    if params is None:
        if system is not REDUCED:
            raise ValueError("analyze_global: pass the parameters of your system (params=...).")
        params = paper_params()
    if method is None:
        method = default_method()
    elif isinstance(method, str):
        method = method_from_name(method)
    elif not isinstance(method, AbstractGlobalMethod):
        raise ValueError(f"method must be a method object (jaxgear.Direct(), jaxgear.PoincareCellMap(), "
                         f"jaxgear.StroboscopicCellMap()) or one of their names, got {type(method).__name__}.")
    grid = method.default_grid(system) if grid is None else grid
    if not isinstance(grid, CellGrid):
        raise ValueError(f"grid must be a jaxgear.CellGrid (CellGrid.box(bounds, counts, ...)), "
                         f"got {type(grid).__name__}.")
    if grid.dim != system.dim:
        raise ValueError(f"the grid has {grid.dim} coordinates, the system {system.dim}.")
    method.check(system, grid)
    check_system(system, params, grid.centres(np.array([0]))[0], batched=False)

    labels, raw, cycles, mean_periods, saddles, _ = method.classify(system, params, grid, progress)
    labels, raw, cycles = _merge_same(labels, raw, cycles, method)
    result = _assemble(system, params, grid, method, labels, raw, cycles, mean_periods,
                       time.perf_counter() - t_start, saddles=saddles)
    if uncertainty:
        result = with_label_uncertainty(result, system, params, method, uncertainty, progress)
        result = dataclasses.replace(result, runtime_s=time.perf_counter() - t_start)
    warn_if_unreliable(result)
    return result


def with_label_uncertainty(result: GlobalResult, system, params, method: AbstractGlobalMethod, samples: int,
                           progress: bool = False) -> GlobalResult:
    """``result`` with its label uncertainty measured on ``samples`` cells
    (:func:`~jaxgear.analysis.label_uncertainty`, by the direct method with the options of
    ``method``, the method that produced the result)."""
    direct = Direct.like(method)
    u = label_uncertainty(system, params, result.grid, result.labels, result.attractors, direct, samples=samples,
                          saddles=result.saddles, progress=progress)
    return dataclasses.replace(result, uncertainty=u)


def analyze_global_values(system: ForcedSystem, params_list, grid: CellGrid, method: AbstractGlobalMethod, *,
                          progress: bool = False, uncertainty: int = DEFAULT_SAMPLES) -> list[GlobalResult]:
    """:func:`analyze_global` at several parameter sets of one system on one grid (the
    arguments already checked): one :class:`~jaxgear.GlobalResult` per set, each the
    result :func:`analyze_global` gives at that set alone, label for label.

    A method with ``classify_values`` (:class:`~jaxgear.Direct`) runs every value in one
    lane pool, and the label uncertainties in one pool each; other methods run value
    after value. In one pool a value's labels are its own when its pilot found all of
    its attractors and the pool met no attractor of boxes, chaotic saddle or unresolved
    cell there: an attractor found later changes the capture radius, and a candidate's
    boxes enter the table, at a moment that depends on the other values' lanes. Any
    other value is analysed again alone. ``runtime_s`` of each result is its share of
    the whole.
    """
    params_list = list(params_list)
    if not hasattr(method, "classify_values") or len(params_list) == 1:
        return [analyze_global(system, p, grid, method, progress=progress, uncertainty=uncertainty)
                for p in params_list]
    t_start = time.perf_counter()
    for params in params_list:
        check_system(system, params, grid.centres(np.array([0]))[0], batched=False)
    results: list = []
    for params, (labels, raw, cycles, mean_periods, saddles, complete) in zip(
            params_list, method.classify_values(system, params_list, grid, progress)):
        if not complete or saddles or any(int(k) == 0 for _, k, _ in raw) or np.any(labels == UNRESOLVED):
            results.append(None)  # (analysed alone below)
            continue
        labels, raw, cycles = _merge_same(labels, raw, cycles, method)
        results.append(_assemble(system, params, grid, method, labels, raw, cycles, mean_periods, 0.0,
                                 saddles=saddles))
    pooled = [i for i, r in enumerate(results) if r is not None]
    if uncertainty and pooled:
        us = label_uncertainties(system, [params_list[i] for i in pooled], grid, [results[i].labels for i in pooled],
                                 [results[i].attractors for i in pooled], Direct.like(method), samples=uncertainty,
                                 saddles_list=[results[i].saddles for i in pooled], progress=progress)
        for i, u in zip(pooled, us):
            results[i] = dataclasses.replace(results[i], uncertainty=u)
    for i in pooled:
        warn_if_unreliable(results[i])
    for i, r in enumerate(results):
        if r is None:
            results[i] = analyze_global(system, params_list[i], grid, method, progress=progress,
                                        uncertainty=uncertainty)
    runtime = (time.perf_counter() - t_start) / len(results)
    return [dataclasses.replace(r, runtime_s=runtime) for r in results]


def _merge_same(labels, raw, cycles, method):
    """Reduce each attractor to its minimal period and merge attractors that are the same."""
    reduced = []
    for pts, k, res in raw:
        if int(k) > 0:  # (an attractor of boxes, period 0, keeps its cloud)
            pts, k = minimal_cycle(np.asarray(pts), int(k), method.period_tol)
        reduced.append((pts, k, res))
    ids = group_attractors([(p, k) for p, k, _ in reduced], method.merge_tol)
    return _merge_groups(labels, reduced, cycles, ids)


def _merge_groups(labels, raw, cycles, ids, join_clouds: bool = False):
    """Labels, attractors and periodic cells with the attractors of each group id ``ids[i]``
    merged into one (the group's first one; with ``join_clouds``, the clouds of period-0
    attractors put together)."""
    if np.array_equal(ids, np.arange(len(raw))):
        return labels, raw, cycles
    out = labels.copy()
    for old, new in enumerate(ids):
        out[labels == old] = new
    n_new = int(ids.max(initial=-1)) + 1
    members = [np.flatnonzero(ids == g) for g in range(n_new)]
    merged = [raw[m[0]] for m in members]
    if join_clouds:
        merged = [(np.concatenate([np.asarray(raw[o][0]) for o in m]), *raw[m[0]][1:]) if raw[m[0]][1] == 0 else r
                  for m, r in zip(members, merged)]
    merged_cycles = [np.unique(np.concatenate([np.asarray(cycles[o], np.int64) for o in m])) for m in members]
    return out, merged, merged_cycles


def _section_index(system, method):
    return method.section_index if method.section_index is not None else system.section_index


ENTROPY_BOX = 5
"""Cells per side of the boxes of the basin entropy (Daza et al. 2016 use 5; smaller
grids use their shortest side)."""

LYAPUNOV_PERIODS = 200
"""Forcing periods over which each attractor's Lyapunov exponents are measured
(:func:`attractor_exponents`; weighted Birkhoff averages converge fast on cycles and tori,
and the error estimate says how far a chaotic attractor's value is known)."""
LYAPUNOV_STRETCHES = 4
"""Stretches of those periods (the error of a single start: the spread of their estimates)."""
LYAPUNOV_LANES = 32
"""Starts on an attractor without a period whose exponents are averaged (points spread over
its cloud, all integrated in one batch): the error is the spread between these independent
estimates, ``std / sqrt(lanes)``: 1-2 % of a chaotic gear attractor's largest exponent,
where one start over the same periods gives 5-20 %."""
LYAPUNOV_RECHECK_LANES = 4
"""Starts of the longer look at an attractor that looked quasi-periodic (a torus's weighted
averages converge fast; a weakly chaotic set shows its positive exponent in each)."""
LYAPUNOV_RECHECK = 8
"""An attractor that the first :data:`LYAPUNOV_PERIODS` periods call quasi-periodic (largest
exponent zero within its error) is measured again, from where the first measurement
ended, over this many times as many periods in as many times as many stretches: a weakly
chaotic attractor (lambda_1 ~ 0.1 per period) can look like a torus over 200 periods,
a torus stays one (its weighted averages converge faster than any power)."""


def with_longer_look(spectrum, measure):
    """Types and leading exponents ``(kinds, exponents, errors, kaplan_yorke)`` (numpy,
    leading axis: the attractors) of the :class:`~jaxgear.LyapunovSpectrum` ``spectrum``
    (measured over :data:`LYAPUNOV_PERIODS` periods, no period known), where those that
    come out quasi-periodic are measured again by ``measure(index, x0, periods,
    stretches) -> LyapunovSpectrum`` from the spectrum's final states, over
    :data:`LYAPUNOV_RECHECK` times as many periods and stretches, and typed by that (as are
    those left undetermined: a zero largest exponent that the first look could not call a
    closed curve)."""
    n = spectrum.exponents.shape[0]
    kinds = np.asarray(classify_attractor(spectrum, period=np.zeros(n, np.int64)))
    exps, errs, ky = (np.array(a) for a in (spectrum.exponents, spectrum.errors, spectrum.kaplan_yorke))
    torus = np.flatnonzero(np.isin(kinds, [int(AttractorType.QUASI_PERIODIC), int(AttractorType.UNDETERMINED)]))
    if torus.size:  # a longer look before a zero exponent is believed (or left undecided)
        longer = measure(torus, np.asarray(spectrum.final_state)[torus], LYAPUNOV_PERIODS * LYAPUNOV_RECHECK,
                         LYAPUNOV_STRETCHES * LYAPUNOV_RECHECK)
        kinds[torus] = classify_attractor(longer, period=np.zeros(torus.size, np.int64))
        for a, b in zip((exps, errs, ky), (longer.exponents, longer.errors, longer.kaplan_yorke)):
            a[torus] = np.asarray(b)
    return kinds, exps, errs, ky


def attractor_exponents(system, params, attractors, integrator, multipliers, n_exponents: int = 2):
    """Type and Lyapunov exponents of each attractor ``(points, period)`` (a cycle's points,
    or the cloud of an attractor of boxes). A P-k cycle's exponents are ``ln |mu_i| / k``
    of its Floquet multipliers ``multipliers[i]`` (exact for a cycle: error 0; the
    multipliers come from autodiff Jacobians, to round-off); an attractor that repeats no point gets
    the exponents of the stroboscopic map averaged over up to :data:`LYAPUNOV_LANES` starts
    spread over its cloud (:func:`~jaxgear.lyapunov_spectrum`, :data:`LYAPUNOV_PERIODS`
    periods each, every start of every attractor in one batch; the error is the spread
    between the starts, :func:`~jaxgear.ensemble_spectrum`; those that look quasi-periodic
    again over :data:`LYAPUNOV_RECHECK` times as long) and its
    :class:`~jaxgear.AttractorType` from them (:func:`~jaxgear.classify_attractor`).
    Returns ``(types (A,), [(exponents, errors, kaplan_yorke)])``."""
    n = min(int(n_exponents), system.dim)
    kinds = np.full(len(attractors), int(AttractorType.PERIODIC), np.int32)
    out: list = [None] * len(attractors)
    for i, ((_, k), mu) in enumerate(zip(attractors, multipliers)):
        if k > 0:
            lam = np.sort(np.log(np.abs(np.asarray(mu))))[::-1][:n] / int(k)
            out[i] = (lam, np.zeros(n), float(kaplan_yorke(lam)))
    free = [i for i, (_, k) in enumerate(attractors) if k <= 0]
    if free:
        starts = [_ensemble_starts(np.asarray(attractors[i][0], np.float64)) for i in free]
        groups = np.concatenate([np.full(len(x), j) for j, x in enumerate(starts)])
        opts = LyapunovOptions(n_exponents=n, periods=LYAPUNOV_PERIODS, transient=0, stretches=LYAPUNOV_STRETCHES)
        lanes = lyapunov_spectrum(system, params, np.concatenate(starts), integrator=integrator, options=opts)

        def measure(which, _, periods, stretches):
            """The attractors ``which`` again, for longer, from where the first
            :data:`LYAPUNOV_RECHECK_LANES` of each one's lanes ended."""
            rank = np.arange(len(groups)) - np.searchsorted(groups, groups)  # (groups are sorted)
            mine = np.isin(groups, which) & (rank < LYAPUNOV_RECHECK_LANES)
            again = lyapunov_spectrum(system, params, np.asarray(lanes.final_state)[mine], integrator=integrator,
                                      options=opts, periods=periods, stretches=stretches)
            return ensemble_spectrum(again, np.searchsorted(which, groups[mine]))

        kinds[free], exps, errs, ky = with_longer_look(ensemble_spectrum(lanes, groups), measure)
        for j, i in enumerate(free):
            out[i] = (exps[j], errs[j], float(ky[j]))
    return kinds, out


def _ensemble_starts(cloud: np.ndarray) -> np.ndarray:
    """Up to :data:`LYAPUNOV_LANES` points spread over an attractor's cloud (its finite
    points, in the order the pool kept them): the ensemble's independent starts."""
    cloud = cloud[np.all(np.isfinite(cloud), axis=1)]
    if len(cloud) <= LYAPUNOV_LANES:
        return cloud
    return cloud[np.linspace(0, len(cloud) - 1, LYAPUNOV_LANES).astype(np.int64)]


def _first_appearance(ids):
    """Group ids renumbered 0.. in order of first appearance."""
    first = {g: n for n, g in enumerate(dict.fromkeys(ids.tolist()))}
    return np.array([first[g] for g in ids.tolist()], np.int64)


def _retyped(system, params, method, labels, raw, cycles, order, kinds, spectra):
    """What the attractors' types change, as new ``(labels, raw, cycles)``, or ``None``:
    an attractor of boxes that contracts (typed periodic by its exponents) is the cycle of
    its period when that is found (:func:`~jaxgear.analysis._orbits.long_cycles`), and
    quasi-periodic attractors on one invariant curve are one
    (:func:`~jaxgear.analysis._tori.joined_tori`). ``order``, ``kinds``, ``spectra``: the
    attractors in the order their types were measured."""
    raw = list(raw)
    finite = [np.asarray(pts, np.float64).reshape(len(pts), -1) for pts, _, _ in raw]
    finite = [p[np.all(np.isfinite(p), axis=1)] for p in finite]
    contracting = [old for old, kind in zip(order, kinds)
                   if raw[old][1] == 0 and kind == int(AttractorType.PERIODIC) and len(finite[old])]
    starts = [finite[old][-1] for old in contracting]
    found = long_cycles(system, params, starts, method.integrator, method.max_period, method.period_tol)
    for old, cycle in zip(contracting, found):
        if cycle is not None:
            raw[old] = cycle
    joined = joined_tori(system, params, method.integrator, [raw[old][0] for old in order], kinds,
                         [e for e, _, _ in spectra])
    if joined is None and all(c is None for c in found):
        return None
    if joined is None:
        return _merge_same(labels, raw, cycles, method)
    ids = np.empty(len(raw), np.int64)  # (ids in the order of `order`: back to the raw attractors')
    ids[order] = joined
    labels, raw, cycles = _merge_groups(labels, raw, cycles, _first_appearance(ids), join_clouds=True)
    return _merge_same(labels, raw, cycles, method) if any(c is not None for c in found) else (labels, raw, cycles)


def _assemble(system, params, grid, method, labels, raw, cycles, mean_periods, runtime,
              typed_again: bool = True, saddles: tuple = ()) -> GlobalResult:
    """Attractors sorted by decreasing share (ids renumbered 0..A-1) and the result object;
    what their types change is done first (:func:`_retyped`: a cycle longer than
    ``max_period`` gets its period, one torus seen as several is one)."""
    n = grid.n_cells
    counts = np.array([(labels == i).sum() for i in range(len(raw))], dtype=np.int64)
    order = np.argsort(-counts, kind="stable")
    out_labels = labels.copy()
    for new, old in enumerate(order):
        out_labels[labels == old] = new
    sec_idx = _section_index(system, method)
    attractors = []
    periodic = [old for old in order if raw[old][1] > 0]
    secs, mults = cycle_sections_and_multipliers(system, params, [raw[old][0] for old in periodic],
                                                 method.integrator, sec_idx, method.direction)
    secs, mults = dict(zip(periodic, secs)), dict(zip(periodic, mults))
    mus = {old: float(np.abs(m).max()) if np.all(np.isfinite(m)) else np.inf for old, m in mults.items()}
    kinds, spectra = attractor_exponents(system, params, [raw[old][:2] for old in order], method.integrator,
                                         [mults.get(old) for old in order])
    if typed_again:
        again = _retyped(system, params, method, labels, raw, cycles, order, kinds, spectra)
        if again is not None:
            return _assemble(system, params, grid, method, *again, mean_periods, runtime, typed_again=False,
                             saddles=saddles)
    for new, old in enumerate(order):
        pts, per, res = raw[old]
        sec = secs.get(old, np.zeros((0, system.dim)))
        attractors.append(Attractor(id=new, period=int(per), points=np.asarray(pts, dtype=float),
                                    section_points=np.asarray(sec, dtype=float), cell_count=int(counts[old]),
                                    share=float(counts[old]) / n, residual=float(res),
                                    periodic_cells=np.asarray(cycles[old], dtype=np.int64),
                                    multiplier=float(mus.get(old, np.nan)), kind=int(kinds[new]),
                                    exponents=spectra[new][0], exponent_errors=spectra[new][1],
                                    kaplan_yorke=float(spectra[new][2])))
    return GlobalResult(
        labels=out_labels.reshape(grid.counts).astype(np.int64), attractors=tuple(attractors), grid=grid,
        method=method, params=params_to_dict(params), system=system.name,
        state_names=tuple(system.state_names), n_sink=int((out_labels == SINK).sum()),
        n_unresolved=int((out_labels == UNRESOLVED).sum()), runtime_s=float(runtime), version=__version__,
        mean_periods=float(mean_periods), saddles=tuple(saddles),
        # (boxes need 2 cells a side: a grid with an axis of one cell has no basin entropy)
        basin_entropy=basin_entropy(out_labels.reshape(grid.counts), box=min(ENTROPY_BOX, *grid.counts))
        if min(grid.counts) >= 2 else None,
    )
