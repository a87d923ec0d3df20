"""Any periodically forced system goes through every analysis with the same calls as the
gear model: global analysis (direct, stroboscopic, poincare-like), shooting/Floquet,
plots, saved results; bad user systems fail with clear errors.

References that do not come from this code: the linear closed form of the forced
oscillator (small-forcing limit of Duffing), Floquet/Liouville (det M = exp(-delta T)),
agreement between independent methods (cell map vs direct integration vs Newton).
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import sample_orbit

# Hardening Duffing inside its resonance hysteresis range: two stable P-1 orbits (small
# and large amplitude) and a saddle between them (harmonic balance: 0.34, 0.95, 1.24).
BISTABLE = dict(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)
RK = jg.RK4(100)  # the Duffing field is smooth: RK4 at 100 steps is accurate to ~1e-7


class MyDuffing(NamedTuple):
    """Parameters of a Duffing oscillator written from scratch (a NamedTuple pytree)."""

    delta: float
    beta: float
    gamma: float
    omega: float


def my_field(t, x, p):
    return jnp.stack([x[1], p.gamma * jnp.cos(p.omega * t) - p.delta * x[1] - x[0] - p.beta * x[0] ** 3])


MY_DUFFING = jg.ForcedSystem(vector_field=my_field, period=lambda p: 2 * jnp.pi / p.omega,
                             state_names=("x", "v"), section_index=1, name="my-duffing")


def _confirm_by_shooting(system, params, result, integrator, atol):
    """Every attractor of a global result is a stable periodic orbit found by Newton from its points."""
    search = jg.find_periodic_orbits(system, params, jg.seeds_from_result(result), integrator=integrator)
    for a in result.attractors:
        assert a.period >= 1, a
        match = [o for o in search.orbits if o.period == a.period
                 and np.min(np.linalg.norm(o.points - a.points[0], axis=1)) <= atol]
        assert len(match) == 1, (a.label, a.points[0], [(o.period, o.points[0]) for o in search.orbits])
        o = match[0]
        assert o.stable and o.max_multiplier < 1.0 and o.residual <= 1e-10
    return search


# --------------------------------------------------------------------------- Duffing, multistable
@pytest.mark.slow
def test_duffing_multistable_all_methods_confirmed_by_shooting():
    p = MyDuffing(delta=0.1, beta=1.0, gamma=0.3, omega=1.4)
    grid = jg.CellGrid.box([(-2.5, 2.5), (-2.5, 2.5)], (20, 20), names=MY_DUFFING.state_names)
    direct = jg.analyze_global(MY_DUFFING, p, grid, method=jg.Direct(integrator=RK), progress=False, uncertainty=0)
    strobe = jg.analyze_global(MY_DUFFING, p, grid, method=jg.StroboscopicCellMap(mapping_steps=10, integrator=RK), progress=False, uncertainty=0)
    for r in (direct, strobe):
        assert sorted(a.period for a in r.attractors) == [1, 1], r.table()
        assert r.n_unresolved == 0 and r.n_sink == 0
        _confirm_by_shooting(MY_DUFFING, p, r, RK, atol=1e-6)
    # shooting also finds the saddle between the two attractors: it is no attractor
    assert any(not o.stable and o.instability == "fold" for o in
               jg.find_periodic_orbits(MY_DUFFING, p, jg.seeds_in_box(30, [-2, -2], [2, 2], seed=3),
                                       integrator=RK).orbits)
    # shares: the stroboscopic cell map agrees with direct integration within 2 percentage points
    key = lambda r: {round(float(a.points[0][0]), 3): a.share for a in r.attractors}
    d, s = key(direct), key(strobe)
    assert d.keys() == s.keys()
    assert max(abs(d[x] - s[x]) for x in d) <= 0.02, (d, s)
    # the large-amplitude orbit attracts most of this box (harmonic balance amplitude ~1.24 vs 0.34)
    big = max(d, key=lambda x: abs(x))
    assert d[big] > 0.5
    # the paper's poincare-like map on the section {v = 0} (a 1-D grid over x at phase 0),
    # against direct integration of the same cell centres: within 7 percentage points (the
    # section map restarts each crossing at phase 0, an approximation: docs/model.md §6)
    line = jg.CellGrid.box([(-2.5, 2.5)], (40,), axes=(0,), base=(0.0, 0.0), names=("x", "v"))
    pl = jg.analyze_global(MY_DUFFING, p, line, method=jg.PoincareCellMap(mapping_steps=10, integrator=RK), progress=False, uncertainty=0)
    dl = jg.analyze_global(MY_DUFFING, p, line, method=jg.Direct(integrator=RK), progress=False, uncertainty=0)
    _confirm_by_shooting(MY_DUFFING, p, pl, RK, atol=1e-6)
    a, b = key(pl), key(dl)
    assert a.keys() == b.keys() == d.keys()
    assert max(abs(a[x] - b[x]) for x in a) <= 0.07, (a, b)
    # the NamedTuple parameters are written out by name and the result reloads exactly
    assert direct.params == {"delta": 0.1, "beta": 1.0, "gamma": 0.3, "omega": 1.4}
    assert direct.system == "my-duffing" and direct.state_names == ("x", "v")


def test_duffing_small_forcing_matches_linear_closed_form():
    # x'' + d x' + x + b x^3 = g cos(w t) with g -> 0: x = Re(g H e^{iwt}), H = 1/(1 - w^2 + i d w);
    # the cubic term changes the amplitude by O(b A^2) ~ 1e-6 relative at A ~ 1e-3
    d, w, g = 0.1, 1.4, 1e-3
    p = MyDuffing(delta=d, beta=1.0, gamma=g, omega=w)
    grid = jg.CellGrid.box([(-1.0, 1.0), (-1.0, 1.0)], (6, 6))
    r = jg.analyze_global(MY_DUFFING, p, grid, method=jg.Direct(integrator=RK), progress=False, uncertainty=0)
    assert len(r.attractors) == 1 and r.attractors[0].period == 1  # no more bistability
    shot = jg.periodic_orbit(MY_DUFFING, p, r.attractors[0].points[0])
    H = 1.0 / (1.0 - w * w + 1j * d * w)
    orbit = sample_orbit(MY_DUFFING, p, shot.point, samples_per_period=256)
    x = np.asarray(orbit.states[:, 0])
    c1 = 2.0 * np.mean(x * np.exp(-1j * w * np.asarray(orbit.times)))  # first harmonic: x ~ Re(c1 e^{iwt})
    assert abs(abs(c1) - g * abs(H)) <= 1e-5 * g * abs(H)
    assert abs(np.angle(c1) - np.angle(H)) <= 1e-5
    np.testing.assert_allclose(np.asarray(shot.point), [g * H.real, (1j * w * g * H).real], rtol=2e-5)
    # Liouville: det of the monodromy = exp(-delta T) (trace of the Jacobian is -delta)
    lam = np.asarray(shot.multipliers)
    assert abs(np.prod(lam).real - np.exp(-d * 2 * np.pi / w)) <= 1e-8


# --------------------------------------------------------------------------- spur pair with backlash
def test_spur_pair_with_backlash_end_to_end():
    # single-DOF spur pair with backlash and mesh-stiffness variation (Kahraman & Singh type),
    # light damping: a contact orbit and a double-sided impact orbit coexist. No gear code.
    p = jg.SpurPairParams(zeta=0.02, kappa=0.2, b=1.0, f_m=0.1, e_amp=0.2, Omega=0.7)
    grid = jg.CellGrid.box([(-4, 4), (-4, 4)], (16, 16), names=jg.SPUR_PAIR.state_names)
    direct = jg.analyze_global(jg.SPUR_PAIR, p, grid, method=jg.Direct(), progress=False, uncertainty=0)
    strobe = jg.analyze_global(jg.SPUR_PAIR, p, grid, method=jg.StroboscopicCellMap(mapping_steps=20), progress=False, uncertainty=0)
    for r in (direct, strobe):
        # both attractors are P-1 (the direct method once reported the slowly spiralling
        # contact orbit as P-3; the period is now read from its refined points)
        assert sorted(a.period for a in r.attractors) == [1, 1], r.table()
        search = _confirm_by_shooting(jg.SPUR_PAIR, p, r, jg.RK4(), atol=1e-6)
        # Liouville: |lambda|^2 = det M = exp(-2 zeta T) for the complex pair of each orbit
        for o in search.orbits:
            assert abs(o.max_multiplier - np.exp(-0.02 * 2 * np.pi / 0.7)) <= 1e-6  # RK4, 200 steps/period
    xs = sorted(float(a.points[0][0]) for a in direct.attractors)
    assert xs[0] < -1.0 < xs[1]  # one orbit reaches back-side contact (x < -b) at phase 0
    d = {round(float(a.points[0][0]), 3): a.share for a in direct.attractors}
    s = {round(float(a.points[0][0]), 3): a.share for a in strobe.attractors}
    assert d.keys() == s.keys() and max(abs(d[x] - s[x]) for x in d) <= 0.03, (d, s)


@pytest.mark.slow
def test_three_dimensional_user_system():
    # a Duffing oscillator driving a first-order filter z' = -a z + x (dimension 3, section on v)
    class P3(NamedTuple):
        gamma: float
        a: float

    def f(t, x, p):
        return jnp.stack([x[1], p.gamma * jnp.cos(1.4 * t) - 0.1 * x[1] - x[0] - x[0] ** 3, -p.a * x[2] + x[0]])

    sys3 = jg.ForcedSystem(f, lambda p: 2 * jnp.pi / 1.4, ("x", "v", "z"), section_index=1, name="duffing+filter")
    p = P3(gamma=0.3, a=2.0)
    grid = jg.CellGrid.box([(-2, 2), (-2, 2), (-1, 1)], (6, 6, 3), names=sys3.state_names)
    r = jg.analyze_global(sys3, p, grid, method=jg.Direct(integrator=RK), progress=False, uncertainty=0)
    assert sorted(a.period for a in r.attractors) == [1, 1] and r.n_sink == 0
    search = _confirm_by_shooting(sys3, p, r, RK, atol=1e-6)
    # the filter only follows x: its multiplier is exp(-a T), the other two those of the Duffing part
    for o in search.orbits:
        assert np.min(np.abs(np.abs(o.multipliers) - np.exp(-2.0 * 2 * np.pi / 1.4))) <= 1e-7
    # the poincare-like method: grid over x, z on {v = 0}
    sec = jg.CellGrid.box([(-2, 2), (-1, 1)], (8, 4), axes=(0, 2), base=(0.0, 0.0, 0.0), names=sys3.state_names)
    rp = jg.analyze_global(sys3, p, sec, method=jg.PoincareCellMap(mapping_steps=10, integrator=RK), progress=False, uncertainty=0)
    assert sorted(a.period for a in rp.attractors) == [1, 1]
    assert all(len(a.section_points) and np.all(np.abs(a.section_points[:, 1]) < 1e-10) for a in rp.attractors)
    # the paper's check by direct integration keeps both stable orbits; figures of a 3-D grid
    for o in search.orbits:
        assert jg.verify_orbit(sys3, p, o, periods=60, integrator=RK).kept
    from jaxgear import plotting

    assert plotting.plot_domains_3d(r).axes[0].get_zlabel() == "z"
    fig = plotting.plot_domains(r, axis="z", values=[-0.6, 0.6])
    assert [a.get_title() for a in fig.axes[:2]] == ["z = -0.667", "z = 0.667"]


# --------------------------------------------------------------------------- plots and saved results
def test_plots_and_saved_result_of_a_user_system(tmp_path):
    from jaxgear import plotting

    p = MyDuffing(delta=0.1, beta=1.0, gamma=0.3, omega=1.4)
    grid = jg.CellGrid.box([(-2.5, 2.5), (-2.5, 2.5)], (8, 8), names=MY_DUFFING.state_names)
    r = jg.analyze_global(MY_DUFFING, p, grid, method=jg.Direct(integrator=RK), progress=False, uncertainty=0)
    assert len(r.attractors) == 2
    # the domains: one image of the 8 x 8 cells (x across), one colour per attractor's domain
    ax = plotting.plot_domains(r).axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x", "v") and len(ax.images) == 1
    image = np.asarray(ax.images[0].get_array())
    labels = np.asarray(r.labels).reshape(8, 8).T
    colours = [set(image[labels == a.id].tolist()) for a in r.attractors]
    assert all(len(c) == 1 for c in colours) and colours[0] != colours[1]
    # the attractors: each one's section points, named in the legend
    ax = plotting.plot_attractors(r, coords=(0, 1)).axes[0]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [f"{a.id}: {a.label}" for a in r.attractors]
    for c, a in zip(ax.collections, r.attractors):
        np.testing.assert_array_equal(c.get_offsets(), a.section_points)
    # the shares: a bar per attractor (and the sink) of its share in percent
    ax = plotting.plot_shares(r).axes[0]
    heights = [b.get_height() for b in ax.patches]
    np.testing.assert_allclose(heights[:2], [100 * a.share for a in r.attractors], rtol=1e-12)
    assert sum(heights) == pytest.approx(100.0) and "%" in ax.get_ylabel()
    # the orbit: one period sampled 40 times, closing on the attractor's point
    a = r.attractors[0]
    ax = plotting.plot_orbit(MY_DUFFING, p, a, samples_per_period=40).axes[0]
    line = ax.get_lines()[0]
    xy = np.stack([line.get_xdata(), line.get_ydata()], -1)
    assert xy.shape == (41, 2)
    np.testing.assert_allclose(xy[0], a.points[0], atol=1e-12)
    np.testing.assert_allclose(xy[-1], a.points[0], atol=1e-5)  # P-1: back after one period
    np.testing.assert_array_equal(ax.collections[0].get_offsets(), a.points)
    path = r.save(tmp_path / "duffing.nc")
    back = jg.load(path)
    assert back.params == r.params and back.system == "my-duffing" and back.state_names == ("x", "v")
    np.testing.assert_array_equal(back.labels, r.labels)
    with pytest.raises(ValueError, match="parameters"):
        jg.compare_with_direct(r, MY_DUFFING)


# --------------------------------------------------------------------------- bad user systems
def _bad(field=None, period=None, dim=2):
    good = lambda t, x, p: jnp.stack([x[1], -x[0] + jnp.cos(t)])
    return jg.ForcedSystem(field or good, period or (lambda p: 2 * jnp.pi), tuple(f"q{i}" for i in range(dim)),
                           name="bad")


BAD_CASES = [
    ("wrong shape", _bad(field=lambda t, x, p: jnp.stack([x[1], -x[0], 0.0])), "shape \\(2,\\)"),
    ("tuple output", _bad(field=lambda t, x, p: (x[1], -x[0])), "one array"),
    ("NaN at x0", _bad(field=lambda t, x, p: jnp.stack([x[1], -x[0] / p.beta])), "not finite"),  # beta = 0
    ("field raises", _bad(field=lambda t, x, p: jnp.stack([x[1], -p.missing * x[0]])), "failed"),
    ("period zero", _bad(period=lambda p: 0.0), "positive"),
    ("period negative", _bad(period=lambda p: -1.0), "positive"),
    ("period NaN", _bad(period=lambda p: jnp.nan), "positive"),
    ("period not scalar", _bad(period=lambda p: jnp.array([1.0, 2.0])), "scalar"),
]


@pytest.mark.parametrize("what, system, match", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_user_systems_fail_clearly(what, system, match):
    from jaxgear import design

    p = MyDuffing(0.1, 0.0, 1.0, 1.0)
    x0 = np.zeros(2)
    grid = jg.CellGrid.box([(-1, 1), (-1, 1)], (2, 2))
    calls = [
        lambda: jg.analyze_global(system, p, grid, method=jg.Direct(), progress=False, uncertainty=0),
        lambda: jg.analyze_global(system, p, grid, method=jg.StroboscopicCellMap(), progress=False, uncertainty=0),
        lambda: jg.periodic_orbit(system, p, x0),
        lambda: jg.find_periodic_orbits(system, p, x0[None]),
        lambda: design(system, p, x0, lambda q, o: jnp.sum(o.states ** 2), free={"delta": (0.0, 1.0)},
                       steps=1, progress=False),
    ]
    for call in calls:
        with pytest.raises(ValueError, match=match):
            call()


def test_a_system_declared_with_lists_is_the_same_system():
    """State names given as a list name the same system as the tuple (equal, hashable: a
    system is a compile-time key of every kernel), and it analyses the same."""
    listed = jg.ForcedSystem(vector_field=my_field, period=lambda p: 2 * jnp.pi / p.omega,
                             state_names=["x", "v"], section_index=1, name="my-duffing")
    assert listed.state_names == ("x", "v") and hash(listed) is not None
    p = MyDuffing(delta=0.1, beta=1.0, gamma=0.3, omega=1.4)
    grid = jg.CellGrid.box([(-2.5, 2.5), (-2.5, 2.5)], (4, 4), names=listed.state_names)
    a, b = (jg.analyze_global(s, p, grid, method=jg.Direct(integrator=RK), progress=False, uncertainty=0)
            for s in (listed, MY_DUFFING))
    np.testing.assert_array_equal(a.labels, b.labels)


def test_gear_defaults_are_not_applied_to_user_systems():
    p = MyDuffing(0.1, 1.0, 0.3, 1.4)
    with pytest.raises(ValueError, match="parameters"):
        jg.analyze_global(MY_DUFFING, None, jg.CellGrid.box([(-1, 1), (-1, 1)], (2, 2)))
    with pytest.raises(ValueError, match="CellGrid"):
        jg.analyze_global(MY_DUFFING, p)
    with pytest.raises(ValueError, match="coordinates"):
        jg.analyze_global(MY_DUFFING, p, jg.CellGrid.paper(counts=(2, 2, 2)))
    with pytest.raises(ValueError, match="section"):
        nosec = jg.ForcedSystem(my_field, lambda q: 2 * jnp.pi / q.omega, ("x", "v"))
        jg.analyze_global(nosec, p, jg.CellGrid.box([(-1, 1)], (4,), axes=(0,), base=(0.0, 0.0)),
                          method=jg.PoincareCellMap())
    # batched parameters (a sweep) may have a batched period; one set may not
    jg.check_system(MY_DUFFING, MyDuffing(0.1, 1.0, 0.3, jnp.array([1.0, 1.4])), batched=True)
    with pytest.raises(ValueError, match="scalar"):
        jg.check_system(MY_DUFFING, MyDuffing(0.1, 1.0, 0.3, jnp.array([1.0, 1.4])), batched=False)
