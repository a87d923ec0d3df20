"""Gear-set parameters: physical description, canonical dimensionless set, presets.

The dimensionless set :class:`GearParams` uses the names of MODEL.md §4 (the reduced
2-DOF model of paper §4.1 and the N-planet model of paper eq. 5). A physical
description :class:`GearSet` (teeth, module, N/m, µm, N·m, rpm) converts to it with
:meth:`GearSet.to_params` following MODEL.md §2-§3. :func:`paper_gear_set` is the
paper's §4.1 gear set with every missing value documented (MODEL.md §6-§7).
"""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Any, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "GearParams",
    "GearSet",
    "PARAM_NAMES",
    "PER_PLANET_NAMES",
    "paper_gear_set",
    "PRESETS",
    "get_preset",
    "resolve_params",
    "format_table",
    "PARAM_ALIASES",
    "param_names",
    "with_param",
    "get_param",
]

# Canonical dimensionless names (MODEL.md §4), in the order they are written out.
PARAM_NAMES = (
    "N", "mu_s", "mu_p", "mu_c",
    "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp",
    "phi_sp", "phi_rp",
    "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr",
    "b_sp", "b_rp", "c_sp", "c_rp",
    "f_D", "f_L", "Omega",
)
# Names that may hold one value per planet (arrays of length N).
PER_PLANET_NAMES = (
    "mu_p", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp",
    "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr",
    "b_sp", "b_rp", "c_sp", "c_rp",
)
PARAM_MEANINGS = {
    "N": "number of planets",
    "mu_s": "m_eq1/m_s",
    "mu_p": "m_eq1/m_p",
    "mu_c": "m_eq1/m_c",
    "kappa_sp_mean": "k_msp/k_msp1 (sun-planet mean stiffness)",
    "kappa_sp_amp": "k_asp/k_msp1 (sun-planet stiffness amplitude)",
    "kappa_rp_mean": "k_mrp/k_msp1 (ring-planet mean stiffness)",
    "kappa_rp_amp": "k_arp/k_msp1 (ring-planet stiffness amplitude)",
    "phi_sp": "sun-planet stiffness phase [rad]",
    "phi_rp": "ring-planet stiffness phase [rad]",
    "e_sp_amp": "e_asp/b_c (sun-planet error amplitude)",
    "e_rp_amp": "e_arp/b_c (ring-planet error amplitude)",
    "beta_sp": "sun-planet error phase [rad]",
    "beta_rp": "ring-planet error phase [rad]",
    "gamma_sr": "sun-ring error phase [rad]",
    "b_sp": "sun-planet half backlash / b_c",
    "b_rp": "ring-planet half backlash / b_c",
    "c_sp": "c_sp/(m_eq1 omega_n)",
    "c_rp": "c_rp/(m_eq1 omega_n)",
    "f_D": "F_D/(k_msp1 b_c) (driving force)",
    "f_L": "F_L/(k_msp1 b_c) (load force)",
    "Omega": "omega/omega_n (mesh frequency)",
}


def _f64(x):
    return jnp.asarray(x, dtype=jnp.float64)


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _require(cond: bool, name: str, value, allowed: str) -> None:
    if not cond:
        raise ValueError(f"parameter {name}={_fmt_value(value)} is out of range: {allowed}.")


def _fmt_value(v) -> str:
    a = np.asarray(v)
    if a.ndim == 0:
        return f"{float(a):.6g}"
    return "[" + ", ".join(f"{float(t):.6g}" for t in a.ravel()) + "]"


class GearParams(eqx.Module):
    """Canonical dimensionless parameters of the planetary set (MODEL.md §4).

    All fields but ``N`` are float64 arrays, so ``jit``/``vmap``/``grad`` apply and a
    change of value never recompiles. Per-mesh fields (``PER_PLANET_NAMES``) may be
    scalars (identical planets) or arrays of shape ``(N,)``. Checked at construction
    when values are concrete: masses positive, ``mu_s + mu_c = 1``, stiffness positive
    and never negative in time (``|kappa_amp| <= kappa_mean``), backlash and damping
    non-negative, everything finite, ``Omega > 0``.
    """

    N: int = eqx.field(static=True)
    mu_s: Any = eqx.field(converter=_f64)
    mu_p: Any = eqx.field(converter=_f64)
    mu_c: Any = eqx.field(converter=_f64)
    kappa_sp_mean: Any = eqx.field(converter=_f64)
    kappa_sp_amp: Any = eqx.field(converter=_f64)
    kappa_rp_mean: Any = eqx.field(converter=_f64)
    kappa_rp_amp: Any = eqx.field(converter=_f64)
    phi_sp: Any = eqx.field(converter=_f64)
    phi_rp: Any = eqx.field(converter=_f64)
    e_sp_amp: Any = eqx.field(converter=_f64)
    e_rp_amp: Any = eqx.field(converter=_f64)
    beta_sp: Any = eqx.field(converter=_f64)
    beta_rp: Any = eqx.field(converter=_f64)
    gamma_sr: Any = eqx.field(converter=_f64)
    b_sp: Any = eqx.field(converter=_f64)
    b_rp: Any = eqx.field(converter=_f64)
    c_sp: Any = eqx.field(converter=_f64)
    c_rp: Any = eqx.field(converter=_f64)
    f_D: Any = eqx.field(converter=_f64)
    f_L: Any = eqx.field(converter=_f64)
    Omega: Any = eqx.field(converter=_f64)

    def __check_init__(self):
        if not isinstance(self.N, (int, np.integer)) or self.N < 1:
            raise ValueError(f"parameter N={self.N} is out of range: the number of planets must be an integer >= 1.")
        leaves = {n: getattr(self, n) for n in PARAM_NAMES if n != "N"}
        if not all(_is_concrete(v) for v in leaves.values()):
            return  # traced values (inside jit/vmap/grad): checked when built concretely
        for name, v in leaves.items():
            a = np.asarray(v)
            _require(bool(np.all(np.isfinite(a))), name, a, "must be finite (no NaN or inf)")
            if name in PER_PLANET_NAMES:
                _require(a.ndim == 0 or a.shape[-1:] == (self.N,) or a.ndim > 1, name, a,
                         f"a scalar or one value per planet (shape ({self.N},))")
            elif a.ndim > 1:
                pass  # batched for a sweep
        pos = lambda n: _require(bool(np.all(np.asarray(leaves[n]) > 0)), n, leaves[n], "must be > 0")
        nonneg = lambda n: _require(bool(np.all(np.asarray(leaves[n]) >= 0)), n, leaves[n], "must be >= 0")
        for n in ("mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_rp_mean", "Omega"):
            pos(n)
        for n in ("b_sp", "b_rp", "c_sp", "c_rp", "e_sp_amp", "e_rp_amp"):
            nonneg(n)
        s = np.asarray(leaves["mu_s"]) + np.asarray(leaves["mu_c"])
        _require(bool(np.all(np.abs(s - 1.0) < 1e-9)), "mu_s + mu_c", s,
                 "must equal 1 (mu_s = m_eq1/m_s, mu_c = m_eq1/m_c with 1/m_eq1 = 1/m_s + 1/m_c)")
        for mesh in ("sp", "rp"):
            mean = np.asarray(leaves[f"kappa_{mesh}_mean"])
            amp = np.asarray(leaves[f"kappa_{mesh}_amp"])
            _require(bool(np.all(np.abs(amp) <= mean)), f"kappa_{mesh}_amp", amp,
                     f"|kappa_{mesh}_amp| must not exceed kappa_{mesh}_mean={_fmt_value(mean)}, "
                     "else the mesh stiffness becomes negative")

    # ----------------------------------------------------------------- helpers
    @property
    def period(self):
        """Forcing period ``T = 2 pi / Omega`` in dimensionless time."""
        return 2.0 * jnp.pi / self.Omega

    @property
    def is_uniform(self) -> bool:
        """True when every per-planet field holds identical values (reduced model valid)."""
        for n in PER_PLANET_NAMES:
            a = np.asarray(getattr(self, n))
            if a.ndim and not np.allclose(a, a.reshape(-1)[0], rtol=0, atol=0):
                return False
        return True

    def replace(self, **changes) -> "GearParams":
        """A copy with some canonical names changed (validated again)."""
        d = self.to_dict()
        unknown = set(changes) - set(PARAM_NAMES)
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {', '.join(PARAM_NAMES)}")
        d.update(changes)
        return GearParams.from_dict(d)

    def to_dict(self) -> dict[str, Any]:
        """Canonical names -> Python floats (or lists for per-planet arrays)."""
        out: dict[str, Any] = {"N": int(self.N)}
        for n in PARAM_NAMES[1:]:
            a = np.asarray(getattr(self, n))
            out[n] = float(a) if a.ndim == 0 else a.tolist()
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "GearParams":
        """Build from a mapping with the canonical names (all required)."""
        missing = [n for n in PARAM_NAMES if n not in d]
        if missing:
            raise ValueError(f"missing parameter(s): {', '.join(missing)}")
        unknown = set(d) - set(PARAM_NAMES)
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {', '.join(PARAM_NAMES)}")
        return cls(**{n: (int(d[n]) if n == "N" else d[n]) for n in PARAM_NAMES})

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    def uniform(self) -> "GearParams":
        """The same parameters with per-planet arrays collapsed to scalars.

        Raises ``ValueError`` if the planets are not identical (the reduced model of
        paper §4.1 needs identical meshes).
        """
        if not self.is_uniform:
            raise ValueError(
                "the reduced 2-DOF model needs identical planets and meshes; these parameters "
                "have per-planet differences: use the N-planet model (jaxgear.nplanet_system)."
            )
        d = self.to_dict()
        for n in PER_PLANET_NAMES:
            a = np.asarray(d[n])
            d[n] = float(a.reshape(-1)[0])
        return GearParams.from_dict(d)

    def table(self) -> str:
        """A readable table of the dimensionless set."""
        rows = [(n, _fmt_value(getattr(self, n)) if n != "N" else str(self.N), PARAM_MEANINGS[n])
                for n in PARAM_NAMES]
        return format_table(rows, ("name", "value", "meaning"))


# --------------------------------------------------------------------------- physical
@dataclasses.dataclass(frozen=True)
class GearSet:
    """A 2K-H planetary set in physical units (ring fixed, sun input, carrier output).

    Geometry follows MODEL.md §1 (pitch radii ``r = m z / 2``, base radii ``r cos(alpha)``,
    carrier radius ``r_s + r_p``); masses and forces follow MODEL.md §2; the
    dimensionless form MODEL.md §3. Per-mesh quantities may be a number (identical
    planets) or a sequence of ``N`` numbers.

    Units: lengths in m except transmission errors, backlashes and ``b_c`` in µm;
    stiffness in N/m; damping coefficients in N·s/m; inertias in kg·m²; torques in
    N·m; phases in rad; ``input_rpm`` is the sun speed in rev/min.

    Sign convention: ``T_D`` drives the sun, ``T_L`` is the load torque on the carrier
    opposing its rotation; both positive in normal operation. ``T_L=None`` takes the
    static torque balance ``T_L = T_D (1 + z_r/z_s)``.

    ``notes`` maps a field name to where its value comes from (e.g. "paper §4.1" or an
    assumption with its reason); :meth:`table` prints it beside the value.
    """

    module: float = 3e-3
    pressure_angle_deg: float = 20.0
    z_s: int = 15
    z_p: int = 24
    z_r: int = 63
    N: int = 3
    face_width: float = 0.025
    density: float = 7850.0
    J_s: float | None = None
    J_p: float | Sequence[float] | None = None
    J_c: float = 0.01
    planet_mass: float | Sequence[float] | None = None
    k_sp_mean: float | Sequence[float] = 0.8256e9
    k_sp_amp: float | Sequence[float] = 0.3e9
    k_rp_mean: float | Sequence[float] = 1.06e9
    k_rp_amp: float | Sequence[float] = 0.3e9
    phi_sp: float | Sequence[float] = 0.0
    phi_rp: float | Sequence[float] = 0.0
    e_sp_amp: float | Sequence[float] = 10.0
    e_rp_amp: float | Sequence[float] = 10.0
    beta_sp: float | Sequence[float] = 0.0
    beta_rp: float | Sequence[float] = 0.0
    gamma_sr: float | Sequence[float] = 0.0
    b_sp: float | Sequence[float] = 50.0
    b_rp: float | Sequence[float] = 50.0
    zeta_sp: float | Sequence[float] | None = 0.04
    zeta_rp: float | Sequence[float] | None = 0.04
    c_sp_coef: float | Sequence[float] | None = None
    c_rp_coef: float | Sequence[float] | None = None
    T_D: float = 349.0
    T_L: float | None = None
    Omega: float | None = 0.87
    input_rpm: float | None = None
    b_c: float = 10.0
    notes: Mapping[str, str] = dataclasses.field(default_factory=dict, compare=False)

    # units for tables
    UNITS = {
        "module": "m", "pressure_angle_deg": "deg", "z_s": "", "z_p": "", "z_r": "", "N": "",
        "face_width": "m", "density": "kg/m^3", "J_s": "kg m^2", "J_p": "kg m^2", "J_c": "kg m^2",
        "planet_mass": "kg", "k_sp_mean": "N/m", "k_sp_amp": "N/m", "k_rp_mean": "N/m",
        "k_rp_amp": "N/m", "phi_sp": "rad", "phi_rp": "rad", "e_sp_amp": "um", "e_rp_amp": "um",
        "beta_sp": "rad", "beta_rp": "rad", "gamma_sr": "rad", "b_sp": "um (half)",
        "b_rp": "um (half)", "zeta_sp": "", "zeta_rp": "", "c_sp_coef": "N s/m",
        "c_rp_coef": "N s/m", "T_D": "N m", "T_L": "N m", "Omega": "", "input_rpm": "rpm",
        "b_c": "um",
    }

    def __post_init__(self):
        self.validate()

    # ------------------------------------------------------------ validation
    def _per_planet(self, name: str) -> np.ndarray:
        v = getattr(self, name)
        a = np.asarray(v, dtype=float)
        if a.ndim == 0:
            return np.full(self.N, float(a))
        if a.shape != (self.N,):
            raise ValueError(f"parameter {name} has {a.size} values; give one number or one per planet (N={self.N}).")
        return a

    def validate(self) -> None:
        """Raise ``ValueError`` naming the parameter and its allowed range."""
        for f in dataclasses.fields(self):
            if f.name == "notes":
                continue
            v = getattr(self, f.name)
            if v is None:
                continue
            a = np.asarray(v, dtype=float)
            _require(bool(np.all(np.isfinite(a))), f.name, a, "must be finite (no NaN or inf)")
        for n in ("z_s", "z_p", "z_r", "N"):
            v = getattr(self, n)
            _require(float(v) == int(v) and int(v) >= 1, n, v, "must be a positive integer")
        _require(self.z_r == self.z_s + 2 * self.z_p, "z_r", self.z_r,
                 f"must equal z_s + 2 z_p = {self.z_s + 2 * self.z_p} for a 2K-H set")
        for n in ("module", "face_width", "density", "J_c", "b_c", "T_D"):
            _require(float(getattr(self, n)) > 0, n, getattr(self, n), "must be > 0")
        _require(0 < self.pressure_angle_deg < 45, "pressure_angle_deg", self.pressure_angle_deg,
                 "must be in (0, 45) degrees")
        for n in ("J_s", "J_p", "planet_mass", "T_L"):
            v = getattr(self, n)
            if v is not None:
                _require(bool(np.all(np.asarray(v, dtype=float) > 0)), n, v, "must be > 0")
        for n in ("k_sp_mean", "k_rp_mean"):
            _require(bool(np.all(self._per_planet(n) > 0)), n, getattr(self, n), "must be > 0 N/m")
        for mesh in ("sp", "rp"):
            amp = self._per_planet(f"k_{mesh}_amp")
            mean = self._per_planet(f"k_{mesh}_mean")
            _require(bool(np.all(np.abs(amp) <= mean)), f"k_{mesh}_amp", amp,
                     f"|k_{mesh}_amp| must not exceed k_{mesh}_mean={_fmt_value(mean)} N/m, "
                     "else the mesh stiffness becomes negative")
        for n in ("b_sp", "b_rp", "e_sp_amp", "e_rp_amp"):
            _require(bool(np.all(self._per_planet(n) >= 0)), n, getattr(self, n), "must be >= 0")
        for n in ("J_p", "planet_mass"):
            if getattr(self, n) is not None:
                self._per_planet(n)
        for mesh in ("sp", "rp"):
            z, c = getattr(self, f"zeta_{mesh}"), getattr(self, f"c_{mesh}_coef")
            if z is None and c is None:
                raise ValueError(f"give damping for the {mesh} mesh: zeta_{mesh} (ratio) or c_{mesh}_coef (N s/m).")
            for n in (f"zeta_{mesh}", f"c_{mesh}_coef"):
                if getattr(self, n) is not None:
                    _require(bool(np.all(self._per_planet(n) >= 0)), n, getattr(self, n), "must be >= 0")
        if (self.Omega is None) == (self.input_rpm is None):
            raise ValueError("give exactly one operating speed: Omega (dimensionless) or input_rpm (sun, rev/min).")
        if self.Omega is not None:
            _require(self.Omega > 0, "Omega", self.Omega, "must be > 0")
        if self.input_rpm is not None:
            _require(self.input_rpm > 0, "input_rpm", self.input_rpm, "must be > 0")

    # ------------------------------------------------------------ derived
    def derived(self) -> dict[str, Any]:
        """Geometry, equivalent masses and ``omega_n`` (MODEL.md §1-§3), SI units."""
        alpha = math.radians(self.pressure_angle_deg)
        r_s, r_p, r_r = (self.module * z / 2 for z in (self.z_s, self.z_p, self.z_r))
        r_bs, r_bp = r_s * math.cos(alpha), r_p * math.cos(alpha)
        r_c = r_s + r_p
        disk_J = lambda r: 0.5 * self.density * math.pi * r**4 * self.face_width
        J_s = self.J_s if self.J_s is not None else disk_J(r_s)
        J_p = self._per_planet("J_p") if self.J_p is not None else np.full(self.N, disk_J(r_p))
        M_p = (self._per_planet("planet_mass") if self.planet_mass is not None
               else np.full(self.N, self.density * math.pi * r_p**2 * self.face_width))
        m_s = J_s / r_bs**2
        m_p = J_p / r_bp**2
        m_c = (self.J_c + float(np.sum(M_p)) * r_c**2) / (r_c * math.cos(alpha)) ** 2
        m_eq1 = m_c * m_s / (m_c + m_s)
        k_ref = float(self._per_planet("k_sp_mean")[0])
        omega_n = math.sqrt(k_ref / m_eq1)
        F_D = self.T_D / r_bs
        T_L = self.T_L if self.T_L is not None else self.T_D * (1 + self.z_r / self.z_s)
        F_L = T_L / (r_c * math.cos(alpha))
        if self.Omega is not None:
            Omega = float(self.Omega)
            omega = Omega * omega_n
        else:
            w_s = self.input_rpm * 2 * math.pi / 60
            omega = self.z_s * w_s * self.z_r / (self.z_s + self.z_r)  # mesh frequency, rad/s
            Omega = omega / omega_n
        return dict(alpha=alpha, r_s=r_s, r_p=r_p, r_r=r_r, r_bs=r_bs, r_bp=r_bp, r_c=r_c,
                    J_s=J_s, J_p=J_p, M_p=M_p, m_s=m_s, m_p=m_p, m_c=m_c, m_eq1=m_eq1,
                    omega_n=omega_n, F_D=F_D, F_L=F_L, T_L=T_L, omega=omega, Omega=Omega,
                    mesh_frequency_hz=omega / (2 * math.pi))

    def to_params(self) -> GearParams:
        """The canonical dimensionless set (MODEL.md §3-§4)."""
        d = self.derived()
        k_ref = float(self._per_planet("k_sp_mean")[0])
        bc = self.b_c * 1e-6
        m_eq1, omega_n = d["m_eq1"], d["omega_n"]

        def pp(a):  # collapse identical per-planet values to a scalar
            a = np.asarray(a, dtype=float)
            return float(a[0]) if np.all(a == a[0]) else a

        def damping(mesh):
            c = getattr(self, f"c_{mesh}_coef")
            if c is not None:
                return self._per_planet(f"c_{mesh}_coef") / (m_eq1 * omega_n)
            k = self._per_planet(f"k_{mesh}_mean")
            zeta = self._per_planet(f"zeta_{mesh}")
            # c = 2 zeta sqrt(k m_eq1)  ->  c/(m_eq1 omega_n) = 2 zeta sqrt(k/k_ref)
            return 2 * zeta * np.sqrt(k / k_ref)

        return GearParams(
            N=int(self.N),
            mu_s=m_eq1 / d["m_s"],
            mu_p=pp(m_eq1 / d["m_p"]),
            mu_c=m_eq1 / d["m_c"],
            kappa_sp_mean=pp(self._per_planet("k_sp_mean") / k_ref),
            kappa_sp_amp=pp(self._per_planet("k_sp_amp") / k_ref),
            kappa_rp_mean=pp(self._per_planet("k_rp_mean") / k_ref),
            kappa_rp_amp=pp(self._per_planet("k_rp_amp") / k_ref),
            phi_sp=pp(self._per_planet("phi_sp")),
            phi_rp=pp(self._per_planet("phi_rp")),
            e_sp_amp=pp(self._per_planet("e_sp_amp") * 1e-6 / bc),
            e_rp_amp=pp(self._per_planet("e_rp_amp") * 1e-6 / bc),
            beta_sp=pp(self._per_planet("beta_sp")),
            beta_rp=pp(self._per_planet("beta_rp")),
            gamma_sr=pp(self._per_planet("gamma_sr")),
            b_sp=pp(self._per_planet("b_sp") * 1e-6 / bc),
            b_rp=pp(self._per_planet("b_rp") * 1e-6 / bc),
            c_sp=pp(damping("sp")),
            c_rp=pp(damping("rp")),
            f_D=d["F_D"] / (k_ref * bc),
            f_L=d["F_L"] / (k_ref * bc),
            Omega=d["Omega"],
        )

    def replace(self, **changes) -> "GearSet":
        """A copy with some physical fields changed (validated again)."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = set(changes) - names
        if unknown:
            raise ValueError(f"unknown gear-set field(s) {sorted(unknown)}; known: {', '.join(sorted(names - {'notes'}))}")
        if "input_rpm" in changes and changes["input_rpm"] is not None and "Omega" not in changes:
            changes["Omega"] = None
        if "Omega" in changes and changes["Omega"] is not None and "input_rpm" not in changes:
            changes["input_rpm"] = None
        notes = dict(self.notes)
        for k in changes:
            notes[k] = "set by the user"
        return dataclasses.replace(self, **changes, notes=notes)

    def table(self) -> str:
        """Physical table (value, unit, source) followed by derived quantities."""
        rows = []
        for f in dataclasses.fields(self):
            if f.name == "notes":
                continue
            v = getattr(self, f.name)
            val = "-" if v is None else (_fmt_value(v) if not isinstance(v, int) else str(v))
            rows.append((f.name, val, self.UNITS.get(f.name, ""), self.notes.get(f.name, "")))
        d = self.derived()
        for k, unit in (("m_s", "kg"), ("m_p", "kg"), ("m_c", "kg"), ("m_eq1", "kg"),
                        ("omega_n", "rad/s"), ("F_D", "N"), ("F_L", "N"), ("T_L", "N m"),
                        ("mesh_frequency_hz", "Hz"), ("Omega", "")):
            rows.append((k, _fmt_value(d[k]), unit, "derived"))
        return format_table(rows, ("name", "value", "unit", "source"))


def format_table(rows, header) -> str:
    """Plain-text table with aligned columns."""
    rows = [tuple(str(c) for c in r) for r in rows]
    widths = [max([len(h)] + [len(r[i]) for r in rows]) for i, h in enumerate(header)]
    line = lambda r: "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip()
    return "\n".join([line(header), line(tuple("-" * w for w in widths))] + [line(r) for r in rows])


# --------------------------------------------------------------------------- presets
def paper_gear_set(**overrides) -> GearSet:
    """The gear set of paper §4.1 with the missing values of MODEL.md §6-§7.

    Values from the paper: module 3 mm, pressure angle 20°, teeth 15/24/63, N = 3,
    k_msp = 0.8256e9 and k_mrp = 1.06e9 N/m, k_asp = k_arp = 0.3e9 N/m,
    e_asp = e_arp = 10 µm, b_sp = b_rp = 50 µm, b_c = 10 µm, all phases 0.

    Assumptions (the paper does not give them), each with its reason:
    - face width 25 mm and steel density 7850 kg/m³: gears as solid steel disks of
      their pitch diameters, the usual first estimate of inertia for a set of this size;
    - carrier inertia J_c = 0.01 kg·m²: a typical welded carrier for r_c = 58.5 mm;
    - 50 µm read as the HALF backlash (eq. 3 uses half backlash): b̄ = 5;
    - damping ratio 0.04 on both meshes (gear meshes are typically 0.02-0.1);
    - T_D such that f_D = 2 (mean mesh force ≈ 2/3 of k_msp b_c per planet, a moderate
      load), and T_L from static torque balance T_L = T_D (1 + z_r/z_s) (f_L = 2 f_D);
    - Omega = 0.87: the excitation frequency at which the reduced model shows the
      paper's structure (unstable P-1 and P-2, dominant P-4, minority P-8), MODEL.md §7;
    - gamma_sr = 0 (the paper sets all other phases to zero).
    """
    paper = "paper §4.1"
    notes = {
        "module": paper, "pressure_angle_deg": paper, "z_s": paper, "z_p": paper, "z_r": paper,
        "N": paper, "k_sp_mean": paper, "k_sp_amp": paper, "k_rp_mean": paper, "k_rp_amp": paper,
        "phi_sp": paper, "phi_rp": paper, "e_sp_amp": paper, "e_rp_amp": paper,
        "beta_sp": paper, "beta_rp": paper, "b_c": paper,
        "b_sp": "paper (50 um), read as HALF backlash (eq. 3)",
        "b_rp": "paper (50 um), read as HALF backlash (eq. 3)",
        "face_width": "assumed: 25 mm, solid steel disks of pitch diameter",
        "density": "assumed: steel",
        "J_s": "derived: solid disk of pitch diameter",
        "J_p": "derived: solid disk of pitch diameter",
        "planet_mass": "derived: solid disk of pitch diameter",
        "J_c": "assumed: typical carrier for r_c = 58.5 mm",
        "zeta_sp": "assumed: typical gear-mesh damping ratio",
        "zeta_rp": "assumed: typical gear-mesh damping ratio",
        "c_sp_coef": "from zeta_sp", "c_rp_coef": "from zeta_rp",
        "gamma_sr": "assumed: 0 like the paper's other phases",
        "T_D": "assumed: chosen so that f_D = 2",
        "T_L": "derived: torque balance T_D (1 + z_r/z_s)",
        "Omega": "assumed: 0.87, where the paper's P-1/P-2/P-4/P-8 structure appears",
        "input_rpm": "from Omega",
    }
    alpha = math.radians(20.0)
    r_bs = 3e-3 * 15 / 2 * math.cos(alpha)
    T_D = 2.0 * 0.8256e9 * 10e-6 * r_bs  # f_D = F_D/(k_msp b_c) = 2
    gs = GearSet(T_D=T_D, notes=notes)
    return gs.replace(**overrides) if overrides else gs


PRESETS = {"paper": paper_gear_set}


def get_preset(name: str) -> GearSet:
    """The named physical preset (see ``PRESETS``) as a :class:`GearSet` in physical units.

    ``"paper"`` is the gear set of paper §4.1 completed by MODEL.md §6-§7 (see
    :func:`paper_gear_set`). Raises ``ValueError`` naming the available presets.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; available: {', '.join(sorted(PRESETS))}")
    return PRESETS[name]()


def _parse_value(text: str):
    text = text.strip()
    if text.lower() in ("none", "null"):
        return None
    if "," in text:
        return [float(t) for t in text.split(",") if t.strip()]
    try:
        v = float(text)
    except ValueError as exc:
        raise ValueError(f"cannot read {text!r} as a number (or comma-separated numbers).") from exc
    return int(v) if v.is_integer() and "." not in text and "e" not in text.lower() else v


def resolve_params(preset: str = "paper", overrides: Mapping[str, Any] | Sequence[str] = ()) -> tuple[GearSet, GearParams]:
    """Preset + overrides -> (physical set, dimensionless parameters).

    ``overrides`` is a mapping or ``["NAME=VALUE", ...]`` (the CLI's ``--set``).
    A NAME that is a physical field of :class:`GearSet` changes the physical set
    before conversion; a canonical dimensionless name (MODEL.md §4, e.g. ``Omega``,
    ``b_sp``, ``kappa_sp_amp``) overrides the converted value directly. ``Omega``
    is both and is applied as a physical field.
    """
    if not isinstance(overrides, Mapping):
        items = {}
        for item in overrides:
            if "=" not in item:
                raise ValueError(f"--set expects NAME=VALUE, got {item!r}")
            k, v = item.split("=", 1)
            items[k.strip()] = _parse_value(v)
        overrides = items
    gs = get_preset(preset)
    phys_names = {f.name for f in dataclasses.fields(GearSet)} - {"notes"}
    # Dimensionless names shared with physical ones but with different units
    # (b_sp, e_sp_amp, ...) are read as dimensionless only when prefixed 'dimless.'.
    phys = {k: v for k, v in overrides.items() if k in phys_names and k not in _DIMLESS_PREFERRED}
    dimless = {k.removeprefix("dimless."): v for k, v in overrides.items() if k not in phys}
    unknown = [k for k in dimless if k not in PARAM_NAMES]
    if unknown:
        raise ValueError(
            f"unknown parameter(s) {unknown}. Physical fields: {', '.join(sorted(phys_names))}. "
            f"Dimensionless: {', '.join(PARAM_NAMES)}."
        )
    if phys:
        gs = gs.replace(**phys)
    params = gs.to_params()
    if dimless:
        if "N" in dimless:
            raise ValueError("N is structural: set it as a physical field of the gear set, not a dimensionless override.")
        params = params.replace(**dimless)
    return gs, params


# Names that exist in both tables: the CLI reads them as dimensionless (MODEL.md §4),
# which is what users sweeping the paper's b̄ and Ω expect.
_DIMLESS_PREFERRED = {"b_sp", "b_rp", "e_sp_amp", "e_rp_amp", "phi_sp", "phi_rp", "beta_sp",
                      "beta_rp", "gamma_sr"}


# --------------------------------------------------------------------------- one parameter by name
# Names that move several canonical fields together (sweeps, continuation, the CLI).
PARAM_ALIASES = {
    "b": ("b_sp", "b_rp"),
    "kappa_amp": ("kappa_sp_amp", "kappa_rp_amp"),
    "e_amp": ("e_sp_amp", "e_rp_amp"),
}


def _is_numeric_leaf(v) -> bool:
    if isinstance(v, bool):
        return False
    return eqx.is_array(v) or isinstance(v, (float, int, np.number))


def _field_names(params) -> tuple[str, ...]:
    """Names of the numeric fields of a parameter pytree (GearParams, eqx.Module, NamedTuple, dict)."""
    if isinstance(params, GearParams):
        return PARAM_NAMES[1:]
    if isinstance(params, Mapping):
        return tuple(k for k, v in params.items() if isinstance(k, str) and _is_numeric_leaf(v))
    if hasattr(params, "_fields"):  # NamedTuple
        return tuple(f for f in params._fields if _is_numeric_leaf(getattr(params, f)))
    if dataclasses.is_dataclass(params):  # eqx.Module and frozen dataclasses
        return tuple(f.name for f in dataclasses.fields(params)
                     if not f.metadata.get("static", False) and _is_numeric_leaf(getattr(params, f.name)))
    raise TypeError(f"parameters of type {type(params).__name__} are not a known pytree "
                    "(use an eqx.Module, a NamedTuple or a dict of arrays).")


def param_names(params) -> tuple[str, ...]:
    """Names accepted by :func:`with_param` / :func:`get_param` for ``params``.

    The numeric fields (for :class:`GearParams` the canonical names of MODEL.md §4 but
    ``N``) plus the aliases of :data:`PARAM_ALIASES` whose fields all exist
    (``"b"`` = ``b_sp`` and ``b_rp``, ``"kappa_amp"`` = ``kappa_sp_amp`` and
    ``kappa_rp_amp``, ``"e_amp"`` = ``e_sp_amp`` and ``e_rp_amp``).
    """
    fields = _field_names(params)
    aliases = tuple(a for a, targets in PARAM_ALIASES.items()
                    if a not in fields and all(t in fields for t in targets))
    return fields + aliases


def _targets(params, name: str) -> tuple[str, ...]:
    fields = _field_names(params)
    if not isinstance(name, str):
        raise ValueError(f"parameter name must be a string, got {name!r}.")
    if name in fields:
        return (name,)
    if name in PARAM_ALIASES and all(t in fields for t in PARAM_ALIASES[name]):
        return PARAM_ALIASES[name]
    raise ValueError(f"unknown parameter {name!r} for {type(params).__name__}; valid names: "
                     f"{', '.join(param_names(params))}.")


def with_param(params, name: str, value):
    """A copy of ``params`` with the parameter ``name`` set to ``value`` (traceable).

    Works on any parameter pytree (:class:`GearParams`, an ``eqx.Module`` such as
    :class:`~jaxgear.DuffingParams`, a NamedTuple or a dict). Per-planet fields of
    :class:`GearParams` are set for all planets (a scalar is broadcast to the field's
    shape); an alias of :data:`PARAM_ALIASES` sets all its fields. ``value`` may be a
    JAX tracer (inside ``jit``/``vmap``/``jacfwd``: no recompilation per value); with
    concrete values the result is validated again (e.g. ``b_sp >= 0``).

    Raises:
        ValueError: unknown name (the message lists the valid names), a value of the
            wrong shape, or (concrete values) a value out of the parameter's range.
    """
    targets = _targets(params, name)
    value = jnp.asarray(value, dtype=jnp.float64)
    new_values = []
    for t in targets:
        old = params[t] if isinstance(params, Mapping) else getattr(params, t)
        shape = jnp.shape(old)
        try:
            new_values.append(jnp.broadcast_to(value, shape) if value.ndim <= len(shape) else None)
        except ValueError:
            new_values.append(None)
        if new_values[-1] is None:
            raise ValueError(f"parameter {name}: a value of shape {value.shape} does not fit field {t} "
                             f"of shape {shape} (give a scalar).")
    if isinstance(params, Mapping):
        out = dict(params)
        out.update(zip(targets, new_values))
        return out
    if hasattr(params, "_replace"):
        return params._replace(**dict(zip(targets, new_values)))
    out = eqx.tree_at(lambda p: [getattr(p, t) for t in targets], params, new_values)
    if _is_concrete(value):
        check = getattr(type(out), "__check_init__", None)
        if check is not None:
            check(out)  # tree_at skips construction-time validation
    return out


def get_param(params, name: str) -> float:
    """The value of parameter ``name`` in ``params`` as a float (concrete values).

    Accepts the same names as :func:`with_param`. Per-planet fields must hold the same
    value for every planet, and the fields of an alias must agree (else there is no
    single value: name one field instead).

    Raises:
        ValueError: unknown name, or differing per-planet / aliased values.
    """
    targets = _targets(params, name)
    vals = []
    for t in targets:
        a = np.asarray(params[t] if isinstance(params, Mapping) else getattr(params, t), dtype=float)
        if a.size == 0 or not np.all(a == a.reshape(-1)[0]):
            raise ValueError(f"parameter {t}={_fmt_value(a)} differs between planets: no single value "
                             f"of {name!r}; set it with with_param first.")
        vals.append(float(a.reshape(-1)[0]))
    if any(v != vals[0] for v in vals):
        raise ValueError(f"parameter {name!r} sets {', '.join(targets)}, which differ "
                         f"({', '.join(f'{v:.6g}' for v in vals)}); name one of them.")
    return vals[0]
