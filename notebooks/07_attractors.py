# ---
# jupyter:
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Attractors of every type: Lyapunov exponents, chaos in the backlash band, fractal basins
#
# The global analysis reports periodic motions (P-k) and also motions that repeat no
# point: chaotic attractors and quasi-periodic ones (invariant curves of the
# stroboscopic map). Each attractor carries its type, its Lyapunov exponents with
# errors and its Kaplan-Yorke dimension (docs: Methods, Attractor types). This notebook
#
# 1. computes the exponents of a textbook chaotic oscillator (Ueda's) and checks them
#    against what the equation fixes exactly;
# 2. finds the chaotic attractor of the reduced gear model at half backlash b = 2;
# 3. sweeps the backlash through the chaotic band (about 1.2 to 2.7) and back to the
#    periodic motions;
# 4. measures how fractal a basin boundary is (basin entropy).
#
# `FULL = False` runs a tiny grid and two values (under a minute on two idle cores); `FULL = True`
# the sizes of the documentation's figure (minutes on a GPU, longer on a CPU).

# %%
FULL = False

import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import display

import jaxgear as jg
from jaxgear import REDUCED, AttractorType, basin_entropy, classify_attractor, lyapunov_spectrum, plotting

jg.enable_compilation_cache()  # a restarted kernel loads the compiled programs instead of compiling them again

grid = jg.CellGrid.paper((25, 15, 30) if FULL else (5, 3, 6))  # region D on the section x4 = 0
backlash = np.linspace(1.0, 3.5, 12) if FULL else np.array([2.0, 3.0])

# %% [markdown]
# ## 1. Lyapunov exponents of Ueda's oscillator
#
# `x'' + 0.05 x' + x^3 = 7.5 cos t` (the forced Duffing oscillator that ships as
# `jaxgear.DUFFING`) is chaotic. `lyapunov_spectrum` maps tangent vectors through the
# integrator's steps and re-orthonormalises them every forcing period (Benettin et al.
# 1980). Whatever the motion, the two exponents of this map add up to `-delta T`: the
# field contracts areas at the constant rate `delta` (its divergence is `-delta`), a
# check of the computation that holds to the integrator's error (about 1e-5 here).

# %%
ueda = jg.DuffingParams(delta=0.05, alpha=0.0, beta=1.0, gamma=7.5, omega=1.0)
spec = lyapunov_spectrum(jg.DUFFING, ueda, jnp.array([2.5, 0.0]),
                         options=jg.LyapunovOptions(periods=2000 if FULL else 400, transient=200 if FULL else 50))
lam = np.asarray(spec.exponents)
print("exponents per period:", lam, "+-", np.asarray(spec.errors))
print("type:", classify_attractor(spec).name, " Kaplan-Yorke dimension:", float(spec.kaplan_yorke))
assert lam[0] > 0.3 and classify_attractor(spec) == AttractorType.CHAOTIC
print(f"sum {lam.sum():.6f}, -delta T = {-0.05 * 2 * np.pi:.6f}")
assert abs(lam.sum() + 0.05 * 2 * np.pi) < 1e-4  # -delta T, to the error of RK4's 200 steps per period

# %% [markdown]
# ## 2. The gear model's chaotic attractor at b = 2
#
# The paper preset has half backlash `b_sp = b_rp = 5` (P-4 and P-8). At `b = 2` every
# cell of region D ends on one chaotic attractor: the lane pool recognises it by the
# boxes of a fine partition that its trajectories keep revisiting (Datseris and
# Wagemakers 2022), reports it with period 0 and a cloud of points, and the exponents
# say what it is.

# %%
b2 = jg.analyze_global(REDUCED, jg.paper_params(b_sp=2.0, b_rp=2.0), grid, progress=False, uncertainty=0)
print(b2.table())
chaotic = [a for a in b2.attractors if a.type == AttractorType.CHAOTIC]
assert chaotic and chaotic[0].period == 0 and chaotic[0].largest_exponent > 0.1
print(f"lambda_1 = {chaotic[0].largest_exponent:+.3f} per period, Kaplan-Yorke dimension "
      f"{chaotic[0].kaplan_yorke:.2f}, {len(chaotic[0].points)} points of the cloud")

# %%
display(plotting.plot_attractors(b2, coords=(0, 2), section=False))

# %% [markdown]
# ## 3. A backlash sweep through the chaotic band
#
# One analysis per value of `b = b_sp = b_rp`; the share of region D attracted to each
# type of attractor and the largest exponent of every attractor. Inside the band the
# attractors are chaotic (some values keep a small periodic basin beside the chaotic
# one); above it the paper's P-4 returns.

# %%
results = [b2 if v == 2.0 else jg.analyze_global(REDUCED, jg.paper_params(b_sp=v, b_rp=v), grid, progress=False,
                                                 uncertainty=0) for v in backlash]
for v, r in zip(backlash, results):
    print(f"b = {v:.3f}: " + ", ".join(f"{a.label} {100 * a.share:.0f} % ({a.largest_exponent:+.3f})"
                                       for a in r.attractors))
types = [{a.type for a in r.attractors} for r in results]
assert any(AttractorType.CHAOTIC in t for t in types)
assert types[-1] == {AttractorType.PERIODIC}  # above the band: periodic again

# %%
kinds = [(AttractorType.PERIODIC, "periodic (P-k)", "tab:blue"), (AttractorType.CHAOTIC, "chaotic", "tab:red"),
         (AttractorType.QUASI_PERIODIC, "quasi-periodic", "tab:green")]
fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
below = np.zeros(len(backlash))
width = 0.8 * np.min(np.diff(backlash))
for kind, name, colour in kinds:
    share = np.array([sum(a.share for a in r.attractors if a.type == kind) for r in results])
    top.bar(backlash, 100 * share, width, bottom=100 * below, color=colour, label=name)
    below += share
    pts = [(v, a.largest_exponent) for v, r in zip(backlash, results) for a in r.attractors if a.type == kind]
    if pts:
        bottom.plot(*np.array(pts).T, "o", color=colour)
top.set_ylabel("share of region D (%)")
top.legend(fontsize=8)
bottom.axhline(0.0, color="k", lw=0.8)
bottom.set_ylabel("largest exponent / period")
bottom.set_xlabel("half backlash b")
plt.show()

# %% [markdown]
# ## 4. How fractal is a basin boundary?
#
# Basin entropy (Daza et al. 2016): cover the grid of labels with boxes of `n^3` cells
# and average the Shannon entropy of the labels in each box; over the boxes that hold
# more than one outcome it is the boundary basin entropy `S_bb`, and `S_bb > ln 2` proves
# a fractal boundary. Here the value of the sweep with the most coexisting outcomes
# (its labels: attractor ids, the sink and unresolved cells are outcomes too).

# %%
mixed = max(results, key=lambda r: len(np.unique(np.asarray(r.labels))))
labels = np.asarray(mixed.labels).reshape(mixed.grid.counts)
ent = basin_entropy(labels, box=5 if FULL else 2)
n_out = len(np.unique(labels))
print(f"{n_out} outcomes; S_b = {ent.S_b:.3f}, S_bb = {ent.S_bb:.3f} (ln 2 = {np.log(2):.3f}): "
      f"{'fractal' if ent.fractal else 'not proved fractal'}")
assert 0.0 <= ent.S_b <= np.log(n_out) + 1e-12  # an entropy of n outcomes is at most ln n
if ent.n_boundary_boxes:
    assert ent.S_b <= ent.S_bb + 1e-12 <= np.log(n_out) + 2e-12
