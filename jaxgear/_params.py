"""Canonical dimensionless parameters of the planetary set, and access by name.

:class:`GearParams` holds the parameters of the reduced 2-DOF model of paper §4.1 and
the N-planet model of paper eq. 5 under the names of the model document §4. Any
parameter of any parameter pytree (:class:`GearParams`, an ``eqx.Module``, a
``NamedTuple``, a dict) can be read and set by name (:func:`with_param`,
:func:`get_param`), with aliases that move several fields together (``b`` sets both
half backlashes); sweeps, continuation, design and the CLI are built on this.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import is_traced
from ._format import fmt_value, format_table

__all__ = [
    "GearParams",
    "PARAM_NAMES",
    "PER_PLANET_NAMES",
    "PARAM_MEANINGS",
    "OPTIONAL_DEFAULTS",
    "MESH_SHAPES",
    "rectangular_peak",
    "PARAM_ALIASES",
    "param_names",
    "param_targets",
    "with_param",
    "get_param",
    "params_to_dict",
    "require",
    "get_field",
    "set_fields",
    "replace_params",
    "params_type_name",
    "params_from_dict",
    "PARAMS_TYPES",
    "params_type",
]

PARAM_NAMES = (
    "N", "mu_s", "mu_p", "mu_c",
    "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp",
    "phi_sp", "phi_rp",
    "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr",
    "b_sp", "b_rp", "c_sp", "c_rp",
    "f_D", "f_L", "Omega",
    "contact_ratio_sp", "contact_ratio_rp",
)
"""Canonical names of the numeric dimensionless parameters (model document §4), in the
order they are written out."""
MAX_MAGNITUDE = 1e12
"""Largest magnitude of a dimensionless parameter: the model's terms (products of two
parameters and the state, ``Omega**2`` times an error amplitude) stay finite below it."""
# Names that may hold one value per planet (arrays of length N).
PER_PLANET_NAMES = (
    "mu_p", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp",
    "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr",
    "b_sp", "b_rp", "c_sp", "c_rp", "contact_ratio_sp", "contact_ratio_rp",
)
# Names that files written before they existed leave out, with the value they had then.
OPTIONAL_DEFAULTS = {"contact_ratio_sp": 1.5, "contact_ratio_rp": 1.5, "mesh_shape": "sine"}
MESH_SHAPES = ("sine", "rectangular")
"""Shapes of the mesh-stiffness variation: the first harmonic (paper eq. 1) or the
rectangular wave of single and double tooth contact it comes from (paper §2.1)."""
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
    "contact_ratio_sp": "sun-planet contact ratio (rectangular stiffness only)",
    "contact_ratio_rp": "ring-planet contact ratio (rectangular stiffness only)",
    "mesh_shape": "mesh-stiffness shape: sine (first harmonic) or rectangular",
}


def _f64(x):
    if isinstance(x, jax.Array):
        return jnp.asarray(x, dtype=jnp.float64)
    # a number from the host: placed as it is (jnp.asarray would compile a conversion,
    # the first computation of a run: a tenth of a second before the run can start)
    return jax.device_put(np.asarray(x, dtype=np.float64))


def _is_concrete(x) -> bool:
    return not is_traced(x)


def require(cond: bool, name: str, value, allowed: str) -> None:
    if not cond:
        raise ValueError(f"parameter {name}={fmt_value(value)} is out of range: {allowed}.")


PARAMS_TYPES: dict[str, type] = {}
"""The package's own parameter classes by :func:`params_type_name`: the only classes a
saved file's parameters are rebuilt as (:func:`params_from_dict`)."""


def params_type(cls: type) -> type:
    """Class decorator: a parameter class of this package that saved results may name."""
    PARAMS_TYPES[f"{cls.__module__}:{cls.__qualname__}"] = cls
    return cls


@params_type
class GearParams(eqx.Module):
    """Canonical dimensionless parameters of the planetary set (docs/model.md §4).

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
    contact_ratio_sp: Any = eqx.field(converter=_f64, default=OPTIONAL_DEFAULTS["contact_ratio_sp"])
    contact_ratio_rp: Any = eqx.field(converter=_f64, default=OPTIONAL_DEFAULTS["contact_ratio_rp"])
    mesh_shape: str = eqx.field(static=True, default="sine")

    def __check_init__(self):
        if not isinstance(self.N, (int, np.integer)) or isinstance(self.N, bool) or self.N < 1:
            raise ValueError(f"parameter N={self.N!r} is out of range: the number of planets must be an integer >= 1.")
        if self.mesh_shape not in MESH_SHAPES:
            raise ValueError(f"parameter mesh_shape={self.mesh_shape!r} must be one of {', '.join(MESH_SHAPES)}.")
        leaves = {n: getattr(self, n) for n in PARAM_NAMES if n != "N"}
        if not all(_is_concrete(v) for v in leaves.values()):
            return  # traced values (inside jit/vmap/grad): checked when built concretely
        for name, v in leaves.items():
            a = np.asarray(v)
            require(bool(np.all(np.isfinite(a))), name, a, "must be finite (no NaN or inf)")
            require(bool(np.all(np.abs(a) <= MAX_MAGNITUDE)), name, a,
                    f"its magnitude must be <= {MAX_MAGNITUDE:g} (a dimensionless parameter; larger values "
                    "overflow the model's terms)")
            if name in PER_PLANET_NAMES:
                require(a.ndim == 0 or a.shape[-1:] == (self.N,) or a.ndim > 1, name, a,
                         f"a scalar or one value per planet (shape ({self.N},))")
            elif a.ndim > 1:
                pass  # batched for a sweep
        pos = lambda n: require(bool(np.all(np.asarray(leaves[n]) > 0)), n, leaves[n], "must be > 0")
        nonneg = lambda n: require(bool(np.all(np.asarray(leaves[n]) >= 0)), n, leaves[n], "must be >= 0")
        for n in ("mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_rp_mean", "Omega"):
            pos(n)
        for n in ("b_sp", "b_rp", "c_sp", "c_rp", "e_sp_amp", "e_rp_amp"):
            nonneg(n)
        s = np.asarray(leaves["mu_s"]) + np.asarray(leaves["mu_c"])
        require(bool(np.all(np.abs(s - 1.0) < 1e-9)), "mu_s + mu_c", s,
                 "must equal 1 (mu_s = m_eq1/m_s, mu_c = m_eq1/m_c with 1/m_eq1 = 1/m_s + 1/m_c)")
        for mesh in ("sp", "rp"):
            mean = np.asarray(leaves[f"kappa_{mesh}_mean"])
            amp = np.asarray(leaves[f"kappa_{mesh}_amp"])
            eps = np.asarray(leaves[f"contact_ratio_{mesh}"])
            require(bool(np.all((eps > 1) & (eps < 2))), f"contact_ratio_{mesh}", eps,
                    "must lie in (1, 2): one or two tooth pairs in contact")
            peak = rectangular_peak(eps) if self.mesh_shape == "rectangular" else 1.0
            require(bool(np.all(np.abs(amp) * peak <= mean)), f"kappa_{mesh}_amp", amp,
                    f"|kappa_{mesh}_amp| must not exceed kappa_{mesh}_mean={fmt_value(mean)}"
                    + (f" / {fmt_value(peak)} for the rectangular wave" if self.mesh_shape == "rectangular" else "")
                    + ", else the mesh stiffness becomes negative")

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

    def replace(self, **changes) -> GearParams:
        """A copy with some canonical names (or ``mesh_shape``) changed (validated again)."""
        d = self.to_dict()
        unknown = set(changes) - set(PARAM_NAMES) - {"mesh_shape"}
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {', '.join(PARAM_NAMES)}, mesh_shape")
        d.update(changes)
        return GearParams.from_dict(d)

    def to_dict(self) -> dict[str, Any]:
        """Canonical names -> Python floats (or lists for per-planet arrays), and ``mesh_shape``."""
        out: dict[str, Any] = {"N": int(self.N)}
        for n in PARAM_NAMES[1:]:
            a = np.asarray(getattr(self, n))
            out[n] = float(a) if a.ndim == 0 else a.tolist()
        out["mesh_shape"] = self.mesh_shape
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GearParams:
        """Build from a mapping with the canonical names (those of :data:`OPTIONAL_DEFAULTS`
        may be missing, as in files written before they existed)."""
        known = set(PARAM_NAMES) | {"mesh_shape"}
        missing = [n for n in PARAM_NAMES if n not in d and n not in OPTIONAL_DEFAULTS]
        if missing:
            raise ValueError(f"missing parameter(s): {', '.join(missing)}")
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {', '.join(sorted(known))}")
        values = {n: d.get(n, OPTIONAL_DEFAULTS.get(n)) for n in known}
        values["N"] = int(values["N"]) if float(values["N"]) == int(values["N"]) else values["N"]
        return cls(**values)

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    def uniform(self) -> GearParams:
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
        rows = [(n, fmt_value(getattr(self, n)) if n != "N" else str(self.N), PARAM_MEANINGS[n])
                for n in PARAM_NAMES]
        rows.append(("mesh_shape", self.mesh_shape, PARAM_MEANINGS["mesh_shape"]))
        return format_table(rows, ("name", "value", "meaning"))


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

    The numeric fields (for :class:`GearParams` the canonical names of docs/model.md §4 but
    ``N``) plus the aliases of :data:`PARAM_ALIASES` whose fields all exist
    (``"b"`` = ``b_sp`` and ``b_rp``, ``"kappa_amp"`` = ``kappa_sp_amp`` and
    ``kappa_rp_amp``, ``"e_amp"`` = ``e_sp_amp`` and ``e_rp_amp``).
    """
    fields = _field_names(params)
    aliases = tuple(a for a, targets in PARAM_ALIASES.items()
                    if a not in fields and all(t in fields for t in targets))
    return fields + aliases


def param_targets(params, name: str) -> tuple[str, ...]:
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
    targets = param_targets(params, name)
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
    targets = param_targets(params, name)
    vals = []
    for t in targets:
        a = np.asarray(params[t] if isinstance(params, Mapping) else getattr(params, t), dtype=float)
        if a.size == 0 or not np.all(a == a.reshape(-1)[0]):
            raise ValueError(f"parameter {t}={fmt_value(a)} differs between planets: no single value "
                             f"of {name!r}; set it with with_param first.")
        vals.append(float(a.reshape(-1)[0]))
    if any(v != vals[0] for v in vals):
        raise ValueError(f"parameter {name!r} sets {', '.join(targets)}, which differ "
                         f"({', '.join(f'{v:.6g}' for v in vals)}); name one of them.")
    return vals[0]


def rectangular_peak(contact_ratio):
    """Largest value of the unit rectangular mesh-stiffness wave of contact ratio ``eps``
    relative to its first harmonic (model document §2): the wave ``(pi / (2 sin(pi d)))
    (1_double - d)``, ``d = eps - 1``, has first harmonic ``sin`` and extremes
    ``pi (1 - d) / (2 sin(pi d))`` and ``-pi d / (2 sin(pi d))``."""
    d = np.asarray(contact_ratio, dtype=float) - 1.0
    return np.pi * np.maximum(d, 1.0 - d) / (2.0 * np.sin(np.pi * d))


def params_to_dict(params) -> dict:
    """Parameters as a JSON-ready dict: the canonical names for :class:`GearParams`
    (model document §4), the pytree paths of the leaves for any other parameter pytree."""
    if isinstance(params, GearParams):
        return params.to_dict()
    out = {}
    for path, leaf in jax.tree_util.tree_leaves_with_path(params):
        a = np.asarray(leaf)
        out[jax.tree_util.keystr(path).lstrip(".")] = float(a) if a.ndim == 0 else a.tolist()
    return out


def get_field(params, name):
    """The field ``name`` of a parameter pytree (eqx.Module, NamedTuple or dict)."""
    return params[name] if isinstance(params, Mapping) else getattr(params, name)


def set_fields(params, names, values):
    """``params`` with the scalar fields ``names`` replaced by ``values`` (no re-validation;
    works for eqx.Module, NamedTuple and dict parameter pytrees, traced or not)."""
    if isinstance(params, Mapping):
        out = dict(params)
        for n, v in zip(names, values):
            out[n] = v
        return type(params)(out) if not isinstance(params, dict) else out
    return eqx.tree_at(lambda p: [getattr(p, n) for n in names], params, list(values))


def replace_params(params, **changes):
    """``params`` with some scalar fields replaced, safe inside ``jax.grad``/``jit``.

    Unlike :meth:`GearParams.replace` (which validates concrete values and rebuilds the
    object) this swaps the leaves with ``eqx.tree_at``, so the new values may be tracers:
    ``jax.grad(lambda c: scalar(replace_params(p, c_sp=c)))(0.08)``. Works for
    eqx.Module, NamedTuple and dict parameters.
    """
    if not changes:
        return params
    names = list(changes)
    try:
        return set_fields(params, names, [jnp.asarray(v, jnp.float64) for v in changes.values()])
    except (TypeError, ValueError, AttributeError, KeyError):
        raise ValueError(f"cannot replace {names}: each must be an array leaf of {type(params).__name__} "
                         "(static fields such as N cannot change).") from None


def params_type_name(params) -> str:
    """``"module:qualname"`` of the parameters' class (saved with a design result)."""
    t = type(params)
    return f"{t.__module__}:{t.__qualname__}"


def params_from_dict(type_name: str, d: dict):
    """Parameters from their saved dict, without importing or calling anything the file
    names: one of the package's own classes (:data:`PARAMS_TYPES`) rebuilt by keyword;
    any other type (a user's parameters) comes back as the plain ``dict`` of its values
    (rebuild it with ``MyParams(**values)``).

    Raises:
        ValueError: the values are not plain data (numbers, texts, lists of them), or do
            not fit the named package class.
    """
    if not isinstance(d, dict) or not all(isinstance(k, str) and _is_value_tree(v) for k, v in d.items()):
        raise ValueError("saved parameters must be a dict of numbers, texts or lists of them.")
    cls = PARAMS_TYPES.get(str(type_name))
    if cls is None:
        return dict(d)
    try:
        return cls.from_dict(d) if cls is GearParams else cls(**d)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"saved parameters do not fit {cls.__name__}: {exc}") from None


def _is_value_tree(v) -> bool:
    """Plain data: numbers, texts (a mesh shape's name), ``None`` and lists of them."""
    if isinstance(v, (list, tuple)):
        return all(_is_value_tree(x) for x in v)
    return isinstance(v, (int, float, str)) and not isinstance(v, bool) or v is None
