# ---
# jupyter:
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # The paper end to end: global analysis of a planetary gear train
#
# This notebook follows *Global Analysis of a Planetary Gear Train* (§2-§4): the gear
# set, the Poincaré section, the cell mapping, the coexisting attractors and their
# domains of attraction (the paper's Figures 3-8), the shooting results and the
# verification by direct integration.
#
# `FULL = False` runs on reduced grids in about a minute; `FULL = True` uses the paper's
# 50 × 30 × 60 cells (a few minutes on a 2-core laptop).

# %%
FULL = False

import numpy as np
from IPython.display import display

import jaxgear as jg
from jaxgear import plotting

jg.enable_compilation_cache()  # a restarted kernel loads the compiled programs instead of compiling them again

counts = (50, 30, 60) if FULL else (10, 6, 12)

# %% [markdown]
# ## 1. The gear set (paper §4.1)
#
# The paper gives the geometry, mesh stiffness, errors and backlash; it leaves out the
# frequency, damping, inertias and torques. The `paper` preset supplies them with the
# reason for each (the `source` column).

# %%
gear = jg.paper_gear_set()
print(gear.table())
p = gear.to_params()
print(p.table())

# %% [markdown]
# ## 2. The Poincaré section Σ = {x4 = 0}
#
# A forced system's exact Poincaré map is the stroboscopic map (state at phase 0 of each
# forcing period). The paper's "Poincaré-like" map uses the hyperplane x4 = 0 instead.
# Below: a trajectory over four periods, its stroboscopic points (circles) and its
# upward crossings of Σ, located to round-off (stars).

# %%
x0 = np.array([1.2736, -2.7122, 5.5372, 0.0])  # the paper's P-1 guess
x_settled = np.asarray(jg.stroboscopic_map(jg.REDUCED, p, x0, periods=600))
ts, xs = jg.sample_trajectory(jg.REDUCED, p, x_settled, periods=4, samples_per_period=200)
strobe = np.asarray(jg.stroboscopic_orbit(jg.REDUCED, p, x_settled, n_points=4))
hit = jg.section_map(jg.REDUCED, p, strobe, periods=0)
print("crossings on x4 = 0 to round-off:", np.abs(np.asarray(hit.state)[:, 3]).max())
assert np.abs(np.asarray(hit.state)[:, 3]).max() < 1e-12

import matplotlib.pyplot as plt

fig, ax = plt.subplots(figsize=(6, 4))
xs = np.asarray(xs)
ax.plot(xs[:, 0], xs[:, 2], lw=0.8, label="trajectory")
ax.plot(strobe[:, 0], strobe[:, 2], "o", label="stroboscopic points")
ax.plot(np.asarray(hit.state)[:, 0], np.asarray(hit.state)[:, 2], "*", ms=12, label="crossings of x4 = 0")
ax.set(xlabel="x1", ylabel="x3", title="Stroboscopic points and section crossings")
ax.legend()

# %% [markdown]
# ## 3. Cell mapping with the paper's method
#
# Region D (eq. 10) is cut into cells; each cell centre, on Σ at phase 0, is integrated
# l = 50 periods and on to the next crossing of Σ: the crossing's cell is the image.
# Hsu's analysis of the resulting cell map gives the periodic groups and their domains.

# %%
grid = jg.CellGrid.paper(counts=counts)
paper_method = jg.analyze_global(jg.REDUCED, p, grid, method=jg.PoincareCellMap(), progress=False)
print(paper_method.table())

# %% [markdown]
# ## 4. The same region classified by direct integration
#
# The `direct` method integrates every cell centre on the stroboscopic map until its
# attractor is recognised. It is the reference for the cell methods.

# %%
direct = jg.analyze_global(jg.REDUCED, p, grid, method=jg.Direct(), progress=False)
print(direct.table())
periods = sorted(a.period for a in direct.attractors)
assert periods == [4, 8], periods  # the paper's coexisting P-4 and P-8
assert direct.n_sink == 0 and direct.n_unresolved == 0

# %% [markdown]
# Direct integration finds the paper's two coexisting attractors, a dominant P-4 and a
# minority P-8. The Poincaré-like map restarts each crossing at phase 0, although the
# crossing happened at another forcing phase; on this model that approximation sends the
# P-8's cells into the P-4 group, so the paper's method reports the P-4 alone. Shares
# per method:

# %%
for r in (paper_method, direct):
    print(f"{r.method.name:>14}: " + ", ".join(f"{a.label} {100 * a.share:.1f} %" for a in r.attractors))

# %% [markdown]
# ## 5. Attractors and their domains (paper Figures 6-8)
#
# Points of each attractor (its crossings of Σ), then slices of the domains of
# attraction through x3 and a 3-D view of the P-8's domain: it is scattered through the
# whole region, finely interleaved with the P-4's.

# %%
plotting.plot_attractors(direct, section=True)

# %%
plotting.plot_domains(direct, axis="x3", n_slices=4)

# %%
p8 = [a.id for a in direct.attractors if a.period == 8]
plotting.plot_domains_3d(direct, attractors=p8)

# %%
plotting.plot_shares(direct)

# %% [markdown]
# ## 6. Shooting: the paper's local method (§4.1)
#
# Newton's method on `P^k(x) - x = 0` with the Jacobian from automatic differentiation
# finds periodic orbits whether or not they are stable. Seeded around the paper's P-1
# guess it finds an unstable P-1 and an unstable P-2 (both with a multiplier below -1, a
# flip: the period-doubling route P-1 → P-2 → P-4); seeded from the global analysis it
# confirms the P-4 and the P-8 as stable orbits.

# %%
n_seeds = 256 if FULL else 64
near_guess = jg.seeds_in_box(n_seeds, x0 - 3.0, x0 + 3.0, seed=1)
local = jg.find_periodic_orbits(jg.REDUCED, p, near_guess, period=(1, 2))
from_cells = jg.find_periodic_orbits(jg.REDUCED, p, jg.seeds_from_result(direct))
orbits = list(local.orbits) + list(from_cells.orbits)
for o in orbits:
    print(f"P-{o.period}: {o.instability:>6}, max |multiplier| {o.max_multiplier:.3f}, "
          f"point {np.round(o.points[0], 4)}")
by_period = {o.period: o for o in orbits}
assert by_period[1].instability == "flip" and not by_period[1].stable
assert by_period[4].stable and by_period[8].stable

# %% [markdown]
# The phase trajectories of the orbits over their k periods, with the stroboscopic points
# numbered and the crossings of Σ marked (the paper's Figures 3-6).

# %%
for k in sorted(by_period):
    fig = plotting.plot_orbit(jg.REDUCED, p, by_period[k], coords=(0, 1, 2), title=f"P-{k}")
    display(fig)

# %% [markdown]
# ## 7. Verification by direct integration
#
# Start on each orbit with a perturbation of 1e-6 and integrate 300 periods: the
# unstable P-1 and P-2 are left within a few dozen periods (the paper: "not of long-term
# stability"), the P-4 and P-8 are kept.

# %%
for k in sorted(by_period):
    check = jg.verify_orbit(jg.REDUCED, p, by_period[k], options=jg.VerifyOptions(periods=300))
    print(f"P-{k}: {'kept' if check.kept else 'left after ' + str(int(check.left_at.max())) + ' periods'}")
    assert check.kept == by_period[k].stable
