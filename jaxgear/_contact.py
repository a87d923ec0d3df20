"""The gear view of an attractor: mesh contact states, dynamic transmission error, mesh
forces and spectra, mesh by mesh.

What a gear engineer asks of every coexisting motion found by the global analysis
(paper §4.2) is not its stroboscopic point but what the teeth do: for each mesh, how much
of the time its drive flanks touch, how much it spends in the backlash gap and on the back
flanks (model document §2.2: drive-flank contact ``X > b``, gap ``|X| <= b``, back-flank
contact ``X < -b``), how often it loses contact and strikes the back flank, the dynamic
transmission error ``X`` (the mesh deflection net of the static error, model document §2.1)
and the dynamic mesh force (§2.4) with its dynamic factor, and the harmonics of the
transmission error.

A mesh is a pair of the system's switching functions (:class:`~jaxgear.ForcedSystem`
``switching``) ``(X - b, X + b)``: the drive-flank and the back-flank surface of paper
eq. (3). The built-in gear models declare theirs; a user system declares its own (in
consecutive pairs, or any pairs through :class:`MeshSpec`). The deflection is their mean
and the half backlash half their difference, so nothing of a mesh is written twice; the
mesh forces of the gear models are :func:`~jaxgear.mesh_forces`.

A P-k attractor is sampled over exactly its ``k`` forcing periods from its stroboscopic
point; an aperiodic one (period 0) over a long run from a point of its cloud, cut into
stretches whose spread gives the error of every share and rate. Contact changes are located
inside a sample interval by bisection on the integrator's own step from the sample before
(a step split at the kinks it meets), so shares are as accurate as the integration.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._batching import SMALL_BATCH, pad_rows, power_of_two_at_least
from ._checks import check_int, check_number, with_changes
from ._codec import array_field, custom_field, items_field, result_type
from ._format import format_table
from ._gearset import GearSet
from ._io import save_result
from ._model import nplanet_switching, reduced_switching
from ._params import GearParams, params_to_dict
from ._poincare import (
    LOCATE_BISECTIONS,
    locate_sign_changes,
    one_period,
    sample_trajectory,
    stroboscopic_map,
    stroboscopic_orbit,
    switching_count,
)
from ._system import ForcedSystem, check_system
from ._version import __version__
from .analysis import Attractor
from .design import mesh_forces
from .integrate import DEFAULT_STEPS_PER_PERIOD, AbstractIntegrator, KinkAwareRK4, integrator_from_dict

__all__ = ["ContactRegime", "MeshSpec", "GearViewOptions", "MeshView", "GearView", "gear_view", "gear_views",
           "RegimeShares", "RegimeMap", "regime_shares"]


class ContactRegime(enum.IntEnum):
    """How a mesh's teeth move over an attractor (the classic impact regimes of a gear pair
    with backlash).

    ``NO_IMPACT``: the contact state never changes (normally the drive flanks stay in
    contact all the time); ``SINGLE_SIDED``: the mesh loses contact and re-engages on the
    drive flank, never touching the back flank; ``DOUBLE_SIDED``: it reaches the back flank.
    """

    NO_IMPACT = 0
    SINGLE_SIDED = 1
    DOUBLE_SIDED = 2

    @property
    def text(self) -> str:
        """``"no impact"``, ``"single-sided impact"`` or ``"double-sided impact"``."""
        return _REGIME_TEXT[self]


_REGIME_TEXT = {ContactRegime.NO_IMPACT: "no impact", ContactRegime.SINGLE_SIDED: "single-sided impact",
                ContactRegime.DOUBLE_SIDED: "double-sided impact"}


@dataclasses.dataclass(frozen=True, kw_only=True)
class MeshSpec:
    """Which switching functions of a system are meshes, their names and their force.

    Attributes:
        pairs: ``((drive, back), ...)``: indices into ``system.switching(t, x, params)`` of the
            drive-flank function ``X - b`` and the back-flank function ``X + b`` of each mesh;
            ``None``: the gear models' own meshes, for any other system consecutive pairs
            ``(0, 1), (2, 3), ...``.
        names: one name per mesh; ``None``: ``"sun-planet"``, ``"ring-planet"`` for the reduced
            gear model (``"sun-planet 1"``, ... for the N-planet model), ``"mesh 1"``, ... otherwise.
        force: ``force(t, x, params) -> (n_meshes,)`` the dynamic mesh forces, in the system's
            force unit; ``None``: :func:`~jaxgear.mesh_forces` for the gear models, no force
            otherwise (force columns then NaN).
        static_force: the static force of each mesh under the same mean load (a number for
            all meshes or one per mesh), the denominator of the dynamic factor; ``None``: the
            gear models' ``f_D / N`` (the sun torque shared by ``N`` planets, model document §4).
    """

    pairs: tuple[tuple[int, int], ...] | None = None
    names: tuple[str, ...] | None = None
    force: Callable[[Any, Any, Any], Any] | None = None
    static_force: float | tuple[float, ...] | None = None

    def __post_init__(self):
        if self.pairs is not None:
            try:
                pairs = tuple((int(a), int(b)) for a, b in self.pairs)
                ok = all(float(a) == int(a) and float(b) == int(b) for a, b in self.pairs)
            except (TypeError, ValueError):
                ok = False
            if not ok or not pairs or min(min(p) for p in pairs) < 0:
                raise ValueError(f"MeshSpec.pairs={self.pairs!r} must be a non-empty tuple of (drive, back) pairs "
                                 "of indices >= 0 into the system's switching functions.")
            object.__setattr__(self, "pairs", pairs)
        if self.names is not None:
            if isinstance(self.names, str) or not all(isinstance(n, str) for n in self.names):
                raise ValueError(f"MeshSpec.names={self.names!r} must be a tuple of strings, one per mesh.")
            object.__setattr__(self, "names", tuple(self.names))
            if self.pairs is not None and len(self.names) != len(self.pairs):
                raise ValueError(f"MeshSpec.names has {len(self.names)} names for {len(self.pairs)} pairs.")
        if self.force is not None and not callable(self.force):
            raise ValueError("MeshSpec.force must be callable force(t, x, params) -> (n_meshes,) or None.")
        if self.static_force is not None:
            a = np.atleast_1d(np.asarray(self.static_force, dtype=float))
            if a.ndim != 1 or not np.all(np.isfinite(a)) or not np.all(a > 0):
                raise ValueError(f"MeshSpec.static_force={self.static_force!r} must be a positive number or one "
                                 "positive number per mesh.")


@dataclasses.dataclass(frozen=True, kw_only=True)
class GearViewOptions:
    """Options of :func:`gear_view`.

    Attributes:
        samples_per_period: samples of the trajectory per forcing period (>= 16); the
            default integrator takes one step per sample. The default is the default
            integrator's steps per period, so the samples and contact changes of the gear
            view reuse the analysis's compiled programs.
        transient: forcing periods integrated from the attractor's point before sampling
            (rounded up to a multiple of ``k`` for a P-k); 0 starts on the point itself.
        stretches, stretch_periods: an aperiodic attractor is followed for ``stretches``
            stretches of ``stretch_periods`` forcing periods each; the error of a share or a
            rate is the standard error of its mean over the stretches.
        max_order: the spectrum is kept up to this multiple of the mesh (forcing) frequency
            (at most half of ``samples_per_period``).
        bisections: bisection steps that locate each contact change inside its sample
            interval (the interval shrinks by ``2**bisections``).
        integrator: ``None``: :class:`~jaxgear.KinkAwareRK4` with ``samples_per_period``
            steps per period; any integrator object otherwise (its ``crossing_stepper``
            locates the contact changes).
    """

    samples_per_period: int = DEFAULT_STEPS_PER_PERIOD
    transient: int = 0
    stretches: int = 8
    stretch_periods: int = 25
    max_order: float = 10.0
    bisections: int = LOCATE_BISECTIONS
    integrator: AbstractIntegrator | None = None

    def __post_init__(self):
        check_int(self.samples_per_period, "samples_per_period", 16)
        check_int(self.transient, "transient", 0)
        check_int(self.stretches, "stretches", 2)
        check_int(self.stretch_periods, "stretch_periods", 1)
        check_int(self.bisections, "bisections", 1, 60)
        check_number(self.max_order, "max_order", 0.0, self.samples_per_period / 2, strict_min=True)
        if self.integrator is not None and not isinstance(self.integrator, AbstractIntegrator):
            raise ValueError(f"integrator={self.integrator!r} must be an integrator object (jaxgear.KinkAwareRK4(...)) "
                             "or None.")


@dataclasses.dataclass(frozen=True, kw_only=True)
class MeshView:
    """One mesh over one attractor (an item of :attr:`GearView.meshes`).

    Shares are fractions of the time (they sum to 1); rates are per forcing period; for
    an aperiodic attractor the ``*_error`` fields are the standard errors over the
    stretches (0 for a P-k, whose values are exact for its sampled orbit). Transmission
    errors and forces are in the units of :attr:`GearView.length_unit` and
    :attr:`GearView.force_unit`.

    Attributes:
        name: the mesh's name.
        regime: its :class:`ContactRegime` (stored as its code).
        drive_share, gap_share, back_share: time shares in drive-flank contact
            (``X > b``), in the gap (``|X| <= b``) and in back-flank contact (``X < -b``).
        losses_per_period: contact losses (``X`` falling through ``b``) per forcing period.
        impacts_per_period: back-flank impacts (``X`` falling through ``-b``) per period.
        te_mean, te_rms, te_ptp: the dynamic transmission error ``X``: mean, RMS about
            the mean, peak-to-peak.
        force_mean, force_max, force_min: the dynamic mesh force (NaN without a force).
        static_force: the static force of the same torque; ``dynamic_factor`` is
            ``force_max / static_force``.
        orders: ``(n,)`` frequencies of the spectrum in multiples of the mesh frequency
            (``j / k`` for a P-k: its exact harmonics); ``amplitudes``: ``(n,)`` the
            one-sided amplitude of ``X`` at each (order 0: the mean).
    """

    name: str
    regime: ContactRegime
    drive_share: float
    gap_share: float
    back_share: float
    drive_share_error: float = 0.0
    gap_share_error: float = 0.0
    back_share_error: float = 0.0
    losses_per_period: float = 0.0
    losses_error: float = 0.0
    impacts_per_period: float = 0.0
    impacts_error: float = 0.0
    te_mean: float = float("nan")
    te_rms: float = float("nan")
    te_ptp: float = float("nan")
    force_mean: float = float("nan")
    force_max: float = float("nan")
    force_min: float = float("nan")
    static_force: float = float("nan")
    dynamic_factor: float = float("nan")
    orders: np.ndarray = array_field(("order",), default_factory=lambda: np.zeros(0))
    amplitudes: np.ndarray = array_field(("order",), default_factory=lambda: np.zeros(0))


@result_type
@dataclasses.dataclass(frozen=True, kw_only=True)
class GearView:
    """Result of :func:`gear_view`: every mesh over one attractor.

    Attributes:
        attractor_id, label, period: the attractor (its id in its result, ``"P-k"`` or the
            aperiodic type, ``k``; 0 for an aperiodic one).
        meshes: one :class:`MeshView` per mesh.
        start: ``(dim,)`` the state at forcing phase 0 the sampling started from.
        periods_covered: forcing periods the statistics cover (``k``, or the long run).
        stretches: 1 for a P-k, the number of stretches of an aperiodic run.
        samples_per_period: samples per forcing period.
        length_unit, force_unit: ``"um"`` and ``"N"`` with a :class:`~jaxgear.GearSet`;
            ``"b_c"`` and ``"k_msp b_c"`` for the dimensionless gear models (model document
            §3); ``"state unit"`` and ``"force unit"`` for a user system.
        length_scale, force_scale: the unit values of the dimensionless model in
            ``length_unit`` and ``force_unit`` (1 without a gear set).
        mesh_frequency_hz: the mesh frequency in Hz with a gear set (NaN otherwise): an
            order times it is a frequency in Hz.
        integrator: the integrator that sampled the attractor.
        system, params (dict), version.
    """

    attractor_id: int
    label: str
    period: int
    meshes: tuple[MeshView, ...] = items_field("mesh")
    start: np.ndarray = array_field(("state",))
    periods_covered: int = 0
    stretches: int = 1
    samples_per_period: int = 0
    length_unit: str = ""
    force_unit: str = ""
    length_scale: float = 1.0
    force_scale: float = 1.0
    mesh_frequency_hz: float = float("nan")
    integrator: AbstractIntegrator = custom_field(lambda i: i.to_dict(), integrator_from_dict,
                                                  default_factory=KinkAwareRK4)
    system: str = ""
    params: dict = dataclasses.field(default_factory=dict)
    version: str = ""

    def mesh(self, name: str) -> MeshView:
        """The :class:`MeshView` called ``name``."""
        for m in self.meshes:
            if m.name == name:
                return m
        raise ValueError(f"no mesh {name!r}; the meshes are {', '.join(m.name for m in self.meshes)}.")

    def frequencies_hz(self, name: str) -> np.ndarray:
        """The spectrum's frequencies of mesh ``name`` in Hz (NaN without a gear set)."""
        return np.asarray(self.mesh(name).orders) * self.mesh_frequency_hz

    def lines(self) -> list[str]:
        """One line per mesh: regime, RMS transmission error and dynamic factor."""
        out = []
        for m in self.meshes:
            df = "-" if not math.isfinite(m.dynamic_factor) else f"{m.dynamic_factor:.3f}"
            out.append(f"attractor {self.attractor_id} ({self.label}), {m.name}: {m.regime.text}, "
                       f"RMS TE {_num(m.te_rms)} {self.length_unit}, dynamic factor {df}")
        return out

    def table(self) -> str:
        """Printable table: one row per mesh (shares in %, rates per forcing period)."""
        rows = []
        err = self.stretches > 1

        def pc(v, e):
            return f"{100 * v:.3f}" + (f" +- {100 * e:.3f}" if err else "")

        def rate(v, e):
            return f"{v:.4g}" + (f" +- {e:.2g}" if err else "")

        for m in self.meshes:
            rows.append((m.name, m.regime.text, pc(m.drive_share, m.drive_share_error),
                         pc(m.gap_share, m.gap_share_error), pc(m.back_share, m.back_share_error),
                         rate(m.losses_per_period, m.losses_error), rate(m.impacts_per_period, m.impacts_error),
                         _num(m.te_mean), _num(m.te_rms), _num(m.te_ptp), _num(m.force_mean), _num(m.force_max),
                         _num(m.force_min), _num(m.dynamic_factor), _dominant(m)))
        head = ("mesh", "regime", "drive %", "gap %", "back %", "losses/T", "impacts/T",
                f"TE mean [{self.length_unit}]", "TE rms", "TE p-p", f"F mean [{self.force_unit}]", "F max",
                "F min", "dyn. factor", "strongest order")
        over = (f"over {self.periods_covered} forcing periods" if self.stretches == 1 else
                f"over {self.periods_covered} forcing periods in {self.stretches} stretches (+- standard error)")
        return f"attractor {self.attractor_id} ({self.label}), {over}\n" + format_table(rows, head)

    def summary(self) -> dict[str, Any]:
        """JSON-able description."""
        meshes = []
        for m in self.meshes:
            d = {f.name: getattr(m, f.name) for f in dataclasses.fields(m)}
            d.update(regime=m.regime.text, orders=np.asarray(m.orders).tolist(),
                     amplitudes=np.asarray(m.amplitudes).tolist())
            meshes.append(d)
        return dict(attractor_id=self.attractor_id, label=self.label, period=self.period, meshes=meshes,
                    start=np.asarray(self.start).tolist(), periods_covered=self.periods_covered,
                    stretches=self.stretches, length_unit=self.length_unit, force_unit=self.force_unit,
                    mesh_frequency_hz=self.mesh_frequency_hz, system=self.system, params=self.params,
                    version=self.version)

    def _attrs(self) -> dict:
        return dict(title="jaxgear gear view of an attractor",
                    units=f"transmission error in {self.length_unit}, force in {self.force_unit}")

    def save(self, path):
        """Write to netCDF atomically; reload with :func:`jaxgear.load`."""
        return save_result(self, path)


def _num(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v:.4g}"


def _dominant(m: MeshView) -> str:
    """The strongest non-zero order of the spectrum and its amplitude."""
    orders, amps = np.asarray(m.orders), np.asarray(m.amplitudes)
    keep = orders > 0
    if not np.any(keep):
        return "-"
    j = int(np.argmax(np.where(keep, amps, -np.inf)))
    return f"{orders[j]:.4g}x: {amps[j]:.3g}"


# ----------------------------------------------------------------------- the meshes
@dataclasses.dataclass(frozen=True)
class _Layout:
    names: tuple[str, ...]
    pairs: tuple[tuple[int, int], ...]
    forces: Callable[[Any, Any, Any], Any] | None  # (params, ts (m,), xs (m, dim)) -> (m, n_meshes)
    static: np.ndarray  # (n_meshes,), NaN where unknown


@functools.partial(jax.jit, static_argnums=(0, 1))
def _gear_forces(N: int, reduced: bool, params, ts, xs):
    """The gear models' mesh forces (:func:`~jaxgear.mesh_forces`) at the samples, one
    column per mesh (sun-planet meshes first): ``(m, n_meshes)``."""
    f = mesh_forces(params, (ts, xs))
    if reduced:
        return jnp.stack([f.sp, f.rp], axis=1)
    return jnp.concatenate([jnp.reshape(f.sp, (len(ts), N)), jnp.reshape(f.rp, (len(ts), N))], axis=1)


@functools.partial(jax.jit, static_argnums=0)
def _user_forces(force, params, ts, xs):
    """A user's ``force(t, x, params)`` at the samples: ``(m, n_meshes)``."""
    return jax.vmap(lambda t, x: jnp.reshape(force(t, x, params), (-1,)))(ts, xs)


def _layout(system: ForcedSystem, params, x0, meshes: MeshSpec | None) -> _Layout:
    if meshes is not None and not isinstance(meshes, MeshSpec):
        raise ValueError(f"meshes={meshes!r} must be a jaxgear.MeshSpec or None.")
    spec = meshes or MeshSpec()
    if system.switching is None:
        raise ValueError(f"{system.name}: the gear view reads each mesh from the system's switching functions "
                         "(ForcedSystem(switching=...), a pair X - b, X + b per mesh); this system declares none.")
    n_sw = switching_count(system, params)
    gear = isinstance(params, GearParams) and system.switching in (reduced_switching, nplanet_switching)
    names: tuple[str, ...]
    if gear and system.switching is reduced_switching:
        N, reduced = 1, True
        pairs, names = ((0, 1), (2, 3)), ("sun-planet", "ring-planet")
    elif gear:
        N, reduced = n_sw // 4, False
        pairs = tuple((i, N + i) for i in range(N)) + tuple((2 * N + i, 3 * N + i) for i in range(N))
        names = tuple(f"sun-planet {i + 1}" for i in range(N)) + tuple(f"ring-planet {i + 1}" for i in range(N))
    else:
        if spec.pairs is None and n_sw % 2:
            raise ValueError(f"meshes: {system.name} has {n_sw} switching functions, not pairs (X - b, X + b); "
                             "say which are meshes with MeshSpec(pairs=((drive, back), ...)).")
        pairs = tuple((2 * i, 2 * i + 1) for i in range(n_sw // 2))
        names = tuple(f"mesh {i + 1}" for i in range(len(pairs)))
    if spec.pairs is not None:
        pairs = spec.pairs
        if spec.names is None and len(names) != len(pairs):
            names = tuple(f"mesh {i + 1}" for i in range(len(pairs)))
    if spec.names is not None:
        if len(spec.names) != len(pairs):
            raise ValueError(f"meshes: {len(spec.names)} names for {len(pairs)} meshes.")
        names = spec.names
    bad = [p for p in pairs if max(p) >= n_sw or p[0] == p[1]]
    if bad:
        raise ValueError(f"meshes: the pair(s) {bad} do not name two different switching functions of "
                         f"{system.name} (it has {n_sw}: indices 0..{n_sw - 1}).")
    n = len(pairs)
    forces = None
    if spec.force is not None:
        forces = functools.partial(_user_forces, spec.force)
        got = np.shape(spec.force(0.0, jnp.asarray(x0), params))
        if int(np.prod(got)) != n:
            raise ValueError(f"meshes: MeshSpec.force returns shape {got}; it must return one force per mesh ({n}).")
    elif gear and spec.pairs is None:
        forces = functools.partial(_gear_forces, N, reduced)
    static = np.full(n, np.nan)
    if spec.static_force is not None:
        s = np.atleast_1d(np.asarray(spec.static_force, dtype=float))
        if s.size not in (1, n):
            raise ValueError(f"meshes: MeshSpec.static_force has {s.size} values for {n} meshes.")
        static = np.broadcast_to(s, (n,)).copy()
    elif gear:
        static = np.full(n, float(np.mean(np.asarray(params.f_D))) / int(params.N))
    return _Layout(names, pairs, forces, static)


# ----------------------------------------------------------------------- kernels
@functools.partial(jax.jit, static_argnums=0)
def _switching_at(system, params, ts, xs):
    """``system.switching`` at every sample: ``(m, n_switching)``."""
    return jax.vmap(system.switching, in_axes=(0, 0, None))(ts, xs, params)


@dataclasses.dataclass
class _Stretch:
    """Per-mesh sums of one sampled stretch of the trajectory."""

    drive: np.ndarray  # time in drive contact (n,)
    back: np.ndarray  # time in back contact (n,)
    losses: np.ndarray  # counts (n,)
    impacts: np.ndarray
    duration: float
    periods: int
    te: np.ndarray  # (m, n) deflection at the samples (end point left out)
    te_end: np.ndarray  # (n,) at the end point
    force: np.ndarray | None  # (m, n)
    force_end: np.ndarray | None


def _small_batch(X: np.ndarray) -> np.ndarray:
    """The starts ``X (n, dim)`` padded to a power of two of at least
    :data:`~jaxgear._batching.SMALL_BATCH` rows (one compiled shape for a few starts)."""
    return pad_rows(X, power_of_two_at_least(len(X), SMALL_BATCH))


def _stretches(system, params, layout: _Layout, stepper, n_iter: int,
               pieces: list[tuple[np.ndarray, np.ndarray, int]]) -> list[_Stretch]:
    """The sums of every sampled stretch ``(times (m,), states (m, dim), periods)`` of
    ``pieces``: the switching functions and forces of all samples in one batch, every
    contact change of every stretch located in one bisection
    (:func:`~jaxgear._poincare.locate_sign_changes`)."""
    sizes = [len(ts) for ts, _, _ in pieces]
    T_all = np.concatenate([ts for ts, _, _ in pieces])
    X_all = np.concatenate([xs for _, xs, _ in pieces])
    n_all = len(T_all)
    rows = power_of_two_at_least(n_all, 256)
    Tp, Xp = jnp.asarray(pad_rows(T_all, rows)), jnp.asarray(pad_rows(X_all, rows))
    S_all = np.asarray(_switching_at(system, params, Tp, Xp))[:n_all]
    if not np.all(np.isfinite(S_all)):
        raise ValueError(f"{system.name}: the trajectory from the attractor's point is not finite (it blew up); "
                         "check the attractor and the parameters.")
    F_all = None if layout.forces is None else np.asarray(layout.forces(params, Tp, Xp))[:n_all]
    used = sorted({i for p in layout.pairs for i in p})
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    found = []  # per piece: (global sample index, function) of each contact change
    for a, b in zip(offsets[:-1], offsets[1:]):
        pos = S_all[a:b] > 0
        change = pos[1:] != pos[:-1]
        j_idx, w_idx = np.nonzero(change[:, used])
        found.append((a + j_idx, np.asarray(used, dtype=np.int64)[w_idx]))
    jj = np.concatenate([j for j, _ in found])
    ww = np.concatenate([w for _, w in found])
    tau_all = np.zeros(0)
    if len(jj):
        n = len(jj)
        size = power_of_two_at_least(n, SMALL_BATCH)  # the section points' shapes: one bisection program
        jp, wp = pad_rows(jj, size), pad_rows(ww, size)
        H = T_all[jp + 1] - T_all[jp]
        tau_all = np.asarray(locate_sign_changes(system, stepper, n_iter, params, jnp.asarray(T_all[jp]),
                                                 jnp.asarray(X_all[jp]).T, jnp.asarray(H),
                                                 jnp.asarray(wp.astype(np.int32)), jnp.asarray(S_all[jp, wp] > 0))[0])[:n]
    drive_i = np.array([p[0] for p in layout.pairs])
    back_i = np.array([p[1] for p in layout.pairs])
    out, first = [], 0
    for (ts, _, periods), (a, b), (j_glob, w_idx) in zip(pieces, zip(offsets[:-1], offsets[1:]), found):
        S = S_all[a:b]
        tau = tau_all[first:first + len(j_glob)]
        first += len(j_glob)
        j_idx = j_glob - a
        H = np.diff(ts)
        pos = S > 0
        change = pos[1:] != pos[:-1]
        # time on the positive side of every used function: whole intervals, corrected where it changes
        positive_time = np.sum(np.where(pos[:-1] & ~change, H[:, None], 0.0), axis=0)
        np.add.at(positive_time, w_idx, np.where(pos[j_idx, w_idx], tau, H[j_idx] - tau))
        falls = np.zeros(S.shape[1])
        np.add.at(falls, w_idx, pos[j_idx, w_idx].astype(float))
        duration = float(ts[-1] - ts[0])
        te = 0.5 * (S[:, drive_i] + S[:, back_i])
        force = force_end = None
        if F_all is not None:
            F = F_all[a:b]
            force, force_end = F[:-1], F[-1]
        out.append(_Stretch(drive=positive_time[drive_i], back=duration - positive_time[back_i],
                            losses=falls[drive_i], impacts=falls[back_i], duration=duration, periods=periods,
                            te=te[:-1], te_end=te[-1], force=force, force_end=force_end))
    return out


def _extreme(y: np.ndarray, periodic: bool, sign: float) -> np.ndarray:
    """Largest (``sign=1``) or smallest (``-1``) value of each column of samples ``y (m, n)``,
    refined by the parabola through the extreme sample and its neighbours (wrapping round
    for a periodic signal)."""
    z = sign * y
    m = len(z)
    j = np.argmax(z, axis=0)
    cols = np.arange(z.shape[1])
    if periodic:
        a, b = z[(j - 1) % m, cols], z[(j + 1) % m, cols]
        inside = np.ones_like(j, dtype=bool)
    else:
        a, b = z[np.clip(j - 1, 0, m - 1), cols], z[np.clip(j + 1, 0, m - 1), cols]
        inside = (j > 0) & (j < m - 1)
    c = z[j, cols]
    curv = a - 2 * c + b
    ok = inside & (curv < 0)
    refined = c - np.where(ok, (b - a) ** 2 / (8 * np.where(ok, curv, -1.0)), 0.0)
    return sign * refined


def _spectrum(te: np.ndarray, k: int, s: int, max_order: float, window: bool):
    """One-sided amplitude spectrum of samples ``te (k s, n)`` covering ``k`` forcing periods:
    orders ``j / k`` of the forcing frequency up to ``max_order``; ``window``: a Hann window
    (an aperiodic stretch), none for exactly ``k`` periods of a P-k (exact harmonics)."""
    n_s = te.shape[0]
    if window:
        w = np.hanning(n_s + 1)[:-1]
        mean = np.mean(te, axis=0)
        X = np.fft.rfft((te - mean) * w[:, None], axis=0) * (2.0 / np.sum(w))
        X[0] = mean
    else:
        X = np.fft.rfft(te, axis=0) / n_s
        X[1:] *= 2.0
        if n_s % 2 == 0:
            X[-1] /= 2.0  # the Nyquist bin is not doubled
    orders = np.arange(X.shape[0]) / k
    keep = orders <= max_order + 1e-12
    return orders[keep], np.abs(X[keep])


# ----------------------------------------------------------------------- the view
def gear_view(system: ForcedSystem, params, attractor: Attractor, gear_set: GearSet | None = None, *,
              meshes: MeshSpec | None = None, options: GearViewOptions | None = None, **changes) -> GearView:
    """Contact states, dynamic transmission error, mesh forces and spectra of every mesh
    over one attractor (see the module; model document §2.2-§2.4).

    A P-k attractor (``attractor.period = k >= 1``) is sampled over exactly its ``k``
    forcing periods, one period from each of its stroboscopic points (phase 0); an
    aperiodic one (period 0) over ``stretches x stretch_periods`` periods from the first
    point of its cloud. For every mesh the times of drive-flank contact, gap and
    back-flank contact are summed between contact changes located by bisection inside
    their sample intervals, and contact losses and back-flank impacts are counted.

    Args:
        system: a :class:`~jaxgear.ForcedSystem` with switching functions (the gear models,
            or a user system declaring a pair ``X - b, X + b`` per mesh).
        params: its parameters (:class:`~jaxgear.GearParams` for the gear models).
        attractor: a :class:`~jaxgear.Attractor` of a :class:`~jaxgear.GlobalResult` of this
            system and these parameters (``result.attractors[i]``).
        gear_set: the :class:`~jaxgear.GearSet` the dimensionless gear parameters come
            from: transmission errors in µm (``b_c``), forces in N (``k_msp b_c``),
            frequencies in Hz (``Omega omega_n / 2 pi``); ``None``: dimensionless.
        meshes: a :class:`MeshSpec` (which switching functions are meshes, their names and
            force); ``None``: the gear models' meshes, consecutive pairs for another system.
        options: a :class:`GearViewOptions`; ``**changes``: fields of it to change.

    Returns:
        a :class:`GearView`. Every argument is checked before any integration
        (``ValueError`` naming it). :func:`gear_views` does several attractors at once.
    """
    return gear_views(system, params, [attractor], gear_set, meshes=meshes, options=options, **changes)[0]


def gear_views(system: ForcedSystem, params, attractors, gear_set: GearSet | None = None, *,
               meshes: MeshSpec | None = None, options: GearViewOptions | None = None,
               **changes) -> list[GearView]:
    """:func:`gear_view` of every attractor of ``attractors`` (a sequence of
    :class:`~jaxgear.Attractor`, e.g. ``result.attractors``), in one batch: the samples of
    all cycles in one integration, of all aperiodic attractors in one per stretch, and
    every contact change in one bisection, so a process compiles each program once
    whatever the attractors' periods. Returns one :class:`GearView` per attractor, in
    order; each equals :func:`gear_view` of that attractor alone to round-off."""
    opts = with_changes(options, GearViewOptions, changes)
    if not isinstance(system, ForcedSystem):
        raise ValueError(f"system={system!r} must be a jaxgear.ForcedSystem.")
    attractors = list(attractors)
    if not attractors:
        return []
    ks = [_check_attractor(system, a) for a in attractors]
    if gear_set is not None:
        if not isinstance(gear_set, GearSet):
            raise ValueError(f"gear_set={type(gear_set).__name__} must be a jaxgear.GearSet or None.")
        if not isinstance(params, GearParams):
            raise ValueError("gear_set: physical units need the gear models' GearParams; this system's parameters "
                             f"are {type(params).__name__} (leave gear_set=None).")
    first = np.asarray(attractors[0].points, dtype=float)[0]
    check_system(system, params, first, batched=False)
    layout = _layout(system, params, first, meshes)
    s = int(opts.samples_per_period)
    integrator = opts.integrator or KinkAwareRK4(s)
    starts = [_start(system, params, a, k, opts, integrator) for a, k in zip(attractors, ks)]
    pieces: list[list[tuple[np.ndarray, np.ndarray, int]]] = [[] for _ in attractors]
    cyc = [i for i, k in enumerate(ks) if k > 0]
    if cyc:
        # one period from every point of every cycle, one batch; a cycle's stretch is its k
        # periods end to end (each ends on the next point to the cycle's residual)
        X = np.concatenate([starts[i] for i in cyc])
        if integrator.crossing_stepper is integrator and int(integrator.steps_per_period) == s:
            ts, xs, _ = one_period(system, params, X, integrator)  # one sample per step: the analysis's program
        else:
            ts, xs = sample_trajectory(system, params, _small_batch(X), periods=1,
                                       samples_per_period=s, integrator=integrator)
            ts, xs = np.asarray(ts), np.asarray(xs)
        T = float(ts[-1] - ts[0])
        row = 0
        for i in cyc:
            k = ks[i]
            t = np.concatenate([ts[:-1] + j * T for j in range(k)] + [ts[-1:] + (k - 1) * T])
            x = np.concatenate([xs[row + j, :-1] for j in range(k)] + [xs[row + k - 1, -1:]])
            pieces[i].append((t, x, k))
            row += k
    aper = [i for i, k in enumerate(ks) if k == 0]
    if aper:
        X = np.stack([starts[i][0] for i in aper])
        for _ in range(opts.stretches):
            ts, xs = sample_trajectory(system, params, _small_batch(X), periods=opts.stretch_periods,
                                       samples_per_period=s, integrator=integrator)
            ts, xs = np.asarray(ts), np.asarray(xs)
            for r, i in enumerate(aper):
                pieces[i].append((ts, xs[r], opts.stretch_periods))
            X = xs[: len(aper), -1]
    flat = [p for ps in pieces for p in ps]
    parts = _stretches(system, params, layout, integrator.crossing_stepper, opts.bisections, flat)
    length_unit, force_unit, length_scale, force_scale, hz = _units(system, params, gear_set)
    views, at = [], 0
    for a, k, start, ps in zip(attractors, ks, starts, pieces):
        mine = parts[at:at + len(ps)]
        at += len(ps)
        meshes_ = _mesh_views(layout, mine, periodic=k > 0, k=k if k > 0 else opts.stretch_periods, s=s, opts=opts,
                              scales=_scales(gear_set, params))
        views.append(GearView(
            attractor_id=int(a.id), label=a.label, period=k, meshes=meshes_, start=np.asarray(start[0]),
            periods_covered=sum(p.periods for p in mine), stretches=len(mine), samples_per_period=s,
            length_unit=length_unit, force_unit=force_unit, length_scale=length_scale, force_scale=force_scale,
            mesh_frequency_hz=hz if gear_set is not None else float("nan"), integrator=integrator,
            system=system.name, params=params_to_dict(params), version=__version__))
    return views


def _check_attractor(system: ForcedSystem, attractor) -> int:
    """The attractor's period ``k`` after checking its type and points."""
    if not isinstance(attractor, Attractor):
        raise ValueError(f"attractor={type(attractor).__name__} must be a jaxgear.Attractor "
                         "(an item of GlobalResult.attractors).")
    points = np.asarray(attractor.points, dtype=float)
    if points.ndim != 2 or points.shape[0] < 1 or points.shape[1] != system.dim:
        raise ValueError(f"attractor: its points have shape {points.shape}; the gear view needs at least one point "
                         f"of the {system.dim} coordinates of {system.name}.")
    if not np.all(np.isfinite(points[0])):
        raise ValueError("attractor: its first point is not finite.")
    return check_int(attractor.period, "attractor.period", 0)


def _start(system, params, attractor, k: int, opts: GearViewOptions, integrator) -> np.ndarray:
    """Where the sampling starts: ``(k, dim)`` the cycle's points for a P-k (after
    ``opts.transient`` periods, rounded up to a multiple of ``k``; the iterates of the
    first point where the attractor holds fewer than ``k`` finite points), ``(1, dim)`` a
    point of the cloud for an aperiodic attractor."""
    points = np.asarray(attractor.points, dtype=float)
    x = points[0]
    if k == 0 and not opts.transient:
        return x[None]
    if k > 0 and not opts.transient and len(points) == k and np.all(np.isfinite(points)):
        return points
    skip = opts.transient if k == 0 else -(-opts.transient // k) * k
    if skip:
        x = stroboscopic_map(system, params, jnp.asarray(x), periods=skip, integrator=integrator)
    if k == 0:
        return np.asarray(x)[None]
    rest = stroboscopic_orbit(system, params, x, n_points=k - 1, integrator=integrator) if k > 1 else None
    return np.concatenate([np.asarray(x)[None]] + ([] if rest is None else [np.asarray(rest)]))


def _scales(gear_set, params) -> tuple[float, float]:
    """(length, force) unit values of the dimensionless gear model in µm and N."""
    if gear_set is None:
        return 1.0, 1.0
    k_ref = float(np.ravel(np.asarray(gear_set.k_sp_mean, dtype=float))[0])
    return float(gear_set.b_c), k_ref * float(gear_set.b_c) * 1e-6


def _units(system, params, gear_set):
    if gear_set is not None:
        length, force = _scales(gear_set, params)
        omega_n = gear_set.derived()["omega_n"]
        return "um", "N", length, force, float(np.asarray(params.Omega)) * omega_n / (2 * math.pi)
    if isinstance(params, GearParams):
        return "b_c", "k_msp b_c", 1.0, 1.0, float("nan")
    return "state unit", "force unit", 1.0, 1.0, float("nan")


def _mean_error(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over the stretches (axis 0) and its standard error (0 for one stretch)."""
    n = values.shape[0]
    mean = np.mean(values, axis=0)
    if n < 2:
        return mean, np.zeros_like(mean)
    return mean, np.std(values, axis=0, ddof=1) / np.sqrt(n)


def _samples_and_range(stretches, periodic: bool, scale):
    """The samples of every stretch ``(samples, end sample)`` together, times ``scale``, and
    their largest and smallest values per mesh (a closed orbit's samples wrap round; an
    open stretch's end sample closes it)."""
    every = np.concatenate([v for v, _ in stretches]) * scale
    if periodic:
        return every, _extreme(every, True, 1.0), _extreme(every, True, -1.0)
    full = [np.concatenate([v, end[None]]) * scale for v, end in stretches]
    return (every, np.max([_extreme(f, False, 1.0) for f in full], axis=0),
            np.min([_extreme(f, False, -1.0) for f in full], axis=0))


def _mesh_views(layout: _Layout, parts: list[_Stretch], *, periodic: bool, k: int, s: int, opts: GearViewOptions,
                scales) -> tuple[MeshView, ...]:
    length, force_scale = scales
    drive, drive_e = _mean_error(np.array([p.drive / p.duration for p in parts]))
    back, back_e = _mean_error(np.array([p.back / p.duration for p in parts]))
    gap, gap_e = _mean_error(np.array([(p.duration - p.drive - p.back) / p.duration for p in parts]))
    losses, losses_e = _mean_error(np.array([p.losses / p.periods for p in parts]))
    impacts, impacts_e = _mean_error(np.array([p.impacts / p.periods for p in parts]))
    te_all, te_hi, te_lo = _samples_and_range([(p.te, p.te_end) for p in parts], periodic, length)
    te_mean = np.mean(te_all, axis=0)
    te_rms = np.sqrt(np.mean((te_all - te_mean) ** 2, axis=0))
    n = len(layout.pairs)
    if parts[0].force is not None:
        f_all, f_hi, f_lo = _samples_and_range([(p.force, p.force_end) for p in parts], periodic, force_scale)
        f_mean = np.mean(f_all, axis=0)
    else:
        f_hi = f_lo = f_mean = np.full(n, np.nan)
    static = layout.static * force_scale
    if periodic:
        orders, amps = _spectrum(parts[0].te * length, k, s, opts.max_order, window=False)
    else:
        spectra = [_spectrum(p.te * length, k, s, opts.max_order, window=True) for p in parts]
        orders = spectra[0][0]
        amps = np.sqrt(np.mean([a ** 2 for _, a in spectra], axis=0))
    out = []
    for i, name in enumerate(layout.names):
        # the contact state changes only through a fall through b or -b (a contact loss or a
        # back-flank impact): without either it holds one state throughout
        regime = (ContactRegime.DOUBLE_SIDED if impacts[i] > 0 else
                  ContactRegime.SINGLE_SIDED if losses[i] > 0 else ContactRegime.NO_IMPACT)
        out.append(MeshView(
            name=name, regime=regime, drive_share=float(drive[i]), gap_share=float(gap[i]),
            back_share=float(back[i]), drive_share_error=float(drive_e[i]), gap_share_error=float(gap_e[i]),
            back_share_error=float(back_e[i]), losses_per_period=float(losses[i]), losses_error=float(losses_e[i]),
            impacts_per_period=float(impacts[i]), impacts_error=float(impacts_e[i]), te_mean=float(te_mean[i]),
            te_rms=float(te_rms[i]), te_ptp=float(te_hi[i] - te_lo[i]), force_mean=float(f_mean[i]),
            force_max=float(f_hi[i]), force_min=float(f_lo[i]), static_force=float(static[i]),
            dynamic_factor=float(f_hi[i] / static[i]) if np.isfinite(static[i]) else float("nan"),
            orders=np.asarray(orders, dtype=float), amplitudes=np.asarray(amps[:, i], dtype=float)))
    return tuple(out)


# ----------------------------------------------------------------------- across a sweep
@dataclasses.dataclass(frozen=True, kw_only=True)
class RegimeShares:
    """Result of :func:`regime_shares` for a basin sweep: at every value, the share of the
    state space (of the grid's cells) whose motion is in each contact regime, mesh by mesh.

    Attributes:
        param: the swept parameter; values: ``(V,)`` its values; label: its axis label
            (with the unit of a physical sweep, ``"b [µm, half]"``).
        meshes: the meshes' names.
        shares: ``(V, n_meshes, 3)`` the share of the cells whose attractor's mesh is in
            regime ``r`` (:class:`ContactRegime` order: no impact, single-sided,
            double-sided); with ``no_attractor`` each value's shares of one mesh add to 1.
        no_attractor: ``(V,)`` the share of the cells on no attractor (sink, unresolved).
    """

    param: str
    values: np.ndarray
    meshes: tuple[str, ...]
    shares: np.ndarray
    no_attractor: np.ndarray
    label: str = ""

    def share(self, mesh: str, regime: ContactRegime) -> np.ndarray:
        """``(V,)`` the share of the cells in ``regime`` on ``mesh``."""
        return self.shares[..., _mesh_index(self.meshes, mesh), int(ContactRegime(regime))]

    def table(self) -> str:
        """One row per value and mesh: the share in each regime (%)."""
        rows = [(f"{v:.6g}", name, *(f"{100 * s:.2f}" for s in self.shares[i, j]), f"{100 * self.no_attractor[i]:.2f}")
                for i, v in enumerate(self.values) for j, name in enumerate(self.meshes)]
        return format_table(rows, (self.label or self.param, "mesh", *(f"{r.text} %" for r in ContactRegime),
                                   "no attractor %"))

    def summary(self) -> dict[str, Any]:
        """JSON-able description."""
        return dict(param=self.param, label=self.label or self.param, values=np.asarray(self.values).tolist(),
                    meshes=list(self.meshes), regimes=[r.text for r in ContactRegime],
                    shares=np.asarray(self.shares).tolist(), no_attractor=np.asarray(self.no_attractor).tolist())


@dataclasses.dataclass(frozen=True, kw_only=True)
class RegimeMap:
    """Result of :func:`regime_shares` for a basin map (:func:`~jaxgear.basin_map`): at
    every point of the grid of two parameters, the share of the state space in each
    contact regime, mesh by mesh, and the regime of the attractor with the largest basin.

    Attributes:
        param_x, values_x ``(nx,)``, param_y, values_y ``(ny,)``: the parameters;
        label_x, label_y: their axis labels (with units for physical parameters).
        meshes: the meshes' names.
        shares: ``(ny, nx, n_meshes, 3)`` the share of the cells whose attractor's mesh is
            in each regime (:class:`ContactRegime` order); with ``no_attractor`` a point's
            shares of one mesh add to 1.
        no_attractor: ``(ny, nx)`` the share of the cells on no attractor.
        dominant_regime: ``(ny, nx, n_meshes)`` the regime code of the map's
            :attr:`~jaxgear.BasinMap.dominant` attractor on each mesh; -1 where the sink
            or the unresolved cells hold more than any attractor.
    """

    param_x: str
    values_x: np.ndarray
    param_y: str
    values_y: np.ndarray
    label_x: str = ""
    label_y: str = ""
    meshes: tuple[str, ...]
    shares: np.ndarray
    no_attractor: np.ndarray
    dominant_regime: np.ndarray

    def share(self, mesh: str, regime: ContactRegime) -> np.ndarray:
        """``(ny, nx)`` the share of the cells in ``regime`` on ``mesh``."""
        return self.shares[..., _mesh_index(self.meshes, mesh), int(ContactRegime(regime))]

    def table(self) -> str:
        """One row per mesh and regime: at how many points the dominant attractor is in it,
        and the least, mean and largest share of the cells in it over the map (%)."""
        rows = []
        n = self.no_attractor.size
        for j, name in enumerate(self.meshes):
            for r in ContactRegime:
                s = self.shares[..., j, int(r)]
                rows.append((name, r.text, f"{int((self.dominant_regime[..., j] == int(r)).sum())}/{n}",
                             f"{100 * s.min():.1f}", f"{100 * s.mean():.1f}", f"{100 * s.max():.1f}"))
        return format_table(rows, ("mesh", "regime", "dominant at", "min %", "mean %", "max %"))

    def summary(self) -> dict[str, Any]:
        """JSON-able description (arrays as nested lists, ``[iy][ix][mesh][regime]``)."""
        return dict(param_x=self.param_x, label_x=self.label_x or self.param_x,
                    values_x=np.asarray(self.values_x).tolist(), param_y=self.param_y,
                    label_y=self.label_y or self.param_y, values_y=np.asarray(self.values_y).tolist(),
                    meshes=list(self.meshes), regimes=[r.text for r in ContactRegime],
                    shares=np.asarray(self.shares).tolist(), no_attractor=np.asarray(self.no_attractor).tolist(),
                    dominant_regime=np.asarray(self.dominant_regime).tolist())


def _mesh_index(meshes, mesh: str) -> int:
    if mesh not in meshes:
        raise ValueError(f"mesh {mesh!r}: the meshes are {', '.join(meshes)}.")
    return list(meshes).index(mesh)


def regime_shares(sweep, system: ForcedSystem, params, gear_set: GearSet | None = None, *,
                  meshes: MeshSpec | None = None, options: GearViewOptions | None = None,
                  **changes) -> RegimeShares | RegimeMap:
    """The share of the state space whose motion is in each contact regime, for every mesh
    at every value of a basin sweep (:func:`~jaxgear.basin_sweep`: for example the share of
    the starts that end in double-sided impacts against the backlash), or at every point
    of a basin map (:func:`~jaxgear.basin_map`, a :class:`RegimeMap`).

    At each value (point), the :func:`gear_views` of the attractors present there (from
    the result's stroboscopic points: a cycle's points, a point of an aperiodic
    attractor's cloud) give each one's regime per mesh; a regime's share is the sum of the
    shares of its attractors. ``params``: the sweep's base parameters (each value's
    dimensionless fields, ``field_values``, are set on them as the sweep did);
    ``gear_set``, ``meshes``, ``options``: as in :func:`gear_view`. The programs are
    compiled once for all values (the parameters are arguments of them).
    """
    from .sweep import BasinMap, BasinSweep
    from .sweep._values import apply_values

    if isinstance(sweep, BasinSweep):
        names, rows = tuple(sweep.fields), np.asarray(sweep.field_values, dtype=float)
    elif isinstance(sweep, BasinMap):
        names = tuple(sweep.fields_x) + tuple(sweep.fields_y)
        rows = sweep.point_rows().reshape(-1, len(names))
    else:
        raise ValueError(f"sweep={type(sweep).__name__} must be a jaxgear.BasinSweep or jaxgear.BasinMap (from "
                         "jaxgear.basin_sweep or jaxgear.basin_map).")
    lead = np.shape(sweep.sink_share)
    G = sweep.n_attractors
    flat = lambda a: np.asarray(a).reshape(-1, *np.shape(a)[len(lead):])  # noqa: E731
    present, period, points, n_points, kind, share = (flat(a) for a in (
        sweep.present, sweep.period, sweep.points, sweep.n_points, sweep.attractor_type, sweep.shares))
    names_m, regime = None, None  # regime: (n, G, n_meshes) code of each attractor on each mesh, -1 absent
    for i, row in enumerate(rows):
        p = apply_values(params, names, row)
        here = np.flatnonzero(present[i])
        attractors = []
        for g in here:
            pts = np.asarray(points[i, g, : max(int(n_points[i, g]), 1)], dtype=float)
            attractors.append(Attractor(id=int(g), period=int(period[i, g]), points=pts,
                                        section_points=np.zeros((0, pts.shape[1])), kind=int(kind[i, g])))
        views = gear_views(system, p, attractors, gear_set, meshes=meshes, options=options, **changes)
        if regime is None and views:
            names_m = tuple(m.name for m in views[0].meshes)
            regime = np.full((len(rows), G, len(names_m)), -1, dtype=np.int64)
        for g, view in zip(here, views):
            regime[i, g] = [int(m.regime) for m in view.meshes]
    if regime is None:  # no attractor anywhere
        names_m = _layout(system, params, np.zeros(system.dim), meshes).names
        regime = np.full((len(rows), G, len(names_m)), -1, dtype=np.int64)
    onehot = regime[..., None] == np.arange(len(ContactRegime))  # (n, G, M, 3)
    shares = np.einsum("ng,ngmr->nmr", share, onehot.astype(float)).reshape(*lead, len(names_m), len(ContactRegime))
    no_attractor = np.asarray(sweep.sink_share, float) + np.asarray(sweep.unresolved_share, float)
    if isinstance(sweep, BasinSweep):
        return RegimeShares(param=sweep.param, values=np.asarray(sweep.values, dtype=float), meshes=names_m,
                            shares=shares, no_attractor=no_attractor, label=sweep.axis_label)
    dom = np.asarray(sweep.dominant).reshape(-1)
    top = np.where(dom[:, None] >= 0, regime[np.arange(len(dom)), np.maximum(dom, 0)], -1)
    label_x, label_y = sweep.axis_labels
    return RegimeMap(param_x=sweep.param_x, values_x=np.asarray(sweep.values_x, float), param_y=sweep.param_y,
                     values_y=np.asarray(sweep.values_y, float), label_x=label_x, label_y=label_y, meshes=names_m,
                     shares=shares, no_attractor=no_attractor, dominant_regime=top.reshape(*lead, len(names_m)))
