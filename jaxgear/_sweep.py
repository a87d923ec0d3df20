"""Parameter sweeps: bifurcation diagrams, basin shares across a parameter, 2-parameter maps.

How the motion of a forced system changes as one parameter (backlash, stiffness
amplitude, frequency, damping, load, error amplitude, ...) changes:

- :func:`bifurcation_diagram` — from several initial states per value, drop a
  transient, record stroboscopic points and classify each (value, start) as P-k
  (recurrence on the stroboscopic map, paper §3), aperiodic (no period up to
  ``max_period``: quasi-periodic or chaotic) or escaped. Values and starts are batched
  with ``vmap`` (``direction="independent"``), or the state is carried from one value
  to the next (``"up"``/``"down"``/``"both"``: a ``lax.scan`` over values, ``vmap``
  over starts), so hysteresis shows; ``"all"`` does both kinds.
- :func:`basin_sweep` — the global analysis (:func:`~jaxgear.analyze_global`) at every
  value, attractors matched from one value to the next by the distance of their
  stroboscopic point sets (global continuation of attractors), so each keeps a global
  identity; shares per value and global attractor, plus the sink.
- :func:`parameter_map` — on a grid of two parameters, the period of the attractor
  reached from a fixed initial state and the number of distinct attractors reached
  from several starts.

Parameters are named by a field of the parameter pytree (for :class:`GearParams` any
canonical name of MODEL.md §4 but ``N``) or by an alias that moves several fields
together (``PARAM_ALIASES`` of :mod:`jaxgear._params`: ``b`` = ``b_sp`` and ``b_rp``,
``kappa_amp`` = ``kappa_sp_amp`` and ``kappa_rp_amp``, ``e_amp`` = ``e_sp_amp`` and
``e_rp_amp``), set with :func:`jaxgear.with_param`; per-planet fields are set for
every planet. Values enter the compiled kernels as array leaves, so nothing is
recompiled per value. When ``Omega`` (the forcing frequency) is swept, every value has
its own period ``T = 2 pi / Omega``; the RK4 step is ``h = T / steps_per_period`` per
value, so the stroboscopic sampling stays exact. Otherwise all values share one clock
and the time-only terms of the vector field are computed once per stage for the batch.

Long sweeps survive interruption: with ``out=DIR`` each block of values is written to
``DIR/parts`` as soon as it is done, with a manifest holding a hash of every setting;
the same call again skips the saved blocks and computes only the rest, and the final
file ``DIR/<kind>.nc`` equals that of an uninterrupted run (it holds no run time or
time stamp; the block layout is fixed by the settings). A different setting raises
``ValueError`` unless ``restart=True``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
from pathlib import Path
from typing import Any, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._cellmap import _pad, _progress, _pytree_dict, _set_distance, detect_period
from ._integrate import RK4, Adaptive, Integrator, advance_batch
from ._io import _atomic_write
from ._params import _targets, with_param
from ._system import ForcedSystem, check_state_shape, check_system

__all__ = [
    "BifurcationDiagram",
    "BasinSweep",
    "ParameterMap",
    "bifurcation_diagram",
    "basin_sweep",
    "parameter_map",
    "load_bifurcation",
    "load_basin_sweep",
    "load_parameter_map",
    "ESCAPED",
    "APERIODIC",
    "DIRECTIONS",
]

ESCAPED = -1
"""Period code of a (value, start) whose motion left ``escape_bound`` or became non-finite."""
APERIODIC = 0
"""Period code when no period <= ``max_period`` recurs (quasi-periodic, chaotic or a slow transient)."""
DIRECTIONS = ("independent", "up", "down", "both", "all")

# =============================================================================== parameters
def _apply(params, names: tuple[str, ...], v):
    """Set parameters ``names`` to the entries of ``v`` (shape ``(len(names),)``)."""
    for j, n in enumerate(names):
        params = with_param(params, n, v[j])
    return params


def _check_values(system: ForcedSystem, params, names: tuple[str, ...], V: np.ndarray) -> bool:
    """Validate every parameter combination ``V (n, len(names))`` once, concretely.

    Returns whether all combinations share one forcing period (then the kernels use one
    clock for the whole batch).
    """
    for v in np.unique(V, axis=0):
        try:
            _apply(params, names, v)  # concrete values: with_param validates (e.g. b_sp >= 0)
        except ValueError as exc:
            what = ", ".join(f"{n}={x:.6g}" for n, x in zip(names, v))
            raise ValueError(f"sweep value {what}: {exc}") from None
    T = np.asarray(jax.vmap(lambda v: system.period(_apply(params, names, v)))(jnp.asarray(V)))
    bad = ~(np.isfinite(T) & (T > 0))
    if bad.any():
        v = V[np.argmax(bad)]
        what = ", ".join(f"{n}={x:.6g}" for n, x in zip(names, v))
        raise ValueError(f"{system.name}: at {what} the forcing period is {T[np.argmax(bad)]}; "
                         "it must be positive and finite.")
    return bool(np.all(T == T[0]))


def _values(values, name: str) -> np.ndarray:
    v = np.asarray(values, dtype=float).reshape(-1)
    if v.size == 0:
        raise ValueError(f"the values of {name} are empty: give at least one value.")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"the values of {name} must be finite.")
    v = np.sort(v)
    if np.any(np.diff(v) == 0):
        raise ValueError(f"the values of {name} must be distinct.")
    return v


def _starts(system, x0s) -> np.ndarray:
    x = np.asarray(x0s, dtype=float)
    if x.ndim == 1:
        x = x[None]
    check_state_shape(system, x)
    if x.ndim != 2 or len(x) == 0:
        raise ValueError(f"initial states must have shape (n, {system.dim}) with n >= 1, got {x.shape}.")
    return x


def _integrator_dict(integ: Integrator) -> dict:
    if isinstance(integ, RK4):
        return {"type": "RK4", "steps_per_period": int(integ.steps_per_period)}
    if isinstance(integ, Adaptive):
        return {"type": "Adaptive", "solver": type(integ.solver).__name__, "rtol": integ.rtol,
                "atol": integ.atol, "max_steps": int(integ.max_steps)}
    raise TypeError(f"unknown integrator {integ!r}; use jaxgear.RK4 or jaxgear.Adaptive.")


def _coord_name(param: str, taken: Sequence[str]) -> str:
    return param if param not in taken else f"param_{param}"


# =============================================================================== kernels
# States of a block are kept as (dim, B, S): B parameter values, S starts per value. With
# RK4 the step of value j is h_j = T_j / steps_per_period; when the swept parameters do
# not change the period (``shared`` clock: everything but Omega for the gear models) the
# clock is one scalar, so time-only terms of the vector field (mesh stiffness, errors)
# are computed once per stage for the whole block.
def _advance_values(system, params, names, V, Y, periods: int, integrator, shared: bool):
    """Advance ``Y (dim, B, S)`` by ``periods`` forcing periods, value j with parameters ``V[j]``."""
    if not isinstance(integrator, RK4):
        def one(v, y):
            return advance_batch(system, _apply(params, names, v), y, jnp.asarray(0.0), periods, integrator)

        return jax.vmap(one, in_axes=(0, 1), out_axes=1)(V, Y)
    steps = int(integrator.steps_per_period)

    def f_starts(t, y, v):  # y (dim, S)
        p = _apply(params, names, v)
        return jax.vmap(lambda yy: system.vector_field(t, yy, p), in_axes=1, out_axes=1)(y)

    if shared:
        h = system.period(_apply(params, names, V[0])) / steps
        hb = h
        f = jax.vmap(f_starts, in_axes=(None, 1, 0), out_axes=1)
    else:
        h = jax.vmap(lambda v: system.period(_apply(params, names, v)))(V) / steps  # (B,)
        hb = h[None, :, None]
        f = jax.vmap(f_starts, in_axes=(0, 1, 0), out_axes=1)

    def step(i, Y):
        t = i * h
        k1 = f(t, Y, V)
        k2 = f(t + 0.5 * h, Y + (0.5 * hb) * k1, V)
        k3 = f(t + 0.5 * h, Y + (0.5 * hb) * k2, V)
        k4 = f(t + h, Y + hb * k3, V)
        return Y + (hb / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)

    one_period = lambda _, Y: jax.lax.fori_loop(0, steps, step, Y)  # noqa: E731
    return jax.lax.fori_loop(0, periods, one_period, Y) if periods > 1 else one_period(0, Y)


def _run_values(system, params, names, V, Y, transient, record, integrator, shared):
    """``transient`` periods, then ``record`` stroboscopic points: ``(B, S, R, dim)``."""
    if transient > 0:
        Y = _advance_values(system, params, names, V, Y, transient, integrator, shared)

    def rec(Y, _):
        Y = _advance_values(system, params, names, V, Y, 1, integrator, shared)
        return Y, Y

    _, Ys = jax.lax.scan(rec, Y, None, length=record)  # (R, dim, B, S)
    return jnp.transpose(Ys, (2, 3, 0, 1))


@eqx.filter_jit
def _independent_kernel(system, params, names, V, X0, transient, record, integrator, shared):
    """Every (value, start) pair: ``V (B, m)``, ``X0 (S, dim)`` -> points ``(B, S, R, dim)``."""
    Y = jnp.broadcast_to(X0.T[:, None, :], (X0.shape[1], V.shape[0], X0.shape[0]))
    return _run_values(system, params, names, V, Y, transient, record, integrator, shared)


@eqx.filter_jit
def _scan_kernel(system, params, names, V, Y0, X0, transient, record, integrator, bound, shared):
    """Values in sequence with the state carried, for ``nd`` sweeps at once (up and down).

    ``V (n, nd, m)``: at step i sweep d runs value ``V[i, d]``; ``Y0 (nd, S, dim)`` the
    carried states. Returns points ``(n, nd, S, R, dim)`` and the state carried out of
    each step ``(n, nd, S, dim)``: the last recorded point, or the start ``X0`` where the
    lane escaped (so one unbounded value does not end the sweep for that start).
    """

    def body(Y, v):
        pts = _run_values(system, params, names, v, jnp.transpose(Y, (2, 0, 1)), transient, record, integrator,
                          shared)
        last = pts[:, :, -1]
        fin = jnp.all(jnp.isfinite(last), axis=-1)
        ok = fin & (jnp.linalg.norm(jnp.where(fin[..., None], last, 0.0), axis=-1) <= bound)
        nxt = jnp.where(ok[..., None], last, X0[None])
        return nxt, (pts, nxt)

    _, (pts, carry) = jax.lax.scan(body, Y0, V)
    return pts, carry


# ------------------------------------------------------------------------- classification
def _classify(points: np.ndarray, max_period: int, tol: float, bound: float) -> np.ndarray:
    """Period code of each recorded sequence ``points (..., R, dim)``: k, ``APERIODIC`` or ``ESCAPED``."""
    with np.errstate(invalid="ignore", over="ignore"):
        per = detect_period(points, max_period, tol)
        big = ~np.all(np.isfinite(points), axis=(-1, -2)) | (np.linalg.norm(np.nan_to_num(points, nan=np.inf,
                                                                                          posinf=np.inf),
                                                                            axis=-1).max(axis=-1) > bound)
    return np.where(big, ESCAPED, per).astype(np.int64)


def _group(points: np.ndarray, period: np.ndarray, merge_tol: float) -> np.ndarray:
    """Distinct attractors among the starts of each row: ``points (..., S, M, dim)`` (the
    last M >= max_period recorded points), ``period (..., S)`` -> ids ``(..., S)``,
    numbered 0.. in order of first start; ``-1`` for escaped lanes.

    Two lanes are one attractor when they have the same period and the Hausdorff distance
    of their point sets (cyclic-shift invariant) is below ``merge_tol * (1 + max |x|)``;
    all aperiodic lanes of a row form one set.
    """
    lead = period.shape[:-1]
    S, M, dim = points.shape[-3:]
    P = points.reshape(-1, S, M, dim)
    K = period.reshape(-1, S)
    ids = np.full(K.shape, -1, dtype=np.int64)
    rows = max(1, int(2e6 // max(S * S * M * M * dim, 1)))
    ar = np.arange(S)
    for a in range(0, len(K), rows):
        p, k = P[a:a + rows], K[a:a + rows]
        with np.errstate(invalid="ignore"):
            d = np.linalg.norm(p[:, :, None, :, None, :] - p[:, None, :, None, :, :], axis=-1)  # (r,S,S,M,M)
            h = np.maximum(d.min(axis=-1).max(axis=-1), d.min(axis=-2).max(axis=-1))  # (r, S, S)
            scale = 1.0 + np.nanmax(np.abs(np.where(np.isfinite(p), p, np.nan)), axis=(1, 2, 3), initial=0.0)
        valid = k >= 0
        same = (k[:, :, None] == k[:, None, :]) & valid[:, :, None] & valid[:, None, :]
        same &= (k[:, :, None] == APERIODIC) | (h <= merge_tol * scale[:, None, None])
        first = np.argmax(same, axis=1)  # (r, S): first lane i that matches lane j
        is_rep = (first == ar) & valid
        rank = np.cumsum(is_rep, axis=1) - 1
        out = np.take_along_axis(rank, first, axis=1)
        ids[a:a + rows] = np.where(valid, out, -1)
    return ids.reshape(*lead, S)


def _label(k: int) -> str:
    return f"P-{k}" if k > 0 else ("aperiodic" if k == APERIODIC else "escaped")


# =============================================================================== checkpoints
def _hash(settings: Mapping) -> str:
    return hashlib.sha256(json.dumps(settings, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _save_dataset(ds, path) -> Path:
    """The shared atomic netCDF writer (:mod:`jaxgear._io`), large arrays compressed."""
    from ._io import _write_netcdf

    for k in ds.data_vars:
        if ds[k].size > 4096:
            ds[k].encoding.update(zlib=True, complevel=4)
    return _write_netcdf(ds, path)


def _read_dataset(path, expected: str):
    from ._io import _check_type, _read_netcdf

    ds = _read_netcdf(path)
    _check_type(ds, expected, path)
    if ds.attrs.get("jaxgear_type") != expected:  # sweep files always carry their type
        raise ValueError(f"{path} is not a {expected} (it has no jaxgear_type {expected!r}).")
    return ds


class _Checkpoint:
    """Blocks of a sweep saved in ``DIR/parts`` under a manifest of the settings' hash.

    ``out=None`` keeps nothing (every block is computed). A directory with a manifest
    of other settings raises ``ValueError`` naming the differing settings, unless
    ``restart`` (then the old parts are removed).
    """

    def __init__(self, out, kind: str, settings: dict, restart: bool = False):
        self.dir = None if out is None else Path(out)
        if self.dir is None:
            return
        self.parts = self.dir / "parts"
        man = self.dir / "manifest.json"
        key = _hash(settings)
        if man.is_file():
            old = json.loads(man.read_text())
            if old.get("hash") != key:
                if not restart:
                    diff = _diff_settings(old.get("settings", {}), settings)
                    raise ValueError(f"{self.dir} holds a {old.get('kind', '?')} sweep with other settings "
                                     f"(differing: {diff}); resume it with the same settings, use another "
                                     "output folder, or restart (restart=True, --restart) to discard it.")
                shutil.rmtree(self.parts, ignore_errors=True)
        elif self.parts.exists() and restart:
            shutil.rmtree(self.parts, ignore_errors=True)
        self.parts.mkdir(parents=True, exist_ok=True)
        text = json.dumps({"kind": kind, "hash": key, "settings": settings}, indent=1, sort_keys=True)
        _atomic_write(man, lambda tmp: Path(tmp).write_text(text))

    def path(self, name: str) -> Path | None:
        return None if self.dir is None else self.parts / name

    def has(self, name: str) -> bool:
        return self.dir is not None and (self.parts / name).is_file()

    def load(self, name: str) -> dict[str, np.ndarray]:
        with np.load(self.parts / name) as z:
            return {k: z[k] for k in z.files}

    def save(self, name: str, **arrays) -> None:
        if self.dir is not None:
            _save_part(self.parts / name, arrays)


def _save_part(path: Path, arrays: dict) -> None:
    """Write one finished block (atomically: a kill never leaves a half-written part)."""

    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)

    _atomic_write(path, write)


def _diff_settings(a: Mapping, b: Mapping) -> str:
    keys = sorted(set(a) | set(b))
    out = []
    for k in keys:
        if a.get(k) != b.get(k):
            va, vb = json.dumps(a.get(k)), json.dumps(b.get(k))
            short = lambda s: s if len(s) <= 40 else s[:37] + "..."
            out.append(f"{k}: {short(va)} saved vs {short(vb)} now")
    return "; ".join(out) or "format"


# =============================================================================== bifurcation
def _ro(a):
    a = np.asarray(a)
    a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True)
class BifurcationDiagram:
    """Result of :func:`bifurcation_diagram` (a one-parameter sweep).

    Attributes:
        param: the swept name as given (a field or an alias); fields: the fields it sets.
        values: ``(V,)`` parameter values, increasing.
        directions: which sweeps: ``("independent",)``, ``("up",)``, ``("down",)``,
            ``("up", "down")`` or ``("independent", "up", "down")``.
        starts: ``(S, dim)`` initial states.
        points: ``(D, V, S, R, dim)`` recorded stroboscopic points (state at forcing phase
            0 of R successive periods after the transient), per direction, value, start.
        period: ``(D, V, S)`` minimal period k of P-k, ``APERIODIC`` (0) or ``ESCAPED`` (-1).
        attractor: ``(D, V, S)`` id of the distinct attractor reached, numbered per
            (direction, value) in order of first start; -1 escaped.
        system, state_names, params (the base parameter set, canonical names), settings
        (transient, record, integrator, tolerances, ...), version.
    """

    param: str
    fields: tuple[str, ...]
    values: np.ndarray
    directions: tuple[str, ...]
    starts: np.ndarray
    points: np.ndarray
    period: np.ndarray
    attractor: np.ndarray
    system: str
    state_names: tuple[str, ...]
    params: dict
    settings: dict
    version: str

    def __post_init__(self):
        for f in ("values", "starts", "points", "period", "attractor"):
            object.__setattr__(self, f, _ro(getattr(self, f)))

    def _d(self, direction: str | None) -> int:
        if direction is None:
            return 0
        if direction not in self.directions:
            raise ValueError(f"direction {direction!r} is not in this diagram; it has {self.directions}.")
        return self.directions.index(direction)

    def attractors_at(self, index: int, direction: str | None = None) -> list[dict]:
        """Distinct attractors at ``values[index]``: label, period, number of starts, one point."""
        d = self._d(direction)
        ids, per, pts = self.attractor[d, index], self.period[d, index], self.points[d, index]
        out = []
        for a in range(int(ids.max(initial=-1)) + 1):
            lanes = np.nonzero(ids == a)[0]
            k = int(per[lanes[0]])
            out.append(dict(id=a, period=k, label=_label(k), starts=int(len(lanes)),
                            point=pts[lanes[0], -1].tolist()))
        n_esc = int((ids < 0).sum())
        if n_esc:
            out.append(dict(id=-1, period=ESCAPED, label="escaped", starts=n_esc, point=None))
        return out

    def transitions(self, direction: str | None = None) -> list[dict]:
        """Where the set of attractor labels changes: ``[{before, after, from, to}, ...]``."""
        d = self._d(direction)
        sets = [tuple(sorted({a["label"] for a in self.attractors_at(i, self.directions[d])},
                             key=_label_key)) for i in range(len(self.values))]
        order = range(len(self.values)) if self.directions[d] != "down" else range(len(self.values) - 1, -1, -1)
        order = list(order)
        out = []
        for i, j in zip(order[:-1], order[1:]):
            if sets[i] != sets[j]:
                out.append({"before": float(self.values[i]), "after": float(self.values[j]),
                            "from": list(sets[i]), "to": list(sets[j])})
        return out

    def _attractor_sets(self, d: int, i: int) -> list[tuple[int, np.ndarray]]:
        ids, per, pts = self.attractor[d, i], self.period[d, i], self.points[d, i]
        out = []
        for a in range(int(ids.max(initial=-1)) + 1):
            s = int(np.argmax(ids == a))
            k = int(per[s])
            out.append((k, pts[s, -k:] if k > 0 else pts[s, -1:]))
        if np.any(ids < 0):
            out.append((ESCAPED, np.zeros((0, pts.shape[-1]))))
        return out

    def differs(self, a: str = "up", b: str = "down") -> np.ndarray:
        """``(V,)`` bool: the sweeps ``a`` and ``b`` end on different sets of attractors at
        each value (same periods and point sets within ``merge_tol`` count as equal);
        for ``"up"`` and ``"down"`` this marks the hysteresis."""
        da, db = self._d(a), self._d(b)
        tol = float(self.settings.get("merge_tol", 1e-3))
        out = np.zeros(len(self.values), dtype=bool)
        for i in range(len(self.values)):
            A, B = self._attractor_sets(da, i), self._attractor_sets(db, i)

            def same(x, y):
                if x[0] != y[0]:
                    return False
                if x[0] <= 0:
                    return True  # aperiodic sets, escape
                scale = 1.0 + max(np.abs(x[1]).max(), np.abs(y[1]).max())
                d = np.linalg.norm(x[1][:, None] - y[1][None], axis=-1)
                return max(d.min(axis=0).max(), d.min(axis=1).max()) <= tol * scale

            out[i] = not (all(any(same(x, y) for y in B) for x in A) and all(any(same(y, x) for x in A) for y in B))
        return out

    def table(self, full: bool = False) -> str:
        """Printable table: runs of values with the same attractors (``full``: every value),
        each attractor with its share of the starts."""
        from ._params import format_table

        rows = []
        S = len(self.starts)
        for d, name in enumerate(self.directions):
            runs = []
            for i in range(len(self.values)):
                atts = self.attractors_at(i, name)
                labels = tuple(sorted({a["label"] for a in atts}, key=_label_key))
                cnt = {}
                for a in atts:
                    cnt[a["label"]] = cnt.get(a["label"], 0) + a["starts"]
                if runs and not full and runs[-1][1] == labels:
                    runs[-1][0].append(i)
                    for k, c in cnt.items():
                        runs[-1][2][k] += c
                else:
                    runs.append(([i], labels, dict(cnt)))
            for idx, labels, cnt in runs:
                lo, hi = self.values[idx[0]], self.values[idx[-1]]
                rng = f"{lo:.5g}" if len(idx) == 1 else f"{lo:.5g} .. {hi:.5g}"
                text = ", ".join(f"{lab} ({100 * cnt[lab] / (S * len(idx)):.0f} %)" for lab in labels)
                rows.append((rng, len(idx), name, text))
        head = (f"{self.param}", "values", "sweep", f"attractors (share of {S} starts)")
        return format_table(rows, head)

    def summary(self) -> dict[str, Any]:
        """JSON-able summary: settings, parameters and the attractors at every value."""
        return dict(
            kind="bifurcation", param=self.param, fields=list(self.fields), values=self.values.tolist(),
            directions=list(self.directions), n_starts=int(len(self.starts)), system=self.system,
            state_names=list(self.state_names), params=self.params, settings=self.settings, version=self.version,
            transitions={d: self.transitions(d) for d in self.directions},
            hysteresis=(self.values[self.differs()].tolist()
                        if "up" in self.directions and "down" in self.directions else None),
            attractors={d: [self.attractors_at(i, d) for i in range(len(self.values))] for d in self.directions},
        )

    def to_xarray(self):
        """The diagram as an ``xarray.Dataset`` (coordinate named after the parameter)."""
        import xarray as xr

        c = _coord_name(self.param, list(self.state_names) + ["direction", "start", "record", "state"])
        dims5 = ("direction", c, "start", "record", "state")
        data = {
            "points": (dims5, self.points, {"description": "stroboscopic points after the transient (phase 0)"}),
            "period": (dims5[:3], self.period, {"description": "minimal period k (P-k); 0 aperiodic; -1 escaped"}),
            "attractor": (dims5[:3], self.attractor,
                          {"description": "distinct attractor id per (direction, value); -1 escaped"}),
            "starts": (("start", "state"), self.starts, {"description": "initial states"}),
        }
        coords = {"direction": ("direction", list(self.directions)),
                  c: (c, self.values, {"long_name": self.param, "sets": ",".join(self.fields)}),
                  "state": ("state", list(self.state_names))}
        attrs = dict(jaxgear_type="BifurcationDiagram", title="jaxgear bifurcation diagram", param=self.param,
                     param_coord=c, fields=json.dumps(list(self.fields)), params=json.dumps(self.params),
                     system=self.system, settings=json.dumps(self.settings), version=self.version,
                     units="dimensionless: lengths in b_c, time in 1/omega_n (MODEL.md §3) for the gear models")
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path) -> Path:
        """Write to netCDF (atomically); reload with :func:`load_bifurcation`."""
        return _save_dataset(self.to_xarray(), path)


def _label_key(label: str):
    if label.startswith("P-"):
        return (0, int(label[2:]))
    return (1, 0) if label == "aperiodic" else (2, 0)


def load_bifurcation(path) -> BifurcationDiagram:
    """Load a :class:`BifurcationDiagram` saved with :meth:`BifurcationDiagram.save` (exact)."""
    ds = _read_dataset(path, "BifurcationDiagram")
    c = ds.attrs["param_coord"]
    return BifurcationDiagram(
        param=str(ds.attrs["param"]), fields=tuple(json.loads(ds.attrs["fields"])), values=ds[c].values,
        directions=tuple(str(s) for s in ds["direction"].values), starts=ds["starts"].values,
        points=ds["points"].values, period=ds["period"].values.astype(np.int64),
        attractor=ds["attractor"].values.astype(np.int64), system=str(ds.attrs["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), params=json.loads(ds.attrs["params"]),
        settings=json.loads(ds.attrs["settings"]), version=str(ds.attrs["version"]),
    )


def _common_checks(system, params, transient, record, max_period, tol, chunk_size):
    from ._model import REDUCED

    if system is None:
        system = REDUCED
    if params is None:
        if system is not REDUCED:
            raise ValueError("pass the parameters of your system.")
        from . import paper_params

        params = paper_params()
    for name, v, lo in (("transient", transient, 0), ("max_period", max_period, 1), ("chunk_size", chunk_size, 1)):
        if int(v) != v or int(v) < lo:
            raise ValueError(f"{name}={v} must be an integer >= {lo}.")
    if int(record) < 2 * int(max_period) + 1:
        raise ValueError(f"record={record} must be >= 2 max_period + 1 = {2 * int(max_period) + 1} "
                         "(period detection compares whole cycles).")
    if not tol > 0:
        raise ValueError(f"tol={tol} must be > 0.")
    return system, params


def bifurcation_diagram(system: ForcedSystem | None, params, param: str, values, x0s, *, transient: int = 400,
                        record: int = 64, direction: str = "independent", integrator: Integrator = RK4(),
                        max_period: int = 16, tol: float = 1e-6, merge_tol: float = 1e-3,
                        escape_bound: float = 1e6, chunk_size: int = 1024, progress: bool = True,
                        out=None, restart: bool = False) -> BifurcationDiagram:
    """Bifurcation diagram: stroboscopic points against one parameter, classified by period.

    For each value of ``param`` and each initial state: ``transient`` forcing periods,
    then ``record`` stroboscopic points (paper §3: the state at forcing phase 0 of
    successive periods), classified as P-k (the smallest ``k <= max_period`` with
    ``|x_j - x_(j-k)| <= tol (1 + |x_j|)`` over the last k+1 points), aperiodic (none:
    quasi-periodic, chaotic or a slow transient) or escaped (non-finite, or a norm above
    ``escape_bound``).

    Args:
        system, params: the :class:`ForcedSystem` and its parameter pytree (defaults: the
            reduced gear model and the ``paper`` preset).
        param: a field of ``params`` (for :class:`GearParams` any canonical name but
            ``N``: ``b_sp``, ``kappa_sp_amp``, ``Omega``, ``c_sp``, ``f_D``, ``e_sp_amp``...)
            or an alias (``b``, ``kappa_amp``, ``e_amp``: both meshes together);
            per-planet fields are set for all planets.
        values: the parameter values (sorted increasing, distinct).
        x0s: initial states ``(S, dim)`` (or one ``(dim,)``).
        direction: ``"independent"`` — every (value, start) from ``x0s``, all batched;
            ``"up"`` — values in increasing order, each value starting from the state the
            previous value ended in (the first from ``x0s``), so a branch is followed
            until it vanishes; ``"down"`` — the same in decreasing order from ``x0s``;
            ``"both"`` — the up and the down sweep, each from ``x0s`` (run together);
            ``"all"`` — independent, up and down. A lane of a sweep that escapes
            restarts from its ``x0`` at the next value.
        integrator: :class:`RK4` (steps per period fixed, step ``h = T/steps`` per value)
            or :class:`Adaptive`.
        max_period, tol: period detection; merge_tol: relative distance under which two
            starts reached the same attractor.
        chunk_size: trajectories per compiled batch (values per block = chunk_size // S);
            also the block written to ``out``.
        out: folder for kill-and-resume (``DIR/parts``, ``DIR/manifest.json``) and the
            final ``DIR/bifurcation.nc``; restart: discard a folder of other settings.
    Returns:
        :class:`BifurcationDiagram`.
    """
    from . import __version__

    system, params = _common_checks(system, params, transient, record, max_period, tol, chunk_size)
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}.")
    _targets(params, param)
    vals = _values(values, param)
    X0 = _starts(system, x0s)
    check_system(system, with_param(params, param, vals[0]), X0[0])
    shared = _check_values(system, params, (param,), vals[:, None])
    S, V = len(X0), len(vals)
    # passes: (name of its parts, directions it computes together)
    passes = {"independent": [("independent", ("independent",))], "up": [("up", ("up",))],
              "down": [("down", ("down",))], "both": [("both", ("up", "down"))],
              "all": [("independent", ("independent",)), ("both", ("up", "down"))]}[direction]
    dirs = tuple(d for _, ds in passes for d in ds)
    blocks = {}
    for name, ds in passes:
        if name == "independent":
            blocks[name] = max(1, min(V, int(chunk_size) // S))
        else:  # sequential: the block only sets how often the sweep is saved
            blocks[name] = max(1, min(V, int(chunk_size) // (S * len(ds)), -(-V // 8)))
    settings = dict(kind="bifurcation", system=system.name, param=param, values=vals.tolist(),
                    starts=X0.tolist(), params=_pytree_dict(params), transient=int(transient), record=int(record),
                    direction=direction, integrator=_integrator_dict(integrator), max_period=int(max_period),
                    tol=float(tol), merge_tol=float(merge_tol), escape_bound=float(escape_bound),
                    block_values=blocks, version=__version__)
    ck = _Checkpoint(out, "bifurcation", settings, restart)
    names = (param,)
    R = int(record)
    points = np.empty((len(dirs), V, S, R, system.dim))
    bar = _progress(len(dirs) * V, f"sweep {param}", progress, unit="value")
    jX0 = jnp.asarray(X0)
    for name, ds in passes:
        B, nd = blocks[name], len(ds)
        rows = [dirs.index(d) for d in ds]
        orders = [np.arange(V)[::-1] if d == "down" else np.arange(V) for d in ds]
        carry = np.broadcast_to(X0, (nd, S, system.dim)).copy()
        for bi, a in enumerate(range(0, V, B)):
            b = min(a + B, V)
            part = f"{name}_{bi:05d}.npz"
            if ck.has(part):
                z = ck.load(part)
                pts, carry = z["points"], z["carry"]
            else:
                if name == "independent":
                    pts = _compute_independent(system, params, names, vals[a:b, None], B, jX0, int(transient), R,
                                               integrator, shared)[:, None]
                else:
                    seq = np.stack([vals[o[a:b]] for o in orders], axis=1)[..., None]  # (n, nd, 1)
                    pts, carry = _compute_scan(system, params, names, seq, B, jX0, carry, int(transient), R,
                                               integrator, float(escape_bound), shared)
                ck.save(part, points=pts, carry=carry)
            for j in range(nd):
                points[rows[j], orders[j][a:b]] = pts[:, j]
            bar.update(nd * (b - a))
    bar.close()
    period = _classify(points, int(max_period), float(tol), float(escape_bound))
    M = int(max_period)
    attractor = _group(points[..., -M:, :], period, float(merge_tol))
    diagram = BifurcationDiagram(
        param=param, fields=_targets(params, param), values=vals, directions=dirs, starts=X0, points=points,
        period=period, attractor=attractor, system=system.name, state_names=tuple(system.state_names),
        params=_pytree_dict(params), settings={k: v for k, v in settings.items()
                                               if k not in ("values", "starts", "params", "system", "param")},
        version=__version__,
    )
    if out is not None:
        diagram.save(Path(out) / "bifurcation.nc")
    return diagram


def _compute_independent(system, params, names, Vrows, size, X0, transient, record, integrator, shared):
    """One block of parameter rows ``Vrows (n, m)``, every start from ``X0``, padded to
    ``size`` rows (one compiled shape). Returns points ``(n, S, R, dim)``."""
    n = len(Vrows)
    V = jnp.asarray(_pad(np.asarray(Vrows, dtype=float), size))
    pts = _independent_kernel(system, params, names, V, X0, transient, record, integrator, shared)
    return np.asarray(pts)[:n]


def _compute_scan(system, params, names, seq, size, X0, carry, transient, record, integrator, bound, shared):
    """One block of a sequential sweep: ``seq (n, nd, m)`` values in order, state carried
    from ``carry (nd, S, dim)``; padded to ``size`` steps. Returns points ``(n, nd, S, R, dim)``
    and the carried state after the block's last value ``(nd, S, dim)``."""
    n = len(seq)
    V = jnp.asarray(_pad(np.asarray(seq, dtype=float), size))
    pts, car = _scan_kernel(system, params, names, V, jnp.asarray(carry), X0, transient, record, integrator, bound,
                            shared)
    return np.asarray(pts)[:n], np.asarray(car)[n - 1]


# =============================================================================== parameter map
@dataclasses.dataclass(frozen=True)
class ParameterMap:
    """Result of :func:`parameter_map` (a grid of two parameters).

    Attributes:
        param_x, fields_x, values_x ``(nx,)``; param_y, fields_y, values_y ``(ny,)``.
        starts: ``(S, dim)`` initial states (the same for every grid point).
        quantity: ``"period"`` or ``"n_attractors"`` (what :attr:`data` and the figure show).
        period: ``(ny, nx, S)`` period code reached from each start (k, 0 aperiodic, -1 escaped).
        attractor: ``(ny, nx, S)`` distinct-attractor id per grid point (-1 escaped).
        n_attractors: ``(ny, nx)`` number of distinct attractors reached (escape not counted).
        last_point: ``(ny, nx, S, dim)`` the last recorded stroboscopic point.
    """

    param_x: str
    fields_x: tuple[str, ...]
    values_x: np.ndarray
    param_y: str
    fields_y: tuple[str, ...]
    values_y: np.ndarray
    starts: np.ndarray
    quantity: str
    period: np.ndarray
    attractor: np.ndarray
    n_attractors: np.ndarray
    last_point: np.ndarray
    system: str
    state_names: tuple[str, ...]
    params: dict
    settings: dict
    version: str

    def __post_init__(self):
        for f in ("values_x", "values_y", "starts", "period", "attractor", "n_attractors", "last_point"):
            object.__setattr__(self, f, _ro(getattr(self, f)))

    @property
    def data(self) -> np.ndarray:
        """``(ny, nx)``: the period reached from the first start, or the number of attractors."""
        return self.period[:, :, 0] if self.quantity == "period" else self.n_attractors

    def table(self) -> str:
        """Share of the grid per period (from the first start) and per number of attractors."""
        from ._params import format_table

        n = self.period[:, :, 0].size
        rows = []
        for k in sorted(np.unique(self.period[:, :, 0]).tolist(), key=lambda k: _label_key(_label(k))):
            c = int((self.period[:, :, 0] == k).sum())
            rows.append(("period from start 0", _label(k), c, f"{100 * c / n:.1f} %"))
        for m in np.unique(self.n_attractors).tolist():
            c = int((self.n_attractors == m).sum())
            rows.append(("attractors reached", str(m), c, f"{100 * c / n:.1f} %"))
        return format_table(rows, ("quantity", "value", "grid points", "share"))

    def summary(self) -> dict[str, Any]:
        return dict(kind="parameter_map", param_x=self.param_x, values_x=self.values_x.tolist(),
                    param_y=self.param_y, values_y=self.values_y.tolist(), quantity=self.quantity,
                    n_starts=int(len(self.starts)), system=self.system, params=self.params, settings=self.settings,
                    version=self.version,
                    period_counts={_label(k): int((self.period[:, :, 0] == k).sum())
                                   for k in np.unique(self.period[:, :, 0]).tolist()},
                    n_attractors_counts={str(m): int((self.n_attractors == m).sum())
                                         for m in np.unique(self.n_attractors).tolist()})

    def to_xarray(self):
        import xarray as xr

        taken = list(self.state_names) + ["start", "state"]
        cx = _coord_name(self.param_x, taken)
        cy = _coord_name(self.param_y, taken + [cx])
        if cy == cx:
            cy = f"{cy}_y"
        data = {
            "period": ((cy, cx, "start"), self.period, {"description": "period code: k, 0 aperiodic, -1 escaped"}),
            "attractor": ((cy, cx, "start"), self.attractor, {"description": "distinct attractor id; -1 escaped"}),
            "n_attractors": ((cy, cx), self.n_attractors, {"description": "distinct attractors reached"}),
            "last_point": ((cy, cx, "start", "state"), self.last_point),
            "starts": (("start", "state"), self.starts),
        }
        coords = {cx: (cx, self.values_x, {"long_name": self.param_x, "sets": ",".join(self.fields_x)}),
                  cy: (cy, self.values_y, {"long_name": self.param_y, "sets": ",".join(self.fields_y)}),
                  "state": ("state", list(self.state_names))}
        attrs = dict(jaxgear_type="ParameterMap", title="jaxgear two-parameter map", param_x=self.param_x,
                     param_y=self.param_y, coord_x=cx, coord_y=cy, fields_x=json.dumps(list(self.fields_x)),
                     fields_y=json.dumps(list(self.fields_y)), quantity=self.quantity,
                     params=json.dumps(self.params), system=self.system, settings=json.dumps(self.settings),
                     version=self.version)
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path) -> Path:
        return _save_dataset(self.to_xarray(), path)


def load_parameter_map(path) -> ParameterMap:
    """Load a :class:`ParameterMap` saved with :meth:`ParameterMap.save` (exact)."""
    ds = _read_dataset(path, "ParameterMap")
    a = ds.attrs
    return ParameterMap(
        param_x=str(a["param_x"]), fields_x=tuple(json.loads(a["fields_x"])), values_x=ds[a["coord_x"]].values,
        param_y=str(a["param_y"]), fields_y=tuple(json.loads(a["fields_y"])), values_y=ds[a["coord_y"]].values,
        starts=ds["starts"].values, quantity=str(a["quantity"]), period=ds["period"].values.astype(np.int64),
        attractor=ds["attractor"].values.astype(np.int64), n_attractors=ds["n_attractors"].values.astype(np.int64),
        last_point=ds["last_point"].values, system=str(a["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), params=json.loads(a["params"]),
        settings=json.loads(a["settings"]), version=str(a["version"]),
    )


def parameter_map(system: ForcedSystem | None, params, param_x: str, values_x, param_y: str, values_y, x0s, *,
                  quantity: str = "period", transient: int = 400, record: int | None = None,
                  integrator: Integrator = RK4(), max_period: int = 16, tol: float = 1e-6, merge_tol: float = 1e-3,
                  escape_bound: float = 1e6, chunk_size: int = 1024, progress: bool = True, out=None,
                  restart: bool = False) -> ParameterMap:
    """Two-parameter map: the period of the attractor reached from a fixed initial state
    (``quantity="period"``: from ``x0s[0]``) or the number of distinct attractors reached
    from several starts (``"n_attractors"``), on the grid ``values_y x values_x``.

    Every (grid point, start) runs as in :func:`bifurcation_diagram` with
    ``direction="independent"`` (``transient`` periods, then ``record`` points, default
    ``2 max_period + 2``), all batched with ``vmap`` in blocks of ``chunk_size``
    trajectories; both period codes and attractor counts are always computed. ``out``:
    kill-and-resume folder and the final ``DIR/parameter_map.nc``.
    """
    from . import __version__

    if record is None:
        record = 2 * int(max_period) + 2
    system, params = _common_checks(system, params, transient, record, max_period, tol, chunk_size)
    if quantity not in ("period", "n_attractors"):
        raise ValueError(f"quantity must be 'period' or 'n_attractors', got {quantity!r}.")
    _targets(params, param_x)
    _targets(params, param_y)
    if set(_targets(params, param_x)) & set(_targets(params, param_y)):
        raise ValueError(f"param_x={param_x!r} and param_y={param_y!r} set the same field.")
    vx, vy = _values(values_x, param_x), _values(values_y, param_y)
    X0 = _starts(system, x0s)
    names = (param_x, param_y)
    VV = np.stack(np.meshgrid(vx, vy, indexing="xy"), axis=-1).reshape(-1, 2)  # (ny*nx, 2), y major
    check_system(system, _apply(params, names, VV[0]), X0[0])
    shared = _check_values(system, params, names, VV)
    S, n = len(X0), len(VV)
    B = max(1, min(n, int(chunk_size) // S))
    settings = dict(kind="parameter_map", system=system.name, param_x=param_x, values_x=vx.tolist(),
                    param_y=param_y, values_y=vy.tolist(), starts=X0.tolist(), params=_pytree_dict(params),
                    transient=int(transient), record=int(record), integrator=_integrator_dict(integrator),
                    max_period=int(max_period), tol=float(tol), merge_tol=float(merge_tol),
                    escape_bound=float(escape_bound), block_points=int(B), version=__version__)
    ck = _Checkpoint(out, "parameter_map", settings, restart)
    M = int(max_period)
    period = np.empty((n, S), dtype=np.int64)
    attractor = np.empty((n, S), dtype=np.int64)
    last = np.empty((n, S, system.dim))
    bar = _progress(n, f"map {param_x} x {param_y}", progress, unit="point")
    jX0 = jnp.asarray(X0)
    for bi, a in enumerate(range(0, n, B)):
        b = min(a + B, n)
        part = f"map_{bi:05d}.npz"
        if ck.has(part):
            z = ck.load(part)
        else:
            pts = _compute_independent(system, params, names, VV[a:b], B, jX0, int(transient), int(record),
                                       integrator, shared)
            per = _classify(pts, M, float(tol), float(escape_bound))
            z = dict(period=per, attractor=_group(pts[..., -M:, :], per, float(merge_tol)), last=pts[:, :, -1])
            ck.save(part, **z)
        period[a:b], attractor[a:b], last[a:b] = z["period"], z["attractor"], z["last"]
        bar.update(b - a)
    bar.close()
    ny, nx = len(vy), len(vx)
    n_att = attractor.max(axis=1, initial=-1) + 1
    pmap = ParameterMap(
        param_x=param_x, fields_x=_targets(params, param_x), values_x=vx, param_y=param_y,
        fields_y=_targets(params, param_y), values_y=vy, starts=X0, quantity=quantity,
        period=period.reshape(ny, nx, S), attractor=attractor.reshape(ny, nx, S),
        n_attractors=n_att.reshape(ny, nx).astype(np.int64), last_point=last.reshape(ny, nx, S, system.dim),
        system=system.name, state_names=tuple(system.state_names), params=_pytree_dict(params),
        settings={k: v for k, v in settings.items()
                  if k not in ("values_x", "values_y", "starts", "params", "system", "param_x", "param_y")},
        version=__version__,
    )
    if out is not None:
        pmap.save(Path(out) / "parameter_map.nc")
    return pmap


# =============================================================================== basin sweep
def _hausdorff(A: np.ndarray, B: np.ndarray) -> float:
    """Symmetric Hausdorff distance of two point sets (invariant to the order of the points)."""
    return max(_set_distance(A, B), _set_distance(B, A))


def _match(results, match_tol: float) -> list[np.ndarray]:
    """Global id of every attractor of every value: ``[ (A_i,) int array ]``.

    Attractors of value i are matched to those of value i-1 greedily by increasing
    Hausdorff distance of their stroboscopic point sets; pairs farther than
    ``match_tol`` are not matched, and an unmatched attractor gets a new global id
    (global ids numbered in order of first appearance).
    """
    out, prev, nxt = [], [], 0  # prev: [(gid, points, period)]
    for r in results:
        cur = [np.asarray(a.points) for a in r.attractors]
        gid = np.full(len(cur), -1, dtype=np.int64)
        if prev and cur:
            D = np.array([[_hausdorff(c, p) if len(c) and len(p) else np.inf for _, p, _ in prev] for c in cur])
            # closest pairs first; at equal distance a pair of the same period first
            same = np.array([[a.period == k for _, _, k in prev] for a in r.attractors])
            used = np.zeros(len(prev), bool)
            for flat in np.lexsort((~same.ravel(), D.ravel())):
                i, j = divmod(int(flat), len(prev))
                if D[i, j] > match_tol:
                    break
                if gid[i] < 0 and not used[j]:
                    gid[i] = prev[j][0]
                    used[j] = True
        for i in range(len(cur)):
            if gid[i] < 0:
                gid[i] = nxt
                nxt += 1
        out.append(gid)
        prev = [(int(g), c, a.period) for g, c, a in zip(gid, cur, r.attractors)]
    return out


@dataclasses.dataclass(frozen=True)
class BasinSweep:
    """Result of :func:`basin_sweep`: basin shares of globally identified attractors.

    Attributes:
        param, fields, values ``(V,)``.
        shares: ``(V, G)`` share of the grid in the domain of global attractor g at each
            value (0 where it does not exist); sink_share, unresolved_share: ``(V,)``.
        period: ``(V, G)`` its period there (k, 0 aperiodic), -1 where it does not exist.
        points: ``(V, G, K, dim)`` its stroboscopic points (NaN padded), n_points ``(V, G)``.
        labels: ``(V, *grid.counts)`` int16: global attractor id of every cell, -1 sink,
            -2 unresolved.
        grid, method, match_tol, system, state_names, params (base), settings, version.
    """

    param: str
    fields: tuple[str, ...]
    values: np.ndarray
    shares: np.ndarray
    sink_share: np.ndarray
    unresolved_share: np.ndarray
    period: np.ndarray
    points: np.ndarray
    n_points: np.ndarray
    labels: np.ndarray
    grid: Any
    method: str
    match_tol: float
    system: str
    state_names: tuple[str, ...]
    params: dict
    settings: dict
    version: str

    def __post_init__(self):
        for f in ("values", "shares", "sink_share", "unresolved_share", "period", "points", "n_points", "labels"):
            object.__setattr__(self, f, _ro(getattr(self, f)))

    @property
    def n_attractors(self) -> int:
        """Number of global attractors."""
        return int(self.shares.shape[1])

    @property
    def present(self) -> np.ndarray:
        """``(V, G)`` bool: the attractor exists at the value."""
        return self.period >= 0

    def attractor_label(self, g: int) -> str:
        """``"P-4"`` or ``"P-4/P-8"`` when its period changes along the sweep."""
        ks = []
        for k in self.period[:, g].tolist():
            if k >= 0 and (not ks or ks[-1] != k):
                ks.append(k)
        return "/".join(_label(k) for k in ks) or "-"

    def events(self, share_step: float = 0.05) -> list[dict]:
        """Where attractors appear, vanish, change period, or their share moves by at least
        ``share_step`` between neighbouring values."""
        ev = []
        pres = self.present
        for g in range(self.n_attractors):
            if pres[0, g]:
                ev.append(dict(index=0, value=float(self.values[0]), id=g, event="present",
                               detail=f"{_label(int(self.period[0, g]))}, share {100 * self.shares[0, g]:.1f} %"))
        for i in range(1, len(self.values)):
            for g in range(self.n_attractors):
                a, b = pres[i - 1, g], pres[i, g]
                e = None
                if b and not a:
                    e = ("appears", f"{_label(int(self.period[i, g]))}, share {100 * self.shares[i, g]:.1f} %")
                elif a and not b:
                    e = ("vanishes", f"was {_label(int(self.period[i - 1, g]))}, share "
                                     f"{100 * self.shares[i - 1, g]:.1f} %")
                elif a and b and self.period[i, g] != self.period[i - 1, g]:
                    e = ("period change", f"{_label(int(self.period[i - 1, g]))} -> {_label(int(self.period[i, g]))}")
                elif a and b and abs(self.shares[i, g] - self.shares[i - 1, g]) >= share_step:
                    e = ("share change", f"{100 * self.shares[i - 1, g]:.1f} % -> {100 * self.shares[i, g]:.1f} %")
                if e:
                    ev.append(dict(index=i, value=float(self.values[i]), id=g, event=e[0], detail=e[1]))
        return ev

    def table(self, share_step: float = 0.05) -> str:
        """Printable table of the events (appear / vanish / period change / share change)."""
        from ._params import format_table

        rows = [(f"{e['value']:.5g}", e["id"], self.attractor_label(e["id"]), e["event"], e["detail"])
                for e in self.events(share_step)]
        return format_table(rows, (self.param, "attractor", "label", "event", "detail"))

    def shares_table(self) -> str:
        """Shares (percent) of every global attractor and the sink at every value."""
        from ._params import format_table

        unres = bool(np.any(self.unresolved_share > 0))
        head = ((self.param,) + tuple(f"{g}: {self.attractor_label(g)}" for g in range(self.n_attractors))
                + ("sink",) + (("unresolved",) if unres else ()))
        rows = [(f"{v:.5g}",) + tuple(f"{100 * s:.1f}" if self.present[i, g] else "-"
                                      for g, s in enumerate(self.shares[i])) + (f"{100 * self.sink_share[i]:.1f}",)
                + ((f"{100 * self.unresolved_share[i]:.1f}",) if unres else ())
                for i, v in enumerate(self.values)]
        return format_table(rows, head)

    def summary(self) -> dict[str, Any]:
        return dict(kind="basins", param=self.param, fields=list(self.fields), values=self.values.tolist(),
                    method=self.method, grid=self.grid.to_dict(), match_tol=self.match_tol, system=self.system,
                    params=self.params, settings=self.settings, version=self.version,
                    attractors=[dict(id=g, label=self.attractor_label(g),
                                     first=float(self.values[self.present[:, g]][0]),
                                     last=float(self.values[self.present[:, g]][-1]),
                                     max_share=float(self.shares[:, g].max())) for g in range(self.n_attractors)],
                    shares=self.shares.tolist(), sink_share=self.sink_share.tolist(),
                    unresolved_share=self.unresolved_share.tolist(), events=self.events())

    def to_xarray(self):
        import xarray as xr

        g = self.grid
        axes = list(g.axis_names)
        c = _coord_name(self.param, list(self.state_names) + axes + ["attractor", "point", "state"])
        data = {
            "shares": ((c, "attractor"), self.shares, {"description": "share of the grid in each domain"}),
            "sink_share": ((c,), self.sink_share),
            "unresolved_share": ((c,), self.unresolved_share),
            "period": ((c, "attractor"), self.period, {"description": "period k; 0 aperiodic; -1 absent"}),
            "points": ((c, "attractor", "point", "state"), self.points, {"description": "stroboscopic points"}),
            "n_points": ((c, "attractor"), self.n_points),
            "labels": ((c, *axes), self.labels,
                       {"description": "global attractor id of each cell; -1 sink, -2 unresolved"}),
        }
        coords = {c: (c, self.values, {"long_name": self.param, "sets": ",".join(self.fields)}),
                  "attractor": ("attractor", np.arange(self.n_attractors)),
                  "state": ("state", list(self.state_names))}
        for j, name in enumerate(axes):
            coords[name] = (name, g.axis_centres(j), {"long_name": f"cell centre {name}"})
        attrs = dict(jaxgear_type="BasinSweep", title="jaxgear basin shares across a parameter", param=self.param,
                     param_coord=c, fields=json.dumps(list(self.fields)), method=self.method,
                     grid=json.dumps(g.to_dict()), match_tol=self.match_tol, params=json.dumps(self.params),
                     system=self.system, settings=json.dumps(self.settings), version=self.version)
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path) -> Path:
        return _save_dataset(self.to_xarray(), path)


def load_basin_sweep(path) -> BasinSweep:
    """Load a :class:`BasinSweep` saved with :meth:`BasinSweep.save` (exact)."""
    from ._cells import CellGrid

    ds = _read_dataset(path, "BasinSweep")
    a = ds.attrs
    return BasinSweep(
        param=str(a["param"]), fields=tuple(json.loads(a["fields"])), values=ds[a["param_coord"]].values,
        shares=ds["shares"].values, sink_share=ds["sink_share"].values,
        unresolved_share=ds["unresolved_share"].values, period=ds["period"].values.astype(np.int64),
        points=ds["points"].values, n_points=ds["n_points"].values.astype(np.int64),
        labels=ds["labels"].values.astype(np.int16), grid=CellGrid.from_dict(json.loads(a["grid"])),
        method=str(a["method"]), match_tol=float(a["match_tol"]), system=str(a["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), params=json.loads(a["params"]),
        settings=json.loads(a["settings"]), version=str(a["version"]),
    )


def _analyze_value(system, params, grid, method, kw):
    """The global analysis at one parameter value (a hook for progress and tests)."""
    from ._cellmap import analyze_global

    return analyze_global(system, params, grid, method=method, **kw)


def basin_sweep(system: ForcedSystem | None, params, param: str, values, grid=None, *, method: str = "direct",
                match_tol: float | None = None, progress: bool = True, out=None, restart: bool = False,
                **analyze_kw) -> BasinSweep:
    """Basin shares across a parameter, attractors continued from value to value.

    At each value :func:`~jaxgear.analyze_global` runs on ``grid`` (default: the paper's
    region D, for the gear model). The attractors of neighbouring values are matched by
    the Hausdorff distance of their stroboscopic point sets (cyclic-shift invariant, the
    idea of global continuation of attractors): greedily, closest pairs first, pairs
    farther than ``match_tol`` not matched (default: 5 % of the diagonal of the grid's
    box over its gridded axes). An attractor that appears gets a new global id; one
    that vanishes keeps its id (it is not matched again later).

    Args:
        param, values: as in :func:`bifurcation_diagram`.
        method: ``"direct"`` (default), ``"poincare-like"`` or ``"stroboscopic"``.
        analyze_kw: further options of :func:`~jaxgear.analyze_global` (``integrator``,
            ``max_period``, ``round_periods``, ...); ``progress`` applies to both.
        out: kill-and-resume folder: each value's :class:`~jaxgear.GlobalResult` is saved
            to ``DIR/parts/value_00000.nc`` when done; the final ``DIR/basins.nc``.
    Returns:
        :class:`BasinSweep`.
    """
    from . import __version__
    from ._cells import CellGrid
    from ._model import REDUCED
    from ._result import load_result

    if system is None:
        system = REDUCED
    if params is None:
        if system is not REDUCED:
            raise ValueError("pass the parameters of your system.")
        from . import paper_params

        params = paper_params()
    if grid is None:
        if system is not REDUCED:
            raise ValueError("pass a CellGrid for your system (CellGrid.box(bounds, counts, ...)).")
        grid = CellGrid.paper()
    if not isinstance(grid, CellGrid):
        raise ValueError(f"grid must be a CellGrid, got {type(grid).__name__}.")
    if grid.dim != system.dim:
        raise ValueError(f"the grid has {grid.dim} coordinates, the system {system.dim}.")
    _targets(params, param)
    vals = _values(values, param)
    _check_values(system, params, (param,), vals[:, None])
    if match_tol is None:
        match_tol = 0.05 * float(np.linalg.norm(np.asarray(grid.upper) - np.asarray(grid.lower)))
    if not match_tol > 0:
        raise ValueError(f"match_tol={match_tol} must be > 0.")
    kw = dict(analyze_kw)
    integ = kw.get("integrator")
    kw_json = {k: (_integrator_dict(v) if isinstance(v, Integrator) else v) for k, v in kw.items()}
    settings = dict(kind="basins", system=system.name, param=param, values=vals.tolist(), params=_pytree_dict(params),
                    grid=grid.to_dict(), method=method, match_tol=float(match_tol), analyze=kw_json,
                    version=__version__)
    try:
        json.dumps(settings)
    except TypeError as exc:
        raise ValueError(f"basin_sweep: analyze options must be plain values or integrators ({exc}).") from None
    del integ
    ck = _Checkpoint(out, "basins", settings, restart)
    results = []
    bar = _progress(len(vals), f"basins {param}", progress, unit="value")
    for i, v in enumerate(vals):
        part = f"value_{i:05d}.nc"
        if ck.has(part):
            r = load_result(ck.path(part))
        else:
            r = _analyze_value(system, with_param(params, param, v), grid, method, dict(kw, progress=False))
            if ck.dir is not None:
                r.save(ck.path(part))
        results.append(r)
        bar.update(1)
    bar.close()
    sweep = _assemble_basins(results, param, _targets(params, param), vals, grid, method, float(match_tol), system,
                             _pytree_dict(params), {k: v for k, v in settings.items()
                                                    if k not in ("values", "params", "system", "param", "grid",
                                                                 "method", "match_tol")}, __version__)
    if out is not None:
        sweep.save(Path(out) / "basins.nc")
    return sweep


def _assemble_basins(results, param, fields, vals, grid, method, match_tol, system, params_dict, settings, version):
    gids = _match(results, match_tol)
    G = int(max([g.max(initial=-1) for g in gids] + [-1])) + 1
    V = len(vals)
    K = max([len(a.points) for r in results for a in r.attractors] + [1])
    dim = system.dim
    shares = np.zeros((V, G))
    period = np.full((V, G), -1, dtype=np.int64)
    points = np.full((V, G, K, dim), np.nan)
    n_points = np.zeros((V, G), dtype=np.int64)
    labels = np.empty((V, *grid.counts), dtype=np.int16)
    sink = np.empty(V)
    unres = np.empty(V)
    for i, (r, g) in enumerate(zip(results, gids)):
        lut = np.full(len(r.attractors) + 2, -1, dtype=np.int64)  # index local id + 2
        lut[0], lut[1] = -2, -1
        for a, gg in zip(r.attractors, g):
            shares[i, gg] = a.share
            period[i, gg] = a.period
            pts = np.asarray(a.points)
            points[i, gg, : len(pts)] = pts
            n_points[i, gg] = len(pts)
            lut[a.id + 2] = gg
        labels[i] = lut[np.asarray(r.labels) + 2].reshape(grid.counts)
        sink[i] = r.n_sink / r.n_cells
        unres[i] = r.n_unresolved / r.n_cells
    return BasinSweep(param=param, fields=tuple(fields), values=vals, shares=shares, sink_share=sink,
                      unresolved_share=unres, period=period, points=points, n_points=n_points, labels=labels,
                      grid=grid, method=method, match_tol=match_tol, system=system.name,
                      state_names=tuple(system.state_names), params=params_dict, settings=settings, version=version)
