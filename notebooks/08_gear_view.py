# ---
# jupyter:
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # The gear engineer's view: contact regimes, transmission error, mesh forces, spectra
#
# The global analysis says which motions coexist and how much of the state space each
# attracts. This notebook asks what each motion does to the teeth (docs: Methods, The gear
# view of an attractor):
#
# 1. the paper preset's two attractors (P-4 and P-8) mesh by mesh, in micrometres and
#    newtons: contact regime, dynamic transmission error, dynamic factor;
# 2. one figure per attractor: the transmission error with the gap and back-flank contact
#    shaded, and its spectrum in orders of the mesh frequency and in Hz;
# 3. a sweep of the half backlash in micrometres: the share of the state space whose motion keeps
#    contact, rattles (single-sided impacts) or hits the back flanks.
#
# `FULL = False` runs a tiny grid and three backlash values (about a minute on two idle
# cores); `FULL = True` the paper's grid and nine values (much longer on a CPU).

# %%
FULL = False

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import display

import jaxgear as jg
from jaxgear import REDUCED, ContactRegime, plotting

jg.enable_compilation_cache()  # a restarted kernel loads the compiled programs instead of compiling them again

grid = jg.CellGrid.paper((50, 30, 60) if FULL else (5, 3, 6))
backlash_um = np.linspace(20.0, 60.0, 9) if FULL else np.array([20.0, 35.0, 50.0])

# %% [markdown]
# ## 1. The paper preset's attractors, mesh by mesh
#
# `resolve_params("paper")` gives the physical gear set and its dimensionless parameters.
# `gear_views` samples every attractor of the result in one batch and locates every
# change of contact; with the gear set the transmission error is in micrometres, the mesh
# force in newtons and the frequencies in hertz.

# %%
gear_set, params = jg.resolve_params("paper")
result = jg.analyze_global(REDUCED, params, grid, progress=False, uncertainty=0)
print(result.table())
views = jg.gear_views(REDUCED, params, result.attractors, gear_set)
for view in views:
    print(view.table(), "\n")
labels = sorted(a.label for a in result.attractors)
assert labels == ["P-4", "P-8"], labels
for view in views:
    sun, ring = view.mesh("sun-planet"), view.mesh("ring-planet")
    # the shares of time add to one; the sun-planet mesh keeps contact, the ring-planet mesh rattles
    for m in view.meshes:
        assert abs(m.drive_share + m.gap_share + m.back_share - 1) < 1e-12
    assert sun.regime == ContactRegime.NO_IMPACT and ring.regime == ContactRegime.SINGLE_SIDED
    assert ring.losses_per_period > 0 and ring.dynamic_factor > sun.dynamic_factor > 1

# %% [markdown]
# ## 2. One figure per attractor
#
# Left: the dynamic transmission error of each mesh over the attractor's k periods, the
# backlash `+-b` dashed, the time in the gap shaded (light) and on the back flank (dark).
# Right: its amplitude spectrum. A P-k has energy only at multiples of `1/k` of the mesh
# frequency (the sub-harmonics that a P-4 and a P-8 add to the mesh frequency's
# harmonics).

# %%
for view in views:
    fig = plotting.plot_gear_view(view, REDUCED, params)
    display(fig)
    plt.close(fig)
    ring = view.mesh("ring-planet")
    k = view.period
    off = np.abs(ring.orders * k - np.round(ring.orders * k)) > 1e-9
    assert not off.any()  # the orders are j / k
    dominant = ring.orders[np.argmax(ring.amplitudes[1:]) + 1]
    print(f"attractor {view.attractor_id} ({view.label}): ring-planet TE strongest at order {dominant:.4g} "
          f"= {dominant * view.mesh_frequency_hz:.0f} Hz")

# %% [markdown]
# ## 3. Backlash in micrometres: where the teeth start to hit the back flanks
#
# The paper preset has a half backlash of 50 um on both meshes (`b = 5` in units
# of `b_c` = 10 um). With `gear_set=`, a basin sweep takes the backlash in micrometres
# (`"b"`: both meshes' half backlash, a field of the gear set); each value goes through
# `gear_set.replace(...).to_params()` to the dimensionless `b_sp`, `b_rp` it means
# (`sweep.field_values`). The sweep analyses the grid at each value, and `regime_shares`
# takes the gear view of every attractor found: the share of the state space in each
# contact regime is the sum of the shares of the attractors in that regime.

# %%
sweep = jg.basin_sweep(REDUCED, params, "b", backlash_um, grid, gear_set=gear_set, uncertainty=0,
                       runner=jg.Runner(progress=False))
regimes = jg.regime_shares(sweep, REDUCED, params, gear_set)
ring = regimes.meshes.index("ring-planet")
for um, b, row, rest in zip(sweep.values, sweep.field_values[:, 0], regimes.shares[:, ring], regimes.no_attractor):
    print(f"{um:5.1f} um (b = {b:g}): " + ", ".join(f"{r.text} {100 * s:5.1f} %" for r, s in zip(ContactRegime, row))
          + f", on no attractor {100 * rest:.1f} %")
assert np.allclose(sweep.field_values[:, 0], backlash_um / gear_set.b_c)  # b_sp in units of b_c
assert np.allclose(regimes.shares.sum(axis=2) + regimes.no_attractor[:, None], 1.0)  # every cell counted once
assert regimes.shares[0, ring, ContactRegime.DOUBLE_SIDED] > 0.5  # the chaotic motion at 20 um hits the back flanks
assert regimes.shares[-1, ring, ContactRegime.SINGLE_SIDED] > 0.5  # the paper's P-4 and P-8 rattle

fig = plotting.plot_regime_shares(regimes)  # its axis: the half backlash in um
display(fig)
plt.close(fig)
