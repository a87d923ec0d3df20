# ---
# jupyter:
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Shooting, Floquet multipliers, and why a local method misses orbits
#
# The paper's local method (§4.1) is **shooting**: a P-k motion of the forced gear model
# is a fixed point of the k-fold stroboscopic map, so Newton's method on
#
# $$G(x) = P^k(x) - x = 0$$
#
# finds it from a nearby seed, whether the motion is stable or not. jaxgear solves this
# in the full state (x1..x4) with the Jacobian $DP^k - I$ from automatic differentiation
# through the integrator. The eigenvalues of the monodromy matrix $DP^m$ (the **Floquet
# multipliers**) then say whether the orbit is stable and, if not, how it loses stability.
#
# This notebook finds the paper preset's orbits (the unstable P-1 and P-2, the stable
# P-4 and P-8), draws their multipliers against the unit circle, and then *shows* the
# paper's conclusion 3: shooting finds the orbit its seeds are near and nothing else,
# while the global analysis finds every attractor and how much of the state space each
# one draws in.
#
# `FULL = False` runs in well under a minute; `FULL = True` uses more seeds and a finer grid.
#
# Written files go to `SCRATCH`: `$JAXGEAR_SCRATCH` if set, else a new temporary folder.

# %%
FULL = False

import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import display

import jaxgear as jg
from jaxgear import plotting

jg.enable_compilation_cache()  # a restarted kernel loads the compiled programs instead of compiling them again

p = jg.paper_params()
n_box = 128 if FULL else 32  # seeds in the box around the paper's P-1 guess
n_ball = 64 if FULL else 16  # seeds per radius in the convergence study
counts = (20, 12, 24) if FULL else (6, 4, 8)  # cells of region D for the global analysis

# every file this notebook writes goes here, never next to the notebook
SCRATCH = Path(os.environ.get("JAXGEAR_SCRATCH") or tempfile.mkdtemp(prefix="jaxgear-"))
SCRATCH.mkdir(parents=True, exist_ok=True)
print("files go to", SCRATCH)

# %% [markdown]
# ## 1. Unstable orbits: the P-1 and the P-2
#
# Seeds drawn uniformly from a box of ±3 around the paper's P-1 guess, shot for k = 1 and
# k = 2. Each seed either converges (residual ≤ 1e-10) or is reported as not converged /
# singular / diverged — never a wrong orbit. Converged seeds are deduplicated (a P-2 found
# from two of its points, or a P-1 found when asking for P-2, is reported once, with its
# minimal period).

# %%
x_guess = np.array([1.2736, -2.7122, 5.5372, 0.0])  # the paper's P-1 guess
# the library's solver (options=None: jg.SearchOptions() with solver=None, Levenberg-Marquardt)
box = jg.find_periodic_orbits(jg.REDUCED, p, jg.seeds_in_box(n_box, x_guess - 3.0, x_guess + 3.0, seed=1),
                              period=(1, 2), progress=False)
print("solver:", box.status_counts)
print(box.table())
P1 = next(o for o in box.orbits if o.period == 1)
P2 = next(o for o in box.orbits if o.period == 2)
assert not P1.stable and P1.instability == "flip" and P1.multipliers[0].real < -1
assert not P2.stable and P2.instability == "flip"

# %% [markdown]
# Newton converges quadratically once it is close: from a point 0.05 off the P-1, one step
# of `optimistix.Newton` at a time (`max_iter=1`, chained through `last_iterate`), the
# residual roughly squares from one step to the next until round-off.

# %%
import optimistix as optx

newton = optx.Newton(rtol=1e-10, atol=1e-12)
x = P1.points[0] + 0.05
hist = []
for _ in range(12):
    hist.append(float(np.linalg.norm(np.asarray(jg.stroboscopic_map(jg.REDUCED, p, x)) - x)))
    step = jg.periodic_orbit(jg.REDUCED, p, x, solver=newton, max_iter=1)
    x = np.asarray(step.last_iterate)
    if int(step.status) == 0:
        hist.append(float(step.residual))
        break
hist = np.array(hist)
fig, ax = plt.subplots(figsize=(5, 3.2))
ax.semilogy(hist, "o-")
ax.set(xlabel="Newton step", ylabel="||P(x) - x||", title="Residual history (P-1)")
print(np.array2string(hist, precision=2))

# %% [markdown]
# ## 2. Stable orbits: the P-4 and the P-8, seeded by the global analysis
#
# The global analysis (direct integration of every cell centre of region D, paper §4) finds
# the coexisting attractors and their domains; every point of each attractor is then a seed
# for shooting, which returns the exact orbit and its multipliers.

# %%
grid = jg.CellGrid.paper(counts=counts)
glob = jg.analyze_global(jg.REDUCED, p, grid, method=jg.Direct(), progress=False)
print(glob.table())
cells = jg.find_periodic_orbits(jg.REDUCED, p, jg.seeds_from_result(glob), progress=False)
print(cells.table())
P4 = next(o for o in cells.orbits if o.period == 4)
P8 = next(o for o in cells.orbits if o.period == 8)
assert P4.stable and P8.stable
assert sorted(a.period for a in glob.attractors) == [4, 8]
shares = {a.period: a.share for a in glob.attractors}
print(f"shares of region D: P-4 {100 * shares[4]:.1f} %, P-8 {100 * shares[8]:.1f} %")

# %% [markdown]
# The phase trajectories over each orbit's period (projected on x1-x3), with the
# stroboscopic points numbered and the crossings of Σ = {x4 = 0} marked. They are drawn
# from the trajectory stored with each orbit: no integration happens here.

# %%
orbits = [P1, P2, P4, P8]
for o in orbits:
    display(plotting.plot_orbit(jg.REDUCED, p, o, coords=(0, 2), title=f"P-{o.period} ({o.instability})"))

# %% [markdown]
# ## 3. Floquet multipliers
#
# An orbit is asymptotically stable when all multipliers of its monodromy matrix lie
# inside the unit circle. The P-1 and the P-2 each have one real multiplier below -1: a
# **flip** (period-doubling) instability, the signature of the cascade P-1 → P-2 → P-4
# that ends at the stable P-4. The P-4 and the P-8 have all four multipliers inside the
# circle (a complex pair and a strongly damped pair).

# %%
for o in orbits:
    lam = ", ".join(f"{z.real:+.4f}{z.imag:+.4f}j" for z in o.multipliers)
    print(f"P-{o.period} {o.instability:>6}: |lambda|max = {o.max_multiplier:.4f}   [{lam}]")
plotting.plot_multipliers(orbits)

# %%
assert P1.max_multiplier > 1 and P2.max_multiplier > 1
assert P4.max_multiplier < 1 and P8.max_multiplier < 1
assert abs(P1.multipliers[0].imag) < 1e-12 and abs(P2.multipliers[0].imag) < 1e-12  # real: a flip, not a pair


# %% [markdown]
# ## 4. Verification by direct integration
#
# The paper checks each orbit by integrating from it. Starting 1e-6 away, the unstable
# orbits are left within a few dozen periods — and the motion ends on the P-4 — while the
# P-4 and the P-8 keep it.

# %%
def nearest_attractor(x):
    d = {o.period: np.min(np.linalg.norm(o.points - x, axis=1)) for o in (P4, P8)}
    k = min(d, key=d.get)
    return f"P-{k}" if d[k] < 1e-3 else "neither"


for o in orbits:
    check = jg.verify_orbit(jg.REDUCED, p, o, options=jg.VerifyOptions(periods=400 if FULL else 300))
    ends = sorted({nearest_attractor(x) for x in check.final_points[:, -1]})
    verdict = "kept" if check.kept else f"left after {int(check.left_at.max())} periods, ends on {', '.join(ends)}"
    print(f"P-{o.period}: {verdict}")
    assert check.kept == o.stable

# %% [markdown]
# ## 5. The paper's conclusion 3, shown
#
# > "The shooting method can only find some coexisting periodic orbits which are close to
# > each other and easy to omit some periodic orbits which are far away."
#
# Suppose we knew only the P-4 (from a measurement, or one simulation). A local search
# seeds Newton near it. Here `n_ball` seeds at each distance r from a P-4 point, r from
# 0.01 to 10 (region D is 50 × 30 × 60), are shot for k = 8: a fixed point of P^8 is a
# P-8 *or* a P-4 (or a P-2, a P-1), so Newton is free to return either stable orbit. Each
# seed ends on the P-4, on the P-8, on another (unstable) orbit, or fails to converge.

# %%
rng = np.random.default_rng(0)
radii = np.array([0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0])
u = rng.standard_normal((len(radii), n_ball, 4))
seeds = P4.points[0] + radii[:, None, None] * u / np.linalg.norm(u, axis=-1, keepdims=True)
# chunks of 8 seeds reuse the Newton kernel compiled for the 8 points of the P-8 above
study = jg.find_periodic_orbits(jg.REDUCED, p, seeds.reshape(-1, 4), period=8, chunk_size=8, progress=False,
                                trajectory_samples=0)
shot = study.shots[8]
conv = shot.status == 0
outcome = np.full(len(conv), 3)  # 0 the P-4, 1 the P-8, 2 another orbit, 3 not converged
for code, o in ((0, P4), (1, P8)):
    d = np.min(np.linalg.norm(shot.point[:, None] - o.points[None], axis=-1), axis=-1)
    outcome[conv & (d < 1e-6)] = code
outcome[conv & (outcome == 3)] = 2
outcome = outcome.reshape(len(radii), n_ball)
period_of = shot.min_period.reshape(len(radii), n_ball)
stable_of = shot.stable.reshape(len(radii), n_ball)
gap = np.min(np.linalg.norm(P4.points[:, None] - P8.points[None], axis=-1))
print(f"distance from the P-4 to the nearest point of the P-8: {gap:.3f}")

# %% [markdown]
# First the local search proper: the seeds within 0.1 of the P-4.

# %%
near = radii <= 0.1
ok = outcome[near] < 3
found = sorted({(int(k), bool(s)) for k, s in zip(period_of[near][ok], stable_of[near][ok])})
print(f"{ok.sum()} of {ok.size} seeds converged, to:",
      ", ".join(f"P-{k} {'stable' if s else 'unstable'}" for k, s in found))
assert not np.any(outcome[near] == 1)  # the local search never finds the P-8
assert [k for k, s in found if s] == [4]  # its only stable orbit is the P-4

# %% [markdown]
# The local search reports one stable motion, the P-4 (and at most the unstable P-2 it
# was born from by period doubling: orbits "close to each other"). The global analysis of
# the same region, above, found two — the P-4 *and* the P-8 — and how much of the region
# each draws in. No amount of Newton iterations near the P-4 reveals that about 1 in 8
# starting states of region D ends on a different motion.

# %%
for a in glob.attractors:
    print(f"global analysis: {a.label} attracts {100 * a.share:.1f} % of region D ({a.cell_count} cells)")
assert len(glob.attractors) == 2 and shares[8] > 0.05

# %% [markdown]
# ## 6. How far does Newton's convergence reach?
#
# All radii: the fraction of seeds ending on each orbit against their distance from the
# P-4. Newton's basin of convergence is a property of the algorithm, not of the motion: it
# is not the domain of attraction.

# %%
names = ["the P-4", "the P-8", "another orbit", "not converged"]
colors = [plotting.attractor_color(0), plotting.attractor_color(1), "#7f7f7f", "#d9d9d9"]
frac = np.stack([(outcome == c).mean(axis=1) for c in range(4)])
fig, ax = plt.subplots(figsize=(6.5, 3.8))
ax.stackplot(radii, frac, labels=names, colors=colors)
ax.axvline(gap, color="k", ls="--", lw=0.8)
ax.text(gap * 1.08, 0.06, "distance\nto the P-8", fontsize=8)
ax.set(xscale="log", xlabel="seed distance r from the P-4", ylabel="fraction of seeds", ylim=(0, 1),
       title="Where Newton on $P^8(x) - x = 0$ ends")
ax.legend(loc="lower left", fontsize=8)
print(study.table())
print("fraction ending on the P-4:", np.round(frac[0], 2))
print("fraction ending on the P-8:", np.round(frac[1], 2))
assert frac[0][0] == 1.0  # the closest seeds: always the P-4
assert frac[1][radii < gap].max() == 0.0  # no seed nearer than the P-8 ever finds it

# %% [markdown]
# Close to the P-4, Newton returns the P-4 (now and then its parent P-2) and never the
# P-8. Only seeds farther out than the P-8 itself ever reach it, and there the outcome is a
# lottery: the P-4, the P-8, unstable orbits (the P-2, sometimes the P-1 or an unstable P-8
# with a multiplier through +1), or no convergence at all — and the fractions say nothing
# about which motion a gear set started there would settle on. That is the global
# analysis's job (notebook 01): integrate the dynamics from every cell, and count.
#
# ## 7. Saving and reloading
#
# Every result saves to a netCDF file and loads back exactly; the file opens as labelled
# arrays with xarray, and figures can be redrawn from the loaded result without
# integrating (`plot_orbit(search, i)` needs neither the system nor the parameters).

# %%
path = cells.save(SCRATCH / "orbits.nc")
again = jg.load(path)
assert [o.period for o in again.orbits] == [4, 8]
np.testing.assert_array_equal(again.orbits[0].points, cells.orbits[0].points)

import xarray as xr

with xr.open_dataset(path) as ds:
    print(ds[["orbits__period", "orbits__points", "orbits__stable"]])
plotting.plot_orbit(again, 1, coords=(0, 1, 2))
