"""Shooting benchmark: converged fractions and wall times of the orbit search on the paper preset.

One run prints one table: 64 random seeds over the paper's region D (x4 in [-5, 5]),
periods 1, 2, 4 and 8, for the hand-written damped Newton (the solver of jaxgear <= 0.1)
and the optimistix solvers, single and multiple shooting, with and without the
transient and deflation; then the full search of ``jaxgear shoot --periods 1-8
--random 64``. "converged" counts seed runs that reached an orbit that re-converged
with the default integrator (kink-aware RK4, 200 steps per period); the rounds run with
classical RK4 (``search_integrator``). Wall times include compilation (a fresh process
pays it once per period and configuration).

    python benchmarks/shooting.py            # about 5 minutes on a 2-core CPU
"""

from __future__ import annotations

import time

import numpy as np

import jaxgear as jg
from jaxgear.cli.shoot import DEFAULT_REGION, SEARCH_DEFAULTS

ROWS = [
    # label, solver, segments, transient, deflation rounds
    ("plain damped Newton (jaxgear 0.1)", "damped-newton", 1, 0, 0),
    ("optimistix Newton", "newton", 1, 0, 0),
    ("optimistix Levenberg-Marquardt", "levenberg-marquardt", 1, 0, 0),
    ("damped Newton + transient 40", "damped-newton", 1, 40, 0),
    ("Newton + transient 40", "newton", 1, 40, 0),
    ("Dogleg + transient 40", "dogleg", 1, 40, 0),
    ("Levenberg-Marquardt + transient 40", "levenberg-marquardt", 1, 40, 0),
    ("Newton, 4 segments + transient 40", "newton", 4, 40, 0),
    ("Levenberg-Marquardt, 4 segments + transient 40", "levenberg-marquardt", 4, 40, 0),
    ("Newton + transient 40 + deflation 2", "newton", 1, 40, 2),
    ("Newton, 4 segments + transient 40 + deflation 2", "newton", 4, 40, 2),
]


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
        runs = sum(c["runs"] for c in s.convergence.values())
        conv = sum(c["converged"] for c in s.convergence.values())
        first = sum(c["first_round"] for c in s.convergence.values())
        orbits = " ".join(f"P-{o.period}{'s' if o.stable else 'u'}" for o in s.orbits)
        lines.append(f"| {label} | {runs} | {conv} | {conv / runs:.1%} | {first}/{64 * len(periods)} | {orbits} "
                     f"| {wall:.1f} |")
        print(lines[-1], flush=True)
        return s

    print("\n".join(lines), flush=True)
    for label, solver, M, tr, dr in ROWS:
        row(label, [1, 2, 4, 8], solver=solver, segments=M, transient=tr, deflation_rounds=dr)
    s = row("search defaults, periods 1-8 (`jaxgear shoot --periods 1-8 --random 64`)", list(range(1, 9)),
            verify=300, **SEARCH_DEFAULTS)
    print()
    print(s.convergence_table())
    print()
    print(s.table())
    for i, o in enumerate(s.orbits):
        c = s.checks[str(i)]
        lam = " ".join(f"{z.real:+.6f}{z.imag:+.6f}j" for z in o.multipliers[:2])
        print(f"orbit {i + 1}: P-{o.period} {'stable' if o.stable else o.instability}, leading multipliers {lam}; "
              f"direct integration: {'kept' if c['kept'] else 'left after {} periods'.format(c['left_at'])}")


if __name__ == "__main__":
    main()
