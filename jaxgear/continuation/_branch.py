"""A branch of periodic orbits followed in one parameter, and the bifurcations on it."""

from __future__ import annotations

import dataclasses
import enum
from typing import Any

import numpy as np

from .._codec import array_field, custom_field, items_field, plain, result_type
from .._format import format_table
from .._io import save_result
from .._system import state_index
from ..integrate import AbstractIntegrator, integrator_from_dict
from ..shooting import ShootOptions
from ._options import ContinuationOptions

__all__ = ["Branch", "BranchSettings", "BifurcationPoint", "BifurcationKind", "BranchStatus", "BIFURCATION_KINDS",
           "BRANCH_STATUS"]

class BifurcationKind(enum.StrEnum):
    """What crossed the unit circle at a located bifurcation (:attr:`meaning` says it in
    words). A ``StrEnum``: each member equals its short name (``"PD"``, ...)."""

    PD = "PD"
    SN = "SN"
    BP = "BP"
    NS = "NS"

    @property
    def meaning(self) -> str:
        return {"PD": "period doubling (real multiplier through -1)",
                "SN": "saddle-node / fold (real multiplier through +1, the parameter turns)",
                "BP": "branch point (real multiplier through +1, no fold)",
                "NS": "Neimark-Sacker (complex pair through |lambda| = 1)"}[self.value]


class BranchStatus(enum.StrEnum):
    """Why a continued branch ended (:attr:`meaning` says it in words). A ``StrEnum``: each
    member equals its name in files (``"stop"``, ``"max_steps"``, ...)."""

    STOP = "stop"
    BOUNDS = "bounds"
    MAX_STEPS = "max_steps"
    DIVERGED = "diverged"
    CORRECTOR_FAILED = "corrector_failed"

    @property
    def meaning(self) -> str:
        return {"stop": "reached the stop value of the parameter",
                "bounds": "left the parameter bounds",
                "max_steps": "took max_steps steps",
                "diverged": "the orbit or the flow diverged (||x|| > max_norm or non-finite) at the smallest step",
                "corrector_failed": "the corrector did not converge at the smallest step ds_min"}[self.value]


BIFURCATION_KINDS = {k.value: k.meaning for k in BifurcationKind}
"""``{kind: meaning}`` of :class:`BifurcationKind` (a view for tables)."""
BRANCH_STATUS = {s.value: s.meaning for s in BranchStatus}
"""``{status: meaning}`` of :class:`BranchStatus` (a view for tables)."""


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class BifurcationPoint:
    """A bifurcation located on a branch.

    Attributes:
        kind: a :class:`BifurcationKind` (``PD``, ``SN``, ``BP`` or ``NS``).
        param_value: the parameter at the bifurcation (located to ``locate_tol`` in
            arclength, typically 1e-10).
        point: ``(dim,)`` the orbit's point at phase ``t0`` (fixed point of ``P^k``).
        multipliers: ``(dim,)`` complex Floquet multipliers of ``P^k`` there, by
            decreasing modulus.
        index: the bifurcation lies between branch points ``index`` and ``index + 1``.
        orbit: ``(k, dim)`` the orbit's ``k`` stroboscopic points there (``orbit[0] = point``).
        test_value: the test function's value at the located point (about 0 for a
            smooth crossing).
        nonsmooth: True when the test function jumps across zero instead of crossing
            it (the multiplier jumps over -1 / +1 / the unit circle at a kink of the
            map, e.g. a contact starting or ending at a backlash boundary —
            a discontinuity-induced bifurcation); ``param_value`` is then the jump's
            location and ``multipliers`` those on one side of it.
    """

    kind: BifurcationKind
    param_value: float
    point: np.ndarray = array_field(("state",))
    multipliers: np.ndarray = array_field(("multiplier",), default_factory=lambda: np.zeros(0, complex))
    index: int = 0
    orbit: np.ndarray | None = array_field(("iterate", "state"), default=None)
    test_value: float = 0.0
    nonsmooth: bool = False

    def __repr__(self) -> str:
        lam = ", ".join(_fmt_complex(z) for z in np.asarray(self.multipliers))
        ns = ", nonsmooth" if self.nonsmooth else ""
        return f"BifurcationPoint({self.kind} at {self.param_value:.10g}{ns}, multipliers [{lam}])"


def _fmt_complex(z) -> str:
    z = complex(z)
    if abs(z.imag) <= 1e-12 * max(1.0, abs(z)):
        return f"{z.real:.6g}"
    return f"{z.real:.6g}{z.imag:+.6g}j"


@dataclasses.dataclass(frozen=True, kw_only=True)
class BranchSettings:
    """What a branch was followed with (:func:`continue_orbit`, :func:`switch_branch`).

    Attributes:
        options: the :class:`ContinuationOptions` (steps, bounds, bifurcation search).
        shoot: the corrector's :class:`~jaxgear.ShootOptions` (``tol``, ``max_iter``,
            ``max_norm``; the starting orbit was converged with them too).
        stop: the parameter value where the branch was to end (None: no target).
        t0: forcing phase (time) of the stroboscopic points.
        integrator: the integrator.
        origin: ``"start"`` or the period-doubling point the branch was switched from.
        amplitude: distance from that point to the branch's first orbit (None for ``"start"``).
    """

    options: ContinuationOptions
    shoot: ShootOptions
    stop: float | None = None
    t0: float
    integrator: AbstractIntegrator = custom_field(lambda i: i.to_dict(), integrator_from_dict)
    origin: str = "start"
    amplitude: float | None = None


@result_type
@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Branch:
    """A branch of P-k orbits followed in one parameter (:func:`continue_orbit`).

    Attributes:
        param: the parameter's name (as given, e.g. ``"Omega"`` or the alias ``"b"``).
        values: ``(m,)`` parameter value at each point of the branch, in order of arclength.
        points: ``(m, k, dim)`` the ``k`` stroboscopic points ``x*, P(x*), ..., P^{k-1}(x*)``
            of each orbit (state at phases ``t0 + jT``).
        multipliers: ``(m, dim)`` complex Floquet multipliers of ``P^k`` (by decreasing modulus).
        stable: ``(m,)`` bool, all ``|multiplier| < 1``.
        residuals: ``(m,)`` ``||P^k(x*) - x*||`` at each point.
        tangents: ``(m, dim + 1)`` unit tangent ``(dx, dp)`` of the branch at each point.
        arclength: ``(m,)`` cumulative arclength in ``(x, p)``.
        status: why the branch ended (a :class:`BranchStatus`).
        bifurcations: the located :class:`BifurcationPoint` s, in order along the branch.
        period: ``k`` (forcing periods per return of the continued map).
        system: the system's name; state_names: its coordinate names.
        params: the parameter set at the start of the branch (dict of the pytree).
        settings: a :class:`BranchSettings` (the continuation and corrector options,
            integrator, ``t0``, origin).
    """

    param: str
    values: np.ndarray = array_field(("point",))
    points: np.ndarray = array_field(("point", "iterate", "state"))
    multipliers: np.ndarray = array_field(("point", "multiplier"))
    stable: np.ndarray = array_field(("point",))
    residuals: np.ndarray = array_field(("point",))
    tangents: np.ndarray = array_field(("point", "tangent_component"))
    arclength: np.ndarray = array_field(("point",))
    status: BranchStatus = BranchStatus.STOP
    bifurcations: tuple[BifurcationPoint, ...] = items_field("bifurcation", default=())
    period: int = 1
    system: str = ""
    state_names: tuple[str, ...] = ()
    params: dict = dataclasses.field(default_factory=dict)
    settings: BranchSettings
    version: str = ""

    # ----------------------------------------------------------------- views
    def __len__(self) -> int:
        return int(len(self.values))

    @property
    def max_multiplier(self) -> np.ndarray:
        """``(m,)`` largest Floquet multiplier modulus at each point."""
        return np.max(np.abs(self.multipliers), axis=-1)

    def coordinate(self, name: str | int = 0) -> np.ndarray:
        """``(m, k)`` one coordinate (name or index) of the stroboscopic points."""
        return self.points[:, :, state_index(self.state_names, name)]

    def amplitude(self) -> np.ndarray:
        """``(m,)`` largest Euclidean norm of the stroboscopic points of each orbit."""
        return np.max(np.linalg.norm(self.points, axis=-1), axis=-1)

    def __repr__(self) -> str:
        bifs = ", ".join(f"{b.kind}@{b.param_value:.6g}" for b in self.bifurcations) or "none"
        rng = f"{self.values.min():.6g}..{self.values.max():.6g}" if len(self) else "empty"
        return (f"Branch(P-{self.period} of {self.system}, {self.param} in {rng}, {len(self)} points, "
                f"status={self.status}, bifurcations: {bifs})")

    def summary(self) -> dict[str, Any]:
        """JSON-able summary: range, counts, stability changes, bifurcations."""
        return dict(
            system=self.system, param=self.param, period=int(self.period), n_points=len(self),
            param_start=float(self.values[0]) if len(self) else None,
            param_end=float(self.values[-1]) if len(self) else None,
            param_min=float(self.values.min()) if len(self) else None,
            param_max=float(self.values.max()) if len(self) else None,
            n_stable=int(np.sum(self.stable)), status=self.status, status_text=BranchStatus(self.status).meaning,
            max_residual=float(np.max(self.residuals)) if len(self) else None,
            bifurcations=[dict(kind=b.kind, param_value=float(b.param_value), point=np.asarray(b.point).tolist(),
                               multipliers=[[float(z.real), float(z.imag)] for z in np.asarray(b.multipliers)],
                               index=int(b.index), nonsmooth=bool(b.nonsmooth)) for b in self.bifurcations],
            settings=plain(self.settings), params=self.params, version=self.version,
        )

    def table(self, max_rows: int = 30) -> str:
        """Readable text: the branch (at most ``max_rows`` rows, evenly spread, plus the
        rows around each bifurcation) and the list of bifurcations."""
        m = len(self)
        names = self.state_names
        head = (f"P-{self.period} branch of {self.system} in {self.param}: {m} points, "
                f"{self.param} {self.values.min():.6g} .. {self.values.max():.6g}, "
                f"status: {self.status} ({BranchStatus(self.status).meaning})") if m else "empty branch"
        if m == 0:
            return head
        rows_idx = set(np.unique(np.linspace(0, m - 1, min(m, max(2, int(max_rows)))).round().astype(int)).tolist())
        for b in self.bifurcations:
            rows_idx.update({b.index, min(b.index + 1, m - 1)})
        rows = []
        marks = {}
        for b in self.bifurcations:
            marks.setdefault(b.index, []).append(b.kind)
        for i in sorted(rows_idx):
            rows.append([str(i), f"{self.values[i]:.8g}"] + [f"{v:.6g}" for v in self.points[i, 0]]
                        + [f"{self.max_multiplier[i]:.6g}", "yes" if self.stable[i] else "no",
                           f"{self.residuals[i]:.1e}", " ".join(f"{k}->" for k in marks.get(i, []))])
        header = ["i", self.param] + list(names) + ["max|lambda|", "stable", "residual", "next"]
        out = [head, format_table(rows, header)]
        if self.bifurcations:
            brows = [[b.kind + (" (nonsmooth)" if b.nonsmooth else ""), f"{b.param_value:.10g}"] + [f"{v:.6g}" for v in np.asarray(b.point)]
                     + [", ".join(_fmt_complex(z) for z in np.asarray(b.multipliers))]
                     for b in self.bifurcations]
            out.append("bifurcations:")
            out.append(format_table(brows, ["kind", self.param] + list(names) + ["multipliers"]))
        else:
            out.append("bifurcations: none detected")
        return "\n".join(out)

    # ----------------------------------------------------------------- I/O
    def _coords(self) -> dict:
        coords = {"state": ("state", list(self.state_names)),
                  "tangent_component": ("tangent_component", list(self.state_names) + [self.param])}
        if self.param not in coords and self.param not in ("point", "iterate", "multiplier", "bifurcation"):
            coords[self.param] = ("point", np.asarray(self.values))
        return coords

    def _attrs(self) -> dict:
        return dict(title="jaxgear branch of periodic orbits (continuation)")

    def save(self, path):
        """Write the branch to a netCDF file atomically; reload with :func:`jaxgear.load`."""
        return save_result(self, path)


def bifurcation_orbit(b: BifurcationPoint, k: int) -> np.ndarray:
    if b.orbit is not None:
        return np.asarray(b.orbit, dtype=float)
    return np.broadcast_to(np.asarray(b.point, dtype=float), (k, len(b.point)))





