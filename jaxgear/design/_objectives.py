"""Scalars of a periodic orbit to design for: mesh forces, transmission error, multipliers.

A converged orbit is sampled over its ``k`` periods (:func:`sample_orbit`, a
differentiable pytree :class:`OrbitSamples`); the functions here reduce it to scalars in
JAX (peak-to-peak and RMS dynamic mesh forces of the gear models, model document §4,
``g_sp`` and ``g_rp``; the dynamic transmission error; the largest Floquet multiplier),
so ``jax.grad`` of a scalar with respect to the parameters is exact for the discrete map.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._checks import check_enum, check_int
from .._model import backlash, mesh_excitation
from .._params import GearParams
from .._system import ForcedSystem
from ..integrate import DEFAULT_STEPS_PER_PERIOD, AbstractIntegrator, resolve_integrator
from ..shooting._floquet import check_period

__all__ = ["OrbitSamples", "sample_orbit", "MeshForces", "GearMesh", "mesh_forces", "transmission_error",
           "peak_to_peak", "rms", "max_multiplier", "mesh_force_ptp", "mesh_force_rms", "transmission_error_rms"]


class GearMesh(enum.StrEnum):
    """Which mesh of the gear models a design scalar reads (:func:`mesh_force_ptp`,
    :func:`mesh_force_rms`, :func:`transmission_error`, ...: their ``mesh``). A
    ``StrEnum``: each member equals its text (``"sp"``, ``"rp"``, ``"both"``), which the
    functions also accept."""

    SP = "sp"
    """The sun-planet mesh(es)."""
    RP = "rp"
    """The ring-planet mesh(es)."""
    BOTH = "both"
    """Both meshes, their values summed (the mesh-force scalars only)."""


class OrbitSamples(eqx.Module):
    """A periodic orbit sampled over its ``k`` forcing periods (a differentiable pytree).

    Attributes:
        point: ``(dim,)`` the orbit's point ``x*`` at time ``t0`` (fixed point of ``P^k``).
        times: ``(m,)`` sample times ``t0 + j T / s``, ``j = 0..m-1``, ``m = k s``
            (``s`` samples per period; the end point ``t0 + kT``, equal to the start on
            a periodic orbit, is left out so means and RMS values are exact averages).
        states: ``(m, dim)`` states at ``times`` (``states[0] = point``).
        period: ``k`` (forcing periods).
        t0: phase of the stroboscopic section.
        system, integrator: the system and the integrator that produced the samples.
    """

    point: jax.Array
    times: jax.Array
    states: jax.Array
    t0: jax.Array
    period: int = eqx.field(static=True)
    system: ForcedSystem = eqx.field(static=True)
    integrator: AbstractIntegrator = eqx.field(static=True)


def sample_orbit(system: ForcedSystem, params, point, *, period: int = 1, t0=0.0, samples_per_period: int | None = None,
                 integrator: AbstractIntegrator | None = None) -> OrbitSamples:
    """Sample the trajectory from ``point`` over ``period`` forcing periods (differentiable).

    The integrator's :meth:`~jaxgear.integrate.AbstractIntegrator.trajectory` (forward- and
    reverse-mode differentiable in ``params`` and ``point``). ``samples_per_period``
    defaults to the integrator's ``steps_per_period`` so every sample is a step of the
    shooting map itself and the sampled orbit closes to the shooting residual.
    """
    k = check_period(period)
    integrator = resolve_integrator(integrator)
    s = check_int(samples_per_period if samples_per_period is not None else
                  getattr(integrator, "steps_per_period", DEFAULT_STEPS_PER_PERIOD), "samples_per_period", 2)
    point = jnp.asarray(point, jnp.float64)
    if point.shape != (system.dim,):
        raise ValueError(f"{system.name}: point must have shape ({system.dim},), got {point.shape}.")
    t0 = jnp.asarray(t0, jnp.float64)
    ts, Ys = integrator.trajectory(system, params, point[:, None], t0, k, s)
    xs = Ys[:, :, 0]
    return OrbitSamples(point=point, times=ts[:-1], states=xs[:-1], t0=t0, period=k, system=system,
                        integrator=integrator)


def _times_states(orbit):
    if isinstance(orbit, OrbitSamples):
        return orbit.times, orbit.states
    ts, xs = orbit
    return jnp.asarray(ts), jnp.asarray(xs)


class MeshForces(NamedTuple):
    """Dynamic mesh forces along an orbit (model document §4: ``g = F / (k_msp b_c)``).

    ``sp``, ``rp``: sun-planet and ring-planet mesh forces, shape ``(m,)`` for the
    reduced model (every planet alike) or ``(m, N)`` for the N-planet model.
    """

    sp: jax.Array
    rp: jax.Array


def _is_reduced(params, dim: int) -> bool:
    """Whether states of dimension ``dim`` are the reduced gear model's (``True``) or the
    ``params.N``-planet model's (``False``); anything else is refused."""
    if not isinstance(params, GearParams):
        raise ValueError("mesh forces are defined for the gear models (GearParams); for your own system "
                         "compute the force from orbit.states in the objective.")
    if dim == 4:
        return True
    if dim == 2 * params.N + 2:
        return False
    raise ValueError(f"a state of dimension {dim} is neither the reduced gear model (4) nor the "
                     f"{params.N}-planet model ({2 * params.N + 2}).")


def mesh_forces(params, orbit) -> MeshForces:
    """Sun-planet and ring-planet mesh forces along a sampled orbit (model document §4).

    ``g_sp = k_sp(t) f(X_sp, b_sp) + c_sp X_sp'`` and ``g_rp = k_rp(t) f(X_rp, b_rp) +
    c_rp X_rp'`` with ``X_rp = X_sc - X_sp - e_sp - e_rp`` (paper eq. 3-5), dimensionless
    (force over ``k_msp b_c``; the static mean of both is ``f_D / N``).

    Args:
        params: :class:`~jaxgear.GearParams`.
        orbit: an :class:`OrbitSamples` of the reduced or the N-planet model, or a pair
            ``(times (m,), states (m, dim))``.
    """
    ts, xs = _times_states(orbit)
    reduced = _is_reduced(params, xs.shape[-1])

    def one(t, x):
        k_sp, k_rp, e_sp, de_sp, _, e_rp, de_rp = mesh_excitation(t, params)
        if reduced:
            X, V, Xsc, Vsc = x[0], x[1], x[2], x[3]
        else:
            N = params.N
            X, V, Xsc, Vsc = x[0:2 * N:2], x[1:2 * N:2], x[2 * N], x[2 * N + 1]
        X_rp = Xsc - X - e_sp - e_rp
        V_rp = Vsc - V - de_sp - de_rp
        g_sp = k_sp * backlash(X, params.b_sp) + params.c_sp * V
        g_rp = k_rp * backlash(X_rp, params.b_rp) + params.c_rp * V_rp
        return g_sp, g_rp

    g_sp, g_rp = jax.vmap(one)(ts, xs)
    return MeshForces(g_sp, g_rp)


def transmission_error(params, orbit, mesh: GearMesh | str = GearMesh.SP):
    """Dynamic transmission error along a sampled gear orbit, ``(m,)`` or ``(m, N)``.

    The mesh deflection along the line of action net of the static error (the relative
    displacement the mesh force acts on, in units of ``b_c``): ``X_sp = x1`` for
    ``mesh="sp"``, ``X_rp = x3 - x1 - e_sp - e_rp`` for ``mesh="rp"`` (model document §4);
    ``mesh`` is a :class:`GearMesh` (``SP`` or ``RP``) or its text.
    """
    mesh = _one_mesh(mesh)
    ts, xs = _times_states(orbit)
    reduced = _is_reduced(params, xs.shape[-1])
    N = params.N
    X = xs[:, 0] if reduced else xs[:, 0:2 * N:2]
    if mesh == GearMesh.SP:
        return X
    Xsc = xs[:, 2] if reduced else xs[:, 2 * N][:, None]
    _, _, e_sp, _, _, e_rp, _ = jax.vmap(lambda t: mesh_excitation(t, params))(ts)
    if not reduced:
        e_sp = jnp.broadcast_to(jnp.reshape(e_sp, (len(ts), -1)), X.shape)
        e_rp = jnp.broadcast_to(jnp.reshape(e_rp, (len(ts), -1)), X.shape)
    return Xsc - X - e_sp - e_rp


def peak_to_peak(x, axis: int = 0, smooth: float | None = None):
    """``max - min`` of samples along ``axis``.

    Exact max/min by default (differentiable almost everywhere: the gradient flows
    through the extreme samples). ``smooth=s > 0`` uses the log-sum-exp soft maximum
    ``s log sum exp(x / s)`` (and the soft minimum likewise), which over-estimates the
    range by at most ``2 s log m`` and is smooth everywhere.
    """
    x = jnp.asarray(x)
    if smooth is None:
        return jnp.max(x, axis=axis) - jnp.min(x, axis=axis)
    if not smooth > 0:
        raise ValueError(f"smooth={smooth} must be > 0 (or None for the exact range).")
    s = float(smooth)
    return s * (jax.nn.logsumexp(x / s, axis=axis) + jax.nn.logsumexp(-x / s, axis=axis))


def rms(x, axis: int = 0, remove_mean: bool = True):
    """Root mean square of samples along ``axis``; ``remove_mean=True`` (default) gives the
    RMS of the dynamic (fluctuating) part, i.e. the standard deviation over the period."""
    x = jnp.asarray(x)
    if remove_mean:
        x = x - jnp.mean(x, axis=axis, keepdims=True)
    return jnp.sqrt(jnp.mean(x * x, axis=axis))


def _one_mesh(mesh) -> GearMesh:
    """``mesh`` as ``GearMesh.SP`` or ``GearMesh.RP`` (a quantity of one mesh)."""
    m = check_enum(mesh, "mesh", GearMesh)
    if m == GearMesh.BOTH:
        raise ValueError(f"mesh={mesh!r} must be one of 'sp', 'rp' (a quantity of one mesh).")
    return m


def _fields(mesh) -> tuple[str, ...]:
    """The :class:`MeshForces` fields ``mesh`` (a :class:`GearMesh` or its text) names."""
    return {GearMesh.SP: ("sp",), GearMesh.RP: ("rp",), GearMesh.BOTH: ("sp", "rp")}[
        check_enum(mesh, "mesh", GearMesh)]


def mesh_force_ptp(params, orbit, mesh: GearMesh | str = GearMesh.SP, smooth: float | None = None):
    """Peak-to-peak dynamic mesh force over the orbit (largest over planets; ``mesh`` a
    :class:`GearMesh` or its text, ``"both"`` sums the sun-planet and ring-planet values).
    Dimensionless (force / ``k_msp b_c``)."""
    names = _fields(mesh)
    forces = mesh_forces(params, orbit)
    return sum(jnp.max(peak_to_peak(getattr(forces, name), 0, smooth)) for name in names)


def mesh_force_rms(params, orbit, mesh: GearMesh | str = GearMesh.SP):
    """RMS of the dynamic part of the mesh force over the orbit (largest over planets;
    ``mesh`` a :class:`GearMesh` or its text, ``"both"`` sums the two meshes).
    Dimensionless (force / ``k_msp b_c``)."""
    names = _fields(mesh)
    forces = mesh_forces(params, orbit)
    return sum(jnp.max(rms(getattr(forces, name), 0)) for name in names)


def transmission_error_rms(params, orbit, mesh: GearMesh | str = GearMesh.SP):
    """RMS of the dynamic transmission error (:func:`transmission_error`, mean removed),
    largest over planets, in units of ``b_c``."""
    return jnp.max(rms(transmission_error(params, orbit, mesh), 0))


def max_multiplier(params, orbit: OrbitSamples):
    """Largest Floquet multiplier modulus ``max |eig(D P^k(x*))|`` of a sampled orbit.

    Differentiable in ``params`` (through the implicit ``x*`` and the monodromy matrix
    from ``jax.jacfwd``) wherever the largest eigenvalue is simple (for a complex pair
    the modulus of the pair). ``< 1``: asymptotically stable.
    """
    if not isinstance(orbit, OrbitSamples):
        raise ValueError("max_multiplier needs an OrbitSamples (from sample_orbit or a design objective).")
    M = jax.jacfwd(lambda z: orbit.integrator.flow(orbit.system, params, z, orbit.t0, orbit.period))(orbit.point)
    return jnp.max(jnp.abs(jnp.linalg.eigvals(M)))


