"""A planetary set in physical units and its conversion to the dimensionless form.

:class:`GearSet` describes a 2K-H set (teeth, module, N/m, µm, N·m, rpm) and converts to
the canonical :class:`~jaxgear.GearParams` with :meth:`GearSet.to_params`, following
the model document §1-§3 (geometry, equivalent masses, ``omega_n``, scaling by ``b_c``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ._format import fmt_value, format_table
from ._params import GearParams, require

__all__ = ["GearSet"]

@dataclasses.dataclass(frozen=True)
class GearSet:
    """A 2K-H planetary set in physical units (ring fixed, sun input, carrier output).

    Geometry follows docs/model.md §1 (pitch radii ``r = m z / 2``, base radii ``r cos(alpha)``,
    carrier radius ``r_s + r_p``); masses and forces follow docs/model.md §2; the
    dimensionless form docs/model.md §3. Per-mesh quantities may be a number (identical
    planets) or a sequence of ``N`` numbers.

    Units: lengths in m except transmission errors, backlashes and ``b_c`` in µm;
    stiffness in N/m; damping coefficients in N·s/m; inertias in kg·m²; torques in
    N·m; phases in rad; ``input_rpm`` is the sun speed in rev/min.

    Sign convention: ``T_D`` drives the sun, ``T_L`` is the load torque on the carrier
    opposing its rotation; both positive in normal operation. ``T_L=None`` takes the
    static torque balance ``T_L = T_D (1 + z_r/z_s)``.

    Mesh stiffness: ``mesh_shape="sine"`` keeps the first harmonic of the tooth-pair
    alternation (the paper's model), ``"rectangular"`` the alternation itself between
    one and two pairs in contact (model document §4), whose duty cycle is the contact
    ratio; ``contact_ratio_sp`` / ``contact_ratio_rp`` default to the standard involute
    values of the geometry (addendum ``addendum_coef * module``, full-depth teeth,
    standard centre distances; :meth:`derived`).

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
    mesh_shape: str = "sine"
    addendum_coef: float = 1.0
    contact_ratio_sp: float | None = None
    contact_ratio_rp: float | None = None
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
        "b_c": "um", "mesh_shape": "", "addendum_coef": "", "contact_ratio_sp": "", "contact_ratio_rp": "",
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
            if f.name in ("notes", "mesh_shape"):
                continue
            v = getattr(self, f.name)
            if v is None:
                continue
            if not _is_numeric(v):
                raise ValueError(f"parameter {f.name}={v!r} must be a number (or one number per planet), "
                                 f"not {type(v).__name__}.")
            a = np.asarray(v, dtype=float)
            require(bool(np.all(np.isfinite(a))), f.name, a, "must be finite (no NaN or inf)")
        for n in ("z_s", "z_p", "z_r", "N"):
            v = getattr(self, n)
            require(float(v) == int(v) and int(v) >= 1, n, v, "must be a positive integer")
        require(self.z_r == self.z_s + 2 * self.z_p, "z_r", self.z_r,
                 f"must equal z_s + 2 z_p = {self.z_s + 2 * self.z_p} for a 2K-H set")
        for n in ("module", "face_width", "density", "J_c", "b_c", "T_D"):
            require(float(getattr(self, n)) > 0, n, getattr(self, n), "must be > 0")
        require(0 < self.pressure_angle_deg < 45, "pressure_angle_deg", self.pressure_angle_deg,
                 "must be in (0, 45) degrees")
        for n in ("J_s", "J_p", "planet_mass", "T_L"):
            v = getattr(self, n)
            if v is not None:
                require(bool(np.all(np.asarray(v, dtype=float) > 0)), n, v, "must be > 0")
        for n in ("k_sp_mean", "k_rp_mean"):
            require(bool(np.all(self._per_planet(n) > 0)), n, getattr(self, n), "must be > 0 N/m")
        for mesh in ("sp", "rp"):
            amp = self._per_planet(f"k_{mesh}_amp")
            mean = self._per_planet(f"k_{mesh}_mean")
            require(bool(np.all(np.abs(amp) <= mean)), f"k_{mesh}_amp", amp,
                     f"|k_{mesh}_amp| must not exceed k_{mesh}_mean={fmt_value(mean)} N/m, "
                     "else the mesh stiffness becomes negative")
        for n in ("b_sp", "b_rp", "e_sp_amp", "e_rp_amp"):
            require(bool(np.all(self._per_planet(n) >= 0)), n, getattr(self, n), "must be >= 0")
        for n in ("J_p", "planet_mass"):
            if getattr(self, n) is not None:
                self._per_planet(n)
        for mesh in ("sp", "rp"):
            z, c = getattr(self, f"zeta_{mesh}"), getattr(self, f"c_{mesh}_coef")
            if z is None and c is None:
                raise ValueError(f"give damping for the {mesh} mesh: zeta_{mesh} (ratio) or c_{mesh}_coef (N s/m).")
            for n in (f"zeta_{mesh}", f"c_{mesh}_coef"):
                if getattr(self, n) is not None:
                    require(bool(np.all(self._per_planet(n) >= 0)), n, getattr(self, n), "must be >= 0")
        require(self.mesh_shape in ("sine", "rectangular"), "mesh_shape", self.mesh_shape,
                "must be 'sine' or 'rectangular'")
        require(0 < float(self.addendum_coef) <= 1.5, "addendum_coef", self.addendum_coef, "must be in (0, 1.5]")
        for n in ("contact_ratio_sp", "contact_ratio_rp"):
            v = getattr(self, n)
            if v is not None:
                require(1 < float(v) < 2, n, v, "must lie in (1, 2): one or two tooth pairs in contact")
        eps_sp, eps_rp = self._contact_ratios()
        for n, v in (("contact_ratio_sp", eps_sp), ("contact_ratio_rp", eps_rp)):
            require(1 < v < 2, n, v, "(from the geometry) must lie in (1, 2) for the two-level stiffness model; "
                    "give it explicitly or change addendum_coef / the teeth")
        if (self.Omega is None) == (self.input_rpm is None):
            raise ValueError("give exactly one operating speed: Omega (dimensionless) or input_rpm (sun, rev/min).")
        if self.Omega is not None:
            require(self.Omega > 0, "Omega", self.Omega, "must be > 0")
        if self.input_rpm is not None:
            require(self.input_rpm > 0, "input_rpm", self.input_rpm, "must be > 0")

    # ------------------------------------------------------------ derived
    def _contact_ratios(self) -> tuple[float, float]:
        """Sun-planet and ring-planet contact ratios: the given ones, else the involute
        values (length of the line of action over the base pitch ``pi m cos(alpha)``):
        external mesh ``(sqrt(ra_s^2 - rb_s^2) + sqrt(ra_p^2 - rb_p^2) - a sin(alpha)) / p_b``
        with ``a = r_s + r_p``; internal mesh ``(sqrt(ra_p^2 - rb_p^2) - sqrt(ra_r^2 - rb_r^2)
        + a sin(alpha)) / p_b`` with ``a = r_r - r_p`` and the ring's addendum circle
        inside its pitch circle."""
        alpha = math.radians(self.pressure_angle_deg)
        m, ha = self.module, float(self.addendum_coef)
        r_s, r_p, r_r = (m * z / 2 for z in (self.z_s, self.z_p, self.z_r))
        rb = lambda r: r * math.cos(alpha)  # noqa: E731
        arm = lambda ra, r: math.sqrt(max(ra * ra - rb(r) ** 2, 0.0))  # noqa: E731
        p_b = math.pi * m * math.cos(alpha)
        sp = (arm(r_s + ha * m, r_s) + arm(r_p + ha * m, r_p) - (r_s + r_p) * math.sin(alpha)) / p_b
        rp = (arm(r_p + ha * m, r_p) - arm(r_r - ha * m, r_r) + (r_r - r_p) * math.sin(alpha)) / p_b
        given = (self.contact_ratio_sp, self.contact_ratio_rp)
        return (float(given[0]) if given[0] is not None else sp, float(given[1]) if given[1] is not None else rp)

    def derived(self) -> dict[str, Any]:
        """Geometry, equivalent masses and ``omega_n`` (docs/model.md §1-§3), SI units."""
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
        eps_sp, eps_rp = self._contact_ratios()
        return dict(alpha=alpha, r_s=r_s, r_p=r_p, r_r=r_r, r_bs=r_bs, r_bp=r_bp, r_c=r_c,
                    contact_ratio_sp=eps_sp, contact_ratio_rp=eps_rp,
                    J_s=J_s, J_p=J_p, M_p=M_p, m_s=m_s, m_p=m_p, m_c=m_c, m_eq1=m_eq1,
                    omega_n=omega_n, F_D=F_D, F_L=F_L, T_L=T_L, omega=omega, Omega=Omega,
                    mesh_frequency_hz=omega / (2 * math.pi))

    def to_params(self) -> GearParams:
        """The canonical dimensionless set (docs/model.md §3-§4)."""
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
            contact_ratio_sp=d["contact_ratio_sp"],
            contact_ratio_rp=d["contact_ratio_rp"],
            mesh_shape=self.mesh_shape,
        )

    def replace(self, **changes) -> GearSet:
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
            val = "-" if v is None else (fmt_value(v) if not isinstance(v, int) else str(v))
            rows.append((f.name, val, self.UNITS.get(f.name, ""), self.notes.get(f.name, "")))
        d = self.derived()
        for k, unit in (("m_s", "kg"), ("m_p", "kg"), ("m_c", "kg"), ("m_eq1", "kg"),
                        ("omega_n", "rad/s"), ("F_D", "N"), ("F_L", "N"), ("T_L", "N m"),
                        ("mesh_frequency_hz", "Hz"), ("Omega", ""), ("contact_ratio_sp", ""),
                        ("contact_ratio_rp", "")):
            rows.append((k, fmt_value(d[k]), unit, "derived"))
        return format_table(rows, ("name", "value", "unit", "source"))


def _is_numeric(v) -> bool:
    """A real number (not a bool or a string) or a flat sequence of them."""
    import numbers

    if isinstance(v, (bool, np.bool_)):
        return False
    if isinstance(v, numbers.Real):
        return True
    if isinstance(v, (str, bytes, dict)):
        return False
    try:
        a = np.asarray(v)
    except Exception:
        return False
    return a.ndim == 1 and a.dtype.kind in "iuf"
