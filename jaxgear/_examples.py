"""Small forced systems with known answers, used in examples and tests.

- :data:`DUFFING` — the forced Duffing oscillator ``x'' + delta x' + alpha x + beta x^3
  = gamma cos(omega t)`` (``beta = 0`` is the forced linear oscillator, closed form);
- :data:`SPUR_PAIR` — the classic single-DOF spur-gear pair with backlash and mesh
  stiffness variation (dimensionless, Kahraman & Singh type):
  ``x'' + 2 zeta x' + (1 + kappa sin(Omega t)) f(x, b) = f_m + e_amp Omega^2 sin(Omega t)``;
  with ``b = 0``, ``f_m = e_amp = 0`` it is the damped Mathieu equation;
- :data:`PARAM_DUFFING` — the parametrically excited Duffing oscillator
  ``x'' + 2 zeta x' + (1 + epsilon cos(Omega t)) x + beta x^3 = 0`` (a Mathieu-type
  system: ``x = 0`` is a P-1 orbit for every ``Omega``, unstable inside the tongues
  around ``Omega = 2/n``, with a P-2 branch born by period doubling at the edges of
  the first tongue);
- :data:`VAN_DER_POL` — the forced van der Pol oscillator
  ``x'' - mu (1 - x^2) x' + x = F cos(omega t)``: self-excited, so a weak forcing at a
  frequency far from a low-order resonance leaves it unlocked (quasi-periodic motion on
  a torus), a strong one locks it (a periodic orbit).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax.numpy as jnp

from ._model import backlash
from ._params import params_type
from ._system import ForcedSystem

__all__ = ["DuffingParams", "DUFFING", "SpurPairParams", "SPUR_PAIR", "ParamDuffingParams", "PARAM_DUFFING",
           "VanDerPolParams", "VAN_DER_POL"]


def _f64(x):
    return jnp.asarray(x, dtype=jnp.float64)


@params_type
class DuffingParams(eqx.Module):
    """Forced Duffing parameters of ``x'' + delta x' + alpha x + beta x^3 = gamma cos(omega t)``.

    A system of the form of paper eq. (6) with known answers (closed form for
    ``beta = 0``), used to check the methods of paper §3-§4. Scalars in consistent
    units of the user's choice (time ``t``, displacement ``x``): ``delta`` [1/time],
    ``alpha`` [1/time²], ``beta`` [1/(time² x²)], ``gamma`` [x/time²], ``omega``
    [rad/time]; the forcing period is ``2 pi / omega``. All fields are float64 arrays
    (scalars, or a leading batch axis for sweeps), so a sweep does not recompile.
    """

    delta: Any = eqx.field(converter=_f64, default=0.1)
    alpha: Any = eqx.field(converter=_f64, default=1.0)
    beta: Any = eqx.field(converter=_f64, default=0.0)
    gamma: Any = eqx.field(converter=_f64, default=1.0)
    omega: Any = eqx.field(converter=_f64, default=1.0)


def _duffing_field(t, x, p: DuffingParams):
    return jnp.stack([x[1], p.gamma * jnp.cos(p.omega * t) - p.delta * x[1] - p.alpha * x[0] - p.beta * x[0] ** 3])


DUFFING = ForcedSystem(
    vector_field=_duffing_field,
    period=lambda p: 2.0 * jnp.pi / p.omega,
    state_names=("x", "v"),
    section_index=1,
    name="duffing",
)
"""Forced Duffing oscillator, state ``(x, v)``, period ``2 pi / omega``."""


@params_type
class SpurPairParams(eqx.Module):
    """Single spur-gear pair with backlash (dimensionless; the one-mesh analogue of paper eq. 3-5).

    ``x'' + 2 zeta x' + (1 + kappa sin(Omega t)) f(x, b) = f_m + e_amp Omega^2 sin(Omega t)``
    with ``f`` the backlash function of paper eq. (3). Time in ``1/omega_n``
    (``omega_n`` the natural frequency of the mean mesh stiffness), lengths in a
    characteristic length ``b_c`` (as docs/model.md §3): ``zeta`` damping ratio, ``kappa``
    relative stiffness amplitude, ``b`` half backlash, ``f_m`` mean load (static
    deflection), ``e_amp`` transmission-error amplitude, ``Omega`` mesh frequency
    (forcing period ``2 pi / Omega``). All fields are float64 arrays.
    """

    zeta: Any = eqx.field(converter=_f64, default=0.05)
    kappa: Any = eqx.field(converter=_f64, default=0.2)
    b: Any = eqx.field(converter=_f64, default=1.0)
    f_m: Any = eqx.field(converter=_f64, default=0.1)
    e_amp: Any = eqx.field(converter=_f64, default=0.1)
    Omega: Any = eqx.field(converter=_f64, default=1.0)


def _spur_field(t, x, p: SpurPairParams):
    k = 1.0 + p.kappa * jnp.sin(p.Omega * t)
    acc = p.f_m + p.e_amp * p.Omega**2 * jnp.sin(p.Omega * t) - 2.0 * p.zeta * x[1] - k * backlash(x[0], p.b)
    return jnp.stack([x[1], acc])


SPUR_PAIR = ForcedSystem(
    vector_field=_spur_field,
    period=lambda p: 2.0 * jnp.pi / p.Omega,
    state_names=("x", "v"),
    section_index=1,
    name="spur-pair",
)
"""Single spur-gear pair with backlash, state ``(x, v)`` (dynamic transmission error)."""


@params_type
class ParamDuffingParams(eqx.Module):
    """Parametrically excited Duffing parameters: damping ratio ``zeta``, stiffness
    modulation depth ``epsilon``, cubic stiffness ``beta``, excitation frequency ``Omega``
    (time scaled by the natural frequency; all float64 arrays)."""

    zeta: Any = eqx.field(converter=_f64, default=0.005)
    epsilon: Any = eqx.field(converter=_f64, default=0.1)
    beta: Any = eqx.field(converter=_f64, default=1.0)
    Omega: Any = eqx.field(converter=_f64, default=2.0)


def _param_duffing_field(t, x, p: ParamDuffingParams):
    k = 1.0 + p.epsilon * jnp.cos(p.Omega * t)
    return jnp.stack([x[1], -2.0 * p.zeta * x[1] - k * x[0] - p.beta * x[0] ** 3])


PARAM_DUFFING = ForcedSystem(
    vector_field=_param_duffing_field,
    period=lambda p: 2.0 * jnp.pi / p.Omega,
    state_names=("x", "v"),
    section_index=1,
    name="param-duffing",
)
"""Parametrically excited Duffing oscillator ``x'' + 2 zeta x' + (1 + epsilon cos(Omega t)) x
+ beta x^3 = 0``, state ``(x, v)``, period ``2 pi / Omega``.

Its linearisation at ``x = 0`` is the damped Mathieu equation. To first order in
``epsilon`` (harmonic balance with ``x = a cos(Omega t/2) + b sin(Omega t/2)``) the
trivial orbit loses stability by period doubling (a Floquet multiplier through -1) on
the edges of the first tongue, ``(1 - Omega^2/4)^2 = (epsilon^2 - 4 zeta^2 Omega^2)/4``,
i.e. ``Omega_pm ~ 2 sqrt(1 +- sqrt(epsilon^2 - 16 zeta^2)/2)``; the P-2 branch of
amplitude ``A`` satisfies ``(1 - Omega^2/4 + 3 beta A^2/4)^2 + zeta^2 Omega^2 = epsilon^2/4``.
"""


@params_type
class VanDerPolParams(eqx.Module):
    """Forced van der Pol parameters of ``x'' - mu (1 - x^2) x' + x = F cos(omega t)``.

    Time scaled by the natural frequency of the linear part, ``x`` by its own unit:
    ``mu`` the strength of the nonlinear (negative at small amplitude) damping, ``F``
    the forcing amplitude, ``omega`` the forcing frequency (period ``2 pi / omega``).
    Without forcing the oscillator has a stable limit cycle of amplitude ``~2`` and
    frequency ``~1`` (for small ``mu``), whose transverse Floquet exponent is ``~ -mu``
    per unit time (van der Pol, Phil. Mag. 2, 978, 1926; Guckenheimer & Holmes,
    Nonlinear Oscillations, Springer 1983, §2.1). A weak forcing (``F`` small) at a
    frequency whose ratio to 1 is far from every ratio of small integers leaves the
    motion quasi-periodic; a forcing inside an Arnold tongue locks it. All fields are
    float64 arrays.
    """

    mu: Any = eqx.field(converter=_f64, default=0.1)
    F: Any = eqx.field(converter=_f64, default=0.05)
    omega: Any = eqx.field(converter=_f64, default=(1.0 + 5.0**0.5) / 2.0)


def _van_der_pol_field(t, x, p: VanDerPolParams):
    return jnp.stack([x[1], p.mu * (1.0 - x[0] ** 2) * x[1] - x[0] + p.F * jnp.cos(p.omega * t)])


VAN_DER_POL = ForcedSystem(
    vector_field=_van_der_pol_field,
    period=lambda p: 2.0 * jnp.pi / p.omega,
    state_names=("x", "v"),
    section_index=1,
    name="van-der-pol",
)
"""Forced van der Pol oscillator, state ``(x, v)``, period ``2 pi / omega``."""
