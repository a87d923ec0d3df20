"""Parameter values of a sweep: checked once, applied to a parameter pytree inside kernels."""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .._params import with_param
from .._system import ForcedSystem, check_state_shape

__all__ = ["apply_values", "check_values", "sorted_values", "check_starts", "coord_name"]


def apply_values(params, names: tuple[str, ...], v):
    """Set parameters ``names`` to the entries of ``v`` (shape ``(len(names),)``)."""
    for j, n in enumerate(names):
        params = with_param(params, n, v[j])
    return params


def check_values(system: ForcedSystem, params, names: tuple[str, ...], V: np.ndarray) -> None:
    """Validate every parameter combination ``V (n, len(names))`` once, concretely
    (``ValueError`` naming the combination and the reason)."""
    for v in np.unique(V, axis=0):
        try:
            apply_values(params, names, v)  # concrete values: with_param validates (e.g. b_sp >= 0)
        except ValueError as exc:
            what = ", ".join(f"{n}={x:.6g}" for n, x in zip(names, v))
            raise ValueError(f"sweep value {what}: {exc}") from None
    T = np.asarray(jax.vmap(lambda v: system.period(apply_values(params, names, v)))(jnp.asarray(V)))
    bad = ~(np.isfinite(T) & (T > 0))
    if bad.any():
        v = V[np.argmax(bad)]
        what = ", ".join(f"{n}={x:.6g}" for n, x in zip(names, v))
        raise ValueError(f"{system.name}: at {what} the forcing period is {T[np.argmax(bad)]}; "
                         "it must be positive and finite.")


def sorted_values(values, name: str) -> np.ndarray:
    try:
        v = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        text = repr(values)
        raise ValueError(f"values={text if len(text) <= 60 else text[:57] + '...'} of {name} must be numbers."
                         ) from None
    if v.size == 0:
        raise ValueError(f"the values of {name} are empty: give at least one value.")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"the values of {name} must be finite.")
    v = np.sort(v)
    if np.any(np.diff(v) == 0):
        raise ValueError(f"the values of {name} must be distinct.")
    return v


def check_starts(system, x0s) -> np.ndarray:
    x = np.asarray(x0s, dtype=float)
    if x.ndim == 1:
        x = x[None]
    check_state_shape(system, x)
    if x.ndim != 2 or len(x) == 0:
        raise ValueError(f"initial states must have shape (n, {system.dim}) with n >= 1, got {x.shape}.")
    return x


def coord_name(param: str, taken: Sequence[str]) -> str:
    return param if param not in taken else f"param_{param}"


