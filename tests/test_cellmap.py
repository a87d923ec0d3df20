"""Cell mapping (paper §3-§4): graph analysis, methods, invariants, period detection."""

import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import CellGrid, ForcedSystem

# ---------------------------------------------------------------- test systems


class BistableParams(eqx.Module):
    a: jnp.ndarray = eqx.field(converter=lambda v: jnp.asarray(v, jnp.float64), default=1.0)


# x' = a x - x^3: attractors x = +-sqrt(a), separatrix exactly x = 0 (any period works)
BISTABLE_1D = ForcedSystem(vector_field=lambda t, x, p: p.a * x - x**3, period=lambda p: 1.0 + 0 * p.a,
                           state_names=("x",), name="bistable-1d")

LINEAR = jg.DuffingParams(delta=0.4, alpha=1.0, beta=0.0, gamma=0.5, omega=0.8)
DOUBLE_WELL = jg.DuffingParams(delta=0.5, alpha=-1.0, beta=1.0, gamma=0.0, omega=1.0)
PERIOD_TWO = jg.DuffingParams(delta=0.3, alpha=-1.0, beta=1.0, gamma=0.28, omega=1.2)


def linear_response(p, t=0.0):
    """Closed-form steady state of x'' + delta x' + alpha x = gamma cos(omega t)."""
    g, a, w, d = (float(v) for v in (p.gamma, p.alpha, p.omega, p.delta))
    z = g / (a - w**2 + 1j * d * w) * np.exp(1j * w * t)
    return np.array([z.real, (1j * w * z).real])


# ---------------------------------------------------------------- graph analysis


def test_cell_map_graph_on_hand_built_map():
    # 0->1->2->0 (3-cycle), 3->3 (fixed), 4->0, 5->4, 6->sink(7), 7 is the sink index
    images = np.array([1, 2, 0, 3, 0, 4, 7])
    cm = jg.analyze_cell_map(images, 7)
    assert list(cm["groups"]) == [0, 3]
    assert list(cm["cycle_length"]) == [3, 1]
    assert list(cm["periodic"]) == [True, True, True, True, False, False, False]
    assert list(cm["group"]) == [0, 0, 0, 3, 0, 0, 7]


def test_cell_map_graph_random_maps_agree_with_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(20):
        n = int(rng.integers(1, 60))
        images = rng.integers(0, n + 1, size=n)
        cm = jg.analyze_cell_map(images, n)
        f = np.append(images, n)
        for i in range(n):
            seen, x = [], i
            while x not in seen:
                seen.append(x)
                x = f[x]
            cycle = seen[seen.index(x):]
            assert cm["group"][i] == min(cycle)
            assert cm["periodic"][i] == (i in cycle)


def test_cell_map_rejects_bad_images():
    with pytest.raises(ValueError, match=r"images .* values in 0\.\.2"):
        jg.analyze_cell_map(np.array([0, 5]), 2)


# ---------------------------------------------------------------- one attractor


@pytest.mark.parametrize("method", ["stroboscopic", "direct"])
def test_forced_linear_oscillator_one_p1_at_closed_form(method):
    grid = CellGrid.box([(-3, 3), (-3, 3)], (12, 12), names=("x", "v"))
    opts = dict(mapping_steps=3, settle_periods=150) if method != "direct" else {}
    r = jg.analyze_global(jg.DUFFING, LINEAR, grid, jg.analysis.method_from_name(method, integrator=jg.RK4(200), **opts),
                          progress=False, uncertainty=0)
    assert len(r.attractors) == 1
    a = r.attractors[0]
    assert a.period == 1
    np.testing.assert_allclose(a.points[0], linear_response(LINEAR), atol=1e-7)
    # domain = every cell not sent to the sink
    assert a.cell_count + r.n_sink + r.n_unresolved == r.n_cells
    assert np.all((r.labels == 0) | (r.labels == jg.SINK))


def test_poincare_like_on_linear_oscillator():
    # grid over x on the section v = 0; the single attractor is P-1 at the closed form
    grid = CellGrid.box([(-3, 3)], (30,), axes=(0,), base=(0.0, 0.0), names=("x", "v"))
    r = jg.analyze_global(jg.DUFFING, LINEAR, grid, method=jg.PoincareCellMap(mapping_steps=20, direction=-1, settle_periods=150), progress=False, uncertainty=0)
    assert [a.period for a in r.attractors] == [1]
    np.testing.assert_allclose(r.attractors[0].points[0], linear_response(LINEAR), atol=1e-7)
    sec = r.attractors[0].section_points
    assert len(sec) == 1 and abs(sec[0, 1]) < 1e-12  # one downward crossing of v = 0 per period
    # on the closed-form orbit, v = 0 with v decreasing where x is at its maximum |H|
    assert sec[0, 0] == pytest.approx(abs(complex(linear_response(LINEAR)[0], linear_response(LINEAR)[1]
                                                  / float(LINEAR.omega))), abs=1e-6)


# ---------------------------------------------------------------- two attractors


@pytest.mark.parametrize("method", ["stroboscopic", "direct"])
def test_bistable_1d_exact_separatrix(method):
    grid = CellGrid.box([(-2, 2)], (40,), names=("x",))
    p = BistableParams(a=1.0)
    opts = dict(mapping_steps=2, settle_periods=60) if method != "direct" else {}
    r = jg.analyze_global(BISTABLE_1D, p, grid, jg.analysis.method_from_name(method, **opts), progress=False, uncertainty=0)
    assert sorted(a.period for a in r.attractors) == [1, 1]
    centres = grid.centres()[:, 0]
    pos = [a for a in r.attractors if a.points[0, 0] > 0][0]
    neg = [a for a in r.attractors if a.points[0, 0] < 0][0]
    np.testing.assert_allclose([pos.points[0, 0], neg.points[0, 0]], [1.0, -1.0], atol=1e-8)
    # the separatrix is x = 0: each cell belongs to the attractor on its side
    assert np.all(r.labels[centres > 0] == pos.id)
    assert np.all(r.labels[centres < 0] == neg.id)


def test_double_well_mirror_symmetric_basins():
    grid = CellGrid.box([(-2, 2), (-2, 2)], (16, 16), names=("x", "v"))
    r = jg.analyze_global(jg.DUFFING, DOUBLE_WELL, grid, method=jg.Direct(), progress=False, uncertainty=0)
    assert sorted(a.period for a in r.attractors) == [1, 1]
    np.testing.assert_allclose(sorted(a.points[0, 0] for a in r.attractors), [-1.0, 1.0], atol=1e-8)
    L = r.labels
    ids = {a.id: np.sign(a.points[0, 0]) for a in r.attractors}
    mirror = np.vectorize(lambda lab: [k for k, s in ids.items() if s == -ids[lab]][0] if lab >= 0 else lab)(L)
    # (x, v) -> (-x, -v) maps the grid onto itself and swaps the basins
    assert np.array_equal(L[::-1, ::-1], mirror)
    shares = sorted(a.share for a in r.attractors)
    assert shares[0] == pytest.approx(0.5, abs=1.0 / 16)


# ---------------------------------------------------------------- invariants


def test_invariants_of_the_cell_map_and_the_analysis(gear_reference):
    p = jg.paper_params()
    grid = CellGrid.paper(counts=(5, 3, 6))  # the grid (and compiled pool) of the band and CLI tests
    # the cell map's invariants hold for any integrator: plain RK4 compiles in a fraction of the time
    images = jg.cell_images(jg.REDUCED, p, grid, jg.PoincareCellMap(mapping_steps=5, integrator=jg.RK4(200)),
                            progress=False)
    assert images.shape == (grid.n_cells,)  # exactly one image per cell
    assert np.all((images >= 0) & (images <= grid.n_cells))  # a cell of the grid or the sink (n_cells)
    r = jg.analyze_global(jg.REDUCED, p, grid, method=jg.Direct(), progress=False, uncertainty=0)
    # labels partition the grid and shares sum to one
    ids = {a.id for a in r.attractors}
    assert set(np.unique(r.labels)) <= ids | {jg.SINK, jg.UNRESOLVED}
    assert sum(a.cell_count for a in r.attractors) + r.n_sink + r.n_unresolved == r.n_cells
    assert sum(r.shares.values()) == pytest.approx(1.0)
    assert sorted(a.period for a in r.attractors) == [4, 8]  # the paper's coexisting P-4 and P-8
    for a in r.attractors:
        # every reported periodic point returns to itself after k periods of the integrator used
        back = np.asarray(jg.stroboscopic_map(jg.REDUCED, p, a.points, periods=a.period))
        assert np.max(np.abs(back - a.points)) < 1e-8
        # ... and one period of an independent, accurate integration (scipy DOP853 at rtol
        # 1e-11, restarted at every backlash kink) carries each point to the next, within
        # the default integrator's accuracy (about 5e-7 per period here; plain RK4 with 800
        # steps, second order at the kinks, is 2e-6 off)
        pts = np.asarray(a.points)
        image = np.array([gear_reference(p, x, 1) for x in pts])
        np.testing.assert_allclose(image, np.roll(pts, -1, axis=0), rtol=0, atol=1e-6)


@pytest.mark.slow
def test_labels_independent_of_chunk_and_pool_size():
    """The Poincare-like cell map's images in chunks of 7 and of 1,000 cells are the same;
    pools of 32 and of 50 lanes (the 144 cells in other orders and groupings of the
    pool's rounds) label every cell alike."""
    p, grid = jg.paper_params(), CellGrid.paper(counts=(6, 4, 6))
    images_a = jg.cell_images(jg.REDUCED, p, grid, jg.PoincareCellMap(mapping_steps=5, chunk_size=7), progress=False)
    images_b = jg.cell_images(jg.REDUCED, p, grid, jg.PoincareCellMap(mapping_steps=5, chunk_size=1000),
                              progress=False)
    assert np.array_equal(images_a, images_b)
    r = jg.analyze_global(jg.REDUCED, p, grid, method=jg.Direct(chunk_size=32), progress=False, uncertainty=0)
    r2 = jg.analyze_global(jg.REDUCED, p, grid, method=jg.Direct(chunk_size=50), progress=False, uncertainty=0)
    assert np.array_equal(r.labels, r2.labels)


@pytest.mark.parametrize("steps", [1, 2, 3])
def test_period_two_reported_as_p2_whatever_l(steps):
    grid = CellGrid.box([(-1.6, 1.6), (-1.2, 1.2)], (10, 8), names=("x", "v"))
    r = jg.analyze_global(jg.DUFFING, PERIOD_TWO, grid, method=jg.StroboscopicCellMap(mapping_steps=steps, settle_periods=300), progress=False, uncertainty=0)
    periodic = [a for a in r.attractors if a.share > 0.05]
    assert periodic and all(a.period == 2 for a in periodic)
    for a in periodic:
        p2 = np.asarray(jg.stroboscopic_map(jg.DUFFING, PERIOD_TWO, a.points, periods=2))
        p1 = np.asarray(jg.stroboscopic_map(jg.DUFFING, PERIOD_TWO, a.points, periods=1))
        assert np.max(np.abs(p2 - a.points)) < 1e-8 and np.min(np.abs(p1 - a.points).max(axis=1)) > 1e-3


def test_detect_period():
    t = np.arange(40)
    seq = np.stack([np.cos(np.pi * t / 2), np.sin(np.pi * t / 2)], -1)  # period 4
    assert jg.detect_period(seq[None], 8, 1e-9)[0] == 4
    assert jg.detect_period(np.stack([t * 0.1, t * 0.0], -1)[None], 8, 1e-9)[0] == 0
    bad = seq.copy()
    bad[3] = np.nan
    assert jg.detect_period(bad[None], 8, 1e-9)[0] == -1


def test_escaping_orbits_go_to_sink_not_nan():
    # x' = x^2 blows up in finite time from x > 0; x <= 0 stays bounded (-> 0^-)
    blow = ForcedSystem(vector_field=lambda t, x, p: x**2 - 0 * p.a * x, period=lambda p: 1.0 + 0 * p.a,
                        state_names=("x",), name="blow-up")
    grid = CellGrid.box([(-1, 1)], (10,), names=("x",))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = jg.analyze_global(blow, BistableParams(), grid, method=jg.Direct(max_periods=60), progress=False, uncertainty=0)
    centres = grid.centres()[:, 0]
    assert np.all(r.labels[centres > 0.5] == jg.SINK)
    assert r.n_sink >= 2
    for a in r.attractors:
        assert np.all(np.isfinite(a.points))


def test_bad_arguments():
    with pytest.raises(ValueError, match="method"):
        jg.analyze_global(method="nope", grid=CellGrid.paper(counts=(2, 2, 2)), progress=False, uncertainty=0)
    with pytest.raises(ValueError, match="every state coordinate"):
        jg.analyze_global(method=jg.StroboscopicCellMap(), grid=CellGrid.paper(counts=(2, 2, 2)), progress=False, uncertainty=0)
    with pytest.raises(ValueError, match=r"axis 0 .* upper > lower, got \[1\.0, -1\.0\]"):
        CellGrid.box([(1, -1)], (3,))
    with pytest.raises(ValueError, match=r"counts\[0\]=0 .* integer >= 1"):
        CellGrid.box([(0, 1)], (0,))


@pytest.mark.slow
def test_direct_round_length_does_not_change_labels():
    grid = CellGrid.paper(counts=(5, 3, 6))
    a = jg.analyze_global(grid=grid, method=jg.Direct(round_periods=5), progress=False, uncertainty=0)
    b = jg.analyze_global(grid=grid, method=jg.Direct(round_periods=10), progress=False, uncertainty=0)
    assert np.array_equal(a.labels, b.labels)
    assert sorted(x.period for x in a.attractors) == [4, 8]  # the paper's coexisting P-4 and P-8


def test_direct_shortcuts_do_not_change_labels():
    """Capture by shadowing a known cycle, the pilot sample and the lane pool only save
    time: with capture off (pure recurrence) and with a pool far smaller than the grid
    (lanes refilled many times) every cell gets the same attractor."""
    grid = CellGrid.paper(counts=(5, 3, 6))
    fast = jg.analyze_global(grid=grid, method=jg.Direct(), progress=False, uncertainty=0)
    slow = jg.analyze_global(grid=grid, method=jg.Direct(capture_radius=0.0, chunk_size=37), progress=False, uncertainty=0)
    assert np.array_equal(fast.labels, slow.labels)
    assert [a.period for a in fast.attractors] == [a.period for a in slow.attractors]
    assert fast.mean_periods < slow.mean_periods  # capture decides cells before a full recurrence test


@pytest.mark.slow
def test_direct_never_reports_an_unstable_cycle():
    """Just past the P-8 -> P-16 period doubling of the gear preset (kappa_amp = 0.33,
    b = 6), states started 1e-5 from the unstable P-8 parent shadow it for hundreds of
    periods, long enough to recur on it within the period tolerance. The direct method
    must not call it an attractor: every attractor it returns has its Floquet multipliers
    (jax.jacfwd, the shooting module: another code path than the method's central
    differences) inside the unit circle, and every state gets the attractor that 4,000
    periods of plain integration reach."""
    p = jg.with_param(jg.with_param(jg.paper_params(), "kappa_amp", 0.33), "b", 6.0)
    near = [[6.353, -0.096, 10.21, -0.792]]  # a point near the P-8 cycle (from the P-16 attractor)
    p8 = jg.periodic_orbit(jg.REDUCED, p, near, period=8)
    assert int(p8.status[0]) == int(jg.Status.CONVERGED) and int(p8.min_period[0]) == 8
    assert np.abs(np.asarray(p8.multipliers[0])).max() > 1.05  # the premise: the P-8 is unstable
    X = np.asarray(p8.point[0]) + 1e-5 * np.random.default_rng(1).standard_normal((6, 4))
    labels, atts, _ = jg.Direct().label_states(jg.REDUCED, p, X)
    assert len(atts) >= 1 and np.all(labels >= 0)
    for pts, k, _ in atts:
        mu = np.asarray(jg.floquet_multipliers(jg.REDUCED, p, np.asarray(pts)[0], period=k))
        assert np.abs(mu).max() < 1.0, (k, np.abs(mu).max())
    x = X
    for _ in range(8):  # 4,000 periods
        x = np.asarray(jg.stroboscopic_orbit(jg.REDUCED, p, x, n_points=500))[:, -1]
    tail = np.asarray(jg.stroboscopic_orbit(jg.REDUCED, p, x, n_points=32))  # (6, 32, 4)
    dist = np.array([[np.linalg.norm(t[:, None] - np.asarray(pts)[None], axis=-1).min(axis=1).max()
                      for pts, _, _ in atts] for t in tail])  # (states, attractors)
    assert dist.min(axis=1).max() < 1e-4  # every state ends on a reported attractor
    np.testing.assert_array_equal(labels, dist.argmin(axis=1))


def test_capture_radius_stays_below_attractor_separation():
    """The pool's automatic capture radius (computed on the device from a value's table):
    a quarter of the smallest gap between points of two attractors, at most 1 % of
    ``1 + max |x|``; a given radius is used as it is."""
    from jaxgear.analysis._lanes import capture_radius, seed_tables

    a = np.array([[0.0, 0.0], [1.0, 0.0]])
    b = np.array([[0.0, 0.04], [1.0, 1.0]])
    t = seed_tables([[(a, 2), (b, 2)]], 2, 2)
    assert float(capture_radius(t.points[0], t.codes[0], None)) == pytest.approx(0.01)  # a quarter of the 0.04 gap
    t = seed_tables([[(a, 2)]], 2, 2)
    assert float(capture_radius(t.points[0], t.codes[0], None)) == pytest.approx(0.02)  # 1 % of 1 + max|x|
    assert float(capture_radius(t.points[0], t.codes[0], 0.3)) == 0.3
    with pytest.raises(ValueError, match="capture_radius"):
        jg.Direct(capture_radius=-1)


def test_pool_compaction_keeps_every_busy_lane_and_its_history():
    """The direct pool's compaction (a device op moving only the busy lanes beyond the
    busy count into free lanes below it, in chunks): afterwards lanes [0, c) hold exactly
    the busy lanes, each with the state, ring, streaks, row and age it had."""
    import jax

    from jaxgear.analysis import _lanes

    rng = np.random.default_rng(3)
    L, dim, M = 6000, 4, 3  # more lanes to move (about 1,500) than one chunk of MOVE_CHUNK (1,024)
    X = rng.normal(size=(L, dim))
    att = _lanes.seed_tables([()], M, dim)
    s = _lanes.init_pool(L, M, jax.device_put(X), jax.device_put(np.zeros(L, np.int32)), att)
    busy = rng.random(L) < 0.45
    s = s._replace(hist=jax.device_put(rng.normal(size=s.hist.shape)),
                   streak=jax.device_put(rng.integers(0, 9, size=s.streak.shape).astype(np.int32)),
                   age=jax.device_put(rng.integers(0, 99, size=L).astype(np.int32)),
                   cell=jax.device_put(np.where(busy, np.arange(L), -1).astype(np.int32)))
    before = {int(c): (np.asarray(s.Y)[:, j], np.asarray(s.hist)[:, :, j], np.asarray(s.streak)[:, j],
                       int(s.age[j])) for j, c in enumerate(np.asarray(s.cell)) if c >= 0}
    out = jax.jit(_lanes.compact)(s)
    c = int(busy.sum())
    cell = np.asarray(out.cell)
    assert int(out.n_active) == c
    assert (cell[:c] >= 0).all() and (cell[c:] < 0).all()
    assert sorted(cell[:c].tolist()) == sorted(before)
    for j in range(c):
        y, h, st, age = before[int(cell[j])]
        np.testing.assert_array_equal(np.asarray(out.Y)[:, j], y)
        np.testing.assert_array_equal(np.asarray(out.hist)[:, :, j], h)
        np.testing.assert_array_equal(np.asarray(out.streak)[:, j], st)
        assert int(out.age[j]) == age
    kept = np.flatnonzero(busy[:c])  # lanes already in place do not move
    np.testing.assert_array_equal(cell[kept], kept)
