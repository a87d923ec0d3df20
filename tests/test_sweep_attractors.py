"""Sweeps and maps follow attractors of every type: cycles, and the quasi-periodic and
chaotic attractors that repeat no point (period 0, clouds of points).

References that do not come from jaxgear's sweep code:
- clouds built here by construction (which cloud is which attractor is known): a ring
  that moves a little, a ring that grows (a crisis widens an attractor: its point sets
  drift apart farther than the tolerance, yet the small one lies inside the large one),
  a cloud far away, a cycle at a ring's centre;
- the backlash sweep of the reduced gear model through its chaotic band (b = b_sp = b_rp
  from about 1.2 to 2.7; the paper preset b = 5 is a P-4 attractor, paper §5): the
  largest exponent of the chaotic attractor checked against a plain (unweighted)
  finite-time estimate from another point of its cloud.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import jaxgear as jg
from jaxgear._lyapunov import AttractorType, lyapunov_spectrum
from jaxgear._matching import cloud_overlap, match_attractors
from jaxgear.analysis import RecurrenceOptions
from jaxgear.sweep import match_across_values, match_on_grid

QUIET = jg.Runner(progress=False)  # nothing written, no progress bars


def _ring(centre, radius, n=400, phase=0.0):
    t = phase + np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.stack([centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)], axis=1)


def _results(*values):
    """Fake per-value results: each value a list of ``(points, period)``."""
    out = []
    for atts in values:
        a = tuple(jg.Attractor(id=i, period=k, points=np.asarray(p, float), section_points=np.zeros((0, 2)),
                               cell_count=1, share=1.0 / len(atts), residual=0.0,
                               periodic_cells=np.zeros(0, np.int64)) for i, (p, k) in enumerate(atts))
        out.append(type("R", (), {"attractors": a})())
    return out


def test_clouds_are_followed_by_the_boxes_they_occupy():
    """A ring that moves by a tenth of the tolerance keeps its id, though the result lists
    it second; a cycle at its centre (closer to it than the tolerance) is never taken for
    it; a cloud far away is a new attractor."""
    tol = 1.0
    ring0 = _ring((0.0, 0.0), 2.0)
    ring1 = _ring((0.1, 0.05), 2.0, n=350, phase=0.3)  # other points on the moved ring
    far = _ring((10.0, 0.0), 2.0)
    ids = match_across_values(_results([(ring0, 0), ([[0.0, 0.0]], 1)],
                                       [([[0.05, 0.0]], 1), (ring1, 0)],
                                       [([[0.1, 0.0]], 1), (far, 0)]), match_tol=tol)
    assert [g.tolist() for g in ids] == [[0, 1], [1, 0], [1, 2]]
    # a cycle and a cloud are never one attractor, however close
    assert match_attractors([(ring0, 0)], [(ring0[:1], 1)], 100.0).tolist() == [-1]


def test_overlap_not_point_distance():
    """A chaotic band that widens threefold (a crisis) drifts farther from its old point set
    than the tolerance, yet occupies the old boxes: the same attractor, whether it widens
    or narrows again."""
    tol = 1.0
    small = np.stack([np.linspace(0.0, 1.0, 300), np.full(300, 0.1)], axis=1)
    wide = np.stack([np.linspace(0.0, 3.0, 900), np.full(900, 0.1)], axis=1)  # the old band's end is 2 away
    assert np.max(np.min(np.linalg.norm(wide[:, None] - small[None], axis=-1), axis=1)) > tol
    assert cloud_overlap(small, wide, width=0.5 * tol) == 1.0
    assert match_attractors([(small, 0)], [(wide, 0)], tol).tolist() == [0]
    assert match_attractors([(wide, 0)], [(small, 0)], tol).tolist() == [0]
    # moved by more than the tolerance: no box in common, a new attractor
    assert match_attractors([(small, 0)], [(small + [0.0, 1.5], 0)], tol).tolist() == [-1]


def test_clouds_on_a_parameter_grid():
    """On a 2 x 2 parameter grid a ring drifting with both parameters keeps one id; a
    cycle beside it keeps another."""
    rings = [_ring((0.1 * ix, 0.1 * iy), 1.5, phase=0.1 * (ix + 2 * iy)) for iy in range(2) for ix in range(2)]
    res = _results(*[[(r, 0), ([[5.0 + 0.05 * i, 0.0]], 2)][:: 1 if i % 2 else -1] for i, r in enumerate(rings)])
    ids = match_on_grid(res, 2, 2, match_tol=1.0)
    for i, g in enumerate(ids):
        per = [a.period for a in res[i].attractors]
        assert g[per.index(0)] == ids[0][[a.period for a in res[0].attractors].index(0)]
        assert g[per.index(2)] == ids[0][[a.period for a in res[0].attractors].index(2)]


def _check_chaotic_sweep(s, values):
    """Every value holds a chaotic attractor with a positive exponent beyond its error,
    all of one global id; at most 1 % of the cells unresolved; the counts see it."""
    assert s.unresolved_share.max() <= 0.01
    chaotic = (s.attractor_type == int(AttractorType.CHAOTIC)) & s.present  # (V, G)
    assert chaotic.any(axis=1).all(), s.shares_table()
    ids = np.nonzero(chaotic.any(axis=0))[0]
    assert len(ids) == 1, s.shares_table()  # one attractor followed through the band
    g = int(ids[0])
    assert chaotic[:, g].all() and np.all(s.period[:, g] == 0)
    assert np.all(s.largest_exponent[:, g] > 3 * s.exponent_error[:, g]) and np.all(s.largest_exponent[:, g] > 0)
    assert s.attractor_label(g) == "chaotic"
    assert np.all(s.coexisting_of(AttractorType.CHAOTIC) == 1) and np.all(s.coexisting >= 1)
    # the largest exponent of the map, from another point of the cloud by a plain
    # (unweighted) finite-time average: within a few errors of both estimates
    i = len(values) // 2
    params = jg.with_param(jg.paper_params(), "b", float(values[i]))
    cloud = s.points[i, g, : s.n_points[i, g]]
    ref = lyapunov_spectrum(jg.REDUCED, params, cloud[len(cloud) // 2], n_exponents=2, periods=200,
                               transient=0, stretches=4, weighted=False)
    lam, err = float(ref.exponents[0]), float(ref.errors[0])
    assert abs(s.largest_exponent[i, g] - lam) <= 4 * np.hypot(err, s.exponent_error[i, g]) + 0.02
    return g


def _fake_result(atts, grid):
    """A per-value result of the sweep's assembly: ``atts = [(points, period, kind,
    lambda_1, error, cells)]``; the cells given to each attractor in order, the rest sink."""
    a = tuple(jg.Attractor(id=i, period=k, points=np.asarray(p, float), section_points=np.zeros((0, 2)),
                           cell_count=c, share=c / grid.n_cells, residual=0.0, periodic_cells=np.zeros(0, np.int64),
                           kind=t, exponents=np.array([lam, -1.0]), exponent_errors=np.array([err, 0.01]))
              for i, (p, k, t, lam, err, c) in enumerate(atts))
    labels = np.concatenate([np.full(c, i) for i, (*_, c) in enumerate(atts)] + [np.zeros(0, int)])
    labels = np.concatenate([labels, np.full(grid.n_cells - len(labels), -1)])
    return type("R", (), dict(attractors=a, labels=labels, n_sink=int((labels == -1).sum()), n_cells=grid.n_cells,
                              n_unresolved=0, uncertainty=None, basin_entropy=None))()


def test_sweep_records_types_and_exponents_and_counts_every_type():
    """A P-4 cycle and a chaotic attractor coexist, then a quasi-periodic one appears far
    away as the cycle vanishes: per value and global attractor its type and largest
    exponent (NaN where absent); ``coexisting`` and ``dominant`` count every type; the
    table, events and share figure name each by its type."""
    from jaxgear import plotting
    from jaxgear.sweep import _basins

    grid = jg.CellGrid.box([(-4.0, 4.0), (-4.0, 4.0)], (5, 4), names=("x", "v"))
    C, Q, P = int(AttractorType.CHAOTIC), int(AttractorType.QUASI_PERIODIC), int(AttractorType.PERIODIC)
    cycle = [[0.0, 3.0], [3.0, 0.0], [0.0, -3.0], [-3.0, 0.0]]
    res = [_fake_result([(cycle, 4, P, -0.2, 0.0, 12), (_ring((0.0, 0.0), 1.0), 0, C, 0.3, 0.02, 8)], grid),
           _fake_result([(_ring((0.05, 0.0), 1.1, phase=0.2), 0, C, 0.35, 0.03, 14), (cycle, 4, P, -0.1, 0.0, 6)],
                        grid),
           _fake_result([(_ring((0.1, 0.0), 1.2), 0, C, 0.4, 0.03, 10), (_ring((0.0, 30.0), 0.5), 0, Q, 0.0, 1e-4, 10)],
                        grid)]
    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=1.0, omega=1.2)
    s = _basins._assemble_basins(res, "gamma", np.array([1.0, 2.0, 3.0]), grid, jg.Direct(),
                                 jg.BasinOptions(match_tol=2.0, uncertainty=0), jg.DUFFING, p)
    assert s.n_attractors == 3
    assert s.period.tolist() == [[4, 0, -1], [4, 0, -1], [-1, 0, 0]]
    assert s.attractor_type.tolist() == [[P, C, -1], [P, C, -1], [-1, C, Q]]
    np.testing.assert_array_equal(s.largest_exponent, [[-0.2, 0.3, np.nan], [-0.1, 0.35, np.nan],
                                                       [np.nan, 0.4, 0.0]])
    np.testing.assert_array_equal(s.exponent_error[:, 1], [0.02, 0.03, 0.03])
    assert [s.attractor_label(g) for g in range(3)] == ["P-4", "chaotic", "quasi-periodic"]
    assert s.coexisting.tolist() == [2, 2, 2] and s.coexisting_of(C).tolist() == [1, 1, 1]
    assert s.coexisting_of(AttractorType.QUASI_PERIODIC).tolist() == [0, 0, 1]
    assert s.dominant.tolist() == [0, 1, 1]  # the chaotic attractor holds the most cells from the second value on
    ev = {(e["index"], e["id"]): (e["event"], e["detail"]) for e in s.events()}
    assert ev[(2, 2)][0] == "appears" and ev[(2, 2)][1].startswith("quasi-periodic")
    assert ev[(2, 0)] == ("vanishes", "was P-4, share 30.0 %")
    assert "1: chaotic" in s.shares_table() and "quasi-periodic" in s.table()
    ax = plotting.plot_basin_shares(s).axes[0]
    assert [t.get_text() for t in ax.get_legend().get_texts()][:3] == ["0: P-4", "1: chaotic", "2: quasi-periodic"]
    lower = plotting.plot_basin_shares(s, exponents=True).axes[1]  # the exponents, chaotic one above zero
    assert any(np.array_equal(line.get_ydata(), [0.3, 0.35, 0.4]) for line in lower.lines)
    summary = s.summary()
    assert summary["attractor_type"] == s.attractor_type.tolist() and [a["label"] for a in summary["attractors"]][1] == "chaotic"
    # a file written before types were recorded: cycles periodic, clouds of unknown type, no exponents
    old = dataclasses.replace(s, attractor_type=None, largest_exponent=None, exponent_error=None)
    assert old.attractor_type.tolist() == [[P, -1, -1], [P, -1, -1], [-1, -1, -1]]
    assert old.attractor_label(1) == "aperiodic" and np.isnan(old.largest_exponent).all()


def test_bifurcation_diagram_labels_chaos_tori_and_cycles():
    """Aperiodic branches get their type from the largest Lyapunov exponent: Ueda's
    Duffing oscillator x'' + 0.05 x' + x^3 = 7.5 cos t is chaotic (largest exponent about
    0.11 per unit time, Ueda's attractor; its exponent against scipy in test_lyapunov),
    at forcing 0.3 it is P-1; the van der Pol oscillator forced at the golden-mean
    frequency (mu = 0.1, F = 0.05: far outside the locking band |omega - 1| < F / 4 of
    the amplitude-2 cycle, Adler; the rotation number checked irrational with scipy in
    test_lyapunov) is quasi-periodic, largest exponent zero within its error, and at
    omega = 1 (inside the band) entrained, P-1. Table and figure name the types."""
    from jaxgear import plotting
    from jaxgear._examples import DUFFING, VAN_DER_POL, DuffingParams, VanDerPolParams

    C, Q, P = int(AttractorType.CHAOTIC), int(AttractorType.QUASI_PERIODIC), int(AttractorType.PERIODIC)
    ueda = DuffingParams(delta=0.05, alpha=0.0, beta=1.0, gamma=7.5, omega=1.0)
    d = jg.bifurcation_diagram(DUFFING, ueda, "gamma", [0.3, 7.5], np.array([[2.5, 0.0]]), transient=100, record=17,
                               max_period=8, integrator=jg.RK4(200), runner=QUIET)
    assert d.period[0, :, 0].tolist() == [1, 0] and d.attractor_type[0, :, 0].tolist() == [P, C]
    lam, err = d.largest_exponent[0, 1, 0], d.exponent_error[0, 1, 0]
    # about 0.11 per unit time: within (0.08, 0.15) up to three of the estimate's standard errors
    # (a finite-time estimate on a chaotic orbit: round-off moves it by about one)
    slack = 3 * err / (2 * np.pi)
    assert lam > 3 * err and 0.08 - slack < lam / (2 * np.pi) < 0.15 + slack and np.isnan(d.largest_exponent[0, 0, 0])
    assert [a["label"] for a in d.attractors_at(1)] == ["chaotic"] and "chaotic" in d.table()
    ax = plotting.plot_bifurcation(d, "x").axes[0]
    assert sorted(t.get_text() for t in ax.get_legend().get_texts()) == ["P-1", "chaotic"]

    golden = (1 + 5**0.5) / 2
    d = jg.bifurcation_diagram(VAN_DER_POL, VanDerPolParams(mu=0.1, F=0.05, omega=1.0), "omega", [1.0, golden],
                               np.array([[2.0, 0.0]]), transient=200, record=17, max_period=8,
                               integrator=jg.RK4(100), runner=QUIET)
    assert d.period[0, :, 0].tolist() == [1, 0] and d.attractor_type[0, :, 0].tolist() == [P, Q]
    lam, err = d.largest_exponent[0, 1, 0], d.exponent_error[0, 1, 0]
    assert abs(lam) <= max(3 * err, 1e-6) and err < 1e-3
    assert d.attractors_at(1)[0]["label"] == "quasi-periodic"
    # an older file: aperiodic of unknown type
    old = dataclasses.replace(d, attractor_type=None, largest_exponent=None, exponent_error=None)
    assert old.attractor_type[0, :, 0].tolist() == [P, -1] and old.attractors_at(1)[0]["label"] == "aperiodic"


def test_backlash_band_every_cell_decided():
    """The band sweep in the default suite (the slow one below is the heavy check): b =
    16/11 (about 1.455), where the chaotic attractor is about a box of the partition wide in
    x1 and x2 and comes back within about a box every 4 periods without ever converging,
    and b = 2 inside the band; 5 x 3 x 6 cells of region D with boxes as coarse
    as those of the default partition on the 25 x 15 x 30 grid (85 boxes across these
    centres' span). At both values every cell is decided, on a chaotic attractor (period 0,
    largest exponent positive beyond its error). Independently of the analysis and of the
    Lyapunov code: a stroboscopic orbit from the cloud never repeats (no P-k, k <= 16, to
    1e-6), stays bounded, and a twin 1e-9 away parts from it to the attractor's size within
    200 periods; at b = 16/11 the cloud is within two boxes wide on x1 and x2 (the case an
    approach to a cycle was once taken for: every cell unresolved)."""
    values = [16 / 11, 2.0]
    grid = jg.CellGrid.paper((5, 3, 6))
    method = jg.Direct(recurrence=RecurrenceOptions(resolution=85))
    s = jg.basin_sweep(jg.REDUCED, jg.paper_params(), "b", values, grid, method=method, runner=QUIET, uncertainty=0)
    assert s.unresolved_share.max() <= 0.01, s.shares_table()
    chaotic = (s.attractor_type == int(AttractorType.CHAOTIC)) & s.present
    assert chaotic.any(axis=1).all(), s.shares_table()
    width = np.asarray(method.boxes(grid.centres()).partition.width)
    for i, b in enumerate(values):
        g = int(np.flatnonzero(chaotic[i])[0])
        assert s.period[i, g] == 0 and s.shares[i, g] >= 0.99, s.shares_table()
        assert s.largest_exponent[i, g] > 3 * s.exponent_error[i, g] > 0
        cloud = s.points[i, g, : s.n_points[i, g]]
        if i == 0:
            assert np.all(np.ptp(cloud, axis=0)[:2] < 2 * width[:2])
        x0 = np.stack([cloud[0], cloud[0] + [1e-9, 0.0, 0.0, 0.0]])
        orbit = np.asarray(jg.stroboscopic_orbit(jg.REDUCED, jg.with_param(jg.paper_params(), "b", b), x0,
                                                 n_points=200))
        assert np.all(np.abs(orbit) < 100)
        for k in range(1, 17):
            assert np.max(np.abs(orbit[0, k:] - orbit[0, :-k])) > 1e-6
        assert np.max(np.abs(orbit[0] - orbit[1])) > 0.1 * np.ptp(cloud, axis=0).max()


@pytest.mark.slow
def test_backlash_sweep_through_the_chaotic_band():
    """The heavy check of the band sweep (the default suite runs
    :func:`test_backlash_band_every_cell_decided`): b = 1.8, 2.0, 2.2 on an 8 x 5 x 10 grid,
    one chaotic attractor followed through them."""
    values = [1.8, 2.0, 2.2]
    s = jg.basin_sweep(jg.REDUCED, jg.paper_params(), "b", values, jg.CellGrid.paper((8, 5, 10)), runner=QUIET,
                       uncertainty=0)
    g = _check_chaotic_sweep(s, values)
    assert [e["event"] for e in s.events() if e["id"] == g and e["event"] != "share change"] == ["present"]


def test_bifurcation_diagram_labels_chaos_and_cycles():
    """From rest, b = 2 (inside the chaotic band) is chaotic with a positive largest
    exponent beyond its error; b = 5 (the paper preset) is the P-4 attractor, periodic,
    no exponent measured; the table and the figure name them. (About 7 s of CPU, nearly
    all of it compiling the diagram's and the exponents' kernels: fewer periods would
    not make it faster.)"""
    from jaxgear import plotting

    d = jg.bifurcation_diagram(jg.REDUCED, jg.paper_params(), "b", [2.0, 5.0], np.zeros((1, 4)), transient=150,
                               record=17, max_period=8, runner=QUIET)
    assert d.period[0, :, 0].tolist() == [0, 4]
    assert d.attractor_type[0, :, 0].tolist() == [int(AttractorType.CHAOTIC), int(AttractorType.PERIODIC)]
    lam, err = d.largest_exponent[0, 0, 0], d.exponent_error[0, 0, 0]
    assert lam > 3 * err and lam > 0.05 and np.isnan(d.largest_exponent[0, 1, 0])
    assert [a["label"] for a in d.attractors_at(0)] == ["chaotic"] and d.attractors_at(1)[0]["label"] == "P-4"
    assert "chaotic" in d.table() and "P-4" in d.table()
    ax = plotting.plot_bifurcation(d).axes[0]
    assert sorted(t.get_text() for t in ax.get_legend().get_texts()) == ["P-4", "chaotic"]


@pytest.mark.slow
def test_bifurcation_diagram_never_calls_the_weakly_chaotic_gear_attractor_a_torus():
    """At b = 16/11 the gear's chaotic attractor has lambda_1 of only about 0.14 per
    period, and 200 periods in 4 stretches from some of its points read zero within three
    errors (the trap of tests/test_lyapunov.py). The diagram measures such a zero again
    over ``LYAPUNOV_RECHECK`` times as many periods: 24 values within 1e-9 of 16/11 (one
    attractor; the chaotic motion puts each value's measured point elsewhere on it), every
    one chaotic, although the short look alone calls some of the same points
    quasi-periodic."""
    from jaxgear._lyapunov import classify_attractor

    values = 16 / 11 + 1e-9 * np.linspace(-1, 1, 24)
    start = np.array([[16 / 11 + 0.3, 0.0, 0.0, 0.0]])
    d = jg.bifurcation_diagram(jg.REDUCED, jg.paper_params(), "b", values, start, transient=300, record=17,
                               max_period=8, runner=QUIET)
    assert np.all(d.period[0, :, 0] == 0), d.period[0, :, 0]
    last = d.points[0, :, 0, -1]
    assert np.ptp(last, axis=0).max() > 0.1  # the values' points lie apart on the attractor
    short = [classify_attractor(lyapunov_spectrum(jg.REDUCED, jg.with_param(jg.paper_params(), "b", b), x,
                                                  periods=200, stretches=4, transient=0))
             for b, x in zip(values, last)]
    assert int(AttractorType.QUASI_PERIODIC) in np.asarray(short).tolist()  # the trap is real here
    assert np.all(d.attractor_type[0, :, 0] == int(AttractorType.CHAOTIC)), d.attractor_type[0, :, 0]
    assert np.all(d.largest_exponent[0, :, 0] > 3 * d.exponent_error[0, :, 0])


def test_exponents_of_many_values_in_one_batch_are_each_values_own():
    """The batched exponents of a diagram (each lane at its own parameter value, chunks
    padded) equal :func:`lyapunov_spectrum` run at each value alone."""
    from jaxgear._examples import DUFFING, DuffingParams
    from jaxgear.sweep._kernels import values_exponent_estimates

    p = DuffingParams(delta=0.05, alpha=0.0, beta=1.0, gamma=7.5, omega=1.0)
    V, X = np.array([[7.5], [7.0], [6.0]]), np.array([[2.5, 0.0], [1.0, 0.0], [0.5, 0.5]])
    est, final = values_exponent_estimates(DUFFING, p, ("gamma",), V, X, n_exponents=2, periods=8, stretches=2,
                                           integrator=jg.RK4(50), chunk_size=2)
    for i in range(3):
        s = lyapunov_spectrum(DUFFING, jg.with_param(p, "gamma", V[i, 0]), X[i], periods=8, stretches=2, transient=0,
                              integrator=jg.RK4(50))
        np.testing.assert_allclose(est[i], s.stretch_exponents, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(final[i], s.final_state, rtol=1e-9, atol=1e-10)


@pytest.mark.slow
def test_a_sweep_in_one_pool_gives_each_value_its_own_labels():
    """A basin sweep of the paper preset in one lane pool (``batched=True``) at b = 5.5 and
    5.556, values that share their P-4, P-8 and P-3 and have a P-18 (longer than
    ``max_period``: found by its boxes): every value's labels and shares are those of the
    global analysis at that value alone, label for label. (In one pool a candidate's boxes
    enter the table at a moment that depends on the other values' lanes, and a cell
    decided by box hits could differ: with a pilot of 16 cells, one did at b = 5.5 before
    such values were analysed alone.)"""
    p = jg.paper_params()
    grid = jg.CellGrid.paper((10, 6, 12))
    method = jg.Direct(pilot=16)
    values = [5.5, 5.556]
    s = jg.basin_sweep(jg.REDUCED, p, "b", values, grid, method=method, runner=QUIET, batched=True, uncertainty=0)
    for i, v in enumerate(values):
        r = jg.analyze_global(jg.REDUCED, jg.with_param(p, "b", v), grid, method, progress=False, uncertainty=0)
        assert 18 in [a.period for a in r.attractors]
        lut = {}
        for a, b in zip(np.asarray(r.labels).ravel(), s.labels[i].ravel()):
            assert lut.setdefault(int(a), int(b)) == int(b)  # one global id per local label, cell by cell
        assert sorted(s.shares[i][s.present[i]]) == sorted(a.share for a in r.attractors)
