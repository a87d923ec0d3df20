"""Basin shares over two parameters (jaxgear.basin_map).

References that do not come from the map's code:
- the Duffing oscillator integrated by scipy from every cell centre (the label of each
  cell) and its harmonic balance (how many P-1 motions coexist), written in the tests;
- the global analysis at each parameter point alone (analyze_global: the map assembles
  these, ids matched across the grid);
- a basin sweep along one parameter (a row of the map, whose ids come from the left
  neighbours only, is that sweep);
- hand-built attractor sets whose global ids are known (the matching over the grid);
- an uninterrupted run (kill-and-resume).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import jaxgear as jg
from jaxgear import Attractor, basin_map, basin_sweep
from jaxgear.sweep import _basins as basins_module
from jaxgear.sweep import match_on_grid

QUIET = jg.Runner(progress=False)  # nothing written, no progress bars

DUFF = dict(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3)
GRID = jg.CellGrid.box([(-3, 3), (-3, 3)], (10, 10), names=("x", "v"))
METHOD = jg.Direct(integrator=jg.RK4(64), max_period=4)
OMEGA = [1.0, 1.3, 1.4]  # one attractor at 1.0, two (the hysteresis interval) at 1.3 and 1.4
GAMMA = [0.25, 0.3]


def _duffing_map(uncertainty: int):
    return basin_map(jg.DUFFING, jg.DuffingParams(**DUFF, omega=1.3), "omega", OMEGA, "gamma", GAMMA, GRID,
                     method=METHOD, runner=QUIET, uncertainty=uncertainty)


@pytest.fixture(scope="module")
def duffing_map():
    """The map without label uncertainties (the checks below read labels, shares and ids)."""
    return _duffing_map(uncertainty=0)


def _assert_point_is(m, iy, ix, r):
    """The map's point ``(iy, ix)`` holds the analysis ``r``: the same partition of the
    cells (local id <-> global id one to one), shares, periods, sink and unresolved."""
    lut = {}
    for a, b in zip(np.asarray(r.labels).ravel(), m.labels[iy, ix].ravel()):
        assert lut.setdefault(int(a), int(b)) == int(b)
    assert len(set(lut.values())) == len(lut)
    assert int(m.present[iy, ix].sum()) == len(r.attractors)
    for a in r.attractors:
        g = lut[a.id]
        assert m.shares[iy, ix, g] == a.share and m.period[iy, ix, g] == a.period
        assert m.multiplier[iy, ix, g] == a.multiplier
    assert m.sink_share[iy, ix] == r.n_sink / r.n_cells
    assert m.unresolved_share[iy, ix] == r.n_unresolved / r.n_cells
    assert m.uncertainty_step[iy, ix] == r.uncertainty.step
    assert m.uncertainty_start[iy, ix] == r.uncertainty.start


@pytest.mark.slow
def test_every_point_is_the_analysis_there_alone():
    """Each point of the map, label uncertainties included, is the analysis there alone."""
    m = _duffing_map(uncertainty=100)
    assert m.shares.shape[:2] == (2, 3) and m.labels.shape == (2, 3, 10, 10)
    np.testing.assert_allclose(m.shares.sum(-1) + m.sink_share + m.unresolved_share, 1.0)
    assert m.coexisting.tolist() != [[m.coexisting[0, 0]] * 3] * 2  # the number of attractors varies
    for iy, gamma in enumerate(GAMMA):
        for ix, omega in enumerate(OMEGA):
            r = jg.analyze_global(jg.DUFFING, jg.DuffingParams(**dict(DUFF, gamma=gamma), omega=omega), GRID,
                                  METHOD, progress=False, uncertainty=100)
            _assert_point_is(m, iy, ix, r)


def _harmonic_balance_amplitudes(delta, alpha, beta, gamma, omega):
    """Amplitudes A of the one-harmonic solutions x = A cos(omega t - phi) of
    x'' + delta x' + alpha x + beta x^3 = gamma cos(omega t): the positive roots z = A^2 of
    z [(alpha - omega^2 + 3/4 beta z)^2 + (delta omega)^2] = gamma^2 (Nayfeh & Mook,
    Nonlinear Oscillations, §4.1). Three roots: the middle one is the saddle."""
    a, k = alpha - omega**2, 0.75 * beta
    z = np.roots([k * k, 2 * a * k, a * a + (delta * omega) ** 2, -gamma**2])
    return np.sqrt(np.sort(z[(np.abs(z.imag) < 1e-9) & (z.real > 0)].real))


def test_every_cell_is_labelled_by_where_its_motion_goes(duffing_map):
    """An independent reference: scipy integrates the Duffing oscillator from every cell
    centre at every point of the map (60 forcing periods, all in one call, in the phase
    omega t), and each cell's label is the global id of the attractor its motion ends on.
    The number of coexisting attractors is that of the stable one-harmonic motions of
    harmonic balance (one, or two around a saddle)."""
    from scipy.integrate import solve_ivp

    m = duffing_map
    X0 = GRID.centres()
    n_cells = len(X0)
    w = np.repeat(np.tile(OMEGA, len(GAMMA)), n_cells)  # (points x cells), gamma major as in the map
    g = np.repeat(np.repeat(GAMMA, len(OMEGA)), n_cells)
    n = len(w)
    d, al, be = DUFF["delta"], DUFF["alpha"], DUFF["beta"]

    def field(phase, y):  # d/d(omega t) of (x, v)
        x, v = y[:n], y[n:]
        return np.concatenate([v / w, (g * np.cos(phase) - d * v - al * x - be * x**3) / w])

    periods = 60
    y0 = np.concatenate([np.tile(X0[:, 0], len(w) // n_cells), np.tile(X0[:, 1], len(w) // n_cells)])
    sol = solve_ivp(field, (0.0, 2 * np.pi * periods), y0, method="DOP853", rtol=1e-7, atol=1e-9)
    assert sol.success, sol.message
    end = np.stack([sol.y[:n, -1], sol.y[n:, -1]], -1).reshape(len(GAMMA), len(OMEGA), n_cells, 2)
    for iy, gamma in enumerate(GAMMA):
        for ix, omega in enumerate(OMEGA):
            amplitudes = _harmonic_balance_amplitudes(d, al, be, gamma, omega)
            ids = np.flatnonzero(m.present[iy, ix])
            assert len(ids) == (2 if len(amplitudes) == 3 else 1), (gamma, omega, amplitudes)
            assert (m.period[iy, ix, ids] == 1).all()
            dist = np.stack([np.linalg.norm(end[iy, ix][:, None] - m.points[iy, ix, i, :m.n_points[iy, ix, i]][None],
                                            axis=-1).min(axis=1) for i in ids], axis=1)  # (cells, attractors)
            assert dist.min(axis=1).max() < 1e-2, (gamma, omega)  # every motion has settled on one of them
            np.testing.assert_array_equal(m.labels[iy, ix].ravel(), ids[dist.argmin(axis=1)],
                                          err_msg=f"gamma={gamma}, omega={omega}")
    assert m.coexisting.tolist() == [[1, 2, 2], [1, 2, 2]]


def test_a_row_is_a_basin_sweep(duffing_map):
    """The first row's ids come from left neighbours only: it is the basin sweep along x,
    ids included; the ids of the next row continue those of the first (the P-1 branches
    of the Duffing move little between the two amplitudes)."""
    m = duffing_map
    s = basin_sweep(jg.DUFFING, jg.DuffingParams(**dict(DUFF, gamma=GAMMA[0]), omega=1.3), "omega", OMEGA, GRID,
                    method=METHOD, runner=QUIET, uncertainty=0)
    G = s.n_attractors
    np.testing.assert_array_equal(m.labels[0], s.labels)
    np.testing.assert_array_equal(m.shares[0, :, :G], s.shares)
    assert not m.present[0, :, G:].any()
    assert m.n_attractors == G  # the second row finds no attractor the first did not


def _results(*points):
    """Fake analyses: one per parameter point, each a list of attractor point sets."""
    out = []
    for atts in points:
        a = tuple(Attractor(id=i, period=len(p), points=np.asarray(p, float), section_points=np.zeros((0, 2)),
                            cell_count=1, share=0.5, residual=0.0, periodic_cells=np.zeros(0, np.int64))
                  for i, p in enumerate(atts))
        out.append(type("R", (), {"attractors": a})())
    return out


def test_ids_come_from_the_left_and_the_lower_neighbour():
    """On a 2 x 2 grid: D appears at (0, 1) and is found again at (1, 1) through the lower
    neighbour only (the left one, (1, 0), lacks it); A, present everywhere, keeps one id
    though both neighbours hold it; E, far from everything, gets the next id."""
    A, D, E = [[0.0, 0.0]], [[5.0, 5.0]], [[9.0, -9.0]]
    near = lambda p: [[x + 0.05 for x in q] for q in p]  # noqa: E731
    res = _results([A], [A, D], [near(A)], [E, near(D), near(A)])
    ids = match_on_grid(res, ny=2, nx=2, match_tol=0.5)
    assert [g.tolist() for g in ids] == [[0], [0, 1], [0], [2, 1, 0]]
    # by the left neighbour alone (one row), D at the end would be new
    assert match_on_grid([res[2], res[3]], ny=1, nx=2, match_tol=0.5)[1].tolist() == [1, 2, 0]


@pytest.mark.slow
def test_kill_and_resume(tmp_path, monkeypatch):
    class Kill(BaseException):
        pass

    p = jg.DuffingParams(**DUFF, omega=1.3)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (5, 5), names=("x", "v"))
    kw = dict(method=jg.Direct(integrator=jg.RK4(32), max_period=4), uncertainty=0)
    args = ("omega", [1.3, 1.4], "gamma", [0.25, 0.3], grid)
    run = jg.Runner(out=tmp_path / "run", progress=False)
    basin_map(jg.DUFFING, p, *args, runner=jg.Runner(out=tmp_path / "full", progress=False), **kw)
    real, calls, kill = basins_module._analyze_values, [], [True]

    def analyze(system, params_list, *a, **k):
        calls.append([(float(q.omega), float(q.gamma)) for q in params_list])
        if kill[0] and len(calls) == 2:
            raise Kill()
        return real(system, params_list, *a, **k)

    monkeypatch.setattr(basins_module, "_analyze_values", analyze)
    monkeypatch.setattr(basins_module, "BLOCK_CELLS", 2 * grid.n_cells)  # blocks of two points: a row
    with pytest.raises(Kill):
        basin_map(jg.DUFFING, p, *args, runner=run, **kw)
    assert calls == [[(1.3, 0.25), (1.4, 0.25)], [(1.3, 0.3), (1.4, 0.3)]]
    calls.clear()
    kill[0] = False
    run.run(basin_map, jg.DUFFING, p, *args, **kw)
    assert calls == [[(1.3, 0.3), (1.4, 0.3)]]  # the killed block only
    import xarray as xr

    with xr.open_dataset(tmp_path / "full" / "basin_map.nc", engine="h5netcdf") as a, \
            xr.open_dataset(tmp_path / "run" / "basin_map.nc", engine="h5netcdf") as b:
        assert a.identical(b)
    loaded = jg.load(tmp_path / "run" / "basin_map.nc", expected="BasinMap")
    assert loaded.coords_xy == ("omega", "gamma") and loaded.labels.shape == (2, 2, 5, 5)
    with pytest.raises(ValueError, match="values_x|omega"):  # the same folder, other values
        basin_map(jg.DUFFING, p, "omega", [1.3, 1.5], "gamma", [0.25, 0.3], grid, runner=run, **kw)


def test_bad_input():
    p = jg.paper_params()
    grid = jg.CellGrid.paper((2, 2, 2))
    with pytest.raises(ValueError, match="same field"):
        basin_map(jg.REDUCED, p, "b", [4, 5], "b_sp", [4, 5], grid)
    with pytest.raises(ValueError, match="empty"):
        basin_map(jg.REDUCED, p, "b", [4, 5], "kappa_amp", [], grid)
    with pytest.raises(ValueError, match="valid names"):
        basin_map(jg.REDUCED, p, "b", [4, 5], "backlash", [1, 2], grid)
    with pytest.raises(ValueError, match="b_sp"):  # a negative backlash, named
        basin_map(jg.REDUCED, p, "b", [-1, 5], "kappa_amp", [0.3, 0.4], grid)


def test_figures(duffing_map):
    from jaxgear import plotting

    m = duffing_map
    fig = plotting.plot_basin_map(m)
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == [f"{g}: {m.attractor_label(g)}" for g in sorted(set(m.dominant.ravel().tolist()))]
    assert len(ax.texts) == m.dominant.size  # the share written in every box
    # the count panel: one shade per count, darker for more, none an attractor's colour (those name ids)
    from matplotlib.collections import QuadMesh
    from matplotlib.colors import to_hex, to_rgb

    from jaxgear.plotting import attractor_color

    mesh = next(c for c in fig.axes[1].collections if isinstance(c, QuadMesh))
    shades = [to_rgb(c) for c in mesh.get_cmap().colors]
    assert len(shades) == m.coexisting.max() + 1 >= 3
    luminance = [0.2126 * r + 0.7152 * g + 0.0722 * b for r, g, b in shades]
    assert all(a > b for a, b in zip(luminance, luminance[1:]))
    assert not {to_hex(c) for c in shades} & {to_hex(attractor_color(g)) for g in range(10)}
    fig = plotting.plot_basin_map(m, "all")
    assert [a.get_title() for a in fig.axes if a.get_visible() and a.get_title()] == [
        f"{g}: {m.attractor_label(g)}" for g in range(m.n_attractors)]
    for bad in (m.n_attractors, -1, "dominant", True, 1.0):
        with pytest.raises(ValueError, match="global id"):
            plotting.plot_basin_map(m, bad)


def test_where_the_sink_or_unresolved_cells_hold_most(duffing_map):
    """``dominant`` is -1 where the sink holds more cells than any attractor, -2 where the
    unresolved cells (a chaotic motion, say) hold more than the sink and every attractor;
    the table and the overview figure name them."""
    from jaxgear import plotting

    m = duffing_map
    assert m.n_attractors >= 2
    shares = np.zeros_like(m.shares[..., :2])  # two attractors
    sink, unres = np.zeros_like(m.sink_share), np.zeros_like(m.unresolved_share)
    unres[0, 0] = 1.0  # all unresolved
    shares[0, 1, 0], sink[0, 1], unres[0, 1] = 0.3, 0.4, 0.3  # the sink ahead
    shares[0, 2, 0], unres[0, 2] = 0.55, 0.45  # an attractor ahead
    shares[1, :, 1] = 1.0
    period = np.where(shares > 0, 1, -1)
    fake = dataclasses.replace(m, shares=shares, sink_share=sink, unresolved_share=unres, period=period,
                               points=m.points[:, :, :2], n_points=m.n_points[..., :2])
    assert fake.dominant.tolist() == [[-2, -1, 0], [1, 1, 1]]
    rows = {line.split()[0]: line.split() for line in fake.table().splitlines()[2:]}
    assert rows["unresolved"][3] == "1" and rows["sink"][3] == "1"  # "largest at" one point each
    ax = plotting.plot_basin_map(fake).axes[0]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["unresolved", "sink", f"0: {fake.attractor_label(0)}",
                                                                   f"1: {fake.attractor_label(1)}"]
    assert ax.texts[0].get_text() == "100" and ax.texts[1].get_text() == "40"  # their shares, in their boxes


@pytest.mark.slow
def test_cli(tmp_path, capsys):
    from jaxgear.cli import main

    out = tmp_path / "map"
    rc = main(["sweep", "--param", "kappa_amp", "--values", "0.36:0.37:2", "--param2", "b", "--values2", "4:5:2",
               "--kind", "basins", "--grid", "3,2,3", "--steps-per-period", "50", "--max-period", "8",
               "--out", str(out), "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "largest at" in text and "basin_map.nc" in text
    m = jg.load(out / "basin_map.nc", expected="BasinMap")
    assert m.labels.shape == (2, 2, 3, 2, 3) and m.fields_x == ("kappa_sp_amp", "kappa_rp_amp")
    assert m.fields_y == ("b_sp", "b_rp")
    assert (out / "basin_map.png").is_file() and (out / "basin_map_shares.png").is_file()
    summary = json.loads((out / "summary.json").read_text())  # the per-point arrays, NaN as null
    for f in ("shares", "multiplier", "sink_share", "unresolved_share", "uncertainty_step", "uncertainty_start"):
        np.testing.assert_array_equal(np.array(summary[f], dtype=float), getattr(m, f), err_msg=f)
    regimes = summary["contact_regimes"]  # the gear views of every point: regime shares per mesh, and the figure
    assert np.shape(regimes["shares"]) == (2, 2, 2, 3) and np.shape(regimes["dominant_regime"]) == (2, 2, 2)
    np.testing.assert_allclose(np.sum(regimes["shares"], axis=-1) + np.asarray(regimes["no_attractor"])[..., None],
                               1.0, atol=1e-12)
    assert (out / "regimes.png").is_file() and "dominant at" in text
    assert main(["sweep", "--param", "b", "--values", "4:5:2", "--param2", "b_sp", "--values2", "4:5:2",
                 "--kind", "basins", "--out", str(tmp_path / "x")]) == 2
    assert "same field" in capsys.readouterr().err
    assert main(["sweep", "--param", "b", "--values", "4:5:2", "--param2", "kappa_amp", "--out",
                 str(tmp_path / "y")]) == 2
    assert "--values2" in capsys.readouterr().err
