"""Shooting benchmark: converged fractions and wall times of the orbit search on the paper preset.

One run prints one table: 64 random seeds over the paper's region D (x4 in [-5, 5]),
periods 1, 2, 4 and 8, for the optimistix solvers (single and multiple shooting, with and
without the transient and deflation) and, as the baseline, the hand-written damped Newton
of jaxgear 0.2 (kept here only: :func:`damped_newton`); then the full search of
``jaxgear shoot --periods 1-8 --random 64`` and the single-period search ``--period 1
--random 64``, which is the same search. "converged" counts seed runs that reached an
orbit that re-converged with the default integrator (kink-aware RK4, 200 steps per
period); "first round" counts the runs that converged in the rounds, which run with
classical RK4 (``search_integrator``) — the only count the baseline has. Wall times
include compilation (a fresh process pays it once per period and configuration).

    python benchmarks/shooting.py            # about 5 minutes on a 2-core CPU
"""

from __future__ import annotations

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import jaxgear as jg
from jaxgear._status import Status
from jaxgear.cli.shoot import DEFAULT_REGION, RANDOM_TRANSIENT, VERIFY_PERIODS
from jaxgear.shooting._floquet import orbit_jacobians

RUNNING = -1
"""Status of a lane whose Newton iteration is still running (never returned)."""

TOLS = dict(rtol=1e-10, atol=1e-12)
ROWS = [
    # label, solver (None: the library's choice; "damped": the baseline), segments, transient, deflation rounds
    ("damped Newton, hand-written (jaxgear 0.1)", "damped", 1, 0, 0),
    ("optimistix Newton", optx.Newton(**TOLS), 1, 0, 0),
    ("optimistix Levenberg-Marquardt", optx.LevenbergMarquardt(**TOLS), 1, 0, 0),
    ("damped Newton, hand-written + transient 40", "damped", 1, 40, 0),
    ("Newton + transient 40", optx.Newton(**TOLS), 1, 40, 0),
    ("Dogleg + transient 40", optx.Dogleg(**TOLS), 1, 40, 0),
    ("Levenberg-Marquardt + transient 40", optx.LevenbergMarquardt(**TOLS), 1, 40, 0),
    ("Newton, 4 segments + transient 40", optx.Newton(**TOLS), 4, 40, 0),
    ("Levenberg-Marquardt, 4 segments + transient 40", optx.LevenbergMarquardt(**TOLS), 4, 40, 0),
    ("Newton + transient 40 + deflation 2", optx.Newton(**TOLS), 1, 40, 2),
    ("Newton, 4 segments + transient 40 + deflation 2", optx.Newton(**TOLS), 4, 40, 2),
]


def damped_newton(evaluate, flow_k, x0, k, tol, max_iter, max_norm, max_backtracks=10, stall=10):
    """Damped Newton on ``G(x) = P^k(x) - x = 0`` with Armijo backtracking on ``||G||``.

    ``evaluate(x) -> (P^k(x), pts, Cs)`` (see ``jaxgear.shooting._floquet.orbit_jacobians``), ``flow_k(x) ->
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



@eqx.filter_jit
def damped_kernel(system, params, X, t0, k, integrator, tol, max_iter, max_norm):
    """Status codes of :func:`damped_newton` from every seed of ``X (n, dim)`` (``vmap``)."""

    def one(x0):
        evaluate = lambda x: orbit_jacobians(system, params, x, t0, k, integrator)
        flow_k = lambda x: integrator.flow(system, params, x, t0, k)
        return damped_newton(evaluate, flow_k, x0, k, tol, max_iter, max_norm)[1][2]

    return jax.vmap(one)(X)


def main():
    p = jg.paper_params()
    region = np.asarray(DEFAULT_REGION)
    seeds = jg.seeds_in_box(64, region[:, 0], region[:, 1], seed=0)
    search_int = jg.RK4(200)
    lines = []
    head = ("| configuration | runs | converged | fraction | first round | orbits (P-m: unstable u / stable s) "
            "| wall s |")
    lines += [head, "|" + "---|" * 7]

    def row(label, periods, **kw):
        t = time.perf_counter()
        s = jg.find_periodic_orbits(jg.REDUCED, p, seeds, period=periods, search_integrator=search_int,
                                    progress=False, trajectory_samples=0, **kw)
        wall = time.perf_counter() - t
        runs = sum(c.runs for c in s.convergence)
        conv = sum(c.converged for c in s.convergence)
        first = sum(int(np.sum(np.asarray(r.status)[: len(seeds)] == Status.CONVERGED)) for r in s.shots.values())
        orbits = " ".join(f"P-{o.period}{'s' if o.stable else 'u'}" for o in s.orbits)
        lines.append(f"| {label} | {runs} | {conv} | {conv / runs:.1%} | {first}/{64 * len(periods)} | {orbits} "
                     f"| {wall:.1f} |")
        print(lines[-1], flush=True)
        return s

    def baseline(label, periods, transient):
        t = time.perf_counter()
        X = np.asarray(jg.stroboscopic_map(jg.REDUCED, p, seeds, periods=transient)) if transient else seeds
        first = sum(int(np.sum(np.asarray(damped_kernel(jg.REDUCED, p, jnp.asarray(X), jnp.asarray(0.0), k,
                                                       search_int, 1e-10, 40, 1e6)) == Status.CONVERGED))
                    for k in periods)
        lines.append(f"| {label} | {64 * len(periods)} | - | - | {first}/{64 * len(periods)} | - "
                     f"| {time.perf_counter() - t:.1f} |")
        print(lines[-1], flush=True)

    print("\n".join(lines), flush=True)
    for label, solver, M, tr, dr in ROWS:
        if solver == "damped":
            baseline(label, [1, 2, 4, 8], tr)
        else:
            row(label, [1, 2, 4, 8], solver=solver, segments=M, transient=tr, deflation_rounds=dr)
    search = dict(transient=RANDOM_TRANSIENT, verify=VERIFY_PERIODS)
    row("search defaults, period 1 (`jaxgear shoot --period 1 --random 64`)", [1], **search)
    s = row("search defaults, periods 1-8 (`jaxgear shoot --periods 1-8 --random 64`)", list(range(1, 9)), **search)
    print()
    print(s.convergence_table())
    print()
    print(s.table())
    for i, o in enumerate(s.orbits):
        c = s.verification_of(i)
        lam = " ".join(f"{z.real:+.6f}{z.imag:+.6f}j" for z in o.multipliers[:2])
        print(f"orbit {i + 1}: P-{o.period} {'stable' if o.stable else o.instability}, leading multipliers {lam}; "
              f"direct integration: {'kept' if c.kept else f'left after {c.left_at} periods'}")


if __name__ == "__main__":
    main()
