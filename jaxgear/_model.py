"""Equations of motion of the planetary set (paper eq. 1-5, model document §2-§4).

Two :class:`~jaxgear.ForcedSystem` instances:

- :data:`REDUCED` — the reduced 2-DOF model of paper §4.1, state
  ``x = (x1, x2, x3, x4) = (X_sp, X_sp', X_sc, X_sc')`` (model document §4);
- :func:`nplanet_system` — the general model with N planets (N+1 DOF), state
  ``(X_sp1, X_sp1', ..., X_spN, X_spN', X_sc, X_sc')`` (model document §2, dimensionless).

Both are pure functions of ``(t, x, params)`` with ``params`` a :class:`GearParams`;
time is the dimensionless ``tau = omega_n t`` and lengths are in units of ``b_c``.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp

from ._params import GearParams
from ._system import ForcedSystem, NativeKernel

__all__ = [
    "backlash",
    "stiffness_wave",
    "reduced_switching",
    "nplanet_switching",
    "gear_time_breaks",
    "mesh_excitation",
    "reduced_vector_field",
    "nplanet_vector_field",
    "REDUCED",
    "nplanet_system",
    "gear_period",
    "reduced_to_nplanet",
]


def backlash(X, b):
    """Backlash (dead-zone) function f(X, b) of paper eq. (3); ``b`` is the HALF backlash.

    At the kinks ``|X| = b`` the contact branch is taken (non-strict comparisons): the
    value is the same, and with ``b = 0`` the function is exactly ``X`` for autodiff too
    (derivative 1 at ``X = 0``, so the trivial orbit of a backlash-free mesh linearises
    to the Mathieu equation rather than to a free mass).
    """
    return jnp.where(X >= b, X - b, jnp.where(X <= -b, X + b, 0.0))


def backlash_piece(X, b, side_hi, side_lo):
    """The branch of :func:`backlash` on the side ``side_hi`` (+-1) of ``X = b`` and ``side_lo``
    of ``X = -b``, extended across them (model document §8): ``X - b`` in contact on the
    drive side, ``X + b`` on the back side, ``0`` in the gap."""
    return jnp.where(side_hi > 0, X - b, jnp.where(side_lo < 0, X + b, 0.0))


def gear_period(p: GearParams):
    """Forcing (mesh) period ``T = 2 pi / Omega`` in dimensionless time."""
    return 2.0 * jnp.pi / p.Omega


def stiffness_wave(angle, contact_ratio, shape: str):
    """Unit mesh-stiffness variation at phase ``angle`` (rad): ``sin(angle)`` (paper eq. 1),
    or the rectangular wave of single and double tooth contact whose first harmonic it is
    (paper §2.1): ``(pi / (2 sin(pi d))) (1_double - d)`` with ``d = contact_ratio - 1``
    the fraction of the mesh period in double contact, centred where the sine peaks."""
    if shape == "sine":
        return jnp.sin(angle)
    d = contact_ratio - 1.0
    u = jnp.mod(angle - 0.5 * jnp.pi + jnp.pi * d, 2.0 * jnp.pi)  # 0 where double contact starts
    double = u < 2.0 * jnp.pi * d
    return (jnp.pi / (2.0 * jnp.sin(jnp.pi * d))) * (jnp.where(double, 1.0, 0.0) - d)


def mesh_excitation(t, p: GearParams):
    """Time-varying stiffness and errors (paper eq. 1-2, model document §4) at time ``t``.

    Returns ``k_sp, k_rp, e_sp, e_sp', e_sp'', e_rp, e_rp'`` (each scalar or per-planet).
    These depend on time only, so under ``vmap`` over states they are computed once
    and shared by every state. ``p.mesh_shape`` selects the sine stiffness or the
    rectangular wave (:func:`stiffness_wave`).
    """
    W = p.Omega
    k_sp = p.kappa_sp_mean + p.kappa_sp_amp * stiffness_wave(W * t + p.phi_sp, p.contact_ratio_sp, p.mesh_shape)
    k_rp = p.kappa_rp_mean + p.kappa_rp_amp * stiffness_wave(W * t + p.phi_rp, p.contact_ratio_rp, p.mesh_shape)
    a_sp = W * t + p.beta_sp
    a_rp = W * t + p.beta_rp + p.gamma_sr
    s_sp, c_sp = jnp.sin(a_sp), jnp.cos(a_sp)
    e_sp = p.e_sp_amp * s_sp
    de_sp = p.e_sp_amp * W * c_sp
    dde_sp = -p.e_sp_amp * W * W * s_sp
    e_rp = p.e_rp_amp * jnp.sin(a_rp)
    de_rp = p.e_rp_amp * W * jnp.cos(a_rp)
    return k_sp, k_rp, e_sp, de_sp, dde_sp, e_rp, de_rp


def reduced_vector_field(t, x, p: GearParams, sides=None):
    """Reduced 2-DOF model (model document §4): identical planets, ``x = (X_sp, X_sp', X_sc, X_sc')``.

    ``x1' = x2``, ``x2' = -(N + mu_p) g_sp + (mu_p - N mu_c) g_rp + mu_s f_D + mu_c f_L - e_sp''``,
    ``x3' = x4``, ``x4' = -N (mu_s + 2 mu_c) g_sp - 2 N mu_c g_rp + mu_s f_D + 2 mu_c f_L``,
    with the mesh forces ``g`` of paper eq. (3) and (5).

    Dimensionless (model document §3): ``t`` is ``tau = omega_n t``, ``x1 = X_sp`` and
    ``x3 = X_sc`` are relative displacements in ``b_c``, ``x2``, ``x4`` their rates;
    ``x`` has shape ``(4,)``. Returns ``dx/dtau``, shape ``(4,)``. With ``sides`` (the signs
    of :func:`reduced_switching`, shape ``(4,)``) the field's smooth piece on those sides.
    """
    x1, x2, x3, x4 = x[0], x[1], x[2], x[3]
    k_sp, k_rp, e_sp, de_sp, dde_sp, e_rp, de_rp = mesh_excitation(t, p)
    X_rp = x3 - x1 - e_sp - e_rp
    V_rp = x4 - x2 - de_sp - de_rp
    if sides is None:
        d_sp, d_rp = backlash(x1, p.b_sp), backlash(X_rp, p.b_rp)
    else:
        d_sp = backlash_piece(x1, p.b_sp, sides[0], sides[1])
        d_rp = backlash_piece(X_rp, p.b_rp, sides[2], sides[3])
    g_sp = k_sp * d_sp + p.c_sp * x2
    g_rp = k_rp * d_rp + p.c_rp * V_rp
    N = p.N
    load1 = p.mu_s * p.f_D + p.mu_c * p.f_L - dde_sp
    load2 = p.mu_s * p.f_D + 2.0 * p.mu_c * p.f_L
    dx2 = -(N + p.mu_p) * g_sp + (p.mu_p - N * p.mu_c) * g_rp + load1
    dx4 = -N * (p.mu_s + 2.0 * p.mu_c) * g_sp - 2.0 * N * p.mu_c * g_rp + load2
    return jnp.stack([x2, dx2, x4, dx4])


def nplanet_vector_field(t, x, p: GearParams, sides=None):
    """General N-planet model (model document §2 in dimensionless form), N+1 DOF.

    State ``(X_sp1, V_sp1, ..., X_spN, V_spN, X_sc, V_sc)``; per-planet stiffness,
    errors, backlash, damping, phases and planet masses (``mu_p`` per planet):

    ``X_spi'' = mu_s f_D + mu_c f_L - e_spi'' - (mu_s + mu_c) sum_j g_spj - mu_c sum_j g_rpj
    - mu_pi (g_spi - g_rpi)``, ``X_sc'' = mu_s f_D + 2 mu_c f_L - (mu_s + 2 mu_c) sum_j g_spj
    - 2 mu_c sum_j g_rpj``. With ``sides`` (the signs of :func:`nplanet_switching`, shape
    ``(4N,)``) the field's smooth piece on those sides.
    """
    N = p.N
    X = x[0 : 2 * N : 2]
    V = x[1 : 2 * N : 2]
    Xsc, Vsc = x[2 * N], x[2 * N + 1]
    k_sp, k_rp, e_sp, de_sp, dde_sp, e_rp, de_rp = mesh_excitation(t, p)
    X_rp = Xsc - X - e_sp - e_rp
    V_rp = Vsc - V - de_sp - de_rp
    if sides is None:
        d_sp, d_rp = backlash(X, p.b_sp), backlash(X_rp, p.b_rp)
    else:
        d_sp = backlash_piece(X, p.b_sp, sides[0:N], sides[N:2 * N])
        d_rp = backlash_piece(X_rp, p.b_rp, sides[2 * N:3 * N], sides[3 * N:4 * N])
    g_sp = k_sp * d_sp + p.c_sp * V
    g_rp = k_rp * d_rp + p.c_rp * V_rp
    S_sp, S_rp = jnp.sum(g_sp), jnp.sum(g_rp)
    dde_sp = jnp.broadcast_to(dde_sp, (N,))
    acc = (p.mu_s * p.f_D + p.mu_c * p.f_L - dde_sp
           - (p.mu_s + p.mu_c) * S_sp - p.mu_c * S_rp - p.mu_p * (g_sp - g_rp))
    acc_sc = p.mu_s * p.f_D + 2.0 * p.mu_c * p.f_L - (p.mu_s + 2.0 * p.mu_c) * S_sp - 2.0 * p.mu_c * S_rp
    pos_vel = jnp.stack([V, acc], axis=-1).reshape(-1)
    return jnp.concatenate([pos_vel, jnp.stack([Vsc, acc_sc])])


def reduced_switching(t, x, p: GearParams):
    """Switching functions of the reduced model: ``x1 -+ b_sp`` and ``X_rp -+ b_rp``, where
    the backlash function of paper eq. (3) has its kinks (model document §8)."""
    _, _, e_sp, _, _, e_rp, _ = mesh_excitation(t, p)
    X_rp = x[2] - x[0] - e_sp - e_rp
    return jnp.stack([x[0] - p.b_sp, x[0] + p.b_sp, X_rp - p.b_rp, X_rp + p.b_rp])


def nplanet_switching(t, x, p: GearParams):
    """Switching functions of the N-planet model: ``X_spi -+ b_sp`` and ``X_rpi -+ b_rp`` for
    every planet ``i`` (``4N`` functions)."""
    N = p.N
    X = x[0: 2 * N: 2]
    _, _, e_sp, _, _, e_rp, _ = mesh_excitation(t, p)
    X_rp = x[2 * N] - X - e_sp - e_rp
    b_sp = jnp.broadcast_to(p.b_sp, (N,))
    b_rp = jnp.broadcast_to(p.b_rp, (N,))
    return jnp.concatenate([X - b_sp, X + b_sp, X_rp - b_rp, X_rp + b_rp])


def gear_time_breaks(p: GearParams):
    """Phases in ``[0, 1)`` of the forcing period where the rectangular stiffness wave jumps
    (two per mesh: double contact starts and ends); none for the sine."""
    if p.mesh_shape == "sine":
        return jnp.zeros((0,))
    out = []
    for phi, eps in ((p.phi_sp, p.contact_ratio_sp), (p.phi_rp, p.contact_ratio_rp)):
        d = eps - 1.0
        for edge in (0.5 * jnp.pi - jnp.pi * d, 0.5 * jnp.pi + jnp.pi * d):
            out.append(jnp.ravel(jnp.mod((edge - phi) / (2.0 * jnp.pi), 1.0)))
    return jnp.concatenate(out)


REDUCED = ForcedSystem(
    vector_field=reduced_vector_field,
    period=gear_period,
    state_names=("x1", "x2", "x3", "x4"),
    section_index=3,
    name="planetary-reduced",
    switching=reduced_switching,
    piece_field=reduced_vector_field,
    time_breaks=gear_time_breaks,
    native=NativeKernel.REDUCED,
)
"""The reduced 2-DOF model of paper §4.1; Σ = {x4 = 0} is its default section."""


@functools.cache
def nplanet_system(N: int) -> ForcedSystem:
    """The general model with ``N`` planets (paper eq. 5) as a :class:`ForcedSystem`.

    State names ``X_sp1, V_sp1, ..., X_spN, V_spN, X_sc, V_sc`` (shape ``(2N + 2,)``,
    dimensionless: displacements in ``b_c``, time ``tau = omega_n t``, model document §3);
    the default section is ``{V_sc = 0}``, the N-planet counterpart of Σ = {x4 = 0}.
    Raises ``ValueError`` for ``N < 1``.
    """
    if int(N) < 1:
        raise ValueError(f"N={N}: the number of planets must be >= 1.")
    names = sum(((f"X_sp{i}", f"V_sp{i}") for i in range(1, N + 1)), ()) + ("X_sc", "V_sc")
    return ForcedSystem(
        vector_field=nplanet_vector_field,
        period=gear_period,
        state_names=names,
        section_index=2 * N + 1,
        name=f"planetary-{N}-planets",
        switching=nplanet_switching,
        piece_field=nplanet_vector_field,
        time_breaks=gear_time_breaks,
    )


def reduced_to_nplanet(x, N: int):
    """Reduced state(s) ``(..., 4)`` -> N-planet state(s) ``(..., 2N+2)`` with identical planets.

    Every planet gets ``(x1, x2)``; the carrier ``(x3, x4)`` (model document §4: the reduced
    model is the N-planet model of paper eq. 5 on its symmetric subspace). Same units.
    """
    x = jnp.asarray(x)
    planets = jnp.tile(x[..., 0:2], (1,) * (x.ndim - 1) + (N,))
    return jnp.concatenate([planets, x[..., 2:4]], axis=-1)
