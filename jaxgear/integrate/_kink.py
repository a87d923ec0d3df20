"""Kink-aware fixed-step RK4: steps split at the crossings of a system's switching surfaces.

A piecewise-smooth vector field (the backlash of the gear models: kinks at ``|X| = b``)
costs a classical RK4 step that straddles a kink two orders of accuracy. Here every
step is first taken as a plain RK4 step (the *trial*); for a lane whose switching
functions ``s(t, x)`` change sign over it, or whose step contains a known time break,
the crossing is located on the cubic Hermite interpolant of the switching function
(values and time derivatives at both ends of the trial step; a known break is exact),
and the step is redone as sub-steps that end and start on the surface, each evaluated
on its own smooth piece of the field (``ForcedSystem.piece_field``); one Newton
correction lands the sub-step's end on the surface to round-off. States then converge
at fourth order, and ``jax.jacfwd`` through the steps converges at fourth order to the
monodromy matrix of the flow, saltation included (identity where the field only kinks;
model document §8).

The lanes that need a split (a few per cent per step) are gathered in chunks in large
batches, and selected from a whole-batch computation in small ones, event by event and
only for the lanes that still have one, without leaving ``jit`` and without restarting
the integrator; the compiled CPU kernel
for the gear models (:mod:`jaxgear.integrate._native`) gathers them per block of lanes.
"""

from __future__ import annotations

import functools
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

# lineax defines the (zero) transpose of stop_gradient, which reverse-mode derivatives
# through the landing's stop-gradient step lengths need (jax.grad of an orbit scalar
# through implicit differentiation); import it with the steps, not by accident elsewhere
import lineax  # noqa: F401
import numpy as np
from jax.custom_derivatives import SymbolicZero

from .._checks import check_bool, check_int
from ._base import DEFAULT_STEPS_PER_PERIOD, AbstractFixedStep, batch_field, check_steps_per_period
from ._rk4 import rk4_step

__all__ = ["KinkAwareRK4", "kink_step", "trial_step", "BREAK_TOL"]

DENSE_MAX = 1024
"""Batches up to this size handle each event with one select over the batch (one fused
computation per stage); larger batches gather the lanes that have one."""
COMPACT_FRACTION = 256
"""On a CPU, large batches gather the lanes with an event in chunks of ``n /
COMPACT_FRACTION`` lanes (at least ``CHUNK_MIN``), as many chunks as there are such lanes
(a few per cent of the lanes per step): small chunks waste little on a partly filled last
chunk, and a chunk's fixed cost is small next to its lanes' work (measured: chunks of
n/32 to n/512 lanes of the paper grid cost 162, 119, 118, 120 ns per step and cell before
the other savings)."""
COMPACT_FRACTION_ACCELERATOR = 8
"""The same on other platforms (GPUs): few wide chunks, each operation being a kernel
launch there."""
CHUNK_MIN = 256

SIMULTANEOUS = 1e-12
"""Crossings within this fraction of a step of the first one are the same event (all
their sides flip together)."""

BREAK_TOL = 1e-10
"""A known time break within ``BREAK_TOL * T`` of a step's end lies on that end: no split,
and the step's stage times are kept that far inside the step (model document §8)."""

_HERMITE_ITERS = 12
_EPS = 2.220446049250313e-16


def _sides(S):
    return jnp.where(S >= 0, 1.0, -1.0)


def _has_breaks(system, params) -> bool:
    """Whether the system has known time breaks for these parameters (a static property:
    the number of breaks is the shape of ``time_breaks(params)``)."""
    return system.time_breaks is not None and jax.eval_shape(system.time_breaks, params).shape[0] > 0


@functools.partial(jax.jit, static_argnums=0)
def _switching(system, params, t, Y):
    """Switching functions on a batch: ``(m, n)`` (``m = 0`` without any). Jitted, as
    :func:`~jaxgear.integrate.batch_field` is, so a step traces it once per shapes."""
    if system.switching is None:
        return jnp.zeros((0, Y.shape[1]), Y.dtype)
    in_t = None if jnp.ndim(t) == 0 else 0
    return jax.vmap(system.switching, in_axes=(in_t, 1, None), out_axes=1)(t, Y, params)


@functools.partial(jax.jit, static_argnums=0)
def _switching_rate(system, params, t, Y, F):
    """Time derivative of the switching functions along the flow, ``ds/dt = s_t + s_x f``: ``(m, n)``.
    ``t`` is a scalar (time-only terms and their rates once for the batch) or ``(n,)``."""
    if system.switching is None:
        return jnp.zeros((0, Y.shape[1]), Y.dtype)

    def one(ti, y, f):
        return jax.jvp(lambda a, b: system.switching(a, b, params), (ti, y), (jnp.ones_like(ti), f))[1]

    return jax.vmap(one, in_axes=(None if jnp.ndim(t) == 0 else 0, 1, 1), out_axes=1)(t, Y, F)


def _break_fraction(system, params, t, h):
    """Where a known time break falls inside each step, as a fraction ``theta`` of the step
    (``(n,)`` or scalar; ``1`` when none lies strictly inside, more than ``BREAK_TOL * T``
    from either end)."""
    if not _has_breaks(system, params):
        return jnp.ones_like(t + h)
    phases = jnp.asarray(system.time_breaks(params))
    T = system.period(params)
    tol = BREAK_TOL * T
    t, h = jnp.asarray(t), jnp.asarray(h)
    shape = jnp.broadcast_shapes(t.shape, h.shape)
    wait = jnp.mod(phases.reshape((-1,) + (1,) * len(shape)) - t / T, 1.0) * T  # time to each break
    inside = (wait > tol) & (wait < h - tol)
    return jnp.min(jnp.where(inside, wait / h, 1.0), axis=0)


def _field(system, params, t, Y, t_lo=None, t_hi=None, sides=None):
    """The vector field on a batch, with stage times kept inside ``[t_lo, t_hi]`` (systems
    with time breaks) and, given ``sides`` (``(m, n)`` of +-1) and a system with a
    ``piece_field``, the smooth piece of those sides of the switching surfaces, extended
    across them."""
    if t_lo is not None:
        t = jnp.clip(t, t_lo, t_hi)
    if sides is None or system.piece_field is None:
        return batch_field(system, params, t, Y)
    return _piece_field(system, params, t, Y, sides)


@functools.partial(jax.jit, static_argnums=0)
def _piece_field(system, params, t, Y, sides):
    """The system's ``piece_field`` on a batch (jitted, as :func:`~jaxgear.integrate.batch_field`)."""
    in_t = None if jnp.ndim(t) == 0 else 0
    return jax.vmap(system.piece_field, in_axes=(in_t, 1, None, 1), out_axes=1)(t, Y, params, sides)


def _rk4(system, params, t, Y, h, window=False, sides=None, k1=None):
    """One RK4 step; returns ``(Y_new, k1)``. ``window``: keep stage times inside the step
    (by ``BREAK_TOL * T``); ``sides``: evaluate every stage with the piece of those sides."""
    if window:
        tol = jnp.minimum(BREAK_TOL * system.period(params), 0.25 * jnp.abs(h))
        lo, hi = t + tol, t + h - tol
    else:
        lo = hi = None
    f = lambda tt, Z: _field(system, params, tt, Z, lo, hi, sides)  # noqa: E731
    h2 = 0.5 * h
    if k1 is None:
        k1 = f(t, Y)
    k2 = f(t + h2, Y + h2 * k1)
    k3 = f(t + h2, Y + h2 * k2)
    k4 = f(t + h, Y + h * k3)
    return Y + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4), k1


def trial_step(system, params, t, Y, h):
    """The plain step every lane takes first: ``(Y_new, k1, s_start, s_end, theta_break)``."""
    window = _has_breaks(system, params)
    Y1, k1 = _rk4(system, params, t, Y, h, window=window)
    S0 = _switching(system, params, t, Y)
    S1 = _switching(system, params, t + h, Y1)
    return Y1, k1, S0, S1, _break_fraction(system, params, t, h)


def _hermite_root(s0, s1, d0, d1, differentiable=True):
    """Root in ``(0, 1)`` of the cubic Hermite interpolant through ``(0, s0, d0)`` and
    ``(1, s1, d1)`` (``d`` scaled by the step), given ``s0 s1 < 0``: safeguarded Newton
    from the secant point, to round-off. Shapes broadcast. ``differentiable``: the root's
    derivative is that of the interpolant's root (one Newton step at the converged point
    carries it); otherwise none (:func:`_event` says when)."""
    sg = jax.lax.stop_gradient
    if not differentiable:
        s0, s1, d0, d1 = sg(s0), sg(s1), sg(d0), sg(d1)

    def p(th):
        t2, t3 = th * th, th * th * th
        return ((2 * t3 - 3 * t2 + 1) * s0 + (t3 - 2 * t2 + th) * d0 + (-2 * t3 + 3 * t2) * s1
                + (t3 - t2) * d1)

    def dp(th):
        t2 = th * th
        return (6 * t2 - 6 * th) * s0 + (3 * t2 - 4 * th + 1) * d0 + (-6 * t2 + 6 * th) * s1 + (3 * t2 - 2 * th) * d1

    a0, a1 = sg(s0), sg(s1)
    denom = a0 - a1
    th = jnp.clip(jnp.where(denom != 0, a0 / jnp.where(denom != 0, denom, 1.0), 0.5), 0.0, 1.0)
    lo, hi = jnp.zeros_like(th), jnp.ones_like(th)
    sgn0 = jnp.sign(a0)

    def body(_, c):
        th, lo, hi = c
        v = sg(p(th))
        same = jnp.sign(v) == sgn0
        lo = jnp.where(same, th, lo)
        hi = jnp.where(same, hi, th)
        d = sg(dp(th))
        nt = th - v / jnp.where(d != 0, d, 1.0)
        # converged: the Newton correction is at round-off; keep th (a bracket end that
        # round-off moved onto th would otherwise reject the step and bisect away)
        done = (v == 0) | ((d != 0) & (jnp.abs(nt - th) <= 4.0 * _EPS))
        ok = (nt > lo) & (nt < hi) & (d != 0)
        nt = jnp.where(ok, nt, 0.5 * (lo + hi))
        return jnp.where(done, th, nt), lo, hi

    th, _, _ = jax.lax.fori_loop(0, _HERMITE_ITERS, body, (th, lo, hi))
    th = sg(th)
    d = dp(th)
    return th - p(th) / jnp.where(d != 0, d, 1.0)


def _crossing_rates(system, params, t, Y, Y1, h, k1):
    """The switching functions' rates at both ends of the step ``Y -> Y1`` (from ``t``,
    length ``h``, field ``k1`` at its start), scaled by the step: the slopes of their cubic
    Hermite interpolants, ``(D0, D1)`` of shape ``(m, n)``. With scalar ``t`` and ``h`` the
    time-only terms are computed once for the batch."""
    F1 = batch_field(system, params, t + h, Y1)
    return _switching_rate(system, params, t, Y, k1) * h, _switching_rate(system, params, t + h, Y1, F1) * h


def _first_crossing(system, params, t, Y, Y1, h, k1, S0, S1, sides, th_break, rates=None):
    """The earliest event of a trial step, per lane: ``(theta, which, flips)`` with
    ``which`` the index of the crossed switching function (``-1`` for a time break or no
    event) and ``flips (m, n)`` every function crossed at that same instant (identical
    planets, or ``b = 0`` where both sides of a backlash coincide), whose sides all flip.
    ``rates``: :func:`_crossing_rates` of the step when already computed."""
    n = Y.shape[1]
    if S0.shape[0]:
        cross = (_sides(S1) != sides) & jnp.isfinite(S1) & jnp.isfinite(S0)
        D0, D1 = _crossing_rates(system, params, t, Y, Y1, h, k1) if rates is None else rates
        # (the root's derivative is needed only where stages are not evaluated piece by piece)
        th = _hermite_root(S0, S1, D0, D1, differentiable=system.piece_field is None)
        th = jnp.where(cross, jnp.clip(th, 0.0, 1.0), 2.0)
        j = jnp.argmin(th, axis=0)
        th_s = jnp.take_along_axis(th, j[None], axis=0)[0]
    else:
        th = jnp.full((0, n), 2.0)
        th_s = jnp.full((n,), 2.0)
        j = jnp.zeros((n,), jnp.int32)
    use_break = th_break < th_s
    theta = jnp.where(use_break, th_break, th_s)
    which = jnp.where(use_break | (th_s > 1.0), -1, j)
    flips = (th <= jax.lax.stop_gradient(th_s) + SIMULTANEOUS) & (which >= 0)[None]
    return jnp.minimum(theta, 1.0), which, flips


def _land(system, params, t, Ym, h1, h, which, flips, sides, window, lazy=False):
    """Put the end ``Ym`` of the sub-step to a crossing on the crossed surface.

    The located crossing (a root of the trial step's interpolant) is off the true one
    by the trial step's error; the sub-steps' derivatives would inherit that offset
    times the jump of the field's Jacobian (one order lost in the monodromy matrix), and
    a jumping field's state that offset times the jump. One Newton correction
    ``dt = -s / (ds/dt)`` along the piece being left (an Euler move of that small
    distance, so its own error is its square) lands the end on the surface to round-off;
    the move is differentiated with the correction held fixed. For a system whose field
    jumps, the saltation matrix ``S = I + (f+ - f-) (grad s)^T / (ds/dt)`` (Leine and
    Nijmeijer) then enters the first derivatives through a term whose value is zero; for
    one that kinks, a term with zero value and zero first derivative gives the second
    derivatives the motion of the kink. Lanes with ``which < 0`` (a time break, no
    event) are unchanged. Returns ``(Ym, h1)``."""
    sg = jax.lax.stop_gradient
    tm = t + h1
    lo, hi = (t + jnp.minimum(BREAK_TOL * system.period(params), 0.25 * jnp.abs(h1)), tm) if window else (None, None)
    w = jnp.maximum(which, 0)[None]
    pick = lambda A: jnp.take_along_axis(A, w, axis=0)[0]  # noqa: E731
    F = _field(system, params, tm, Ym, lo, hi, sides)
    rate = pick(_switching_rate(system, params, tm, Ym, F))
    dt = -pick(_switching(system, params, tm, Ym)) / jnp.where(rate != 0, rate, 1.0)
    ok = (which >= 0) & (rate != 0) & jnp.isfinite(dt) & (jnp.abs(dt) <= 0.25 * jnp.abs(h))
    dt = sg(jnp.where(ok, dt, 0.0))
    Ym, tm = Ym + F * dt[None], tm + dt
    other = jnp.where(flips, -sides, sides)
    if system.field_jumps:
        F_old = _field(system, params, tm, Ym, lo, None if hi is None else tm, sides)
        F_new = _field(system, params, tm, Ym, None, None, other)
        rate = pick(_switching_rate(system, params, tm, Ym, F_old))
        s_w = pick(_switching(system, params, tm, Ym))
        gain = jnp.where(ok & (rate != 0), (s_w - sg(s_w)) / sg(jnp.where(rate != 0, rate, 1.0)), 0.0)
        Ym = Ym + sg(F_new - F_old) * gain[None]
    else:
        # second derivatives: the split point is held fixed, so the frozen-split map misses
        # how the Jacobian's kink moves with the crossing time; the exact flow differs from
        # it by -w dtc^2 / 2, w = d/dt (f- - f+) along the flow at the surface and dtc the
        # crossing-time shift (value and first derivative zero; Hessians and mixed
        # parameter-state derivatives of the monodromy matrix come out right). ``lazy``:
        # its value being zero, computed only where the step is differentiated (large
        # batches; in small ones, the derivative paths, tracing that rule under every
        # transformation costs more than evaluating the term)
        inv_rate = jnp.where(ok & (rate != 0), 1.0 / sg(jnp.where(rate != 0, rate, 1.0)), 0.0)
        if lazy:
            Ym = _kink_motion(system, Ym, tm, params, which, F, sides, other, inv_rate)
        else:
            Ym = Ym - _kink_term(system, params, tm, Ym, F, sides, other, which, inv_rate)
    return Ym, h1 + dt


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _kink_motion(system, Ym, tm, params, which, F, sides, other, inv_rate):
    """``Ym`` plus the crossing-time term of :func:`_land` for a field that kinks,
    ``-w dtc^2 / 2`` with ``dtc = (s - stop_gradient(s)) / rate`` the crossing-time shift
    (``s`` the crossed switching function at ``(tm, Ym)``, ``w`` the rate of the jump of
    the field's pieces along ``F``): value and first derivative zero, so the value is
    ``Ym`` and the term is evaluated only in the derivative rule, where its derivative
    (zero, whose own derivative is ``-w dtc dtc'``) gives second derivatives the motion
    of the kink."""
    return Ym


def _kink_motion_jvp(system, primals, tangents):
    Ym, tm, params, which, F, sides, other, inv_rate = primals
    zero = lambda d: isinstance(d, SymbolicZero)  # noqa: E731
    w = jnp.maximum(which, 0)[None]
    # the crossed switching function moves only along the inputs that are differentiated
    # (symbolic zeros: no derivative of the parameters when only states are, and so on)
    moving = [(i, a, d) for i, (a, d) in enumerate(((Ym, tangents[0]), (tm, tangents[1]))) if not zero(d)]
    if not all(zero(d) for d in jax.tree.leaves(tangents[2], is_leaf=zero)):
        dp = jax.tree.map(lambda d, a: _zero_tangent(a) if zero(d) else d, tangents[2], params, is_leaf=zero)
        moving.append((2, params, dp))

    def crossed(*vals):
        args = [Ym, tm, params]
        for (i, _, _), v in zip(moving, vals):
            args[i] = v
        return jnp.take_along_axis(_switching(system, args[2], args[1], args[0]), w, axis=0)[0]

    dYm = jnp.zeros_like(Ym) if zero(tangents[0]) else tangents[0]
    if not moving:
        return Ym, dYm
    s_w, ds_w = jax.jvp(crossed, tuple(a for _, a, _ in moving), tuple(d for _, _, d in moving))
    return Ym, dYm - _rate_of_jump(system, params, tm, Ym, F, sides, other) * (
        (s_w - jax.lax.stop_gradient(s_w)) * inv_rate * inv_rate * ds_w)[None]


def _rate_of_jump(system, params, tm, Ym, F, sides, other):
    """``w = d/dt (f_sides - f_other)`` along ``F`` at ``(tm, Ym)`` (held fixed)."""
    sg = jax.lax.stop_gradient
    tt = jnp.broadcast_to(tm, (Ym.shape[1],))

    def one(ti, y, f, sa, sb):
        gap = lambda a, b: system.piece_field(a, b, params, sa) - system.piece_field(a, b, params, sb)  # noqa: E731
        return jax.jvp(gap, (ti, y), (jnp.ones_like(ti), f))[1]

    return jax.vmap(one, in_axes=(0, 1, 1, 1, 1), out_axes=1)(sg(tt), sg(Ym), sg(F), sides, other)


def _kink_term(system, params, tm, Ym, F, sides, other, which, inv_rate):
    """The term ``w dtc^2 / 2`` of :func:`_kink_motion`, evaluated (value zero)."""
    s_w = jnp.take_along_axis(_switching(system, params, tm, Ym), jnp.maximum(which, 0)[None], axis=0)[0]
    shift = (s_w - jax.lax.stop_gradient(s_w)) * inv_rate
    return _rate_of_jump(system, params, tm, Ym, F, sides, other) * (0.5 * shift * shift)[None]


_kink_motion.defjvp(_kink_motion_jvp, symbolic_zeros=True)


def _zero_tangent(a):
    a = jnp.asarray(a)
    if jnp.issubdtype(a.dtype, jnp.inexact):
        return jnp.zeros_like(a)
    return np.zeros(a.shape, jax.dtypes.float0)


class _SubStep(NamedTuple):
    """The state of :func:`_event`: a (sub-)step's start ``Ys`` and end ``Ye`` states
    ``(dim, n)``, its start time ``tt`` and length ``hh`` ``(n,)``, the field ``k1`` at its
    start, the ``sides`` its stages use and the switching functions ``S0``, ``S1`` at both
    ends."""

    Ys: Any
    tt: Any
    hh: Any
    k1: Any
    Ye: Any
    sides: Any
    S0: Any
    S1: Any


def _event(system, params, state, lazy=False, first=None):
    """One event of the lanes in ``state`` (each holding one): locate the first event of
    the (sub-)step ``Ys -> Ye`` (from ``tt``, length ``hh``), sub-step to it, land, flip
    the crossed surface's side, step the rest of the step. Returns the new state and
    whether its rest step holds another event.

    ``state``: a :class:`_SubStep`. ``first = (i, rates)``: in a loop over events, the
    event's index and the :func:`_crossing_rates` of the whole step, computed before the
    loop where the step's times are still shared by the lanes (used by event 0).

    With the system's ``piece_field`` every stage of a sub-step is evaluated on that
    sub-step's piece, so each sub-step is an RK4 step of a smooth field (in value and
    derivative) and the split points carry no derivative: where the field only kinks,
    moving the crossing does not change the flow's derivative (the saltation matrix is
    the identity) and differentiating the sub-steps with respect to their lengths would
    add an error of order ``h^4`` per crossing that depends on where the crossing falls
    in the step; :func:`_land` puts the crossing on the surface and, where the field
    jumps, supplies the saltation matrix. Without a ``piece_field`` the stages see the
    field itself and the crossing's place is differentiated (fourth order still, less
    regular)."""
    window = _has_breaks(system, params)
    sided = system.piece_field is not None
    pieces = lambda sd: sd if sided else None  # noqa: E731
    Ys, tt, hh, k1, Ye, sides, S0, S1 = state
    th_break = _break_fraction(system, params, tt, hh)
    rates = None
    if first is not None and S0.shape[0]:
        i, rates = first
        rates = jax.lax.cond(i == 0, lambda: rates, lambda: _crossing_rates(system, params, tt, Ys, Ye, hh, k1))
    th, which, flips = _first_crossing(system, params, tt, Ys, Ye, hh, k1, S0, S1, sides, th_break, rates)
    h1 = th * hh
    Ym, _ = _rk4(system, params, tt, Ys, h1, window=window, sides=pieces(sides), k1=None if window else k1)
    if sided:
        Ym, h1 = _land(system, params, tt, Ym, h1, hh, which, flips, sides, window, lazy)
    sides = jnp.where(flips, -sides, sides)
    tt, hh = tt + h1, hh - h1
    Ye, k1 = _rk4(system, params, tt, Ym, hh, window=window, sides=pieces(sides))
    S0, S1 = _switching(system, params, tt, Ym), _switching(system, params, tt + hh, Ye)
    return _SubStep(Ym, tt, hh, k1, Ye, sides, S0, S1), _pending(system, params, tt, hh, S0, S1, sides)


def _pending(system, params, t, h, S0, S1, sides):
    """Lanes whose step from ``t`` (length ``h``, switching functions ``S0``, ``S1`` at its
    ends, stages on ``sides``) holds an event: a side changed, or a known break inside."""
    n = S0.shape[1]
    if S0.shape[0]:
        need = jnp.any((_sides(S1) != sides) & jnp.isfinite(S1) & jnp.isfinite(S0), axis=0)
    else:
        need = jnp.zeros((n,), bool)
    if _has_breaks(system, params):
        need = need | (jnp.broadcast_to(_break_fraction(system, params, t, h), (n,)) < 1.0)
    return need


def _chunk(n: int) -> int:
    """Lanes of one gathered chunk for a batch of ``n`` (whole SIMD vectors) on the default
    backend (the platform the step is compiled for)."""
    fraction = COMPACT_FRACTION if jax.default_backend() == "cpu" else COMPACT_FRACTION_ACCELERATOR
    per = max(-(-n // fraction), CHUNK_MIN)
    return -(-per // 8) * 8


def kink_step(system, params, t, Y, h, max_splits: int = 2):
    """One kink-aware step of size ``h`` from ``t`` for a batch ``Y (dim, n)`` (see the module).

    ``t`` and ``h`` are scalars or ``(n,)``. Lanes without an event inside the step get the
    plain RK4 step. Each event (up to ``max_splits``) is handled only on the lanes that
    still have one: in a batch of up to ``DENSE_MAX`` lanes computed for the whole batch
    and selected (one fused computation per stage, what accelerators want), in a larger
    one gathered in chunks (:func:`_chunk`), as many chunks as there are such lanes; an
    event no lane has is skipped. The event is compiled once per batch shape (no second
    copy as a fallback). Every loop has a fixed trip count and skips by ``lax.cond``, so
    the step is differentiable both ways (``jax.jacfwd``, ``jax.grad``).
    """
    Y1, k1, S0, S1, _ = trial_step(system, params, t, Y, h)
    sides = _sides(S0) if S0.shape[0] else S0
    n = Y.shape[1]
    need = _pending(system, params, t, h, S0, S1, sides)

    if n <= DENSE_MAX:
        # every lane of the batch through every event (a lane without a further event
        # steps the rest of its step whole again), selected at the end
        lane = lambda a: jnp.broadcast_to(a, (n,))  # noqa: E731
        state = _SubStep(Y, lane(t), lane(h), k1, Y1, sides, S0, S1)

        def dense(_):
            rates = _crossing_rates(system, params, t, Y, Y1, h, k1)
            ev = lambda i, c: _event(system, params, c[0], first=(i, rates))  # noqa: E731
            end = jax.lax.fori_loop(0, max_splits, ev, (state, need))[0].Ye
            return jnp.where(need[None], end, Y1)

        return jax.lax.cond(jnp.any(need), dense, lambda _: Y1, None)

    # larger batches: the lanes with an event are listed (``idx``, the first ``count``) and
    # gathered chunk by chunk; nothing but the step's end is kept for the whole batch (a
    # lane's own stage values would cost more memory traffic than the plain step). A lane
    # with a further event is listed for the next level, which redoes its earlier events
    # (a few lanes per step) instead of keeping their states
    C = _chunk(n)
    size = -(-n // C) * C

    def level(lev, c):
        Yout, idx, count = c

        def one_chunk(s, c):
            def go(c):
                Yout, nxt, k = c
                ids = jax.lax.dynamic_slice_in_dim(idx, s * C, C)
                take = lambda a: jnp.take(a, ids, axis=-1, mode="clip")  # noqa: E731
                # (a scalar time stays scalar: the time terms of the trial's ends once per chunk)
                tt = t if jnp.ndim(t) == 0 else take(t)
                hh = h if jnp.ndim(h) == 0 else take(h)
                sub = _start_state(system, params, tt, take(Y), hh, take(Y1))
                rates = _crossing_rates(system, params, tt, sub.Ys, sub.Ye, hh, sub.k1)
                sub = sub._replace(tt=jnp.broadcast_to(tt, (C,)), hh=jnp.broadcast_to(hh, (C,)))

                def ev(i, c):
                    return jax.lax.cond(i <= lev, lambda c: _event(system, params, c[0], lazy=True, first=(i, rates)),
                                        lambda c: c, c)

                end, more = jax.lax.fori_loop(0, max_splits, ev, (sub, jnp.zeros((C,), bool)))
                Yout = Yout.at[:, ids].set(end.Ye, mode="drop")
                more = more & (ids < n)
                at = jnp.where(more, k + jnp.cumsum(more) - 1, size)
                return Yout, nxt.at[at].set(ids, mode="drop"), k + jnp.sum(more)

            return jax.lax.cond(s * C < count, go, lambda c: c, c)

        def run(c):
            empty = jnp.full((size,), n, idx.dtype)
            return jax.lax.fori_loop(0, size // C, one_chunk, (c[0], empty, jnp.zeros_like(count)))

        return jax.lax.cond(count > 0, run, lambda c: c, c)

    idx, count = _listed(need, size)
    return jax.lax.fori_loop(0, max_splits, level, (Y1, idx, count))[0]


def _start_state(system, params, t, Y, h, Y1):
    """The state of :func:`_event` for lanes at the start of a step whose trial step ended
    on ``Y1`` (the trial's first stage and switching functions recomputed)."""
    if _has_breaks(system, params):
        tol = jnp.minimum(BREAK_TOL * system.period(params), 0.25 * jnp.abs(h))
        k1 = _field(system, params, t, Y, t + tol, t + h - tol)
    else:
        k1 = _field(system, params, t, Y)
    S0, S1 = _switching(system, params, t, Y), _switching(system, params, t + h, Y1)
    return _SubStep(Y, t, h, k1, Y1, _sides(S0) if S0.shape[0] else S0, S0, S1)


def _listed(mask, size: int, block: int = 32):
    """The indices of the true entries of ``mask (n,)`` in order, padded with ``n`` to
    ``size >= n``, and their number. ``jnp.nonzero``'s prefix sum costs more than the rest
    of a plain RK4 step on a CPU; ranks within blocks of ``block`` lanes are a product
    with a triangular matrix of ones (exact in float32: integers <= ``block``), and only
    the block totals are summed as a prefix."""
    n = mask.shape[0]
    nb = -(-n // block)
    m = jnp.pad(mask, (0, nb * block - n)).reshape(nb, block).astype(jnp.float32)
    tri = jnp.triu(jnp.ones((block, block), jnp.float32))
    within = jnp.matmul(m, tri, precision=jax.lax.Precision.HIGHEST).astype(jnp.int32)
    totals = within[:, -1]
    rank = (within + (jnp.cumsum(totals) - totals)[:, None]).reshape(-1)[:n] - 1
    idx = jnp.full((size,), n, jnp.int32).at[jnp.where(mask, rank, size)].set(
        jnp.arange(n, dtype=jnp.int32), mode="drop")
    return idx, jnp.sum(totals)


_traced_once_step = jax.jit(kink_step, static_argnums=(0, 5))
""":func:`kink_step` under its own ``jit`` (inlined into the loop that calls it): traced once
per system and shapes, so the many transformations of one loop (``vmap``, ``jacfwd``, a
solver's linearisations: a shooting solve takes nine) reuse that trace instead of running
the step's Python again, which halves the tracing time of a shooting solve."""


class KinkAwareRK4(AbstractFixedStep):
    """RK4 with ``steps_per_period`` fixed steps, each split at the crossings of the system's
    switching surfaces and at its known time breaks (see the module).

    For a system without switching functions or time breaks this is classical RK4. For
    the gear models states converge at fourth order and Floquet multipliers from
    ``jax.jacfwd`` at (at least) third order, where plain RK4 gives second and first
    (model document §8).

    Attributes:
        steps_per_period: fixed steps per forcing period (>= 1).
        max_splits: events handled inside one step (1-3; a further event in the same
            step is stepped over as plain RK4 would).
        native: ``True`` — use the compiled CPU kernel when the system has one
            (``ForcedSystem.native``, the built-in reduced gear model) and the platform
            is a CPU (:mod:`jaxgear.integrate._native`; the pure-JAX steps otherwise, and
            always for derivatives and GPUs); ``False`` — always the pure-JAX steps (the
            reference). Both give the same states to round-off.
    """

    name: ClassVar[str] = "KinkAwareRK4"
    steps_per_period: int = eqx.field(static=True, default=DEFAULT_STEPS_PER_PERIOD)
    max_splits: int = eqx.field(static=True, default=2)
    native: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        check_steps_per_period(self.steps_per_period)
        check_int(self.max_splits, "max_splits", 1, 3)
        check_bool(self.native, "KinkAwareRK4.native")

    def step(self, system, params, t, Y, h):
        if not system.is_piecewise:
            return rk4_step(system, params, t, Y, h)
        return _traced_once_step(system, params, t, Y, h, int(self.max_splits))

    def advance(self, system, params, Y, t0, periods: int, n_active=None):
        if self.native and system.native is not None:
            from ._native import native_advance

            return native_advance(self, system, params, Y, t0, int(periods), n_active)
        return super().advance(system, params, Y, t0, periods)

    def advance_rows(self, system, params_rows, rows, Y, t0, periods: int, n_active=None):
        if self.native and system.native is not None:
            from ._native import native_advance

            return native_advance(self, system, params_rows, Y, t0, int(periods), n_active, rows=rows)
        return super().advance_rows(system, params_rows, rows, Y, t0, periods)

    def flow(self, system, params, x, t0, periods: int):
        # the pure-JAX steps: differentiable both ways (monodromy matrices, implicit gradients)
        return AbstractFixedStep.advance(self, system, params, x[:, None], t0, periods)[:, 0]

    def to_dict(self):
        return {"type": self.name, "steps_per_period": int(self.steps_per_period),
                "max_splits": int(self.max_splits), "native": bool(self.native)}
