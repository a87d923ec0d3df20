"""Global analysis by cell mapping (paper §3-§4; Hsu 1980; Levitas et al. 1994).

Three methods, one result type (:class:`~jaxgear.GlobalResult`):

- ``"poincare-like"`` — the paper's method (§3, eq. 9): each cell centre, on the section
  Σ at forcing phase 0, is integrated ``l`` forcing periods and on to the next crossing
  of Σ; the image cell is where that crossing lies.
- ``"stroboscopic"`` — Hsu's simple cell mapping of the exact stroboscopic map
  ``x -> P^l(x)`` on a grid over all state coordinates.
- ``"direct"`` — every cell centre is integrated on the stroboscopic map until its
  attractor is recognised (recurrence to tolerance, or capture by an attractor found
  earlier) or it escapes; no discretisation of images. The reference for the others.

For the cell methods the cell map's periodic groups (its cycles) and domains of
attraction come from a vectorised graph analysis (:func:`analyze_cell_map`); each
periodic group is then followed on the stroboscopic map at point level to read its
period P-k (which the cycle length of the cell map cannot give: it depends on ``l``)
and groups that are the same attractor are merged.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._cells import CellGrid
from ._integrate import RK4, Integrator, advance_batch
from ._poincare import STATUS_OK, _section_kernel, sample_trajectory, section_map, stroboscopic_orbit
from ._result import SINK, UNRESOLVED, Attractor, GlobalResult
from ._system import ForcedSystem, check_system

__all__ = ["analyze_global", "cell_images", "analyze_cell_map", "detect_period", "compare_with_direct", "METHODS"]

METHODS = ("poincare-like", "stroboscopic", "direct")

_MIN_CELLS = 10
"""Cell methods: an attractor resolved by fewer cells triggers a 'refine the grid' warning."""


def _progress(total: int, desc: str, enabled: bool, unit: str = "cell"):
    """A tqdm bar (a widget in notebooks when ipywidgets is installed) with time left."""
    import warnings as _w

    with _w.catch_warnings():
        _w.simplefilter("ignore")  # tqdm.auto warns when ipywidgets is missing, then falls back
        from tqdm.auto import tqdm

        return tqdm(total=total, desc=desc, unit=unit, unit_scale=True, disable=not enabled, leave=False)


def _chunks(n: int, size: int):
    for start in range(0, n, size):
        yield start, min(start + size, n)


def _pad(X: np.ndarray, size: int) -> np.ndarray:
    """Pad a chunk to a fixed size (one compiled shape) by repeating its first row."""
    if len(X) == size:
        return X
    return np.concatenate([X, np.repeat(X[:1], size - len(X), axis=0)], axis=0)


# --------------------------------------------------------------------- images
@eqx.filter_jit
def _strobe_chunk(system, params, X, periods, integrator):
    Y = advance_batch(system, params, X.T, jnp.asarray(0.0), periods, integrator)
    return Y.T


def cell_images(system: ForcedSystem, params, grid: CellGrid, *, method: str = "poincare-like",
                mapping_steps: int = 50, integrator: Integrator = RK4(), direction: int = 1,
                section_index: int | None = None, chunk_size: int = 131072, progress: bool = True) -> np.ndarray:
    """Image cell of every cell (paper eq. 9): an int array ``(n_cells,)``; the sink is ``n_cells``.

    ``poincare-like``: centre on Σ at phase 0 -> ``mapping_steps`` periods -> next
    crossing of Σ (``direction``) -> its cell. ``stroboscopic``: centre -> ``P^l`` -> its
    cell (the grid must cover every state coordinate). Work is done in chunks of
    ``chunk_size`` cells (one compiled shape; memory bounded by the chunk, not the grid);
    the images do not depend on the chunk size.
    """
    if method not in ("poincare-like", "stroboscopic"):
        raise ValueError(f"cell_images: method must be 'poincare-like' or 'stroboscopic', got {method!r}.")
    if int(mapping_steps) < (1 if method == "stroboscopic" else 0):
        raise ValueError(f"mapping_steps={mapping_steps} must be >= 1 (stroboscopic) or >= 0 (poincare-like).")
    if int(chunk_size) < 1:
        raise ValueError(f"chunk_size={chunk_size} must be >= 1.")
    if method == "poincare-like":
        idx = system.section_index if section_index is None else section_index
        if idx is None:
            raise ValueError("poincare-like mapping needs a section: pass section_index=i for Σ = {x_i = 0}.")
        if idx in grid.axes:
            raise ValueError(f"the section coordinate {idx} cannot be a grid axis of the poincare-like method.")
        if grid.base[idx] != 0.0:
            raise ValueError(f"cell centres must lie on Σ: grid.base[{idx}] must be 0.")
    elif sorted(grid.axes) != list(range(system.dim)):
        raise ValueError(
            f"the stroboscopic cell map needs a grid over every state coordinate (0..{system.dim - 1}); "
            f"this grid covers {grid.axes}. Use CellGrid.box(bounds, counts) with {system.dim} axes."
        )
    n = grid.n_cells
    chunk = -(-n // -(-n // int(chunk_size)))  # equal chunks of at most chunk_size cells
    images = np.empty(n, dtype=np.int64)
    bar = _progress(n, f"{method} map", progress)
    search = integrator.steps_per_period if isinstance(integrator, RK4) else 400
    for a, b in _chunks(n, chunk):
        X = _pad(grid.centres(np.arange(a, b)), chunk)
        if method == "poincare-like":
            Yc, _, _, status = _section_kernel(system, params, jnp.asarray(X.T), jnp.asarray(0.0),
                                               int(mapping_steps), idx, int(direction), 4.0, integrator, search)
            Y = np.array(Yc.T)
            Y[np.asarray(status) != STATUS_OK] = np.nan
        else:
            Y = np.asarray(_strobe_chunk(system, params, jnp.asarray(X), int(mapping_steps), integrator))
        images[a:b] = grid.locate(Y[: b - a])
        bar.update(b - a)
    bar.close()
    return images


# --------------------------------------------------------------- graph analysis
def analyze_cell_map(images: np.ndarray, n_cells: int | None = None) -> dict[str, np.ndarray]:
    """Periodic groups and domains of a simple cell map, vectorised (pointer doubling).

    Hsu's analysis of a simple cell map (paper §3; Hsu 1980): every cell's sequence ends
    in a periodic group (a cycle of cells) or in the sink; the cells ending in a group
    form its domain of attraction. Cells are integer indices (no units).

    Args:
        images: ``(n,)`` image of each regular cell; the value ``n`` is the sink, which
            maps to itself.
    Returns a dict with
        ``group``: ``(n,)`` id of the periodic group each cell's sequence ends in (the
        smallest cell index of that cycle; ``n`` for the sink);
        ``periodic``: ``(n,)`` bool, the cell lies on a cycle (a periodic cell);
        ``groups``: sorted ids of the periodic groups (sink excluded);
        ``cycle_length``: number of cells of each group's cycle.
    After ``K >= log2(n+1)`` doublings ``f^(2^K)(i)`` lies on the cycle that cell ``i``
    ends in; the cycle's smallest index is the running minimum over ``2^K`` iterates.
    """
    images = np.asarray(images, dtype=np.int64)
    n = len(images) if n_cells is None else int(n_cells)
    if images.shape != (n,) or images.min(initial=0) < 0 or images.max(initial=0) > n:
        raise ValueError(f"images must be an int array of shape ({n},) with values in 0..{n} (n = sink).")
    f = np.append(images, n)  # the sink maps to itself
    K = max(1, int(np.ceil(np.log2(n + 1))) + 1)
    m = np.arange(n + 1)
    P = f.copy()
    for _ in range(K):
        m = np.minimum(m, m[P])
        P = P[P]
    land = P  # f^(2^K)(i): on a cycle
    periodic = np.zeros(n + 1, dtype=bool)
    periodic[land] = True
    # m[i] is the minimum over f^j(i), j < 2^K: for a cycle cell, the whole cycle.
    group = m[land]
    groups, counts = np.unique(group[:n][periodic[:n]], return_counts=True)
    keep = groups != n
    return dict(group=group[:n], periodic=periodic[:n], groups=groups[keep], cycle_length=counts[keep])


# --------------------------------------------------------------- period detection
def detect_period(orbit: np.ndarray, max_period: int, tol: float) -> np.ndarray:
    """Minimal period of each stroboscopic sequence ``orbit (..., K, dim)`` (the P-k of paper §4).

    The smallest ``k <= max_period`` with ``|x_j - x_(j-k)| <= tol (1 + |x_j|)`` for the
    last ``k + 1`` points ``j`` (so a whole cycle and one more step repeat); ``0`` if
    none, ``-1`` if the sequence is not finite. Needs ``K >= 2 max_period + 1``.
    ``tol`` is relative (dimensionless); returns an int array of shape ``(...)``.
    """
    orbit = np.asarray(orbit)
    K = orbit.shape[-2]
    if K < 2 * max_period + 1:
        raise ValueError(f"detect_period needs at least {2 * max_period + 1} points, got {K}.")
    lead = orbit.shape[:-2]
    out = np.zeros(lead, dtype=np.int64)
    done = np.zeros(lead, dtype=bool)
    scale = 1.0 + np.linalg.norm(orbit[..., -1, :], axis=-1)
    for k in range(1, max_period + 1):
        idx = np.arange(K - k - 1, K)
        d = np.linalg.norm(orbit[..., idx, :] - orbit[..., idx - k, :], axis=-1).max(axis=-1)
        hit = (d <= tol * scale) & ~done
        out[hit] = k
        done |= hit
    out[~np.all(np.isfinite(orbit), axis=(-1, -2))] = -1
    return out


def _set_distance(A: np.ndarray, B: np.ndarray) -> float:
    """Largest distance from a point of A to its nearest point of B (directed Hausdorff)."""
    d = np.linalg.norm(A[:, None, :] - B[None, :, :], axis=-1)
    return float(d.min(axis=1).max())


def _section_points(system, params, points: np.ndarray, integrator, index, direction, samples=200) -> np.ndarray:
    """Crossings of Σ = {x_index = 0} over the k periods of a periodic orbit (k = len(points))."""
    if index is None or len(points) == 0 or not np.all(np.isfinite(points)):
        return np.zeros((0, system.dim))
    k = len(points)
    ts, xs = sample_trajectory(system, params, jnp.asarray(points[0]), periods=k, samples_per_period=samples,
                               integrator=integrator)
    ts, xs = np.asarray(ts), np.asarray(xs)
    g = xs[:, index]
    if direction > 0:
        hits = np.nonzero((g[:-1] < 0) & (g[1:] >= 0))[0]
    elif direction < 0:
        hits = np.nonzero((g[:-1] > 0) & (g[1:] <= 0))[0]
    else:
        hits = np.nonzero(np.sign(g[:-1]) * np.sign(g[1:]) < 0)[0]
    out = []
    for i in hits:
        h = section_map(system, params, xs[i], periods=0, t0=ts[i], index=index, direction=direction,
                        max_extra_periods=2.0 / samples, integrator=integrator)
        if int(h.status) == STATUS_OK:
            out.append(np.asarray(h.state))
    return np.asarray(out).reshape(-1, system.dim)


def _follow(system, params, X: np.ndarray, integrator, settle: int, max_period: int, tol: float):
    """Integrate states ``X (n, dim)`` ``settle`` periods, then record ``2 max_period + 2``
    stroboscopic points; returns (periods (n,), recorded points (n, K, dim))."""
    Xs = _strobe_chunk(system, params, jnp.asarray(X), int(settle), integrator) if settle > 0 else jnp.asarray(X)
    orbit = np.asarray(stroboscopic_orbit(system, params, Xs, n_points=2 * max_period + 2, integrator=integrator))
    return detect_period(orbit, max_period, tol), orbit


def _refine_orbit(system, params, x: np.ndarray, k: int, integrator, settle: int = 0) -> tuple[np.ndarray, float]:
    """The k stroboscopic points from ``x`` (after ``settle`` more periods, rounded to a
    multiple of k) and the residual ``|P^k(p) - p|``."""
    if settle > 0:
        x = _strobe_chunk(system, params, jnp.asarray(x)[None], int(-(-settle // k) * k), integrator)[0]
    orb = np.asarray(stroboscopic_orbit(system, params, jnp.asarray(x), n_points=2 * k, integrator=integrator))
    pts = orb[k - 1 : 2 * k - 1]
    res = float(np.max(np.linalg.norm(orb[2 * k - 1] - orb[k - 1])))
    # report points in a canonical order: start at the point with the smallest first coordinate
    start = int(np.argmin(pts[:, 0]))
    return np.roll(pts, -start, axis=0), res


def _minimal_periods(labels: np.ndarray, att_points: list, cycles: list, tol: float, merge_tol: float):
    """Reduce each attractor to the minimal period of its refined points and merge duplicates.

    A slowly spiralling transient (complex multipliers whose rotation is close to 2 pi / k)
    can pass the recurrence test at ``k`` times the true period before it passes at the true
    one; after refinement its ``k`` points then repeat with a smaller period ``j`` (a P-1
    spur-gear orbit with multipliers 0.84 e^(+-2.1i) was reported as P-3). Returns
    ``(labels, att_points, cycles)`` with periods reduced and equal attractors merged.
    """
    reduced = []
    for pts, k, res in att_points:
        pts = np.asarray(pts)
        if k > 1 and len(pts) == k and np.all(np.isfinite(pts)):
            scale = tol * (1.0 + np.abs(pts).max())
            for j in (d for d in range(1, k) if k % d == 0):
                if np.max(np.linalg.norm(pts - np.roll(pts, -j, axis=0), axis=1)) <= scale:
                    pts, k = pts[:j], j
                    break
        reduced.append([pts, k, res])
    target = list(range(len(reduced)))
    for i in range(len(reduced)):
        for j in range(i):
            if target[j] != j:
                continue
            (pi, ki, _), (pj, kj, _) = reduced[i], reduced[j]
            if ki == kj and ki > 0 and _set_distance(pi, pj) <= merge_tol * (1 + np.abs(pj).max()):
                target[i] = j
                break
    if target == list(range(len(reduced))):
        return labels, [tuple(r) for r in reduced], cycles
    keep = sorted(set(target))
    new_id = {old: keep.index(target[old]) for old in range(len(reduced))}
    out = labels.copy()
    for old, new in new_id.items():
        out[labels == old] = new
    merged_cycles = [np.unique(np.concatenate([np.asarray(cycles[o], np.int64) for o in range(len(reduced))
                                               if target[o] == t])) for t in keep]
    return out, [tuple(reduced[t]) for t in keep], merged_cycles


# --------------------------------------------------------------- main entry
def analyze_global(system: ForcedSystem | None = None, params=None, grid: CellGrid | None = None, *,
                   method: str = "poincare-like", mapping_steps: int | None = None,
                   integrator: Integrator | None = None, steps_per_period: int | None = None,
                   direction: int = 1, section_index: int | None = None, chunk_size: int = 131072,
                   max_period: int = 16, period_tol: float = 1e-6, settle_periods: int = 400,
                   merge_tol: float = 1e-4, round_periods: int = 5, max_periods: int = 2000,
                   capture_radius: float | str = "auto", escape_bound: float = 1e6, progress: bool = True,
                   version: str | None = None) -> GlobalResult:
    """Every coexisting attractor in a region, its period and its domain (paper §3-§4).

    Args:
        system: a :class:`ForcedSystem` (default: the reduced gear model ``REDUCED``).
        params: its parameter pytree (default: the ``paper`` preset).
        grid: the :class:`CellGrid` (default for the gear model: the paper's region D,
            50 × 30 × 60 cells on Σ = {x4 = 0}; the stroboscopic method needs a grid over
            every coordinate).
        method: ``"poincare-like"`` (paper), ``"stroboscopic"`` (Hsu) or ``"direct"``.
        mapping_steps: ``l``, forcing periods per cell-map step (default 50 for
            poincare-like as in the paper, 1 for stroboscopic; unused by direct).
        integrator / steps_per_period: default ``RK4(steps_per_period or 200)``.
        direction: crossing direction of Σ (+1: ``x_i`` increasing).
        max_period: largest period k detected (P-1 ... P-max_period).
        period_tol: relative recurrence tolerance of the period detection.
        settle_periods: periods each periodic group is followed before its period is read.
        merge_tol: groups whose attractor points lie within this distance are one attractor.
        chunk_size: cells integrated in one batch (memory is bounded by it, not by the
            grid; results do not depend on it). On a 2-core CPU batches below ~65,000
            cells run single-threaded, about twice slower per cell.
        round_periods, max_periods, capture_radius, escape_bound: ``direct`` method:
            periods per round between checks, limit per cell (then ``UNRESOLVED``),
            the radius within which a trajectory's last k stroboscopic points must follow
            the whole cycle of a known P-k attractor to be decided (``"auto"``: a quarter
            of the smallest distance between two attractors' points, at most 1 % of their
            scale; see :func:`_capture_radius`), and the norm beyond which a state counts
            as escaped (sink).
        progress: show progress bars (tqdm); ``False`` silences them.
    Returns:
        :class:`GlobalResult`. Warnings name what to change when the result looks
        unreliable: many sink cells or an attractor on the region's edge (enlarge the
        region), no period found or many unresolved cells (raise ``max_period`` /
        ``max_periods``), an attractor resolved by few cells (refine the grid).
    """
    from . import __version__
    from ._model import REDUCED

    t_start = time.perf_counter()
    system = REDUCED if system is None else system
    if params is None:
        if system is not REDUCED:
            raise ValueError("analyze_global: pass the parameters of your system.")
        from . import paper_params

        params = paper_params()
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}.")
    if grid is None:
        if system is not REDUCED:
            raise ValueError("analyze_global: pass a CellGrid for your system (CellGrid.box(bounds, counts, ...)).")
        grid = CellGrid.paper()
        if method == "stroboscopic":
            raise ValueError("the stroboscopic method needs a grid over x1..x4, e.g. "
                             "CellGrid.box([(-25,25),(-10,20),(-10,50),(-10,10)], (25,15,30,10), names=REDUCED.state_names).")
    if grid.dim != system.dim:
        raise ValueError(f"the grid has {grid.dim} coordinates, the system {system.dim}.")
    if integrator is None:
        integrator = RK4(int(steps_per_period or 200))
    elif steps_per_period is not None:
        raise ValueError("give either integrator or steps_per_period, not both.")
    if mapping_steps is None:
        mapping_steps = 50 if method == "poincare-like" else 1
    for name, v, lo in (("max_period", max_period, 1), ("settle_periods", settle_periods, 0),
                        ("round_periods", round_periods, 1), ("max_periods", max_periods, 1),
                        ("chunk_size", chunk_size, 1)):
        if int(v) < lo:
            raise ValueError(f"{name}={v} must be >= {lo}.")
    if not (capture_radius == "auto" or (isinstance(capture_radius, (int, float)) and capture_radius >= 0)):
        raise ValueError(f"capture_radius={capture_radius!r} must be 'auto' or a number >= 0.")
    check_system(system, params, grid.centres(np.array([0]))[0], batched=False)
    sec_idx = system.section_index if section_index is None else section_index
    n = grid.n_cells
    settings: dict[str, Any] = dict(
        mapping_steps=int(mapping_steps), integrator=type(integrator).__name__,
        steps_per_period=getattr(integrator, "steps_per_period", None), direction=int(direction),
        section_index=sec_idx, max_period=int(max_period), period_tol=period_tol,
        settle_periods=int(settle_periods), merge_tol=merge_tol, chunk_size=int(chunk_size),
    )
    params_dict = _pytree_dict(params)

    if method == "direct":
        settings.update(round_periods=int(round_periods), max_periods=int(max_periods),
                        capture_radius=capture_radius, escape_bound=escape_bound)
        labels, att_points, mean_periods = _direct(system, params, grid.centres(), integrator, chunk_size,
                                                   round_periods, max_periods, max_period, period_tol,
                                                   capture_radius, escape_bound, merge_tol, progress)
        cycles = [np.zeros(0, np.int64)] * len(att_points)
    else:
        images = cell_images(system, params, grid, method=method, mapping_steps=mapping_steps,
                             integrator=integrator, direction=direction, section_index=sec_idx,
                             chunk_size=chunk_size, progress=progress)
        labels, att_points, cycles = _classify_groups(system, params, grid, images, integrator, settle_periods,
                                                      max_period, period_tol, merge_tol, chunk_size)
        mean_periods = float(mapping_steps)

    labels, att_points, cycles = _minimal_periods(labels, att_points, cycles, period_tol, merge_tol)
    # Assemble attractors, sorted by decreasing share, ids renumbered 0..A-1.
    counts = np.array([(labels == i).sum() for i in range(len(att_points))], dtype=np.int64)
    order = np.argsort(-counts, kind="stable")
    relabel = {old: new for new, old in enumerate(order)}
    out_labels = labels.copy()
    for old, new in relabel.items():
        out_labels[labels == old] = new
    attractors = []
    for new, old in enumerate(order):
        pts, per, res = att_points[old]
        sec = (_section_points(system, params, pts, integrator, sec_idx, direction) if per > 0 else
               np.zeros((0, system.dim)))
        attractors.append(Attractor(id=new, period=int(per), points=pts, section_points=sec,
                                    cell_count=int(counts[old]), share=float(counts[old]) / n, residual=float(res),
                                    periodic_cells=np.asarray(cycles[old], dtype=np.int64)))
    n_sink = int((out_labels == SINK).sum())
    n_unres = int((out_labels == UNRESOLVED).sum())
    result = GlobalResult(
        labels=out_labels.reshape(grid.counts), attractors=tuple(attractors), grid=grid, method=method,
        settings=settings, params=params_dict, system=system.name, state_names=tuple(system.state_names),
        n_sink=n_sink, n_unresolved=n_unres, runtime_s=time.perf_counter() - t_start,
        version=version or __version__, mean_periods=float(mean_periods),
    )
    _warn_if_unreliable(result)
    return result


def _pytree_dict(params) -> dict:
    """Parameters as a JSON-ready dict: the canonical names for :class:`GearParams`
    (MODEL.md §4), the pytree paths of the leaves for any other parameter pytree."""
    from ._params import GearParams

    if isinstance(params, GearParams):
        return params.to_dict()
    leaves = jax.tree_util.tree_leaves_with_path(params)
    out = {}
    for path, leaf in leaves:
        a = np.asarray(leaf)
        out[jax.tree_util.keystr(path).lstrip(".")] = float(a) if a.ndim == 0 else a.tolist()
    return out


def _classify_groups(system, params, grid, images, integrator, settle, max_period, tol, merge_tol, chunk):
    """Cell-map groups -> attractors at point level; returns (labels (n,), [(points, period, residual)], cycles)."""
    n = grid.n_cells
    cm = analyze_cell_map(images, n)
    groups = cm["groups"]
    group_of_cell = cm["group"]
    labels = np.full(n, SINK, dtype=np.int64)
    if len(groups) == 0:
        return labels, [], []
    # Follow one representative (the group's smallest periodic cell) per group at point level.
    reps = grid.centres(groups)
    periods = np.empty(len(groups), dtype=np.int64)
    orbits = np.empty((len(groups), 2 * max_period + 2, system.dim))
    for a, b in _chunks(len(groups), chunk):
        periods[a:b], orbits[a:b] = _follow(system, params, reps[a:b], integrator, settle, max_period, tol)
    # Merge groups that reach the same attractor (a Python loop over groups, not cells).
    attractors: list[list] = []  # [points, period, residual, group list]
    group_label = np.full(len(groups), SINK, dtype=np.int64)
    for gi in range(len(groups)):
        k = int(periods[gi])
        if k < 0:
            continue  # escaped: its domain belongs to the sink
        pts = orbits[gi, -max(k, 1):] if k > 0 else orbits[gi, -1:]
        found = -1
        for ai, (apts, ak, _, _) in enumerate(attractors):
            if ak == k and k > 0 and _set_distance(pts, apts) <= merge_tol * (1 + np.abs(apts).max()):
                found = ai
                break
            if ak == 0 and k == 0:
                found = ai  # all non-periodic groups form one 'non-periodic' set
                break
        if found < 0:
            attractors.append([pts, k, np.nan, []])
            found = len(attractors) - 1
        attractors[found][3].append(groups[gi])
        group_label[gi] = found
    pos = np.searchsorted(groups, group_of_cell)
    pos = np.clip(pos, 0, len(groups) - 1)
    valid = groups[pos] == group_of_cell
    labels = np.where(valid, group_label[pos], SINK)
    out, cycles = [], []
    periodic = cm["periodic"]
    for pts, k, _, glist in attractors:
        if k > 0:
            pts, res = _refine_orbit(system, params, pts[-1], k, integrator)
        else:
            res = np.nan
        out.append((pts, k, res))
        cycles.append(np.nonzero(periodic & np.isin(group_of_cell, glist))[0])
    return labels, out, cycles


# --------------------------------------------------------------- direct method
@eqx.filter_jit
def _direct_round(system, params, X, periods, integrator):
    """Advance ``X (C, dim)`` by ``periods`` periods, returning all stroboscopic points ``(C, periods, dim)``."""
    def step(Y, _):
        Y = advance_batch(system, params, Y, jnp.asarray(0.0), 1, integrator)
        return Y, Y

    _, Ys = jax.lax.scan(step, X.T, None, length=periods)
    return jnp.transpose(Ys, (2, 0, 1))


def _pool_size(n_busy: int, pool: int, smallest: int = 256) -> int:
    """Padded batch size for ``n_busy`` lanes: the pool size, or ``smallest * 4^j`` below it,
    so a draining pool compiles few shapes (each costs ~0.5 s) for some idle lanes."""
    if n_busy >= pool:
        return pool
    size = smallest
    while size < n_busy:
        size *= 4
    return min(size, pool)


def _capture_radius(attractors: list, capture) -> float:
    """Capture radius around known attractors' points (state units).

    ``capture="auto"``: a quarter of the smallest distance between points of two
    different known attractors, and at most 1 % of ``1 + max |point|`` (the attractors'
    scale); a number is used as given.
    """
    if capture != "auto":
        return float(capture)
    pts = [np.asarray(p) for p, _, _ in attractors]
    r = 0.01 * (1.0 + max(float(np.abs(p).max()) for p in pts))
    for i in range(len(pts)):
        for j in range(i):
            d = np.linalg.norm(pts[i][:, None, :] - pts[j][None, :, :], axis=-1).min()
            r = min(r, 0.25 * float(d))
    return r


def _shadowing(hist: np.ndarray, points: np.ndarray) -> np.ndarray:
    """How closely each lane's last ``k`` stroboscopic points follow a period-k cycle.

    ``hist (lanes, H, dim)`` (newest last), ``points (k, dim)`` in the cycle's order
    (``points[j+1] = P(points[j])``). Returns ``(lanes,)``: the smallest, over the k
    alignments of the cycle, of the largest distance along the last k points, and
    ``inf`` for lanes whose window holds non-finite values (not yet filled).
    """
    k = len(points)
    W = hist[:, -k:]  # (lanes, k, dim), W[:, i] aligned with points[(j + i) % k]
    best = np.full(len(hist), np.inf)
    for j in range(k):
        d = np.linalg.norm(W - np.roll(points, -j, axis=0)[None], axis=-1).max(axis=1)
        best = np.minimum(best, np.where(np.isfinite(d), d, np.inf))
    return best


def _direct(system, params, X, integrator, chunk, R, max_periods, max_period, tol, capture, bound, merge_tol,
            progress, pilot: int = 1024):
    """Direct classification of the states ``X (n, dim)``: a pilot sample first, then the rest.

    The pilot (``pilot`` cells drawn with a fixed seed) runs alone until each of its
    trajectories recurs, so the common attractors are known before the bulk of the
    cells starts and those can be decided by capture (:func:`_direct_pool`) as soon as
    they reach an attractor instead of after a full recurrence test. Attractors the
    pilot misses are still found by recurrence in the second pass; the labels do not
    depend on the pilot, only the time does.
    Returns ``(labels, [(points, period, residual)], mean periods per cell)``.
    """
    X = np.asarray(X, dtype=float)
    n = len(X)
    attractors: list[list] = []
    labels = np.full(n, UNRESOLVED, dtype=np.int64)
    used = np.zeros(n, dtype=np.int64)
    first = np.sort(np.random.default_rng(0).choice(n, size=min(int(pilot), n), replace=False))
    rest = np.setdiff1d(np.arange(n), first)
    bar = _progress(n, "direct", progress)
    for part in (first, rest):
        if len(part):
            labels[part], used[part] = _direct_pool(system, params, X[part], integrator, chunk, R, max_periods,
                                                    max_period, tol, capture, bound, merge_tol, attractors, bar)
    bar.close()
    out = []
    for pts, k, _ in attractors:
        pts, res = _refine_orbit(system, params, pts[-1], k, integrator, settle=200)
        out.append((pts, k, res))
    return labels, out, float(used.mean())


def _direct_pool(system, params, X, integrator, chunk, R, max_periods, max_period, tol, capture, bound, merge_tol,
                 attractors, bar):
    """Integrate every cell centre on the stroboscopic map until its fate is known.

    A pool of ``chunk`` lanes runs rounds of ``R`` periods; after each round a lane is
    decided and leaves the pool when its trajectory escapes (norm > ``bound`` or not
    finite: the sink), when its last k stroboscopic points follow, within the capture
    radius (:func:`_capture_radius`), the whole cycle of a known P-k attractor and their
    distance to it has not grown over that cycle (:func:`_shadowing`; a single close
    point is not enough), when it recurs with a period ``<= max_period`` (a new or known
    attractor, :func:`detect_period`), or after ``max_periods`` periods (unresolved).
    Freed lanes take the next cells, so the pool stays full until the grid is used up;
    then the busy lanes are compacted into a batch padded to a power of two, so no
    lane idles for long and memory stays bounded by ``chunk``, not by the grid.
    ``attractors`` (a list of ``[points (k, dim) in cycle order, period, residual]``) is
    extended in place. Returns ``(labels (n,), periods integrated per cell (n,))``.
    """
    n, dim = X.shape
    H = 2 * max_period + 1
    pool = max(1, min(int(chunk), n))
    labels = np.full(n, UNRESOLVED, dtype=np.int64)
    used = np.zeros(n, dtype=np.int64)  # periods integrated per cell
    cell = np.full(pool, -1, dtype=np.int64)  # cell held by each lane, -1: free
    state = np.zeros((pool, dim))
    hist = np.full((pool, H, dim), np.nan)
    age = np.zeros(pool, dtype=np.int64)
    fed = 0
    while True:
        free = np.nonzero(cell < 0)[0][: n - fed]
        if len(free):
            cell[free] = np.arange(fed, fed + len(free))
            state[free] = X[fed : fed + len(free)]
            hist[free] = np.nan
            age[free] = 0
            fed += len(free)
        busy = np.nonzero(cell >= 0)[0]
        if not len(busy):
            break
        size = _pool_size(len(busy), pool)
        P = np.empty((len(busy), R, dim))
        for a, b in _chunks(len(busy), size):
            P[a:b] = np.asarray(_direct_round(system, params, jnp.asarray(_pad(state[busy[a:b]], size)), int(R),
                                              integrator))[: b - a]
        state[busy] = P[:, -1]
        age[busy] += R
        H_b = np.concatenate([hist[busy], P], axis=1)[:, -H:]
        hist[busy] = H_b
        newX = P[:, -1]
        lab = np.full(len(busy), UNRESOLVED, dtype=np.int64)
        decided = np.zeros(len(busy), dtype=bool)
        # escape -> sink
        norms = np.linalg.norm(newX, axis=1)
        esc = ~np.isfinite(norms) | (norms > bound)
        lab[esc] = SINK
        decided |= esc
        # capture: the last k points shadow a known P-k cycle, not moving away from it
        if attractors:
            r = _capture_radius(attractors, capture)
            for ai, (apts, k, _) in enumerate(attractors):
                und = np.nonzero(~decided)[0]
                if len(und) and k <= H:  # cheap pre-filter: the newest point must be close already
                    und = und[np.linalg.norm(newX[und, None] - apts[None], axis=-1).min(axis=1) <= r]
                if not len(und) or k > H:
                    continue
                d_now = _shadowing(H_b[und], apts)
                d_before = _shadowing(H_b[und, :-k], apts) if H > 2 * k else np.full(len(und), np.inf)
                cap = und[(d_now <= r) & ((d_now <= d_before) | ~np.isfinite(d_before))]
                lab[cap] = ai
                decided[cap] = True
        # recurrence -> a new attractor, or one found in this round by another lane
        cand = np.nonzero(~decided & (age[busy] >= H))[0]
        if len(cand):  # cheap pre-filter: the newest point must return within max_period periods
            back = np.linalg.norm(H_b[cand, -1:] - H_b[cand, -1 - max_period : -1], axis=-1).min(axis=1)
            cand = cand[~(back > tol * (1.0 + norms[cand]))]  # keeps non-finite for detect_period
        if len(cand):
            per = detect_period(H_b[cand], max_period, tol)
            rec, per = cand[per > 0], per[per > 0]
            while len(rec):
                li, k = rec[0], int(per[0])
                pts = H_b[li, -k:]
                scale = 1.0 + np.abs(pts).max()
                found = next((ai for ai, (apts, ak, _) in enumerate(attractors)
                              if ak == k and _set_distance(pts, apts) <= merge_tol * scale), -1)
                if found < 0:
                    attractors.append([pts, k, np.nan])
                    found = len(attractors) - 1
                apts = attractors[found][0]
                last = H_b[rec, -1]
                same = (per == k) & (np.linalg.norm(last[:, None] - apts[None], axis=-1).min(axis=1)
                                     <= merge_tol * scale)
                same[0] = True
                lab[rec[same]] = found
                decided[rec[same]] = True
                rec, per = rec[~same], per[~same]
        # out of time -> unresolved
        decided |= age[busy] >= max_periods
        done = busy[decided]
        labels[cell[done]] = lab[decided]
        used[cell[done]] = age[done]
        cell[done] = -1
        bar.update(int(decided.sum()))
        bar.set_postfix_str(f"{len(busy) - int(decided.sum())} in flight, {len(attractors)} attractors", refresh=False)
    return labels, used


def _warn_if_unreliable(r: GlobalResult) -> None:
    """Warn when a result looks unreliable, naming what the user can change.

    - many sink cells (> 20 %): cell methods -> enlarge the region (the grid's bounds,
      ``--region``); direct -> unbounded motion or a blow-up of the integration
      (``steps_per_period``, ``escape_bound``);
    - an attractor's points on or beyond the region's edge -> enlarge the region;
    - period detection at its limit: an attractor with no period <= ``max_period``
      -> raise ``max_period`` / ``settle_periods``; many unresolved cells (> 1 %, direct)
      -> raise ``max_periods`` / ``max_period``;
    - cell methods: an attractor resolved by fewer than ``_MIN_CELLS`` cells, or a P-k
      whose k points share cells (stroboscopic) -> refine the grid (more cells).
    """
    s = r.settings
    n = r.n_cells
    cell_method = r.method in ("poincare-like", "stroboscopic")
    if r.n_sink > 0.2 * n:
        if cell_method:
            warnings.warn(f"{100 * r.n_sink / n:.1f} % of the cells went to the sink (their images left the "
                          f"region): enlarge the region (the CellGrid bounds, --region), or check for unbounded "
                          f"motion.", stacklevel=3)
        else:
            warnings.warn(f"{100 * r.n_sink / n:.1f} % of the cells went to the sink (the motion blew up or "
                          f"exceeded escape_bound={s.get('escape_bound')}): check for unbounded motion, raise "
                          f"steps_per_period (now {s.get('steps_per_period')}) if the integration blew up, or raise "
                          f"escape_bound.", stacklevel=3)
    if r.n_unresolved > 0.01 * n:
        warnings.warn(f"{r.n_unresolved} cells ({100 * r.n_unresolved / n:.1f} %) were not resolved within "
                      f"max_periods={s.get('max_periods')} periods: raise max_periods (slow transients), or "
                      f"max_period (now {s.get('max_period')}) if the motion has a longer period, or period_tol.",
                      stacklevel=3)
    g = r.grid
    for a in r.attractors:
        if a.period == 0:
            warnings.warn(f"attractor {a.id} showed no period <= max_period={s.get('max_period')}: it may have a "
                          "longer period, be quasi-periodic or chaotic, or be a slow transient; raise max_period or "
                          "settle_periods.", stacklevel=3)
        pts = np.asarray(a.points)
        if len(pts):
            for j, ax in enumerate(g.axes):
                lo, hi = g.lower[j], g.upper[j]
                h = 0.02 * (hi - lo)
                if np.any(pts[:, ax] < lo + h) or np.any(pts[:, ax] > hi - h):
                    warnings.warn(f"attractor {a.id} ({a.label}) lies on or beyond the region's edge along "
                                  f"{g.axis_names[j]} (region [{lo:g}, {hi:g}]): enlarge the region (the CellGrid "
                                  f"bounds, --region).", stacklevel=3)
                    break
        if cell_method and a.cell_count < _MIN_CELLS:
            warnings.warn(f"attractor {a.id} ({a.label}) was resolved by only {a.cell_count} cell(s): its domain and "
                          f"share are unreliable; refine the grid (more cells per axis, --grid).", stacklevel=3)
        elif r.method == "stroboscopic" and 0 < len(a.periodic_cells) < a.period:
            warnings.warn(f"the {a.period} points of attractor {a.id} ({a.label}) fall into only "
                          f"{len(a.periodic_cells)} cell(s): the cells are too coarse to separate them; refine the "
                          f"grid (more cells per axis, --grid).", stacklevel=3)


def compare_with_direct(result: GlobalResult, system: ForcedSystem | None = None, params=None, *,
                        n_samples: int = 500, seed: int = 0, integrator: Integrator | None = None,
                        progress: bool = True) -> dict[str, Any]:
    """Agreement report (``jaxgear analyze --compare``): run ``direct`` on a random sample
    of cells and compare with the labels of ``result``.

    Checks a cell-mapping result (paper §3-§4) against direct integration of the same
    cell centres, the paper's verification by direct integration applied to domains.
    ``n_samples`` cells are drawn without replacement (``seed``); ``system`` and
    ``params`` default to the reduced gear model with ``result.params``. Direct
    attractors are matched to the result's attractors by period and distance of their
    stroboscopic points (within ``1e-2 (1 + |x|)``, state units). Returns
    ``{"n_samples", "agreement" (overall fraction in [0, 1]), "per_attractor": {id:
    {"cells", "agree", "fraction"}}, "direct_only": [{"period", "point" (dim,), "cells"}]}``.
    """
    from ._model import REDUCED

    system = REDUCED if system is None else system
    if params is None:
        if system is not REDUCED:
            raise ValueError("compare_with_direct: pass the parameters of your system (params=...).")
        from ._params import GearParams

        params = GearParams.from_dict(result.params)
    if result.grid.dim != system.dim:
        raise ValueError(f"compare_with_direct: the result's grid has {result.grid.dim} coordinates, "
                         f"the system {system.dim}.")
    s = result.settings
    integrator = integrator or RK4(int(s.get("steps_per_period") or 200))
    rng = np.random.default_rng(seed)
    n = result.n_cells
    cells = rng.choice(n, size=min(int(n_samples), n), replace=False)
    X = result.grid.centres(cells)
    labels, atts, _ = _direct(system, params, X, integrator, int(s.get("chunk_size", 131072)), 5, 2000,
                              int(s.get("max_period", 16)), float(s.get("period_tol", 1e-6)), "auto", 1e6,
                              float(s.get("merge_tol", 1e-4)), progress)
    # map direct attractor ids -> result attractor ids
    mapping = {}
    direct_only = []
    for i, (pts, k, _) in enumerate(atts):
        best, bd = None, np.inf
        for a in result.attractors:
            if a.period == k and len(a.points):
                d = _set_distance(pts, np.asarray(a.points))
                if d < bd:
                    best, bd = a.id, d
        if best is not None and bd <= 1e-2 * (1 + np.abs(pts).max()):
            mapping[i] = best
        else:
            mapping[i] = -100 - i
            direct_only.append(dict(period=int(k), point=np.asarray(pts[0]).tolist(),
                                    cells=int((labels == i).sum())))
    direct_ids = np.array([mapping.get(int(l), int(l)) for l in labels])
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
