"""Basin entropy, boundary basin entropy and the uncertainty exponent (jaxgear.analysis._fractal).

References independent of the code: entropies of boxes worked out by hand, the
binomial expectation of the entropy of random labels, the geometry of a straight
boundary (alpha = 1, a known number of boundary boxes), and the basins of Newton's
method for z^3 = 1 (computed with numpy here), whose boundary is a fractal (a Julia set).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

import jaxgear as jg
from jaxgear.analysis._fractal import LOG2, basin_entropy, scaling_range, uncertain_fraction, uncertainty_exponent


def _h(p):
    p = np.asarray(p, float)
    p = p[p > 0]
    return float(-(p * np.log(p)).sum())


def _half_plane(points):
    return (points[:, 0] > 0.3 + 0.2 * points[:, 1]).astype(np.int64)


def _newton_labels(points, iters=60):
    """Root of z^3 = 1 that Newton's method reaches from each point (0, 1, 2), -1 if none."""
    z = points[:, 0] + 1j * points[:, 1]
    with np.errstate(all="ignore"):
        for _ in range(iters):
            z = z - (z**3 - 1) / (3 * z**2)
    roots = np.exp(2j * np.pi * np.arange(3) / 3)
    d = np.abs(z[:, None] - roots[None])
    lab = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=1)
    return np.where(np.min(np.where(np.isfinite(d), d, np.inf), axis=1) < 1e-6, lab, -1)


def _grid(n, lo, hi):
    x = np.linspace(lo, hi, n)
    X, Y = np.meshgrid(x, x, indexing="ij")
    return np.stack([X.ravel(), Y.ravel()], axis=1)


def test_hand_worked_boxes_and_reserved_labels():
    lab = np.array([[0, 1, 0, 0], [1, 1, 0, 0], [2, 2, 0, -1], [2, 2, -1, -1]])
    h = _h([0.25, 0.75])
    r = basin_entropy(lab, box=2)
    assert (r.n_boxes, r.n_boundary_boxes, r.n_outcomes) == (4, 2, 4)
    np.testing.assert_allclose([r.S_b, r.S_bb], [2 * h / 4, h], rtol=1e-14)
    # the sink label left out: the bottom-right box holds one outcome only
    r = basin_entropy(lab, box=2, ignore=[-1])
    assert (r.n_boxes, r.n_boundary_boxes, r.n_outcomes) == (4, 1, 3)
    np.testing.assert_allclose([r.S_b, r.S_bb], [h / 4, h], rtol=1e-14)
    # cells beyond whole boxes are left out; one label everywhere: no boundary
    r = basin_entropy(np.zeros((7, 9), np.int32), box=3)
    assert (r.n_boxes, r.n_boundary_boxes) == (6, 0) and r.S_b == 0 and np.isnan(r.S_bb)


def test_random_labels_in_three_dimensions_match_the_binomial_expectation():
    rng = np.random.default_rng(1)
    lab = (rng.random((40, 40, 40)) < 0.5).astype(np.int8)
    r = basin_entropy(lab, box=2)
    k = np.arange(9)
    H = np.array([_h([j / 8, 1 - j / 8]) for j in k])
    pk = binom.pmf(k, 8, 0.5)
    want_b = float(pk @ H)
    want_bb = want_b / (1 - pk[0] - pk[8])
    assert r.n_boxes == 8000
    # 8000 boxes: the standard error of the mean entropy is ~0.2/sqrt(8000) ~ 0.002
    assert abs(r.S_b - want_b) < 0.01 and abs(r.S_bb - want_bb) < 0.01


def test_smooth_boundary_entropy_below_log2():
    n = 500
    pts = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(pts, pts, indexing="ij")
    lab = (X > 0.3 + 0.2 * Y).astype(np.int64)
    r = basin_entropy(lab, box=5)
    assert r.n_boxes == 100 * 100
    # the line x = 0.3 + 0.2 y crosses 100 box rows and 20 box columns: a boundary box in
    # each row, and at most one more where it passes into the next column
    assert 100 <= r.n_boundary_boxes <= 120
    assert r.S_bb < LOG2 and not r.fractal
    # a straight cut at a uniformly distributed place: the mean binary entropy is 1/2 nat
    assert abs(r.S_bb - 0.5) < 0.1


def test_smooth_boundary_uncertainty_exponent_is_one():
    eps = np.logspace(-3.5, -1, 6)
    n = 40_000
    f = uncertain_fraction(_half_plane, [0.0, 0.0], [1.0, 1.0], eps, n_samples=n, seed=3)
    # closed form: a state within eps |u.n| of the line is uncertain, E|u.n| = 2/pi for a
    # random direction in the plane, and the line is sqrt(1 + 0.2^2) long in the unit
    # square: f = 2 eps (2/pi) sqrt(1.04), within 4 binomial standard deviations
    want = 4 * eps / np.pi * np.hypot(1, 0.2)
    assert np.all(np.abs(f - want) <= 4 * np.sqrt(want / n))
    r = uncertainty_exponent(eps, f, n_samples=n)
    assert abs(r.alpha - 1) <= 3 * r.alpha_err and r.alpha_err < 0.05
    assert r.dimension(2) == pytest.approx(2 - r.alpha)
    r0 = uncertainty_exponent(eps, f)  # unweighted: the same slope within its error
    assert abs(r0.alpha - 1) <= 3 * r0.alpha_err


def test_exact_power_law_fit():
    eps = np.array([1e-4, 1e-3, 1e-2, 1e-1])
    r = uncertainty_exponent(eps, 0.5 * eps**0.4)
    assert r.alpha == pytest.approx(0.4, abs=1e-12) and r.alpha_err < 1e-12
    assert r.log_prefactor == pytest.approx(np.log(0.5), abs=1e-12)


def test_newton_basins_are_fractal():
    lab = _newton_labels(_grid(400, -1.0, 1.0)).reshape(400, 400)
    assert set(np.unique(lab)) <= {-1, 0, 1, 2}
    r = basin_entropy(lab, box=5)
    assert r.S_bb > LOG2 and r.fractal
    eps = np.logspace(-6, -2, 5)
    n = 8000
    f = uncertain_fraction(_newton_labels, [-1.0, -1.0], [1.0, 1.0], eps, n_samples=n, seed=0)
    u = uncertainty_exponent(eps, f, n_samples=n)
    # the Julia set of z -> z - (z^3 - 1)/(3 z^2) has box dimension ~1.42: alpha ~ 0.6
    assert u.alpha + 3 * u.alpha_err < 0.9
    assert 0.3 < u.alpha


def test_the_scaling_range_leaves_out_the_saturated_fractions():
    """f = min(c eps^a, f_sat) counted on n samples (binomial), eps one a decade from 1e-8
    to 1: the range is the power law's, 1e-8 to 1e-3 (the three saturated points left
    out), with alpha within 3 errors of a and a consistent fit; a fit of every point
    misses a by many errors. (A bend that the counting errors hide, f_sat reached between
    two points, can be taken into the range; here f saturates at a point.)"""
    a, c, n = 0.3, 0.8, 4000
    eps = 10.0 ** np.arange(-8, 1)
    truth = np.minimum(c * eps**a, c * 1e-3**a)  # saturated from eps = 1e-3
    for seed in range(5):
        f = np.random.default_rng(seed).binomial(n, truth) / n
        r = scaling_range(eps, f, n)
        assert r.reason is None and (r.eps_min, r.eps_max) == (1e-8, 1e-3), (seed, r)
        np.testing.assert_array_equal(r.used, eps <= 1e-3)
        assert abs(r.alpha - a) <= 3 * r.alpha_err and r.alpha_err < 0.02, (seed, r)
        assert r.reduced_chi2 <= jg.analysis._fractal.MAX_REDUCED_CHI2
        assert r.fit.alpha == r.alpha and r.fit.reduced_chi2 == r.reduced_chi2
        every = uncertainty_exponent(eps, f, n_samples=n)
        assert abs(every.alpha - a) > 3 * every.alpha_err  # what the range avoids
    # the order of the points does not matter
    back = scaling_range(eps[::-1], f[::-1], n)
    assert back.alpha == pytest.approx(r.alpha, rel=1e-12) and np.array_equal(back.used, r.used[::-1])


def test_no_power_law_gives_no_scaling_range():
    """A flat f (saturated everywhere), too few fractions above zero, and an f that jumps
    up and down give no exponent (NaN) and the reason."""
    eps = 10.0 ** np.arange(-8, 1)
    n = 4000
    flat = np.random.default_rng(0).binomial(n, np.full(len(eps), 0.2)) / n
    few = np.array([0, 0, 0, 0, 0, 0, 0.01, 0.1, 0.2])  # three above zero
    gap = np.array([0.001, 0.002, 0.004, 0, 0.01, 0.02, 0.05, 0.1, 0.2])  # runs of 3 and 5 (over 4 decades)
    zigzag = np.tile([0.01, 0.2], 5)[:9]
    for f, why in ((flat, "does not rise"), (few, "fewer than 4"), (zigzag, "fits a power law")):
        r = scaling_range(eps, f, n)
        assert np.isnan(r.alpha) and np.isnan(r.alpha_err) and np.isnan(r.eps_min) and not r.used.any(), r
        assert r.fit is None and r.reason.startswith("no scaling range: ") and why in r.reason, r.reason
    r = scaling_range(eps, gap, n)  # the run after the zero, 1e-4 to 1
    assert (r.eps_min, r.eps_max) == (1e-4, 1.0) and r.reason is None
    with pytest.raises(ValueError, match="in \\[0, 1\\]"):
        scaling_range(eps, -flat, n)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="box=1"):
        basin_entropy(np.zeros((4, 4), int), box=1)
    with pytest.raises(ValueError, match="box=5 is larger"):
        basin_entropy(np.zeros((4, 40), int), box=5)
    with pytest.raises(ValueError, match="integer array"):
        basin_entropy(np.zeros((10, 10)), box=2)
    with pytest.raises(ValueError, match="f_uncertain must lie in"):
        uncertainty_exponent([1e-3, 1e-2, 1e-1], [0.0, 0.1, 0.2])
    with pytest.raises(ValueError, match="at least 3"):
        uncertainty_exponent([1e-3, 1e-2], [0.01, 0.1])
    with pytest.raises(ValueError, match="n_samples"):
        uncertainty_exponent([1e-3, 1e-2, 1e-1], [0.01, 0.1, 0.5], n_samples=0)
    with pytest.raises(ValueError, match="one label per point"):
        uncertain_fraction(lambda p: np.zeros(3), [0, 0], [1, 1], [0.1], n_samples=5)
    with pytest.raises(ValueError, match="low < high"):
        uncertain_fraction(_half_plane, [0, 0], [1, 0], [0.1])


def test_a_grid_with_an_axis_of_one_cell_has_no_basin_entropy():
    """Boxes of the basin entropy need two cells a side: a grid with an axis of one cell
    gets its analysis and no entropy (instead of an error after the whole analysis)."""
    grid = jg.CellGrid.box([(-2, 2), (-2, 2)], (1, 4), names=("x", "v"))
    r = jg.analyze_global(jg.DUFFING, jg.DuffingParams(delta=0.5, alpha=-1.0, beta=1.0, gamma=0.0, omega=1.0), grid,
                          method=jg.Direct(integrator=jg.RK4(64)), progress=False, uncertainty=0)
    assert r.basin_entropy is None and sum(a.share for a in r.attractors) == 1.0
