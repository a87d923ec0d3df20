"""Multiple shooting with deflation, solved by optimistix (paper §4.1, extended).

A P-k orbit is split into ``M`` segments of ``k T / M`` each. The unknowns are the
states ``X = (X_0, ..., X_{M-1})`` at the segment starts ``t0 + s k T / M``; the
residuals are the continuity defects

    R_s(X) = phi_s(X_s) - X_{s+1 mod M},    s = 0 .. M-1,

where ``phi_s`` is the integrator's flow over segment ``s``. ``M = 1`` is single
shooting, ``R = P^k(x) - x``. Each segment is integrated independently (in parallel
under ``vmap``), so an unstable orbit is never integrated over its whole period from
a poor guess: Newton's reach widens (Stoer & Bulirsch §7.3.5).

The Jacobian of ``R`` is block-cyclic: ``dR_s/dX_s = D phi_s`` and ``dR_s/dX_{s+1} = -I``.
:func:`segment_map` has a custom JVP that computes the ``M`` blocks ``D phi_s`` by
``jax.jacfwd`` (``dim`` tangents per segment, all segments at once) and applies them,
instead of pushing ``M dim`` tangents through every segment.

**Deflation** (Farrell, Birkisson & Funke, SIAM J. Sci. Comput. 37 (2015) A2026): with
known orbit points ``r_i``, the solver works on

    D(X) R(X),    D(X) = prod_i (1 / ||X_0 - r_i||^p + shift),

which has the same roots except the known ones (near ``r_i`` it stays away from zero
for ``p >= 2``), so a seed that went to a known orbit goes elsewhere.

The solver is an optimistix object (``Newton``, ``Dogleg``, ``LevenbergMarquardt``, ...) under
``vmap`` with ``throw=False``: every seed ends with its own :class:`~jaxgear.Status`.
Derivatives of the root with respect to the parameters are implicit (the implicit
function theorem, ``dX = -(dG/dX)^-1 dG/dp dp`` at the root, with the Jacobian the
solve's singularity check already computed: the solver's iterations are not
differentiated).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from .._status import Status
from ..integrate import AbstractIntegrator
from ._options import ShootOptions, _optx

__all__ = ["Shooting", "segment_map", "check_segments", "solve_orbit", "optx_status"]

class Shooting(eqx.Module):
    """The multiple-shooting problem of a P-k orbit: system, integrator, ``k``, ``M``.

    Segment ``s`` runs from ``t0 + s k T / M`` for ``k T / M``, as the integrator's
    ``segment_flow`` runs it (a fixed-step integrator with ``n`` steps per period: ``k n / M``
    steps on the step grid of ``P^k``, so ``M`` must divide ``k n``; any other integrator
    needs ``M`` dividing ``k``: ``check_segments``).
    """

    system: object = eqx.field(static=True)
    integrator: AbstractIntegrator = eqx.field(static=True)
    k: int = eqx.field(static=True)
    segments: int = eqx.field(static=True)

    def phi(self, params, t0, x, s):
        """Flow of segment ``s`` (traced int) from ``x (dim,)``: ``(dim,)``."""
        return self.integrator.segment_flow(self.system, params, x, t0, self.k, self.segments, s)

    def all_segments(self, X, args):
        params, t0 = args
        return jax.vmap(lambda x, s: self.phi(params, t0, x, s))(X, jnp.arange(self.segments))

    def initial_states(self, params, t0, x0):
        """Segment starts ``(M, dim)`` obtained by integrating from ``x0`` (the seed)."""
        def one(x, s):
            y = self.phi(params, t0, x, s)
            return y, x

        _, X = jax.lax.scan(one, x0, jnp.arange(self.segments))
        return X

    def residual(self, X, args):
        """Continuity defects ``(M * dim,)`` of segment starts ``X (M, dim)``."""
        Phi = segment_map(self, X, args)
        return (Phi - jnp.roll(X, -1, axis=0)).reshape(-1)


def check_segments(integrator, k: int, segments: int) -> int:
    """``segments`` as an int that splits a P-k orbit for ``integrator`` (else ``ValueError``)."""
    if isinstance(segments, bool) or int(segments) != segments or int(segments) < 1:
        raise ValueError(f"segments={segments!r} must be an integer >= 1.")
    M = int(segments)
    integrator.check_segments(int(k), M)
    return M


def _instantiate(t, primal):
    if not isinstance(t, SymbolicZero):
        return t
    dtype = jax.dtypes.float0 if not jnp.issubdtype(jnp.result_type(primal), jnp.inexact) else t.aval.dtype
    return np.zeros(np.shape(primal), dtype) if dtype == jax.dtypes.float0 else jnp.zeros(np.shape(primal), dtype)


@jax.custom_jvp
def _segment_map(shoot, X, args):
    return shoot.all_segments(X, args)


def segment_map(shoot: Shooting, X, args):
    """``phi_s(X_s)`` for all segments, ``(M, dim)``; ``args = (params, t0)``.

    Its JVP applies the per-segment Jacobians (computed once per linearisation, all
    segments in parallel), so a dense Jacobian of the multiple-shooting residual costs
    ``dim`` tangents per segment, not ``M dim`` through every segment.
    """
    return _segment_map(shoot, X, args)


def _segment_map_jvp(primals, tangents):
    shoot, X, args = primals
    _, dX, dargs = tangents

    def one(x, s):
        def f(z):
            y = shoot.phi(args[0], args[1], z, s)
            return y, y

        J, y = jax.jacfwd(f, has_aux=True)(x)
        return y, J

    Phi, J = jax.vmap(one)(X, jnp.arange(shoot.segments))
    out = jnp.zeros_like(Phi)
    if not isinstance(dX, SymbolicZero):
        out = out + jnp.einsum("sij,sj->si", J, dX)
    # parameter (and phase) tangents: one JVP through all segments, skipped when they are zero
    is_zero = lambda t: isinstance(t, SymbolicZero)
    if not all(is_zero(t) for t in jax.tree_util.tree_leaves(dargs, is_leaf=is_zero)):
        dargs = jax.tree_util.tree_map(_instantiate, dargs, args, is_leaf=is_zero)
        out = out + jax.jvp(lambda a: shoot.all_segments(X, a), (args,), (dargs,))[1]
    return Phi, out


_segment_map.defjvp(_segment_map_jvp, symbolic_zeros=True)


SINGULAR_RCOND = 1e-10
"""A converged root whose Jacobian's smallest singular value is below this share of its
largest (at least 1) is reported as singular (:func:`solve_orbit`)."""


def optx_status(result, finite, residual, tol, diverged):
    """A :class:`~jaxgear.Status` code from an optimistix ``RESULTS`` and the residual check."""
    optx = _optx()
    R = optx.RESULTS
    singular = (result == R.singular) | (result == R.breakdown)
    return jnp.where(residual <= tol, Status.CONVERGED,
                     jnp.where(singular, Status.SINGULAR,
                               jnp.where(~finite | diverged, Status.DIVERGED, Status.NOT_CONVERGED)))


def deflation(x, known, power: float, shift: float):
    """``prod_i (1 / ||x - r_i||^p + shift)`` over the rows of ``known (R, dim)`` that are finite."""
    if known is None or known.shape[0] == 0:
        return jnp.asarray(1.0)
    ok = jnp.all(jnp.isfinite(known), axis=1)
    d2 = jnp.sum((x[None] - jnp.where(ok[:, None], known, 0.0)) ** 2, axis=1)
    fac = 1.0 / jnp.where(ok, d2, 1.0) ** (0.5 * power) + shift  # rows left out: finite, zero derivative
    return jnp.prod(jnp.where(ok, fac, 1.0))


def _deflated_residual(shoot: Shooting, known, power: float, shift: float, Xf, args):
    """The function whose roots the solver finds: the deflated continuity defects
    ``D(X_0) R(X)`` of the flattened segment starts ``Xf (M * dim,)``; ``args = (params, t0)``."""
    X = Xf.reshape(shoot.segments, -1)
    return deflation(X[0], known, power, shift) * shoot.residual(X, args)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2))
def _implicit_root(shoot: Shooting, power: float, shift: float, Xf, J, ok, known, params, t0):
    """``Xf``, a root of :func:`_deflated_residual` at ``(params, t0)`` found by the solver,
    with the derivatives of the implicit function theorem: ``dX = -J^-1 dG/dp dp`` with
    ``J = dG/dX`` at the root. Where ``ok`` is false (no converged, regular root) the
    derivative is zero."""
    return Xf


@_implicit_root.defjvp
def _implicit_root_jvp(shoot, power, shift, primals, tangents):
    Xf, J, ok, known, params, t0 = primals
    _, dG = jax.jvp(lambda p, t: _deflated_residual(shoot, known, power, shift, Xf, (p, t)), (params, t0),
                    (tangents[4], tangents[5]))
    eye = jnp.eye(J.shape[0], dtype=J.dtype)  # where there is no root: the identity (no NaN either way)
    dX = -jnp.linalg.solve(jnp.where(ok, J, eye), jnp.where(ok, dG, 0.0))
    return Xf, dX


def solve_orbit(shoot: Shooting, params, t0, x0, known, options: ShootOptions):
    """Solve the (deflated) multiple-shooting problem from one seed ``x0 (dim,)``.

    Returns ``x (dim,)`` (the first segment start, differentiable w.r.t. ``params`` by
    the implicit function theorem), the status code, the iterations, the residual
    ``||P^k(x) - x||`` of the composed segments and the solver's last iterate ``(dim,)``.
    """
    optx = _optx()
    args = (params, t0)
    X0 = shoot.initial_states(params, t0, x0)
    X0 = jax.lax.stop_gradient(jnp.where(jnp.all(jnp.isfinite(X0)), X0, jnp.broadcast_to(x0, X0.shape)))
    solver = options.root_finder
    power, shift = options.deflation_power, options.deflation_shift

    fn = functools.partial(_deflated_residual, shoot, known, power, shift)

    # the solve itself is not differentiated: derivatives come from the implicit function
    # theorem, attached below at the root (_implicit_root)
    sargs = jax.lax.stop_gradient(args)
    sol = optx.root_find(fn, solver, X0.reshape(-1), sargs, max_steps=int(options.max_iter), throw=False,
                         adjoint=optx.ImplicitAdjoint())
    Xs = jax.lax.stop_gradient(sol.value)
    x = Xs.reshape(X0.shape)[0]
    xk = shoot.integrator.flow(shoot.system, params, x, t0, shoot.k)
    r = jax.lax.stop_gradient(jnp.linalg.norm(xk - x))
    finite = jnp.all(jnp.isfinite(Xs)) & jnp.isfinite(r)
    diverged = jnp.max(jnp.linalg.norm(jnp.where(jnp.isfinite(Xs), Xs, 0.0).reshape(X0.shape), axis=1)) > options.max_norm
    st = optx_status(sol.result, finite, r, options.tol, diverged)
    # a root where G' is singular is no isolated orbit (a continuum of them, e.g. free
    # flight): reported as SINGULAR, whatever a regularised solver (Levenberg-Marquardt)
    # converged to; its implicit derivatives would not exist
    J = jax.jacfwd(fn)(jnp.where(finite, Xs, X0.reshape(-1)), sargs)
    sv = jnp.linalg.svd(J, compute_uv=False)
    singular_root = ~(sv[-1] > SINGULAR_RCOND * jnp.maximum(sv[0], 1.0))
    st = jnp.where((st == Status.CONVERGED) & singular_root, Status.SINGULAR, st)
    # implicit derivatives at a converged, regular root (that Jacobian); a seed without one
    # gets zero derivatives (its point is NaN anyway): a linear solve with a singular
    # Jacobian (e.g. past a fold) must not fail a batch that reports failure as data
    conv = st == Status.CONVERGED
    x_ad = _implicit_root(shoot, float(power), float(shift), jnp.where(conv, Xs, X0.reshape(-1)),
                         jax.lax.stop_gradient(J), conv, known, params, t0).reshape(X0.shape)[0]
    # a seed that already meets the tolerance counts no iteration (optimistix always takes
    # one step, a correction below the tolerance, before it tests for termination)
    x0s = jax.lax.stop_gradient(x0)
    r0 = jnp.linalg.norm(shoot.integrator.flow(shoot.system, params, x0s, t0, shoot.k) - x0s)
    steps = jnp.where(r0 <= options.tol, 0, sol.stats["num_steps"])
    return x_ad, st, steps, jnp.where(finite, r, jnp.inf), x
