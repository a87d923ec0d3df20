"""Newton's method on ``G(x) = P^k(x) - x = 0`` with autodiff Jacobians (paper §4.1).

The Jacobian ``DP^k - I`` comes from ``jax.jacfwd`` through the integrator (no finite
differences); the one-period Jacobians along the orbit are kept, so the Floquet data of
the converged orbit come for free.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._status import Status

__all__ = ["value_and_jacobian", "orbit_jacobians", "damped_newton", "RUNNING"]

RUNNING = -1
"""Status of a lane whose Newton iteration is still running (never returned)."""


def value_and_jacobian(fun, x):
    """``(fun(x), jacfwd(fun)(x))`` with one primal evaluation."""

    def both(z):
        y = fun(z)
        return y, y

    J, y = jax.jacfwd(both, has_aux=True)(x)
    return y, J


def orbit_jacobians(system, params, x, t0, k, integrator):
    """Points and Jacobians along ``k`` periods from ``x`` at ``t0``.

    Returns ``x_k = P^k(x)``, the points ``pts = (x, P(x), ..., P^{k-1}(x))`` of shape
    ``(k, dim)`` and ``Cs`` of shape ``(k, dim, dim)`` with ``Cs[j] = D P^{j+1}(x)``
    (products of one-period Jacobians from ``jax.jacfwd``; ``Cs[k-1]`` is ``DP^k``).
    """
    T = system.period(params)

    def one_period(z, i):
        y, J = value_and_jacobian(lambda w: integrator.flow(system, params, w, t0 + i * T, 1), z)
        return y, (z, J)

    xk, (pts, Js) = jax.lax.scan(one_period, x, jnp.arange(k, dtype=jnp.float64))

    def accumulate(C, J):
        C = J @ C
        return C, C

    _, Cs = jax.lax.scan(accumulate, jnp.eye(x.shape[0]), Js)
    return xk, pts, Cs


def damped_newton(evaluate, flow_k, x0, k, tol, max_iter, max_norm, max_backtracks=10, stall=10):
    """Damped Newton on ``G(x) = P^k(x) - x = 0`` with Armijo backtracking on ``||G||``.

    ``evaluate(x) -> (P^k(x), pts, Cs)`` (see :func:`_orbit_jacobians`), ``flow_k(x) ->
    P^k(x)``. The step is the Newton step ``dx = -(DP^k - I)^{-1} G`` times ``a``, from
    ``a = 1`` shortened (quadratic-model backtracking, factor 0.1-0.5, at most
    ``max_backtracks`` times) until ``||G(x + a dx)|| <= (1 - 1e-4 a) ||G(x)||``.
    Every pass of the loop evaluates ``G`` and its Jacobian at the current iterate and stops there when ``||G|| <= tol``
    (converged: the points and Jacobians of that last evaluation are the Floquet data),
    when ``DP^k - I`` is singular (cond > 1e13), when the flow is not finite or the
    iterate left ``||x|| <= max_norm`` (diverged), or when the line search finds no
    decrease (a local minimum of ``||G||``), the residual did not halve over the last
    ``stall`` steps, or ``max_iter`` steps were taken (not converged).

    Returns ``x, (residual, iterations, status, history, pts, Cs)``; ``history[j]`` is
    the residual after ``j`` Newton steps.
    """
    dim = x0.shape[0]
    eye = jnp.eye(dim)
    pts0 = jnp.zeros((k, dim))
    Cs0 = jnp.zeros((k, dim, dim))
    hist0 = jnp.full(max_iter + 1, jnp.nan)

    def cond(c):
        return c[3] == RUNNING

    def body(c):
        it, x, _, st_in, hist, _, _ = c
        xk, pts, Cs = evaluate(x)
        g = xk - x
        A = Cs[-1] - eye
        r = jnp.linalg.norm(g)
        hist = hist.at[it].set(r)
        finite = jnp.isfinite(r) & jnp.all(jnp.isfinite(A))
        A_safe = jnp.where(finite, A, eye)
        s = jnp.linalg.svd(A_safe, compute_uv=False)
        singular = ~(s[-1] > 1e-13 * s[0])
        dx = jnp.linalg.solve(jnp.where(singular, eye, A_safe), -jnp.where(finite, g, 0.0))

        def ok(a, rn):
            return jnp.isfinite(rn) & (rn <= (1.0 - 1e-4 * a) * r)

        def ls_cond(lc):
            a, _, rn, j = lc
            return ~done_here & ~ok(a, rn) & (j < max_backtracks)

        def ls_body(lc):
            a, _, rn, j = lc
            # minimiser of the quadratic model of ||G(x + a dx)||^2 through phi(0) = r^2,
            # phi'(0) = -2 r^2 and phi(a) = rn^2, kept in [a/10, a/2]; first pass a = 1
            q = r * r * a * a / (rn * rn - r * r + 2.0 * r * r * a)
            a_new = jnp.where(j == 0, 1.0,
                              jnp.where(jnp.isfinite(q), jnp.clip(q, 0.1 * a, 0.5 * a), 0.1 * a))
            xn = x + a_new * dx
            return a_new, xn, jnp.linalg.norm(flow_k(xn) - xn), j + 1

        # stalled: the residual did not halve over the last `stall` steps (wandering far
        # from any orbit; a Newton iterate that approaches one converges fast)
        stalled = (it >= stall) & (r > 0.5 * hist[jnp.maximum(it - stall, 0)])
        # under vmap the body also runs for finished lanes (st_in set): no line search there
        done_here = (st_in != RUNNING) | (r <= tol) | ~finite | singular | (it >= max_iter) | stalled
        # the line search runs only for lanes that take a step
        ls0 = (jnp.asarray(1.0), x, jnp.asarray(jnp.inf), jnp.asarray(0))
        a, xn, rn, _ = jax.lax.while_loop(ls_cond, ls_body, ls0)
        accept = ~done_here & ok(a, rn)
        st = jnp.where(
            r <= tol, Status.CONVERGED,
            jnp.where(~finite, Status.DIVERGED,
                      jnp.where(singular, Status.SINGULAR,
                                jnp.where((it >= max_iter) | stalled | ~accept, Status.NOT_CONVERGED,
                                          jnp.where(jnp.linalg.norm(xn) > max_norm, Status.DIVERGED,
                                                    RUNNING)))))
        x_new = jnp.where(accept, xn, x)
        return it + accept.astype(it.dtype), x_new, r, st, hist, pts, Cs

    init = (jnp.asarray(0), x0, jnp.asarray(jnp.inf), jnp.asarray(RUNNING), hist0, pts0, Cs0)
    it, x, r, st, hist, pts, Cs = jax.lax.while_loop(cond, body, init)
    return x, (r, it, st, hist, pts, Cs)

