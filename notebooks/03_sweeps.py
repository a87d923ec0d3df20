# ---
# jupyter:
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Sweeps: backlash and mesh-stiffness amplitude of the paper's gear set
#
# How does the motion of the planetary set change when the backlash `b` or the mesh
# stiffness amplitude `kappa_amp` changes? The paper analyses one parameter set; here we
# sweep around it with the tools of `jaxgear` for that:
#
# - `jg.bifurcation_diagram` — stroboscopic points of many starts per parameter value,
#   classified by period and type (P-k, quasi-periodic, chaotic, escaped), from
#   independent starts and by sweeping up and down with the state carried from value to
#   value (hysteresis);
# - `jg.basin_sweep` — the global analysis at every value, with the attractors matched
#   from one value to the next so each keeps its identity: basin shares as a function of
#   the parameter;
# - `jg.parameter_map` — both parameters at once.
#
# Every sweep is also one command of the `jaxgear sweep` CLI (shown before each cell; the
# CLI writes the result file, `summary.json` and the figures). The sweep functions compute
# and return; a `jg.Runner` holds what they write and show (an output folder to resume
# from, progress bars): `quiet` below writes nothing and shows no bar. `FULL = False` runs reduced
# sizes in about a minute; `FULL = True` the sizes of the README figures (several minutes).
#
# Written files go to `SCRATCH`: `$JAXGEAR_SCRATCH` if set, else a new temporary folder.

# %%
FULL = False

import os
import tempfile
import time
from pathlib import Path

import numpy as np

import jaxgear as jg
from jaxgear import plotting

jg.enable_compilation_cache()  # a restarted kernel loads the compiled programs instead of compiling them again

p = jg.paper_params()
b0, k0 = jg.get_param(p, "b"), jg.get_param(p, "kappa_amp")
print(f"paper preset: b = b_sp = b_rp = {b0:g}, kappa_amp = kappa_sp_amp = kappa_rp_amp = {k0:.4f}, "
      f"Omega = {float(p.Omega):g}")

# The starts of `jaxgear sweep --starts N --seed 0`: uniform in the paper's region D on x4 = 0.
n_starts = 32 if FULL else 16
D = np.asarray(jg.PAPER_REGION)
starts = np.zeros((n_starts, 4))
starts[:, :3] = jg.seeds_in_box(n_starts, D[:, 0], D[:, 1], seed=0)

# every file this notebook writes goes here, never next to the notebook
SCRATCH = Path(os.environ.get("JAXGEAR_SCRATCH") or tempfile.mkdtemp(prefix="jaxgear-"))
SCRATCH.mkdir(parents=True, exist_ok=True)
print("files go to", SCRATCH)
quiet = jg.Runner(progress=False)  # the sweeps' runner: nothing written, no progress bars

# %% [markdown]
# ## 1. Backlash: bifurcation diagram
#
# `b` sets both half backlashes (`b_sp` and `b_rp`). At each value every start is
# integrated 400 forcing periods, then 64 stroboscopic points are recorded and the period
# is read by recurrence. `direction="all"` runs the independent starts and the two
# sweeps with the state carried from value to value.
#
# ```
# jaxgear sweep --param b --values 0.25:6:24 --out sweep-b
# ```
# (`FULL`: `--values 0.1:6:60 --starts 32`.)

# %%
b_values = np.linspace(0.1, 6, 60) if FULL else np.linspace(0.25, 6, 24)
t = time.perf_counter()
bif_b = jg.bifurcation_diagram(jg.REDUCED, p, "b", b_values, starts, direction="all", runner=quiet)
print(f"{len(b_values)} values x {n_starts} starts x 3 sweeps in {time.perf_counter() - t:.1f} s\n")
print(bif_b.table())
print("\nup and down sweeps differ at b =", np.round(bif_b.values[bif_b.differs("up", "down")], 3).tolist())
plotting.plot_bifurcation(bif_b, "x1")

# %% [markdown]
# Reading the diagram from small to large backlash: a single P-1 motion at small `b`,
# then period-2, 3 and 6 windows, a band of aperiodic (quasi-periodic or chaotic) motion,
# and from `b ≈ 2.75` the family of the paper: a dominant P-4 with a coexisting P-8 (and
# near `b = 6` a P-3). The P-8 shows only among the independent starts: sweeping up or
# down, every start follows the P-4 branch it sits on, so the P-8 — an isolated attractor
# with a small basin — is never reached quasi-statically. That is the paper's point about
# global methods in another form.
#
# At the preset's own backlash the independent starts find both the P-4 and the P-8:

# %%
i0 = int(np.argmin(np.abs(bif_b.values - b0)))
at_b0 = bif_b.attractors_at(i0, "independent")
print(f"b = {bif_b.values[i0]:g}:", [(a["label"], a["starts"]) for a in at_b0])
assert np.isclose(bif_b.values[i0], b0)
assert {"P-4", "P-8"} <= {a["label"] for a in at_b0}


# %% [markdown]
# Above `b ≈ 3` the P-4 does not change shape at all: its points move by exactly
# `(Δb, 0, 2Δb, 0)`. As long as the teeth never reach the back flank (`x1 > -b_sp` and
# `X_rp > -b_rp` all along the orbit) the backlash function is `max(X - b, 0)`, so only
# `x1 - b_sp` and `x3 - x1 - b_rp` enter the mesh forces (docs/model.md §4) and the equations
# are invariant under `x1 → x1 + Δb`, `x3 → x3 + 2Δb`. The sweep confirms it to round-off:

# %%
def p4_points(value):
    i = int(np.argmin(np.abs(bif_b.values - value)))
    d = bif_b.directions.index("independent")
    lane = int(np.argmax(bif_b.period[d, i] == 4))
    return bif_b.points[d, i, lane, -4:]


def set_distance(A, B):
    dist = np.linalg.norm(A[:, None] - B[None], axis=-1)
    return max(dist.min(0).max(), dist.min(1).max())


shift = set_distance(p4_points(5.0), p4_points(4.0) + np.array([1.0, 0.0, 2.0, 0.0]))
print(f"P-4 at b = 5 minus (P-4 at b = 4 shifted by (1, 0, 2, 0)): {shift:.1e}")
assert shift < 1e-6

# %% [markdown]
# ## 2. Backlash: basin shares
#
# The global analysis (direct method) at every value on a grid over the paper's region D;
# the attractors of neighbouring values are matched by the distance of their
# stroboscopic point sets, so each band of the figure is one attractor followed across
# the sweep (its label lists its periods along the way).
#
# ```
# jaxgear sweep --param b --values 2.75:5:6 --kind basins --grid 6,4,8 --out shares-b
# ```
# (`FULL`: `--values 2.5:6:15 --grid 20,12,24`.)

# %%
counts = (20, 12, 24) if FULL else (6, 4, 8)
grid = jg.CellGrid.box(jg.PAPER_REGION, counts, axes=(0, 1, 2), base=(0.0,) * 4, names=jg.REDUCED.state_names)
t = time.perf_counter()
bs_b = jg.basin_sweep(jg.REDUCED, p, "b", np.linspace(2.5, 6, 15) if FULL else np.linspace(2.75, 5, 6), grid,
                      runner=quiet)
print(f"{len(bs_b.values)} values x {grid.n_cells} cells in {time.perf_counter() - t:.1f} s\n")
print(bs_b.shares_table())
print()
print(bs_b.table())
plotting.plot_basin_shares(bs_b)

# %%
i0 = int(np.argmin(np.abs(bs_b.values - b0)))
shares_b0 = {int(bs_b.period[i0, g]): float(bs_b.shares[i0, g]) for g in np.nonzero(bs_b.present[i0])[0]}
print(f"b = {bs_b.values[i0]:g}: share by period", {f"P-{k}": round(v, 3) for k, v in shares_b0.items()})
assert np.isclose(bs_b.values[i0], b0) and 4 in shares_b0 and 8 in shares_b0
assert shares_b0[4] > shares_b0[8] > 0.03  # a dominant P-4 and a minority P-8, as in the paper

# %% [markdown]
# ## 3. Stiffness amplitude: bifurcation diagram
#
# `kappa_amp` sets both stiffness amplitudes (`kappa_sp_amp`, `kappa_rp_amp`).
#
# ```
# jaxgear sweep --param kappa_amp --values 0.1:0.6:26 --out sweep-kappa
# ```
# (`FULL`: `--values 0.1:0.6:101 --starts 32`.)

# %%
k_values = np.linspace(0.1, 0.6, 101) if FULL else np.linspace(0.1, 0.6, 26)
t = time.perf_counter()
bif_k = jg.bifurcation_diagram(jg.REDUCED, p, "kappa_amp", k_values, starts, direction="all", runner=quiet)
print(f"{len(k_values)} values in {time.perf_counter() - t:.1f} s\n")
print(bif_k.table())
plotting.plot_bifurcation(bif_k, "x1")

# %% [markdown]
# Weak stiffness modulation gives chaotic motion, strong modulation a P-2; the paper's
# P-4/P-8 structure lives in a narrow window around the preset's `kappa_amp ≈ 0.363`
# (docs/model.md §7 found the same by exploration). At the preset's own value:

# %%
at_k0 = jg.bifurcation_diagram(jg.REDUCED, p, "kappa_amp", [k0], starts, direction="independent", runner=quiet)
print(at_k0.table())
assert {"P-4", "P-8"} <= {a["label"] for a in at_k0.attractors_at(0)}
assert {a["label"] for a in bif_k.attractors_at(0, "independent")} == {"chaotic"}  # kappa_amp = 0.1
assert {a["label"] for a in bif_k.attractors_at(len(k_values) - 1, "independent")} == {"P-2"}  # kappa_amp = 0.6

# %% [markdown]
# ## 4. Stiffness amplitude: basin shares across the window
#
# ```
# jaxgear sweep --param kappa_amp --values 0.33:0.38:6 --kind basins --grid 6,4,8 --out shares-kappa
# ```
# (`FULL`: `--values 0.33:0.38:11 --grid 20,12,24`.)

# %%
t = time.perf_counter()
bs_k = jg.basin_sweep(jg.REDUCED, p, "kappa_amp", np.linspace(0.33, 0.38, 11 if FULL else 6), grid,
                      runner=quiet)
print(f"{len(bs_k.values)} values x {grid.n_cells} cells in {time.perf_counter() - t:.1f} s\n")
print(bs_k.shares_table())
print()
print(bs_k.table())
plotting.plot_basin_shares(bs_k, multipliers=True)

# %% [markdown]
# Each band is one attractor followed across the values; its label lists the periods it
# has along the way. The lower panel draws each attractor's largest Floquet multiplier
# modulus (`bs_k.multiplier`): all are below 1, since the direct method reports only
# stable cycles, and one close to 1 marks a bifurcation nearby. The dominant attractor is the P-4 from about 0.35 on; towards smaller
# `kappa_amp` it doubles its period — read from right to left, a period-doubling cascade
# into the aperiodic motion found below 0.33 in section 3 (a finer sweep with 3000
# transient periods gives P-4 at 0.34, P-8 at 0.335, P-16 at 0.33, aperiodic at 0.325).
# The minority attractor (the preset's P-8 near 0.36) shrinks and is gone at 0.38, where
# the P-4 is alone. Near such bifurcations orbits converge slowly and the periods found
# on a coarse grid can differ from grid to grid; confirm them with more periods or with
# `jaxgear shoot`.

# %%
i36 = int(np.argmin(np.abs(bs_k.values - 0.36)))
periods_36 = sorted(int(k) for k in bs_k.period[i36][bs_k.present[i36]])
print(f"kappa_amp = {bs_k.values[i36]:g}: periods {periods_36}")
assert 4 in periods_36 and 8 in periods_36
assert bs_k.present[-1].sum() == 1 and bs_k.period[-1][bs_k.present[-1]][0] == 4  # kappa_amp = 0.38: only the P-4

# %% [markdown]
# ## 5. Both parameters: period and number of attractors
#
# `jg.parameter_map` runs every (b, kappa_amp) pair from the same starts, all batched:
# the period reached from the first start, and the number of distinct attractors the
# starts reach.

# %%
nb, nk = (41, 41) if FULL else (9, 9)
t = time.perf_counter()
pmap = jg.parameter_map(jg.REDUCED, p, "b", np.linspace(1, 6, nb), "kappa_amp", np.linspace(0.2, 0.5, nk),
                        starts[: 16 if FULL else 6], runner=quiet)
print(f"{nb * nk} parameter pairs in {time.perf_counter() - t:.1f} s\n")
print(pmap.table())
plotting.plot_parameter_map(pmap, "period")

# %%
plotting.plot_parameter_map(pmap, "n_attractors")

# %% [markdown]
# ### Both parameters: basin shares
#
# `jg.basin_map` runs the global analysis at every (kappa_amp, b) point of a grid and
# matches the attractors to those of the left and lower neighbours, so each keeps one id
# across the map. The figure shows the attractor with the largest basin (its share in
# percent) and how many attractors coexist at each point; `plot_basin_map(bmap, "all")`
# draws every attractor's share.
#
# ```
# jaxgear sweep --param kappa_amp --values 0.34:0.37:4 --param2 b --values2 4:6:3 --kind basins --grid 6,4,8 --out map
# ```

# %%
t = time.perf_counter()
bmap = jg.basin_map(jg.REDUCED, p, "kappa_amp", np.linspace(0.34, 0.37, 7 if FULL else 4), "b",
                    np.linspace(4, 6, 5 if FULL else 3), grid, runner=quiet)
print(f"{bmap.sink_share.size} points x {grid.n_cells} cells in {time.perf_counter() - t:.1f} s\n")
print(bmap.table())
np.testing.assert_allclose(bmap.shares.sum(-1) + bmap.sink_share + bmap.unresolved_share, 1.0)
plotting.plot_basin_map(bmap)

# %% [markdown]
# ## 6. Interrupted sweeps resume
#
# Run by `jg.Runner(out=DIR)` (the CLI's `--out`) a sweep writes every finished block of
# values to `DIR/parts` under a manifest of its settings. Started again with the same settings it
# loads what is there and computes only the rest; the final `DIR/bifurcation.nc` is the
# same file as that of an uninterrupted run. Here the second call finds everything done:

# %%
folder = Path(tempfile.mkdtemp(prefix="sweep-kappa-", dir=SCRATCH))  # new and empty: the first run starts afresh
t = time.perf_counter()
runner = jg.Runner(out=folder, progress=False)
first = runner.run(jg.bifurcation_diagram, jg.REDUCED, p, "kappa_amp", k_values, starts[:4], direction="both")
t1 = time.perf_counter() - t
t = time.perf_counter()
again = runner.run(jg.bifurcation_diagram, jg.REDUCED, p, "kappa_amp", k_values, starts[:4], direction="both")
t2 = time.perf_counter() - t
print(f"first run {t1:.2f} s, second run {t2:.2f} s; files:", sorted(x.name for x in folder.iterdir()))
assert np.array_equal(first.points, again.points)
loaded = jg.load(folder / "bifurcation.nc")
assert np.array_equal(loaded.period, first.period)
