# ---
# jupyter:
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Your own forced system, analysed like the gear set
#
# Every analysis in jaxgear takes a `ForcedSystem`: a vector field `f(t, x, params)`
# written in JAX, its forcing period, the state names and a parameter pytree. The
# planetary gear models are two such systems. Here a forced Duffing oscillator written from
# scratch in a few lines, then the classic single spur-gear pair with backlash, both
# analysed with exactly the calls used for the gear set: `analyze_global`,
# `find_periodic_orbits`, `plot_domains`, `plot_orbit`.
#
# `FULL = False` runs small grids (well under a minute); `FULL = True` finer ones.

# %%
FULL = False

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from IPython.display import display

import jaxgear as jg
from jaxgear import plotting

jg.enable_compilation_cache()  # a restarted kernel loads the compiled programs instead of compiling them again

n = 60 if FULL else 20  # cells per axis


# %% [markdown]
# ## 1. A system in ten lines
#
# `x'' + delta x' + x + beta x^3 = gamma cos(omega t)`, state `(x, v)`. Parameters can be
# any pytree: a NamedTuple, an `equinox.Module`, a dict.

# %%
class Duffing(NamedTuple):
    delta: float
    beta: float
    gamma: float
    omega: float


def duffing(t, x, p):
    return jnp.stack([x[1], p.gamma * jnp.cos(p.omega * t) - p.delta * x[1] - x[0] - p.beta * x[0] ** 3])


system = jg.ForcedSystem(vector_field=duffing, period=lambda p: 2 * jnp.pi / p.omega,
                         state_names=("x", "v"), section_index=1, name="duffing")
p = Duffing(delta=0.1, beta=1.0, gamma=0.3, omega=1.4)  # hardening, inside the hysteresis range

# %% [markdown]
# Mistakes are caught before any integration, with a message that says what is wrong:

# %%
broken = jg.ForcedSystem(lambda t, x, p: jnp.stack([x[1], -x[0], 0.0]), lambda p: 2 * jnp.pi, ("x", "v"))
try:
    jg.periodic_orbit(broken, p, jnp.zeros(2))
except ValueError as e:
    print("ValueError:", e)

# %% [markdown]
# ## 2. Global analysis: every attractor and its domain
#
# The same call as for the gear set, with a grid over the state plane. `direct`
# integrates every cell centre until its attractor is recognised; `stroboscopic` is Hsu's
# cell map of the exact Poincaré map.

# %%
grid = jg.CellGrid.box([(-2.5, 2.5), (-2.5, 2.5)], (n, n), names=system.state_names)
direct = jg.analyze_global(system, p, grid, method=jg.Direct(), progress=False)
strobe = jg.analyze_global(system, p, grid, method=jg.StroboscopicCellMap(mapping_steps=10), progress=False)
print(direct.table())
for r in (direct, strobe):
    print(f"{r.method.name:>12}: " + ", ".join(f"{a.label} at x = {a.points[0][0]:+.3f}: {100 * a.share:.1f} %"
                                          for a in r.attractors))
assert sorted(a.period for a in direct.attractors) == [1, 1]
assert max(abs(a.share - b.share) for a, b in zip(direct.attractors, strobe.attractors)) < 0.03

# %%
plotting.plot_domains(direct)

# %% [markdown]
# ## 3. Shooting and Floquet multipliers
#
# Seeded from the global result, Newton confirms both attractors as stable P-1 orbits;
# seeded from a box it also finds the saddle (a fold-type multiplier > 1) that separates
# their domains.

# %%
confirmed = jg.find_periodic_orbits(system, p, jg.seeds_from_result(direct))
everything = jg.find_periodic_orbits(system, p, jg.seeds_in_box(40, [-2, -2], [2, 2], seed=1))
for o in everything.orbits:
    print(f"P-{o.period} {o.instability:>6}: x = {o.points[0][0]:+.4f}, v = {o.points[0][1]:+.4f}, "
          f"max |multiplier| {o.max_multiplier:.3f}")
assert len(confirmed.orbits) == 2 and all(o.stable for o in confirmed.orbits)
assert len(everything.orbits) == 3 and sum(not o.stable for o in everything.orbits) == 1

# %%
for o in everything.orbits:
    display(plotting.plot_orbit(system, p, o, title=f"P-{o.period} ({o.instability})"))

# %% [markdown]
# **Small forcing.** With `gamma -> 0` the response is that of the linear oscillator,
# `x = Re(gamma H e^{i omega t})`, `H = 1 / (1 - omega^2 + i delta omega)`:

# %%
small = p._replace(gamma=1e-3)
orbit = jg.periodic_orbit(system, small, jnp.zeros(2))
H = 1.0 / (1.0 - p.omega**2 + 1j * p.delta * p.omega)
linear = np.array([small.gamma * H.real, (1j * p.omega * small.gamma * H).real])
print("shooting:", np.asarray(orbit.point), " linear theory:", linear)
assert np.allclose(np.asarray(orbit.point), linear, rtol=2e-5)

# %% [markdown]
# ## 4. The single spur-gear pair with backlash
#
# The classic one-degree-of-freedom gear model (Kahraman & Singh):
# `x'' + 2 zeta x' + (1 + kappa sin(Omega t)) f(x, b) = f_m + e Omega^2 sin(Omega t)`, with
# `f` the backlash function. It ships as `jaxgear.SPUR_PAIR`, but it is a plain
# `ForcedSystem` too. With light damping a contact orbit and an orbit with back-side
# impacts coexist:

# %%
sp = jg.SpurPairParams(zeta=0.02, kappa=0.2, b=1.0, f_m=0.1, e_amp=0.2, Omega=0.7)
grid_sp = jg.CellGrid.box([(-4, 4), (-4, 4)], (n, n), names=jg.SPUR_PAIR.state_names)
spur = jg.analyze_global(jg.SPUR_PAIR, sp, grid_sp, method=jg.Direct(), progress=False)
print(spur.table())
spur_orbits = jg.find_periodic_orbits(jg.SPUR_PAIR, sp, jg.seeds_from_result(spur))
for o in spur_orbits.orbits:
    print(f"P-{o.period} {o.instability}: point {np.round(o.points[0], 4)}, max |multiplier| {o.max_multiplier:.4f}")
assert len(spur.attractors) == 2 and all(o.stable for o in spur_orbits.orbits) and len(spur_orbits.orbits) == 2

# %%
plotting.plot_domains(spur)

# %%
for o in spur_orbits.orbits:
    fig = plotting.plot_orbit(jg.SPUR_PAIR, sp, o, title=f"spur pair, P-{o.period}")
    ax = fig.axes[0]
    for xb in (-sp.b, sp.b):
        ax.axvline(xb, color="k", lw=0.6, ls=":")  # contact boundaries |x| = b
    display(fig)

# %% [markdown]
# ## 5. Differentiable response of your own system
#
# The orbit is differentiable in the parameters of any system: here the RMS dynamic
# transmission error of the contact orbit and its derivative with respect to the damping
# ratio, checked by a finite difference of re-converged orbits.

# %%
contact = max(spur_orbits.orbits, key=lambda o: o.points[0][0]).points[0]


def dte_rms(zeta):
    q = jg.replace_params(sp, zeta=zeta)
    r = jg.periodic_orbit(jg.SPUR_PAIR, q, contact)
    return jg.rms(jg.sample_orbit(jg.SPUR_PAIR, q, r.point).states[:, 0])


g = float(jax.grad(dte_rms)(0.02))
fd = (float(dte_rms(0.02 + 1e-6)) - float(dte_rms(0.02 - 1e-6))) / 2e-6
print(f"RMS DTE {float(dte_rms(0.02)):.4f}, d/dzeta = {g:.5f} (finite difference {fd:.5f})")
assert abs(g - fd) < 1e-5 * abs(fd)
