"""Continuation benchmark: the corrector's optimistix Newton against a hand-written loop.

The corrector of :func:`jaxgear.continue_orbit` is ``optimistix.Newton`` on the bordered
system ``F(z) = 0, t . (z - z_pred) = 0`` (``jaxgear/continuation/_arclength.py``).
:func:`hand_written_newton` is the loop it replaced: the same bordered Newton written as a
``lax.while_loop``, stopping on the residual alone. Both run in the same process on two
branches:

- the paper preset's stable P-4 continued in Omega from 0.87 to 0.9 through its
  period doubling (``tests/test_continuation.py::test_paper_p4_continuation_in_omega``);
- the hardening Duffing oscillator continued in omega from 0.9 to 1.15 through its two
  folds (the ``duffing_folds`` fixture of ``tests/test_continuation.py``).

Each branch is compiled once per corrector (the compile run also counts corrector calls
and Newton iterations), then timed ``--repeat`` times alternating the correctors and
their order; the best wall time and the best CPU time of the process (less sensitive to
other jobs on a shared machine) are kept. Prints one Markdown table.

    python benchmarks/continuation.py [--repeat 10]     # about 2 minutes on a 2-core CPU
"""

from __future__ import annotations

import argparse
import collections
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxgear as jg
from jaxgear.continuation import _arclength

_OK, _NOT_CONVERGED, _DIVERGED, _RUN = 0, 1, 3, -1


def hand_written_newton(evaluate, z_guess, anchor, w, tol, max_iter, max_norm):
    """The hand-written bordered Newton (reference): ``jnp.linalg.solve`` on ``[J; w^T]``,
    converged when ``||F|| <= tol`` and ``|w . (z - anchor)| <= tol (1 + ||anchor||)`` at an
    evaluated point, given up after ``max_iter`` steps or when the residual grows a
    hundredfold. Same signature and outputs as ``_arclength._bordered_newton``."""
    n = z_guess.shape[0] - 1

    def cond(c):
        return c[2] == _RUN

    def body(c):
        it, z, _, _, _, _, r0 = c
        F, J, pts = evaluate(z)
        cval = w @ (z - anchor)
        rF = jnp.linalg.norm(F)
        r = jnp.sqrt(rF**2 + cval**2)
        finite = jnp.isfinite(r) & jnp.all(jnp.isfinite(J))
        B = jnp.concatenate([J, w[None]], axis=0)
        B = jnp.where(finite, B, jnp.eye(n + 1))
        dz = jnp.linalg.solve(B, -jnp.where(finite, jnp.concatenate([F, cval[None]]), 0.0))
        r0 = jnp.where(it == 0, r, r0)
        conv = (rF <= tol) & (jnp.abs(cval) <= tol * (1.0 + jnp.linalg.norm(anchor)))
        div = ~finite | (jnp.linalg.norm(z[:-1]) > max_norm)
        fail = (it >= max_iter) | ((it >= 2) & (r > 1e2 * r0)) | ~jnp.all(jnp.isfinite(dz))
        st = jnp.where(conv, _OK, jnp.where(div, _DIVERGED, jnp.where(fail, _NOT_CONVERGED, _RUN)))
        z_new = jnp.where(st == _RUN, z + dz, z)
        return it + (st == _RUN).astype(it.dtype), z_new, st, rF, J, pts, r0

    F, J, pts = jax.eval_shape(evaluate, z_guess)
    init = (jnp.asarray(0), z_guess, jnp.asarray(_RUN), jnp.asarray(jnp.inf), jnp.zeros(J.shape),
            jnp.zeros(pts.shape), jnp.asarray(jnp.inf))
    it, z, st, rF, J, pts, _ = jax.lax.while_loop(cond, body, init)
    return z, st, it, rF, J, pts


CORRECTORS = {"hand-written loop": hand_written_newton, "optimistix Newton": _arclength._bordered_newton}


def paper_p4():
    x0 = np.array([5.3608, -0.1903, 8.2803, -0.8374])
    return jg.continue_orbit(jg.REDUCED, jg.paper_params(), x0, param="Omega", stop=0.9, period=4,
                             options=jg.ContinuationOptions(ds=0.01), progress=False)


def duffing_folds():
    p = jg.DuffingParams(omega=0.9, delta=0.01, alpha=1.0, beta=1.0, gamma=0.003)
    return jg.continue_orbit(jg.DUFFING, p, np.zeros(2), param="omega", stop=1.15,
                             options=jg.ContinuationOptions(ds=0.01, ds_max=0.05), progress=False)


BRANCHES = {"paper P-4 in Omega (0.87 to 0.9, PD)": paper_p4, "Duffing in omega (0.9 to 1.15, two folds)": duffing_folds}


def run_with(newton, branch, count=False):
    """``branch()`` with the corrector's Newton ``newton``; with ``count`` also the number
    of corrector calls and of Newton iterations."""
    calls = collections.Counter()
    saved_newton, saved_correct = _arclength._bordered_newton, _arclength._Ctx.correct

    def counting(self, *a):
        out = saved_correct(self, *a)
        calls["calls"] += 1
        calls["iterations"] += int(out.iterations)
        return out

    _arclength._bordered_newton = newton
    if count:
        _arclength._Ctx.correct = counting
    try:
        t, c = time.perf_counter(), time.process_time()
        br = branch()
        return (time.perf_counter() - t, time.process_time() - c), br, calls
    finally:
        _arclength._bordered_newton, _arclength._Ctx.correct = saved_newton, saved_correct


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=10, help="timed runs per branch and corrector (best kept)")
    repeat = ap.parse_args(argv).repeat
    print(f"jaxgear {jg.__version__}, jax {jax.__version__}, {jax.devices()[0].platform}, best of {repeat}")
    print()
    print("| branch | corrector | wall s per branch | CPU s per branch | points | corrector calls "
          "| Newton iterations | bifurcations | wall ratio | CPU ratio |")
    print("|" + "---|" * 10)
    for label, branch in BRANCHES.items():
        first = {name: run_with(newton, branch, count=True) for name, newton in CORRECTORS.items()}
        best = {name: np.array([np.inf, np.inf]) for name in CORRECTORS}
        for r in range(repeat):
            order = list(CORRECTORS.items())
            for name, newton in order if r % 2 == 0 else order[::-1]:
                best[name] = np.minimum(best[name], run_with(newton, branch)[0])
        ref = best["hand-written loop"]
        for name in CORRECTORS:
            _, br, calls = first[name]
            bifs = " ".join(f"{b.kind}{'*' if b.nonsmooth else ''} {b.param_value:.10f}" for b in br.bifurcations)
            wall, cpu = best[name]
            print(f"| {label} | {name} | {wall:.3f} | {cpu:.3f} | {len(br)} | {calls['calls']} | {calls['iterations']} "
                  f"| {bifs} | {wall / ref[0]:.2f} | {cpu / ref[1]:.2f} |", flush=True)

if __name__ == "__main__":
    main()
