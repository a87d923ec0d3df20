"""Sweeps in physical units: a :class:`~jaxgear.GearSet` field mapped to the dimensionless
fields it changes.

A sweep always integrates the dimensionless model (docs/model.md §3-§4). A physical
quantity (the half backlash in µm, the stiffness amplitude in N/m, the input speed in
rpm, the drive torque in N m) is swept by converting ``gear_set.replace(name=v)`` with
:meth:`~jaxgear.GearSet.to_params` at every value ``v`` and comparing with the base
conversion: the dimensionless fields that change are swept together, each at its exact
converted value (:class:`SweepAxis`). Every changed field must be proportional to the
swept value (``b_sp = v / b_c``, ``Omega ∝ rpm``, ``f_D, f_L ∝ T_D``): the sweep then runs
along one line of the dimensionless parameter space. A quantity whose change is not
(the module or a mean stiffness, which rescale masses, ``omega_n`` and every force) is
refused, naming the fields: sweep those dimensionless fields instead.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .._gearset import GearSet
from .._params import PARAM_NAMES, param_targets
from ._values import sorted_values

__all__ = ["PHYSICAL_ALIASES", "SweepAxis", "physical_names", "sweep_axis", "joint_rows", "axis_label",
           "physical_summary", "resolve_gear_set"]

PHYSICAL_ALIASES = {
    "b": ("b_sp", "b_rp"),
    "e_amp": ("e_sp_amp", "e_rp_amp"),
    "k_amp": ("k_sp_amp", "k_rp_amp"),
}
"""Names that move several :class:`~jaxgear.GearSet` fields together in a physical sweep:
``b`` both half backlashes [µm], ``e_amp`` both error amplitudes [µm], ``k_amp`` both
stiffness amplitudes [N/m]."""

_RTOL = 1e-9  # a changed field is proportional to the swept value within this relative error


class SweepAxis(NamedTuple):
    """One swept parameter as the sweep applies it: ``name`` as given, the dimensionless
    ``fields`` it sets, its ``values (V,)`` (sorted; in ``unit`` when ``physical``) and
    ``rows (V, len(fields))``, the dimensionless value of each field at each value."""

    name: str
    fields: tuple[str, ...]
    values: np.ndarray
    rows: np.ndarray
    unit: str = ""
    physical: bool = False

    def applied(self) -> tuple[tuple[str, ...], np.ndarray]:
        """``(names, rows)`` for :func:`~jaxgear.sweep._values.apply_values`: the name
        itself and the values ``(V, 1)`` for a dimensionless sweep, the fields and their
        converted values for a physical one."""
        return (self.fields, self.rows) if self.physical else ((self.name,), self.values[:, None])


def physical_names() -> tuple[str, ...]:
    """The names a physical sweep accepts: the numeric :class:`~jaxgear.GearSet` fields (but
    the number of planets ``N``, the model's structure) and the aliases of
    :data:`PHYSICAL_ALIASES`."""
    fields = tuple(f.name for f in dataclasses.fields(GearSet) if f.name not in ("notes", "mesh_shape", "N"))
    return fields + tuple(PHYSICAL_ALIASES)


def _targets(name: str) -> tuple[str, ...]:
    if not isinstance(name, str) or name not in physical_names():
        raise ValueError(f"unknown gear-set parameter {name!r} for a physical sweep; valid names: "
                         f"{', '.join(physical_names())}.")
    return PHYSICAL_ALIASES.get(name, (name,))


def _unit(name: str) -> str:
    return GearSet.UNITS.get(_targets(name)[0], "")


def resolve_gear_set(gear_set, params, system_is_default: bool):
    """The base parameters of a physical sweep: ``params`` when given, else the gear set's
    conversion (for the default reduced model with identical planets collapsed to
    scalars); ``ValueError`` unless ``gear_set`` is a :class:`~jaxgear.GearSet`."""
    if not isinstance(gear_set, GearSet):
        raise ValueError(f"gear_set={type(gear_set).__name__} must be a jaxgear.GearSet or None.")
    if params is not None:
        return params
    p = gear_set.to_params()
    return p.uniform() if system_is_default else p


def _converted(gear_set: GearSet, changes: dict) -> dict:
    """``gear_set.replace(**changes).to_params()`` as a dict (``ValueError`` naming the
    values when the gear set refuses them)."""
    try:
        return gear_set.replace(**changes).to_params().to_dict()
    except (TypeError, ValueError) as exc:
        what = ", ".join(f"{k}={v:.6g}" for k, v in changes.items())
        raise ValueError(f"sweep value {what}: {exc}") from None


def _changed(base: dict, conv: list[dict]) -> list[str]:
    names = [n for n in (*PARAM_NAMES, "mesh_shape") if any(np.any(np.asarray(d[n]) != np.asarray(base[n]))
                                                           for d in conv)]
    return names


def sweep_axis(params, name: str, values, gear_set: GearSet | None = None) -> SweepAxis:
    """The :class:`SweepAxis` of ``name`` at ``values``: a field or alias of ``params``
    (:func:`~jaxgear.with_param`) without ``gear_set``; with it a field of the gear set
    (or an alias of :data:`PHYSICAL_ALIASES`) in physical units, mapped to the
    dimensionless fields it changes through :meth:`~jaxgear.GearSet.to_params` (module
    docstring; docs/model.md §3-§4). ``ValueError`` for an unknown name (listing the valid
    ones), a value the gear set refuses, a change of ``N`` or ``mesh_shape``, a change of
    no field, per-planet differences, or fields not proportional to the value."""
    if gear_set is None:
        fields = tuple(param_targets(params, name))
        vals = sorted_values(values, name)
        return SweepAxis(name, fields, vals, np.repeat(vals[:, None], len(fields), axis=1))
    targets = _targets(name)
    vals = sorted_values(values, name)
    base = gear_set.to_params().to_dict()
    conv = [_converted(gear_set, dict.fromkeys(targets, float(v))) for v in vals]
    changed = _changed(base, conv)
    structural = [n for n in changed if n in ("N", "mesh_shape")]
    if structural:
        raise ValueError(f"gear-set parameter {name!r} changes {', '.join(structural)}, the structure of the "
                         "model: a sweep cannot change it.")
    if not changed:
        raise ValueError(f"gear-set parameter {name!r} changes no dimensionless parameter at these values "
                         "(e.g. zeta_sp when c_sp_coef is given, or input_rpm when Omega is given): nothing to sweep.")
    rows = np.empty((len(vals), len(changed)))
    for j, f in enumerate(changed):
        col = [np.asarray(d[f], dtype=float) for d in conv]
        if any(c.ndim and not np.all(c == c.reshape(-1)[0]) for c in col):
            raise ValueError(f"gear-set parameter {name!r}: {f} differs between planets; a sweep sets one value "
                             "for every planet.")
        rows[:, j] = [float(c.reshape(-1)[0]) for c in col]
    bad = _not_proportional(gear_set, targets, vals, base, changed, rows)
    if bad:
        raise ValueError(
            f"gear-set parameter {name!r} changes the dimensionless {', '.join(changed)}, of which "
            f"{', '.join(bad)} not in proportion to {name}: a physical sweep runs along one line through the "
            "origin of the dimensionless parameters (docs/methods/sweeps.md), which this change leaves. Sweep "
            "those dimensionless fields instead.")
    return SweepAxis(name, tuple(changed), vals, rows, _unit(name), True)


def _not_proportional(gear_set, targets, vals, base, changed, rows) -> list[str]:
    """The changed fields that are not ``c * value`` for one ``c`` over ``vals`` and the
    gear set's own value (where it is one number)."""
    own = getattr(gear_set, targets[0])
    x = list(vals)
    own_ok = own is not None and np.ndim(own) == 0 and all(getattr(gear_set, t) == own for t in targets)
    if own_ok:
        x.append(float(own))
    x = np.asarray(x, dtype=float)
    bad = []
    for j, f in enumerate(changed):
        y = list(rows[:, j]) + ([float(np.asarray(base[f]).reshape(-1)[0])] if own_ok else [])
        y = np.asarray(y, dtype=float)
        c = float(x @ y / (x @ x)) if np.any(x) else 0.0
        if not np.allclose(y, c * x, rtol=_RTOL, atol=_RTOL * max(float(np.max(np.abs(y))), 1e-300)):
            bad.append(f)
    return bad


def joint_rows(gear_set: GearSet, axes: tuple[SweepAxis, ...], VV: np.ndarray) -> np.ndarray:
    """The dimensionless rows of a map's points ``VV (n, len(axes))``: each axis's rows side
    by side, checked against the gear set converted at both values at once (``ValueError``
    where the two quantities act on each other's fields)."""
    out = np.concatenate([ax.rows[np.searchsorted(ax.values, VV[:, i])] for i, ax in enumerate(axes)], axis=1)
    if gear_set is None or not all(ax.physical for ax in axes):
        return out
    fields = [f for ax in axes for f in ax.fields]
    for v, row in zip(VV, out):
        changes = {t: float(x) for ax, x in zip(axes, v) for t in _targets(ax.name)}
        d = _converted(gear_set, changes)
        got = np.array([float(np.asarray(d[f]).reshape(-1)[0]) for f in fields])
        if not np.allclose(got, row, rtol=_RTOL, atol=0.0):
            raise ValueError(f"gear-set parameters {axes[0].name!r} and {axes[1].name!r} change each other's "
                             "dimensionless fields: a map over both is not two dimensionless axes.")
    return out


def axis_label(name: str, fields, unit: str = "", physical: bool = False) -> str:
    """An axis label: ``"b_sp [µm, half]"`` for a physical sweep, the name with the fields
    it sets for an alias (``"b  (b_sp, b_rp)"``)."""
    if physical:
        u = unit.replace("um", "µm").replace(" (", ", ").rstrip(")")
        return f"{name} [{u}]" if u else name
    fields = tuple(fields)
    return name + ("" if fields in ((), (name,)) else f"  ({', '.join(fields)})")


def physical_summary(unit: str, physical: bool, field_values, suffix: str = "") -> dict:
    """What a physical sweep adds to its ``summary()``: the unit of its values and the
    dimensionless value of each field at each (``{}`` for a dimensionless sweep)."""
    if not physical:
        return {}
    return {f"unit{suffix}": unit, f"physical{suffix}": True,
            f"field_values{suffix}": np.asarray(field_values).tolist()}
