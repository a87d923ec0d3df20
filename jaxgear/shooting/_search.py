"""Many seeds, several periods, distinct orbits: :func:`find_periodic_orbits` and its result."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from .._batching import chunks, pad_rows, progress_bar
from .._codec import array_field, custom_field, items_field, result_type
from .._devices import local_devices, shard_rows
from .._format import format_table
from .._matching import group_attractors, same_attractor
from .._params import params_to_dict
from .._poincare import sample_trajectory, stroboscopic_map
from .._status import Status, count_statuses
from .._system import ForcedSystem, check_state_shape, check_system
from .._version import __version__
from ..integrate import AbstractIntegrator, integrator_from_dict, resolve_integrator
from ._floquet import Instability, check_period
from ._options import SearchOptions, ShootOptions, with_changes
from ._orbit import ShootResult, check_shooting, shoot_kernel
from ._solve import check_segments

__all__ = ["PeriodicOrbit", "OrbitSearch", "SearchSettings", "PeriodConvergence", "OrbitVerification",
           "find_periodic_orbits", "NEWTON_STATUSES"]

NEWTON_STATUSES = (Status.CONVERGED, Status.NOT_CONVERGED, Status.SINGULAR, Status.DIVERGED)
"""The outcomes a Newton run can have."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class PeriodicOrbit:
    """One periodic orbit of the stroboscopic map (deduplicated), paper §4.1.

    Attributes:
        points: ``(m, dim)`` stroboscopic points ``x*, P(x*), ..., P^{m-1}(x*)`` (state
            units) at times ``t0 + j T``, rotated so that the point with the smallest
            first coordinate comes first.
        period: minimal period ``m`` (forcing periods).
        multipliers: ``(dim,)`` complex Floquet multipliers of ``P^m``, by decreasing modulus.
        stable: all ``|multiplier| < 1``.
        instability: ``"stable"``, ``"fold"``, ``"flip"`` or ``"neimark-sacker"``.
        residual: ``||P^k(x*) - x*||`` of the best converged seed (state units).
        n_seeds: how many seeds converged to this orbit.
        t0: phase of the stroboscopic section (time of ``points[0]``, system time unit).
        trajectory: ``(m * s + 1, dim)`` the orbit sampled ``s`` times per forcing period
            from ``points[0]`` at ``t0`` over its ``m`` periods (for figures drawn without
            integrating, e.g. from a loaded result), or ``None``.
    """

    points: np.ndarray = array_field(("point", "state"))
    period: int = 1
    multipliers: np.ndarray = array_field(("multiplier",), default_factory=lambda: np.zeros(0, complex))
    stable: bool = False
    instability: str = "unknown"
    residual: float = float("nan")
    n_seeds: int = 0
    t0: float = 0.0
    trajectory: np.ndarray | None = array_field(("sample", "state"), default=None)

    @property
    def max_multiplier(self) -> float:
        """Largest Floquet multiplier modulus."""
        return float(np.max(np.abs(self.multipliers)))

    @property
    def samples_per_period(self) -> int:
        """Samples per forcing period of :attr:`trajectory` (0 when there is none)."""
        if self.trajectory is None:
            return 0
        return (len(self.trajectory) - 1) // int(self.period)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (without the sampled trajectory)."""
        return {
            "period": int(self.period), "points": np.asarray(self.points).tolist(),
            "multipliers_abs": np.abs(self.multipliers).tolist(),
            "multipliers": [[float(z.real), float(z.imag)] for z in np.asarray(self.multipliers)],
            "stable": bool(self.stable), "instability": self.instability,
            "residual": float(self.residual), "n_seeds": int(self.n_seeds), "t0": float(self.t0),
        }


@dataclasses.dataclass(frozen=True, kw_only=True)
class PeriodConvergence:
    """How the seed runs of one period ``k`` of a search converged (an item of
    :attr:`OrbitSearch.convergence`).

    Attributes:
        period: ``k`` (the map ``P^k`` the seeds were shot on).
        runs: seed runs (all deflation rounds).
        seeds: seeds shot.
        converged: runs that converged to an orbit of the result.
        seeds_converged: seeds with at least one such run.
        first_round: converged runs of the undeflated round.
        orbits: ``{orbit index: runs}``: to which orbits of the result the runs converged.
    """

    period: int
    runs: int
    seeds: int
    converged: int
    seeds_converged: int
    first_round: int
    orbits: dict[int, int] = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able (without ``period``; the orbit indices as texts): the entry of
        :meth:`OrbitSearch.summary`'s ``convergence`` for this period."""
        return dict(runs=int(self.runs), seeds=int(self.seeds), converged=int(self.converged),
                    seeds_converged=int(self.seeds_converged), first_round=int(self.first_round),
                    orbits={str(int(i)): int(n) for i, n in self.orbits.items()})


@dataclasses.dataclass(frozen=True, kw_only=True)
class OrbitVerification:
    """An orbit of a search checked by direct integration (:func:`verify_orbit`; an item of
    :attr:`OrbitSearch.checks`).

    Attributes:
        orbit: index of the orbit in :attr:`OrbitSearch.orbits`.
        periods: forcing periods integrated.
        kept: every perturbed start stayed on the orbit.
        left_at: first period at which a perturbed start left the orbit (-1 if never).
        consistent: kept exactly when the multipliers say stable.
    """

    orbit: int
    periods: int
    kept: bool
    left_at: int
    consistent: bool

    def to_dict(self) -> dict[str, Any]:
        """JSON-able (without ``orbit``): the entry of :meth:`OrbitSearch.summary`'s ``checks``."""
        return dict(periods=int(self.periods), kept=bool(self.kept), left_at=int(self.left_at),
                    consistent=bool(self.consistent))


def _convergence_of_dict(d: dict) -> tuple[PeriodConvergence, ...]:
    """``OrbitSearch.convergence`` of a file of format 4 (a dictionary keyed by ``"k"``)."""
    return tuple(PeriodConvergence(period=int(k), runs=int(c["runs"]), seeds=int(c["seeds"]),
                                   converged=int(c["converged"]), seeds_converged=int(c["seeds_converged"]),
                                   first_round=int(c["first_round"]),
                                   orbits={int(i): int(n) for i, n in c["orbits"].items()})
                 for k, c in sorted(d.items(), key=lambda kv: int(kv[0])))


def _checks_of_dict(d: dict) -> tuple[OrbitVerification, ...]:
    """``OrbitSearch.checks`` of a file of format 4 (a dictionary keyed by ``"i"``)."""
    return tuple(OrbitVerification(orbit=int(i), periods=int(c["periods"]), kept=bool(c["kept"]),
                                   left_at=int(c["left_at"]), consistent=bool(c["consistent"]))
                 for i, c in sorted(d.items(), key=lambda kv: int(kv[0])))


@dataclasses.dataclass(frozen=True, kw_only=True)
class SearchSettings:
    """What a search of :func:`find_periodic_orbits` was run with (saved field by field).

    Attributes:
        options: the :class:`SearchOptions` (every option of each solve and of the search).
        periods: the ``k`` tried, increasing.
        t0: phase of the stroboscopic section (system time unit).
        integrator: the integrator of the reported orbits (the rounds ran with
            ``options.search_integrator`` when it is given).
    """

    options: SearchOptions
    periods: tuple[int, ...]
    t0: float
    integrator: AbstractIntegrator = custom_field(lambda i: i.to_dict(), integrator_from_dict)

    @property
    def search_integrator(self) -> AbstractIntegrator:
        """The integrator of the rounds (``options.search_integrator``, or :attr:`integrator`)."""
        return self.integrator if self.options.search_integrator is None else self.options.search_integrator

    def to_dict(self) -> dict[str, Any]:
        """Every setting, JSON-able and flat: the options (:meth:`SearchOptions.to_dict`),
        ``periods``, ``t0``, ``integrator`` and the rounds' ``search_integrator``."""
        return dict(self.options.to_dict(), periods=list(self.periods), t0=float(self.t0),
                    integrator=self.integrator.to_dict(), search_integrator=self.search_integrator.to_dict())


@result_type
@dataclasses.dataclass(frozen=True, kw_only=True)
class OrbitSearch:
    """Result of :func:`find_periodic_orbits` (paper §4.1): the distinct orbits and every shot.

    Saves to netCDF with :meth:`save` (reload with :func:`jaxgear.load`; open with
    ``xarray.open_dataset``).

    Attributes:
        orbits: distinct orbits found, sorted by period then first coordinate.
        shots: ``{k: ShootResult}`` the per-seed results for each ``k`` tried (numpy
            arrays, leading dimension the seeds).
        status_counts: number of seeds per Newton status name, over all ``k``.
        seeds: ``{k: (n_k, dim)}`` the seeds shot for each ``k``.
        system: the system's name; state_names: its coordinate names;
        section_index: its default section coordinate (or ``None``).
        params: the full parameter set as a dict (canonical names for the gear models).
        settings: a :class:`SearchSettings`: the :class:`SearchOptions`, the periods
            tried, ``t0`` and the integrator.
        version: jaxgear version; runtime_s: wall time of the search (s).
        convergence: one :class:`PeriodConvergence` per ``k`` tried, in increasing ``k``
            (``period``, ``runs``, ``seeds``, ``converged``, ``seeds_converged``,
            ``first_round``, ``orbits``): to what the seeds converged
            (:meth:`convergence_of`).
        checks: one :class:`OrbitVerification` per orbit, in the order of ``orbits``: the
            check by direct integration (:func:`verify_orbit`; ``orbit``, ``periods``,
            ``kept``, ``left_at``, ``consistent``; :meth:`verification_of`). Empty unless
            ``verify`` was given.
    """

    orbits: tuple[PeriodicOrbit, ...] = items_field("orbit")
    shots: dict[int, ShootResult] = dataclasses.field(default_factory=dict)
    status_counts: dict[str, int] = dataclasses.field(default_factory=dict)
    seeds: dict[int, np.ndarray] = dataclasses.field(default_factory=dict)
    system: str = ""
    state_names: tuple[str, ...] = ()
    section_index: int | None = None
    params: dict = dataclasses.field(default_factory=dict)
    settings: SearchSettings
    version: str = ""
    runtime_s: float = float("nan")
    convergence: tuple[PeriodConvergence, ...] = items_field("searched_period", legacy=_convergence_of_dict,
                                                             default=())
    checks: tuple[OrbitVerification, ...] = items_field("verified_orbit", legacy=_checks_of_dict, default=())

    def convergence_of(self, period: int) -> PeriodConvergence:
        """The :class:`PeriodConvergence` of the period ``k = period``; ``KeyError`` if it was not tried."""
        for c in self.convergence:
            if c.period == period:
                return c
        raise KeyError(f"period {period} was not tried; the search tried {[c.period for c in self.convergence]}.")

    def verification_of(self, orbit: int) -> OrbitVerification | None:
        """The :class:`OrbitVerification` of ``orbits[orbit]``, or ``None`` (not verified)."""
        return next((c for c in self.checks if c.orbit == orbit), None)

    @property
    def n_seeds(self) -> int:
        """Seed runs over all ``k``."""
        return int(sum(np.asarray(r.status).size for r in self.shots.values()))

    def table(self) -> str:
        """Printable table: one row per orbit (period, stability, max |multiplier|, first point)."""
        names = self.state_names or tuple(f"x{i + 1}" for i in range(self._dim()))
        rows = [(i, f"P-{o.period}", "stable" if o.stable else f"unstable ({o.instability})",
                 f"{o.max_multiplier:.4f}", "[" + ", ".join(f"{v:.4f}" for v in o.points[0]) + "]",
                 f"{o.residual:.1e}", o.n_seeds) for i, o in enumerate(self.orbits)]
        head = ("orbit", "period", "stability", "max |multiplier|", "point (" + ", ".join(names) + ")",
                "residual", "seeds")
        return format_table(rows, head)

    def convergence_table(self) -> str:
        """Printable table: per ``k``, seed runs, converged runs and to which orbits."""
        rows = []
        for c in sorted(self.convergence, key=lambda c: c.period):
            to = ", ".join(f"#{i + 1} P-{self.orbits[i].period} x{n}" for i, n in sorted(c.orbits.items())) or "-"
            rows.append((f"P^{c.period}", c.runs, c.converged, f"{c.converged / max(c.runs, 1):.0%}",
                         f"{c.seeds_converged}/{c.seeds}", to))
        return format_table(rows, ("map", "runs", "converged", "fraction", "seeds converged", "to orbits"))

    def _dim(self) -> int:
        for o in self.orbits:
            return int(np.shape(o.points)[-1])
        for X in self.seeds.values():
            return int(np.shape(X)[-1])
        return len(self.state_names)

    def summary(self) -> dict[str, Any]:
        """Everything but the per-seed arrays and trajectories, JSON-able."""
        return dict(
            jaxgear_type="OrbitSearch", system=self.system, state_names=list(self.state_names),
            params=self.params, settings=self.settings.to_dict(), n_seeds=self.n_seeds,
            status_counts=dict(self.status_counts), orbits=[o.to_dict() for o in self.orbits],
            convergence={str(c.period): c.to_dict() for c in self.convergence},
            checks={str(c.orbit): c.to_dict() for c in self.checks},
            runtime_s=self.runtime_s, version=self.version,
        )

    # ---------------------------------------------------------------- I/O
    def _coords(self) -> dict:
        names = list(self.state_names) or [f"x{i + 1}" for i in range(self._dim())]
        return {"state": ("state", names)}

    def _attrs(self) -> dict:
        return dict(title="jaxgear periodic orbits (shooting)",
                    units="state units of the system; time in the system's unit (dimensionless for the gear "
                          "models, model document §3)")

    def save(self, path):
        """Write the search to a netCDF file atomically; reload with :func:`jaxgear.load`."""
        from .._io import save_result

        return save_result(self, path)

    def write_summary(self, path):
        """Write :meth:`summary` as strict JSON."""
        from .._io import write_json

        return write_json(self.summary(), path)


def _orbits_from_shots(res: ShootResult, dedup_tol: float, t0: float = 0.0) -> list[PeriodicOrbit]:
    st = np.asarray(res.status).reshape(-1)
    conv = np.flatnonzero(st == Status.CONVERGED)
    if conv.size == 0:
        return []
    k = res.orbit.shape[-2]
    dim = res.orbit.shape[-1]
    orbit = np.asarray(res.orbit).reshape(-1, k, dim)[conv]
    mper = np.asarray(res.min_period).reshape(-1)[conv]
    lam = np.asarray(res.multipliers).reshape(-1, dim)[conv]
    stab = np.asarray(res.stable).reshape(-1)[conv]
    kind = np.asarray(res.instability).reshape(-1)[conv]
    resid = np.asarray(res.residual).reshape(-1)[conv]
    label = group_attractors([(orbit[i, : mper[i]], int(mper[i])) for i in range(len(conv))], dedup_tol)
    out = []
    for rep in np.unique(label):  # a handful of distinct orbits
        members = np.flatnonzero(label == rep)
        best = members[np.argmin(resid[members])]
        m = int(mper[best])
        pts = orbit[best, :m]
        pts = np.roll(pts, -int(np.argmin(pts[:, 0])), axis=0)
        out.append(PeriodicOrbit(points=pts, period=m, multipliers=lam[best],
                                 stable=bool(stab[best]), instability=Instability(int(kind[best])).label,
                                 residual=float(resid[best]), n_seeds=int(members.size), t0=float(t0)))
    return out


def _merge_orbits(orbits: Sequence[PeriodicOrbit], dedup_tol: float, keep_order: bool = False) -> list[PeriodicOrbit]:
    merged: list[PeriodicOrbit] = []
    for o in orbits:
        for i, q in enumerate(merged):
            if same_attractor(o.points, o.period, q.points, q.period, dedup_tol):
                keep = o if o.residual < q.residual else q
                merged[i] = dataclasses.replace(keep, n_seeds=o.n_seeds + q.n_seeds)
                break
        else:
            merged.append(o)
    if not keep_order:
        merged.sort(key=lambda o: (o.period, float(o.points[0, 0])))
    return merged


def _with_trajectories(system, params, orbits: list[PeriodicOrbit], samples: int, integrator) -> list[PeriodicOrbit]:
    """Attach to each orbit its trajectory over its ``m`` periods (one batched integration)."""
    if not orbits or samples < 1:
        return orbits
    by_t0: dict[float, list[int]] = {}
    for i, o in enumerate(orbits):
        by_t0.setdefault(float(o.t0), []).append(i)
    out = list(orbits)
    for t0, idx in by_t0.items():
        mmax = max(orbits[i].period for i in idx)
        starts = np.stack([orbits[i].points[0] for i in idx])
        _, states = sample_trajectory(system, params, starts, periods=mmax, samples_per_period=samples, t0=t0,
                                      integrator=integrator)
        states = np.asarray(states)
        for j, i in enumerate(idx):
            out[i] = dataclasses.replace(orbits[i], trajectory=states[j, : orbits[i].period * samples + 1])
    return out


class _Search(NamedTuple):
    """What every round of a search shares: the problem and its options."""

    system: ForcedSystem
    params: Any
    t0: jax.Array
    integrator: AbstractIntegrator  # the rounds' (search) integrator
    options: SearchOptions
    bar: Any


def _run_kernel(ctx: _Search, X, k: int, known, options: ShootOptions, chunk_size: int) -> ShootResult:
    """``shoot_kernel`` over ``X (n, dim)`` in chunks of ``chunk_size``: a numpy :class:`ShootResult`.

    The chunks of one device, one per local device at a time (sharded over the devices,
    :func:`jaxgear._devices.shard_rows`): each device runs the chunk shape of one device,
    so the result (each seed converges alone) is that of one device bit for bit (the
    solver's round-off depends on its batch shape). Several devices pay off once there
    are more seeds than ``chunk_size``."""
    X = np.asarray(X)
    size = min(int(chunk_size), len(X))
    D = len(local_devices())
    shoot = check_shooting(ctx.system, ctx.integrator, k, options)
    opts = options.shoot_options()
    parts = []
    for a, b in chunks(len(X), D * size):
        rows = -(-(b - a) // size) * size  # whole chunks
        res = shard_rows(shoot_kernel, shoot, ctx.params, pad_rows(X[a:b], rows), ctx.t0, known, opts, batch=2,
                         per_device=size, partitioned_by_xla=True)
        parts.append(ShootResult(*[f[: b - a] for f in res]))
        if ctx.bar is not None:
            ctx.bar.update(b - a)
    return _concat(parts)


def _known_points(orbits: Sequence[PeriodicOrbit], k: int, rows: int, dim: int):
    """The points of the orbits whose period divides ``k``, padded with NaN to ``rows`` rows (fixed shape)."""
    pts = [o.points for o in orbits if k % int(o.period) == 0]
    P = np.concatenate(pts, axis=0) if pts else np.zeros((0, dim))
    rows = max(rows, -(-len(P) // rows) * rows)
    out = np.full((rows, dim), np.nan)
    out[: len(P)] = P
    return jnp.asarray(out)


def _concat(results: Sequence[ShootResult]) -> ShootResult:
    return ShootResult(*[np.concatenate(f, axis=0) for f in zip(*results)])


def _seed_groups(system: ForcedSystem, seeds, period) -> dict[int, np.ndarray]:
    """``{k: (n_k, dim)}`` from an array shot for every ``k`` of ``period``, or a mapping."""
    if isinstance(seeds, Mapping):
        groups = {check_period(k): np.asarray(v, dtype=float) for k, v in seeds.items()}
    else:
        ks = [period] if isinstance(period, (int, np.integer)) else list(period)
        if not ks:
            raise ValueError("period must name at least one k >= 1.")
        groups = {check_period(k): np.asarray(seeds, dtype=float) for k in ks}
    if not groups:
        raise ValueError("no seeds: give an (n, dim) array or a non-empty mapping {k: (n_k, dim)}.")
    for k, X in groups.items():
        if X.ndim != 2 or X.shape[1] != system.dim or len(X) == 0:
            raise ValueError(f"seeds for period {k} must have shape (n, {system.dim}) with n >= 1 "
                             f"({', '.join(system.state_names)}), got {X.shape}.")
        check_state_shape(system, X)
    return groups


def _after_transient(ctx: _Search, groups: dict[int, np.ndarray], integrator) -> dict[int, np.ndarray]:
    """Each seed mapped ``transient`` forcing periods forward (kept where that blew up)."""
    n = ctx.options.transient
    if not n:
        return groups
    out = {}
    for k, X in groups.items():
        Y = np.asarray(stroboscopic_map(ctx.system, ctx.params, X, periods=int(n), t0=ctx.t0, integrator=integrator))
        out[k] = np.where(np.all(np.isfinite(Y), axis=1, keepdims=True), Y, X)
    return out


def _shoot_rounds(ctx: _Search, X, k: int, found: list[PeriodicOrbit]):
    """The plain round and the deflated rounds for ``P^k`` from ``X``.

    Returns the shots of all rounds (concatenated) and the distinct orbits known after
    them (``found`` extended)."""
    opts = ctx.options
    rounds = []
    for r in range(1 + opts.deflation_rounds):
        known = _known_points(found, k, 16, ctx.system.dim) if r > 0 else None
        if r > 0 and not np.any(np.isfinite(np.asarray(known))):
            break
        res = _run_kernel(ctx, X, k, known, opts, opts.chunk_size)
        rounds.append(res)
        n_before = len(found)
        found = _merge_orbits(list(found) + _orbits_from_shots(res, opts.dedup_tol, float(ctx.t0)), opts.dedup_tol,
                              keep_order=True)
        if r > 0 and len(found) == n_before:
            break
    return _concat(rounds), found


def _orbit_index(res: ShootResult, orbits: Sequence[PeriodicOrbit], dedup_tol: float) -> np.ndarray:
    """Per run of ``res``: the index of the orbit of ``orbits`` it converged to, -1 if none."""
    st = np.asarray(res.status)
    lab = np.full(len(st), -1)
    for i in np.flatnonzero(st == Status.CONVERGED):
        m = int(res.min_period[i])
        for j, o in enumerate(orbits):
            if same_attractor(res.orbit[i, :m], m, o.points, o.period, dedup_tol):
                lab[i] = j
                break
    return lab


def _polish(ctx: _Search, orbits, integrator, dedup_tol):
    """Re-converge each orbit (found with the search integrator) with ``integrator``: the
    library's solver on its minimal period ``m`` with one segment per period. Returns
    ``(orbits, index)``, ``index[i]`` the polished orbit of input ``i`` or -1 when that failed."""
    out: list[PeriodicOrbit] = []
    index = np.full(len(orbits), -1)
    by_m: dict[int, list[int]] = {}
    for i, o in enumerate(orbits):
        by_m.setdefault(int(o.period), []).append(i)
    pctx = ctx._replace(integrator=integrator, bar=None)
    for m, idx in sorted(by_m.items()):
        X = np.stack([orbits[i].points[0] for i in idx])
        try:
            M = check_segments(integrator, m, m)
        except ValueError:
            M = 1
        pol = ShootOptions(tol=ctx.options.tol, max_iter=min(ctx.options.max_iter, 20), max_norm=ctx.options.max_norm,
                           period_tol=ctx.options.period_tol, segments=M)
        res = _run_kernel(pctx, X, m, None, pol, 8)
        found = _orbits_from_shots(res, dedup_tol, float(ctx.t0))
        lab = _orbit_index(res, found, dedup_tol)
        index[idx] = np.where(lab >= 0, lab + len(out), -1)
        out.extend(dataclasses.replace(o, n_seeds=0) for o in found)
    return out, index


def _final_orbits(found, index, lanes, dedup_tol):
    """Merge the (polished) orbits that coincide, sort them by period and first coordinate,
    count the runs that reached each. Returns the orbits and, per ``k``, each run's index
    into them (-1: no reported orbit)."""
    order = _merge_orbits(found, dedup_tol, keep_order=True)
    remap = np.array([next(j for j, q in enumerate(order) if same_attractor(o.points, o.period, q.points, q.period,
                                                                           dedup_tol)) for o in found], dtype=int)
    sorted_idx = sorted(range(len(order)), key=lambda j: (order[j].period, float(order[j].points[0, 0])))
    rank = np.empty(len(order), dtype=int)
    rank[sorted_idx] = np.arange(len(order))
    of_found = np.array([rank[remap[i]] if i >= 0 else -1 for i in index], dtype=int)
    to_final = {k: np.where(lab >= 0, of_found[np.maximum(lab, 0)], -1) if len(index) else lab
                for k, lab in lanes.items()}
    counts = np.zeros(len(order), dtype=int)
    for lab in to_final.values():
        counts += np.bincount(lab[lab >= 0], minlength=len(order))
    orbits = [dataclasses.replace(order[j], n_seeds=int(counts[rank[j]])) for j in sorted_idx]
    return orbits, to_final


def _convergence(to_final: dict[int, np.ndarray], groups: dict[int, np.ndarray]) -> tuple[PeriodConvergence, ...]:
    """Per ``k`` (increasing): runs, seeds, converged runs, seeds with a converged run, to which orbits."""
    out = []
    for k, lab in sorted(to_final.items()):
        n = len(groups[k])
        ok = lab >= 0
        per_seed = ok.reshape(-1, n).any(axis=0) if len(lab) else np.zeros(n, bool)
        out.append(PeriodConvergence(period=int(k), runs=int(len(lab)), seeds=int(n), converged=int(ok.sum()),
                                     seeds_converged=int(per_seed.sum()), first_round=int(np.sum(ok[:n])),
                                     orbits={int(j): int(c) for j, c in zip(*np.unique(lab[ok], return_counts=True))}))
    return tuple(out)


def _checks(ctx: _Search, orbits, integrator) -> tuple[OrbitVerification, ...]:
    """Each orbit checked by direct integration over ``verify`` periods (:func:`verify_orbit`)."""
    from ._verify import verify_orbit

    n = ctx.options.verify
    out = []
    for i, o in enumerate(orbits if n else ()):
        c = verify_orbit(ctx.system, ctx.params, o, periods=n, t0=ctx.t0, integrator=integrator)
        left = c.left_at[c.left_at > 0]
        out.append(OrbitVerification(orbit=i, periods=int(n), kept=bool(c.kept),
                                     left_at=int(left.min()) if left.size else -1,
                                     consistent=bool(c.kept) == bool(o.stable)))
    return tuple(out)


def find_periodic_orbits(system: ForcedSystem, params, seeds: Float[ArrayLike, "n dim"] | Mapping, *,
                         period: int | Sequence[int] = 1, t0=0.0, integrator: AbstractIntegrator | None = None,
                         options: SearchOptions | None = None, progress: bool = True, **changes) -> OrbitSearch:
    """Shoot from many seeds and return the distinct periodic orbits (paper §4.1, ref. [15]).

    For every ``k`` and every seed, a Newton-type solve of ``G(x) = P^k(x) - x = 0`` (the
    k-fold stroboscopic map of paper eq. 6, full state; single or multiple shooting, see
    :func:`periodic_orbit`); then the Floquet multipliers of each converged orbit (its
    minimal period ``m``), and the converged seeds deduplicated into distinct orbits.
    One period and a range of periods are the same search (``jaxgear shoot --period K``
    and ``--periods K1-K2``): seeds are processed in chunks (one compiled shape per
    ``k``, ``vmap`` over the chunk), so memory is bounded by the chunk and the result
    does not depend on its size. The system and parameters are checked once on entry
    (:func:`~jaxgear.check_system`).

    The :class:`SearchOptions` add to each solve (:class:`ShootOptions`):

    - ``transient``: the seeds are first mapped ``transient`` forcing periods forward
      (direct integration), which brings seeds from anywhere in a region near the
      attractors and the unstable orbits they are born from (random seeds need it;
      ``jaxgear shoot --random`` uses 40);
    - ``deflation_rounds``: after the plain round, the same seeds are shot again with the
      orbits known so far (of periods dividing ``k``) deflated away, so that they go to
      other orbits (see :mod:`jaxgear.shooting._solve`); rounds stop when one finds
      nothing new;
    - ``search_integrator``: the rounds use this (cheaper) integrator; each distinct
      orbit is then re-converged with ``integrator`` (one segment per period) and only
      orbits that re-converge are reported, with ``integrator``'s multipliers;
    - ``verify``: each orbit checked by direct integration (:func:`verify_orbit`).

    Args:
        system: a :class:`~jaxgear.ForcedSystem` of state dimension ``dim``.
        params: its parameter pytree (not batched), e.g. :func:`jaxgear.paper_params`.
        seeds: ``(n, dim)`` array of states at phase ``t0`` (state units; shot for
            every ``k`` in ``period``), or a mapping ``{k: (n_k, dim)}`` such as
            :func:`seeds_from_result` returns.
        period: ``k`` or a sequence of ``k`` (forcing periods; ignored when ``seeds``
            is a mapping).
        t0: phase of the stroboscopic section (system time unit; the gear models use
            dimensionless time ``omega_n t``).
        integrator: any integrator object; default :func:`~jaxgear.default_integrator`
            (kink-aware RK4, 200 steps per period).
        options: :class:`SearchOptions`; ``None``: the defaults.
        progress: show a progress bar (tqdm, with time left); ``False`` silences it.
        **changes: fields of ``options`` to change, e.g. ``max_iter=15, transient=40``.
    Returns:
        :class:`OrbitSearch`: ``orbits`` (distinct, sorted by period), ``shots``
        ``{k: ShootResult}`` with leading shape ``(n_k (rounds + 1),)`` (round after
        round; with a search integrator the fields are that integrator's),
        ``status_counts``, the seeds (after the transient), the per-``k`` convergence,
        the parameter set and the settings.
    Raises:
        ValueError: seeds not of shape ``(n, dim)`` or not finite, ``k < 1``, bad
            options, or a system/parameter set that fails :func:`~jaxgear.check_system`.
    """
    start = time.perf_counter()
    groups = _seed_groups(system, seeds, period)
    opts = with_changes(options, SearchOptions, changes)
    integrator = resolve_integrator(integrator)
    search_int = integrator if opts.search_integrator is None else resolve_integrator(opts.search_integrator)
    for k in groups:
        check_shooting(system, search_int, k, opts)
    check_system(system, params, next(iter(groups.values()))[0])
    ctx = _Search(system, params, jnp.asarray(t0, jnp.float64), search_int, opts, None)
    groups = _after_transient(ctx, groups, integrator)
    shots: dict[int, ShootResult] = {}
    found: list[PeriodicOrbit] = []  # distinct orbits of the search integrator's map
    bar = progress_bar(sum(len(X) for X in groups.values()) * (1 + opts.deflation_rounds), "shooting", progress,
                       unit="seed")
    try:
        for k, X in sorted(groups.items()):  # one jit per distinct k (and chunk shape)
            shots[k], found = _shoot_rounds(ctx._replace(bar=bar), X, k, found)
    finally:
        bar.close()
    lanes = {k: _orbit_index(res, found, opts.dedup_tol) for k, res in shots.items()}
    if search_int != integrator and found:
        polished, index = _polish(ctx, found, integrator, opts.dedup_tol)
    else:
        polished, index = list(found), np.arange(len(found))
    orbits, to_final = _final_orbits(polished, index, lanes, opts.dedup_tol)
    orbits = _with_trajectories(system, params, orbits, opts.trajectory_samples, integrator)
    counts = count_statuses(np.concatenate([np.asarray(r.status).reshape(-1) for r in shots.values()]),
                            NEWTON_STATUSES)
    settings = SearchSettings(options=opts, periods=tuple(sorted(groups)), t0=float(t0), integrator=integrator)
    return OrbitSearch(orbits=tuple(orbits), shots=shots, status_counts=counts, seeds=groups, system=system.name,
                       state_names=tuple(system.state_names), section_index=system.section_index,
                       params=params_to_dict(params), settings=settings, version=__version__,
                       runtime_s=time.perf_counter() - start, convergence=_convergence(to_final, groups),
                       checks=_checks(ctx, orbits, integrator))
