"""Time integration of a :class:`~jaxgear.ForcedSystem`: strategies behind one interface.

- :class:`KinkAwareRK4` — fixed-step RK4 whose steps are split at the crossings of the
  system's switching surfaces (the default: fourth order through the backlash kinks);
  on CPUs the built-in gear model runs through a compiled kernel (:mod:`._native`);
- :class:`RK4` — classical fixed-step RK4 (the paper's integrator);
- :class:`Adaptive` — any diffrax solver with a PID step-size controller (reference).

Every analysis takes an integrator object and uses only the operations of
:class:`AbstractIntegrator`; :func:`default_integrator` is the one default.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ._adaptive import Adaptive
from ._base import (
    DEFAULT_STEPS_PER_PERIOD,
    AbstractFixedStep,
    AbstractIntegrator,
    batch_field,
    check_steps_per_period,
    stack_params,
)
from ._kink import KinkAwareRK4
from ._rk4 import RK4, rk4_step

__all__ = ["AbstractIntegrator", "AbstractFixedStep", "KinkAwareRK4", "RK4", "Adaptive", "default_integrator",
           "integrator_from_dict", "resolve_integrator", "DEFAULT_STEPS_PER_PERIOD", "batch_field", "rk4_step",
           "check_steps_per_period", "stack_params"]


def default_integrator(steps_per_period: int | None = None) -> AbstractFixedStep:
    """The default integrator, the same for the library and the command line:
    :class:`KinkAwareRK4` with ``steps_per_period`` steps per forcing period (default 200,
    :data:`DEFAULT_STEPS_PER_PERIOD`, chosen by measurement: see the convergence table of
    the documentation's benchmarks page)."""
    steps = DEFAULT_STEPS_PER_PERIOD if steps_per_period is None else check_steps_per_period(steps_per_period)
    return KinkAwareRK4(steps)


def integrator_from_dict(d: Mapping[str, Any]) -> AbstractIntegrator:
    """Rebuild an integrator from :meth:`AbstractIntegrator.to_dict` (also the flat settings
    of files written by jaxgear 0.1: ``{"integrator": "RK4", "steps_per_period": 200}``)."""
    kind = d.get("type", d.get("integrator", "RK4"))
    if kind == "RK4":
        return RK4(int(d.get("steps_per_period") or DEFAULT_STEPS_PER_PERIOD))
    if kind == "KinkAwareRK4":
        if "native" in d:
            native = d["native"]
        else:  # files written before the typed option: backend "auto" (the kernel) or "jax"
            backend = d.get("backend", "auto")
            if backend not in ("auto", "jax"):
                raise ValueError(f"integrator backend={backend!r} in the saved settings; known: 'auto', 'jax'.")
            native = backend == "auto"
        return KinkAwareRK4(int(d.get("steps_per_period") or DEFAULT_STEPS_PER_PERIOD),
                            max_splits=int(d.get("max_splits", 2)), native=native)
    if kind == "Adaptive":
        import diffrax

        name = str(d.get("solver", "Tsit5"))
        cls = getattr(diffrax, name, None) if name.isidentifier() else None
        if not (isinstance(cls, type) and issubclass(cls, diffrax.AbstractSolver)) or getattr(cls, "__abstractmethods__", None):
            raise ValueError(f"solver {name!r} in the saved settings is not a diffrax solver.")
        solver = cls()
        return Adaptive(solver=solver, rtol=float(d.get("rtol", 1e-10)), atol=float(d.get("atol", 1e-10)),
                        max_steps=int(d.get("max_steps", 200_000)),
                        search_steps_per_period=int(d.get("search_steps_per_period", 400)))
    raise ValueError(f"unknown integrator type {kind!r}; known: KinkAwareRK4, RK4, Adaptive.")


def resolve_integrator(integrator) -> AbstractIntegrator:
    """``integrator``, or the default one for ``None``; ``ValueError`` for anything that is
    not an integrator object."""
    if integrator is None:
        return default_integrator()
    if not isinstance(integrator, AbstractIntegrator):
        raise ValueError(f"integrator={integrator!r} must be an integrator object (jaxgear.RK4(...), "
                         "jaxgear.Adaptive(...)) or None for the default.")
    return integrator
