"""Compiled kernels of the sweeps: many parameter values x many starts in one batch.

States of a block are kept as ``(dim, B, S)``: ``B`` parameter values, ``S`` starts per
value. Values are array leaves of the parameter pytree (nothing is recompiled per value)
and the integrator object advances each value's ``(dim, S)`` batch under ``vmap``; when
``Omega`` is swept every value has its own period and step.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import pad_rows
from .._devices import rows_over_processes, shard_rows
from .._lyapunov import _lyapunov_kernel, birkhoff_weights
from ._values import apply_values

__all__ = ["advance_values", "record_values", "independent_points", "sequential_points", "values_exponent_estimates"]


def advance_values(system, params, names, V, Y, periods: int, integrator):
    """Advance ``Y (dim, B, S)`` by ``periods`` forcing periods, value j with parameters ``V[j]``."""

    def one(v, y):
        return integrator.advance(system, apply_values(params, names, v), y, jnp.asarray(0.0), periods)

    return jax.vmap(one, in_axes=(0, 1), out_axes=1)(V, Y)


def record_values(system, params, names, V, Y, transient, record, integrator):
    """``transient`` periods, then ``record`` stroboscopic points: ``(B, S, R, dim)``."""
    if transient > 0:
        Y = advance_values(system, params, names, V, Y, transient, integrator)

    def rec(Y, _):
        Y = advance_values(system, params, names, V, Y, 1, integrator)
        return Y, Y

    _, Ys = jax.lax.scan(rec, Y, None, length=record)  # (R, dim, B, S)
    return jnp.transpose(Ys, (2, 3, 0, 1))


@eqx.filter_jit
def _independent_kernel(system, params, names, V, X0, transient, record, integrator):
    """Every (value, start) pair: ``V (B, m)``, ``X0 (S, dim)`` -> points ``(B, S, R, dim)``."""
    Y = jnp.broadcast_to(X0.T[:, None, :], (X0.shape[1], V.shape[0], X0.shape[0]))
    return record_values(system, params, names, V, Y, transient, record, integrator)


@eqx.filter_jit
def _scan_kernel(system, params, names, V, Y0, X0, transient, record, integrator, bound):
    """Values in sequence with the state carried, for ``nd`` sweeps at once (up and down).

    ``V (n, nd, m)``: at step i sweep d runs value ``V[i, d]``; ``Y0 (nd, S, dim)`` the
    carried states. Returns points ``(n, nd, S, R, dim)`` and the state carried out of
    each step ``(n, nd, S, dim)``: the last recorded point, or the start ``X0`` where the
    lane escaped (so one unbounded value does not end the sweep for that start).
    """

    def body(Y, v):
        pts = record_values(system, params, names, v, jnp.transpose(Y, (2, 0, 1)), transient, record, integrator)
        last = pts[:, :, -1]
        fin = jnp.all(jnp.isfinite(last), axis=-1)
        ok = fin & (jnp.linalg.norm(jnp.where(fin[..., None], last, 0.0), axis=-1) <= bound)
        nxt = jnp.where(ok[..., None], last, X0[None])
        return nxt, (pts, nxt)

    _, (pts, carry) = jax.lax.scan(body, Y0, V)
    return pts, carry


def independent_points(system, params, names, Vrows, size, X0, transient, record, integrator) -> np.ndarray:
    """One block of parameter rows ``Vrows (n, m)``, every start from ``X0``, padded to
    ``size`` rows (one compiled shape). Returns points ``(n, S, R, dim)``.

    With several processes (:func:`jaxgear._devices.rows_over_processes`) each computes
    one contiguous part of the ``size`` rows and the parts are exchanged, so every
    process returns the whole block; a process's part is sharded over its local devices
    (:func:`jaxgear._devices.shard_rows`). Every value is integrated alone, so the points
    do not depend on the number of devices or processes."""
    Vrows = np.asarray(Vrows, dtype=float)

    def part(V):
        return shard_rows(_independent_kernel, system, params, names, V, X0, transient, record, integrator, batch=3)

    return rows_over_processes(part, pad_rows(Vrows, int(size)))[: len(Vrows)]


def sequential_points(system, params, names, seq, size, X0, carry, transient, record, integrator, bound):
    """One block of a sequential sweep: ``seq (n, nd, m)`` values in order, state carried
    from ``carry (nd, S, dim)``; padded to ``size`` steps. Returns points ``(n, nd, S, R, dim)``
    and the carried state after the block's last value ``(nd, S, dim)``."""
    n = len(seq)
    V = jnp.asarray(pad_rows(np.asarray(seq, dtype=float), size))
    pts, car = _scan_kernel(system, params, names, V, jnp.asarray(carry), X0, transient, record, integrator, bound)
    return np.asarray(pts)[:n], np.asarray(car)[n - 1]


@eqx.filter_jit
def _values_lyapunov_kernel(system, params, names, V, X, k, stretches, weights, integrator):
    """Lyapunov stretch estimates of lanes with parameters of their own: ``V (n, m)``, ``X (n, dim)``
    -> ``(n, stretches, k)`` and the final states ``(n, dim)`` (the kernel of
    :func:`~jaxgear.lyapunov_spectrum`, one lane per parameter row, under ``vmap``)."""

    def one(v, x):
        est, y = _lyapunov_kernel(system, apply_values(params, names, v), x[:, None], jnp.asarray(0.0), k, 0,
                                  stretches, weights, integrator)
        return est[:, 0], y[:, 0]

    return jax.vmap(one)(V, X)


def values_exponent_estimates(system, params, names, Vrows, X, *, n_exponents: int, periods: int, stretches: int,
                              integrator, chunk_size: int):
    """The stretch estimates of the ``n_exponents`` largest Lyapunov exponents of the
    stroboscopic map (per forcing period, as :func:`~jaxgear.lyapunov_spectrum` with
    ``transient=0``) from the states ``X (n, dim)``, each at its own parameter row
    ``Vrows (n, m)``: all in one compiled batch of ``chunk_size`` lanes at a time (padded,
    one compiled shape), each stretch a weighted Birkhoff average
    (:func:`~jaxgear._lyapunov.birkhoff_weights`). Returns ``(n, stretches, n_exponents)`` estimates and ``(n, dim)`` final states."""
    Vrows, X = np.asarray(Vrows, dtype=float), np.asarray(X, dtype=float)
    n = len(X)
    size = min(int(chunk_size), n)
    w = jnp.asarray(birkhoff_weights(int(periods) // int(stretches)), jnp.float64)
    ests, finals = [], []
    for a in range(0, n, size):
        V = jnp.asarray(pad_rows(Vrows[a:a + size], size))
        Y = jnp.asarray(pad_rows(X[a:a + size], size))
        est, fin = _values_lyapunov_kernel(system, params, names, V, Y, int(n_exponents), int(stretches), w,
                                           integrator)
        ests.append(np.asarray(est)[: min(size, n - a)])
        finals.append(np.asarray(fin)[: min(size, n - a)])
    return np.concatenate(ests, axis=0), np.concatenate(finals, axis=0)
