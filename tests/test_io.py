"""Saved results: save -> load round trips exactly (arrays bit-for-bit with their dtypes,
metadata equal), ``jaxgear.load`` dispatches on the file's type, files open as labelled
arrays with xarray, and every plotting function draws from a loaded result without
integrating anything (the integration kernels are replaced by functions that raise)."""

import dataclasses
import json
import warnings

import numpy as np
import pytest
import xarray as xr

import jaxgear as jg
from jaxgear import CellGrid

DOUBLE_WELL = jg.DuffingParams(delta=0.5, alpha=-1.0, beta=1.0, gamma=0.0, omega=1.0)
BISTABLE_DUFFING = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)
# unstable P-1 of the paper preset (found by shooting; multipliers -1.81, -0.42, 0.31 +- 0.21i)
PAPER_P1 = np.array([5.579052199612337, -0.6199479424748091, 10.674852626381336, -0.2538837950512047])


def assert_same(a, b, where="result"):
    """Recursive exact equality: arrays bit-for-bit (NaN where NaN) with equal dtypes."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype, f"{where}: dtype {a.dtype} != {b.dtype}"
        assert a.shape == b.shape, f"{where}: shape {a.shape} != {b.shape}"
        if a.dtype.kind in "fc":
            assert np.array_equal(a.view(np.uint8), b.view(np.uint8)) or np.array_equal(a, b, equal_nan=True), where
            assert np.array_equal(np.signbit(a.real), np.signbit(b.real)), f"{where}: signed zeros differ"
        else:
            assert np.array_equal(a, b), where
    elif dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, tuple) and hasattr(a, "_fields"):  # NamedTuple
        assert type(a) is type(b), where
        for name, x, y in zip(a._fields, a, b):
            assert_same(x, y, f"{where}.{name}")
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for k in a:
            assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), where
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"


def _quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


# ---------------------------------------------------------------- results to save
@pytest.fixture(scope="module")
def duffing_results():
    """Double-well Duffing, one result per method (2 x P-1 each)."""
    g2 = CellGrid.box([(-2, 2), (-2, 2)], (6, 5), names=("x", "v"))
    g1 = CellGrid.box([(-2, 2)], (8,), axes=(0,), base=(0.0, 0.0), names=("x", "v"))
    return {
        "direct": _quiet(jg.analyze_global, jg.DUFFING, DOUBLE_WELL, g2, method="direct", progress=False),
        "stroboscopic": _quiet(jg.analyze_global, jg.DUFFING, DOUBLE_WELL, g2, method="stroboscopic",
                               settle_periods=50, progress=False),
        "poincare-like": _quiet(jg.analyze_global, jg.DUFFING, DOUBLE_WELL, g1, method="poincare-like",
                                mapping_steps=3, settle_periods=50, progress=False),
    }


@pytest.fixture(scope="module")
def paper_result():
    """The paper preset's P-4 by the paper's method on a 3 x 2 x 3 grid of region D."""
    return _quiet(jg.analyze_global, jg.REDUCED, jg.paper_params(), CellGrid.paper(counts=(3, 2, 3)),
                  method="poincare-like", mapping_steps=20, settle_periods=300, progress=False)


@pytest.fixture(scope="module")
def duffing_search():
    """Three P-1 orbits (two stable, a saddle), seeds shot for k = 1 and 2, some failing."""
    seeds = np.array([[1.0, 1.1], [-0.3, 0.1], [-0.85, 0.64], [40.0, -40.0], [0.9, 1.0]])
    return jg.find_periodic_orbits(jg.DUFFING, BISTABLE_DUFFING, seeds, period=(1, 2), chunk_size=2,
                                   max_iter=12, progress=False, trajectory_samples=40)


@pytest.fixture(scope="module")
def paper_search():
    seeds = np.array([PAPER_P1 + 1e-3, PAPER_P1 - 2e-3, [20.0, 10.0, 40.0, 3.0]])
    return jg.find_periodic_orbits(jg.REDUCED, jg.paper_params(), seeds, period=1, max_iter=15, progress=False,
                                   trajectory_samples=50)


# ---------------------------------------------------------------- round trips
@pytest.mark.parametrize("method", ["direct", "stroboscopic", "poincare-like"])
def test_global_result_round_trip_exact(duffing_results, method, tmp_path):
    r = duffing_results[method]
    assert r.method == method and sorted(a.period for a in r.attractors) == [1, 1]
    path = r.save(tmp_path / "r.nc")
    assert_same(jg.load_result(path), r)
    assert_same(jg.load(path), r)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.nc"]  # no temporary file left behind


def test_paper_result_round_trip_exact_and_labelled(paper_result, tmp_path):
    r = paper_result
    assert [a.period for a in r.attractors] == [4]
    path = r.save(tmp_path / "sub" / "paper.nc")  # parent folders are created
    q = jg.load(path)
    assert_same(q, r)
    assert q.params == jg.paper_params().to_dict()
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["jaxgear_type"] == "GlobalResult"
        assert ds["labels"].dims == ("x1", "x2", "x3")  # coordinates named after the state variables
        np.testing.assert_array_equal(ds["x3"].values, r.grid.axis_centres(2))
        assert list(ds["state"].values) == ["x1", "x2", "x3", "x4"]
        assert json.loads(ds.attrs["params"]) == jg.paper_params().to_dict()
        for name, v in jg.paper_params().to_dict().items():  # the canonical set, one attribute each
            assert ds.attrs[f"param_{name}"] == v
        assert ds.attrs["system"] == jg.REDUCED.name and ds.attrs["version"] == jg.__version__


def test_orbit_search_round_trip_exact(duffing_search, tmp_path):
    s = duffing_search
    assert [o.period for o in s.orbits] == [1, 1, 1] and [o.stable for o in s.orbits].count(False) == 1
    st = s.shots[1].status
    assert np.any(st == jg._shooting.SHOOT_CONVERGED) and np.any(st != jg._shooting.SHOOT_CONVERGED)
    assert all(o.trajectory.shape == (41, 2) for o in s.orbits)
    path = s.save(tmp_path / "orbits.nc")
    assert_same(jg.load_orbits(path), s)
    assert_same(jg.load(path), s)
    # the stored multipliers are the complex numbers themselves, not only their moduli
    q = jg.load(path)
    assert all(o.multipliers.dtype == np.complex128 for o in q.orbits)
    assert any(np.any(o.multipliers.imag != 0) for o in q.orbits)  # the stable foci: a complex pair


def test_empty_orbit_search_round_trip(tmp_path):
    s = jg.find_periodic_orbits(jg.DUFFING, BISTABLE_DUFFING, np.array([[40.0, -40.0]]), max_iter=2, progress=False)
    assert s.orbits == ()
    assert_same(jg.load(s.save(tmp_path / "none.nc")), s)


def test_paper_orbit_search_labelled(paper_search, tmp_path):
    s = paper_search
    assert len(s.orbits) == 1 and s.orbits[0].instability == "flip" and s.orbits[0].period == 1
    path = s.save(tmp_path / "o.nc")
    assert_same(jg.load(path), s)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["jaxgear_type"] == "OrbitSearch"
        assert list(ds["state"].values) == list(jg.REDUCED.state_names)
        assert ds["points"].dims == ("orbit", "point", "state")
        np.testing.assert_array_equal(ds["points"].sel(state="x3").values[0, :1], s.orbits[0].points[:, 2])
        assert json.loads(ds.attrs["params"]) == jg.paper_params().to_dict()
        assert ds.attrs["param_Omega"] == jg.paper_params().to_dict()["Omega"]
        assert str(ds["instability"].values[0]) == "flip"


def test_save_overwrites_atomically(duffing_results, tmp_path):
    a, b = duffing_results["direct"], duffing_results["stroboscopic"]
    path = tmp_path / "r.nc"
    a.save(path)
    b.save(path)
    assert_same(jg.load(path), b)
    assert [p.name for p in tmp_path.iterdir()] == ["r.nc"]


# ---------------------------------------------------------------- jaxgear.load
def test_load_reads_files_without_jaxgear_type(duffing_results, tmp_path):
    r = duffing_results["direct"]
    ds = r.to_xarray()
    del ds.attrs["jaxgear_type"]  # as written by jaxgear 0.1
    ds.to_netcdf(tmp_path / "old.nc", engine="h5netcdf")
    assert_same(jg.load(tmp_path / "old.nc"), r)
    assert_same(jg.load_result(tmp_path / "old.nc"), r)


def test_load_errors_name_the_problem(duffing_results, duffing_search, tmp_path, monkeypatch):
    from jaxgear._io import LOADERS

    with pytest.raises(FileNotFoundError):
        jg.load(tmp_path / "missing.nc")
    xr.Dataset({"a": ("i", np.arange(3))}).to_netcdf(tmp_path / "foreign.nc", engine="h5netcdf")
    with pytest.raises(ValueError, match="not written by jaxgear"):
        jg.load(tmp_path / "foreign.nc")
    xr.Dataset(attrs={"jaxgear_type": "Nonsense"}).to_netcdf(tmp_path / "bad.nc", engine="h5netcdf")
    with pytest.raises(ValueError, match="unknown jaxgear_type 'Nonsense'"):
        jg.load(tmp_path / "bad.nc")
    # a type whose module is not part of this build (e.g. sweeps in a build without them):
    # the error names the module
    monkeypatch.setitem(LOADERS, "Future", "jaxgear._not_in_this_build:load_future")
    xr.Dataset(attrs={"jaxgear_type": "Future"}).to_netcdf(tmp_path / "future.nc", engine="h5netcdf")
    with pytest.raises(ImportError, match=r"jaxgear\._not_in_this_build"):
        jg.load(tmp_path / "future.nc")
    # a typed loader refuses the other type
    duffing_search.save(tmp_path / "orbits.nc")
    with pytest.raises(ValueError, match="OrbitSearch"):
        jg.load_result(tmp_path / "orbits.nc")
    duffing_results["direct"].save(tmp_path / "r.nc")
    with pytest.raises(ValueError, match="GlobalResult"):
        jg.load_orbits(tmp_path / "r.nc")


def test_registry_matches_the_convention():
    from jaxgear._io import LOADERS

    assert LOADERS == {
        "GlobalResult": "jaxgear._result:load_result", "OrbitSearch": "jaxgear._shooting:load_orbits",
        "BifurcationDiagram": "jaxgear._sweep:load_bifurcation", "BasinSweep": "jaxgear._sweep:load_basin_sweep",
        "ParameterMap": "jaxgear._sweep:load_parameter_map", "Branch": "jaxgear._continuation:load_branch",
        "DesignResult": "jaxgear._design:load_design",
    }


# ---------------------------------------------------------------- plotting from disk
@pytest.fixture
def no_integration(monkeypatch):
    """Every integration entry point raises: a figure drawn now used stored data only."""
    import jaxgear._cellmap as cm
    import jaxgear._integrate as it
    import jaxgear._poincare as pc
    import jaxgear._shooting as sh
    import jaxgear.plotting._orbit as po

    def boom(*a, **k):
        raise AssertionError("integration during plotting")

    for mod, names in ((it, ("advance", "advance_batch", "sample", "rk4_step_batch")),
                       (pc, [n for n in dir(pc) if "kernel" in n] + ["stroboscopic_map", "stroboscopic_orbit",
                                                                   "section_map", "sample_trajectory"]),
                       (sh, ("_shoot_kernel", "_monodromy_kernel", "_flow", "sample_trajectory",
                             "stroboscopic_orbit")),
                       (cm, ("_strobe_chunk", "_direct_round", "_section_kernel", "sample_trajectory", "section_map",
                             "stroboscopic_orbit")),
                       (po, ("sample_trajectory",)),
                       (jg, ("advance", "stroboscopic_map", "stroboscopic_orbit", "section_map", "sample_trajectory"))):
        for n in names:
            if hasattr(mod, n):
                monkeypatch.setattr(mod, n, boom)


def test_no_integration_fixture_is_effective(no_integration):
    from jaxgear.plotting import plot_orbit

    with pytest.raises(AssertionError, match="integration during plotting"):
        plot_orbit(jg.DUFFING, BISTABLE_DUFFING, np.array([[1.0, 1.1]]))  # bare points: must integrate
    with pytest.raises(AssertionError, match="integration during plotting"):
        jg.stroboscopic_map(jg.DUFFING, BISTABLE_DUFFING, np.zeros(2))


def test_basin_figures_from_a_loaded_result(paper_result, tmp_path, no_integration):
    from jaxgear import plotting

    r = paper_result
    q = jg.load(r.save(tmp_path / "r.nc"))
    fig = plotting.plot_domains(q, axis="x3", n_slices=3)
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert len(panels) == 3 and all(len(ax.images) == 1 for ax in panels)
    orig = plotting.plot_domains(r, axis="x3", n_slices=3)
    for a, b in zip(panels, orig.axes):
        np.testing.assert_array_equal(a.images[0].get_array(), b.images[0].get_array())
    fig = plotting.plot_domains_3d(q)
    assert len(fig.axes) == 1 and fig.axes[0].name == "3d"
    assert len(fig.axes[0].collections) == 2  # the P-4's domain and its periodic cells
    fig = plotting.plot_attractors(q, section=True)
    assert fig.axes[0].name == "3d" and len(fig.axes[0].collections) == len(q.attractors)
    fig = plotting.plot_shares(q)
    assert len(fig.axes[0].patches) == len(q.attractors) + 1  # one bar per attractor and the sink
    assert fig.axes[0].patches[0].get_height() == pytest.approx(100 * q.attractors[0].share)


def test_orbit_figures_from_a_loaded_search(paper_search, duffing_search, tmp_path, no_integration):
    from jaxgear.plotting import plot_multipliers, plot_orbit

    q = jg.load(paper_search.save(tmp_path / "o.nc"))
    o = q.orbits[0]
    fig = plot_orbit(q, 0, coords=(0, 1, 2))  # from the search alone: no system, no parameters
    ax = fig.axes[0]
    assert ax.name == "3d" and len(ax.lines) == 1
    xs, ys, zs = ax.lines[0].get_data_3d()
    np.testing.assert_array_equal(np.stack([xs, ys, zs], -1), o.trajectory[:, :3])
    assert len(ax.collections) == 2  # stroboscopic points and crossings of x4 = 0
    fig = plot_orbit(jg.REDUCED, jg.paper_params(), o, coords=(0, 2))  # the stored trajectory is used
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_xydata(), o.trajectory[:, [0, 2]])
    d = jg.load(duffing_search.save(tmp_path / "d.nc"))
    fig = plot_multipliers(d)
    ax = fig.axes[0]
    assert len(ax.collections) == len(d.orbits)
    for coll, orb in zip(ax.collections, d.orbits):
        np.testing.assert_array_equal(coll.get_offsets(), np.stack([orb.multipliers.real, orb.multipliers.imag], -1))
    circle = ax.lines[0].get_xydata()
    np.testing.assert_allclose(np.hypot(circle[:, 0], circle[:, 1]), 1.0)
