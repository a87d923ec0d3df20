"""Named gear sets (presets) and the parameters a command line builds from them.

:func:`paper_gear_set` is the gear set of paper §4.1 completed with documented
assumptions for what the paper leaves out (model document §6-§7); :func:`resolve_params`
turns a preset name and ``NAME=VALUE`` overrides into the physical set and its
dimensionless parameters.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

from ._gearset import GearSet
from ._params import PARAM_ALIASES, PARAM_NAMES, GearParams

__all__ = ["paper_gear_set", "paper_params", "PRESETS", "get_preset", "resolve_params", "parse_value"]

def paper_gear_set(**overrides) -> GearSet:
    """The gear set of paper §4.1 with the missing values of docs/model.md §6-§7.

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
      paper's structure (unstable P-1 and P-2, dominant P-4, minority P-8), docs/model.md §7;
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

    ``"paper"`` is the gear set of paper §4.1 completed by docs/model.md §6-§7 (see
    :func:`paper_gear_set`). Raises ``ValueError`` naming the available presets.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; available: {', '.join(sorted(PRESETS))}")
    return PRESETS[name]()


def _number(text: str) -> float:
    """``float(text)`` without Python's literal extras (``0_9`` would be 9)."""
    if "_" in text:
        raise ValueError(f"cannot read {text!r} as a number: numbers are written without '_'.")
    try:
        return float(text)
    except ValueError as exc:
        raise ValueError(f"cannot read {text!r} as a number (or comma-separated numbers).") from exc


def parse_value(text: str):
    """A ``--set``/override value: a number, comma-separated numbers, or ``none``."""
    text = text.strip()
    if text.lower() in ("none", "null"):
        return None
    if "," in text:
        return [_number(t.strip()) for t in text.split(",") if t.strip()]
    v = _number(text)
    return int(v) if v.is_integer() and "." not in text and "e" not in text.lower() else v


def resolve_params(preset: str = "paper", overrides: Mapping[str, Any] | Sequence[str] = ()) -> tuple[GearSet, GearParams]:
    """Preset + overrides -> (physical set, dimensionless parameters).

    ``overrides`` is a mapping or ``["NAME=VALUE", ...]`` (the CLI's ``--set``).
    A NAME that is a physical field of :class:`GearSet` changes the physical set
    before conversion; a canonical dimensionless name (docs/model.md §4, e.g. ``Omega``,
    ``b_sp``, ``kappa_sp_amp``) overrides the converted value directly. ``Omega``
    is both and is applied as a physical field.
    """
    if not isinstance(overrides, Mapping):
        items = {}
        for item in overrides:
            if "=" not in item:
                raise ValueError(f"--set expects NAME=VALUE, got {item!r}")
            k, v = item.split("=", 1)
            try:
                items[k.strip()] = parse_value(v)
            except ValueError as exc:
                raise ValueError(f"--set {k.strip()}={v.strip()}: {exc}") from None
        overrides = items
    gs = get_preset(preset)
    phys_names = {f.name for f in dataclasses.fields(GearSet)} - {"notes"}
    # Dimensionless names shared with physical ones but with different units
    # (b_sp, e_sp_amp, ...) are read as dimensionless only when prefixed 'dimless.'.
    phys = {k: v for k, v in overrides.items() if k in phys_names and k not in _DIMLESS_PREFERRED}
    dimless = {}
    for k, v in overrides.items():  # an alias (b = b_sp and b_rp, ...) sets each of its names
        if k not in phys:
            k = k.removeprefix("dimless.")
            dimless.update(dict.fromkeys(PARAM_ALIASES.get(k, (k,)), v))
    unknown = [k for k in dimless if k not in PARAM_NAMES]
    if unknown:
        raise ValueError(
            f"unknown parameter(s) {unknown}. Physical fields: {', '.join(sorted(phys_names))}. "
            f"Dimensionless: {', '.join(PARAM_NAMES)}; aliases: {', '.join(PARAM_ALIASES)}."
        )
    if phys:
        gs = gs.replace(**phys)
    params = gs.to_params()
    if dimless:
        if "N" in dimless:
            raise ValueError("N is structural: set it as a physical field of the gear set, not a dimensionless override.")
        params = params.replace(**dimless)
    return gs, params


# Names that exist in both tables: the CLI reads them as dimensionless (docs/model.md §4),
# which is what users sweeping the paper's b̄ and Ω expect.
_DIMLESS_PREFERRED = {"b_sp", "b_rp", "e_sp_amp", "e_rp_amp", "phi_sp", "phi_rp", "beta_sp",
                      "beta_rp", "gamma_sr"}



def paper_params(**overrides) -> GearParams:
    """Dimensionless parameters of the ``paper`` preset (model document §4, §7).

    ``overrides`` may name physical fields of :class:`GearSet` or canonical
    dimensionless names (see :func:`resolve_params`).
    """
    return resolve_params("paper", overrides)[1]
