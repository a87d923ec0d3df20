"""Saved results: save -> load round trips exactly (arrays bit-for-bit with their dtypes,
metadata equal), ``jaxgear.load`` dispatches on the file's type, files open as labelled
arrays with xarray, and every plotting function draws from a loaded result without
integrating anything (the integration kernels are replaced by functions that raise)."""

import ast
import dataclasses
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import jaxgear as jg
from jaxgear import CellGrid
from jaxgear._codec import FORMAT, RESULT_TYPES, array_field, custom_field, from_dataset, items_field, to_dataset
from jaxgear.analysis import LabelUncertainty
from jaxgear.integrate import integrator_from_dict

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
            assert np.array_equal(a.reshape(-1).view(np.uint8), b.reshape(-1).view(np.uint8)) \
                or np.array_equal(a, b, equal_nan=True), where
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
    """Double-well Duffing, one result per method (2 x P-1 each); the stroboscopic one carries
    a label uncertainty (its fields round-trip too: values of the kind a measurement gives,
    set here, since the codec and not the measurement is checked; tests/test_attractors.py,
    test_cli_analyze.py and test_sweep.py measure it)."""
    g2 = CellGrid.box([(-2, 2), (-2, 2)], (6, 5), names=("x", "v"))
    g1 = CellGrid.box([(-2, 2)], (8,), axes=(0,), base=(0.0, 0.0), names=("x", "v"))
    strobe = _quiet(jg.analyze_global, jg.DUFFING, DOUBLE_WELL, g2, method=jg.StroboscopicCellMap(settle_periods=50),
                    progress=False, uncertainty=0)
    u = LabelUncertainty(samples=30, step=1 / 30, start=2 / 30, perturbation=1e-3,
                         refined_integrator=strobe.method.integrator.refined(),
                         perturbations=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8),
                         start_fractions=(2 / 30, 2 / 30, 1 / 30, 1 / 30, 1 / 30, 0.0), alpha=0.3141592653589793,
                         alpha_error=0.02718281828459045, alpha_range=(1e-7, 1e-3), alpha_chi2=0.7071067811865476)
    return {
        "direct": _quiet(jg.analyze_global, jg.DUFFING, DOUBLE_WELL, g2, method=jg.Direct(), progress=False,
                         uncertainty=0),
        "stroboscopic": dataclasses.replace(strobe, uncertainty=u),
        "poincare-like": _quiet(jg.analyze_global, jg.DUFFING, DOUBLE_WELL, g1, method=jg.PoincareCellMap(mapping_steps=3, settle_periods=50),
                                progress=False, uncertainty=0),
    }


@pytest.fixture(scope="module")
def paper_result():
    """The paper preset's P-4 by the paper's method on a 3 x 2 x 3 grid of region D. Plain
    RK4: the file format, not the accuracy at the kinks, is checked here (a third of the
    kink-aware section's time)."""
    method = jg.PoincareCellMap(mapping_steps=20, settle_periods=300, integrator=jg.RK4(200))
    return _quiet(jg.analyze_global, jg.REDUCED, jg.paper_params(), CellGrid.paper(counts=(3, 2, 3)),
                  method=method, progress=False, uncertainty=0)


@pytest.fixture(scope="module")
def duffing_search():
    """Three P-1 orbits (two stable, a saddle), seeds shot for k = 1 and 2, some failing."""
    seeds = np.array([[1.0, 1.1], [-0.3, 0.1], [-0.85, 0.64], [40.0, -40.0], [0.9, 1.0]])
    return jg.find_periodic_orbits(jg.DUFFING, BISTABLE_DUFFING, seeds, period=(1, 2), chunk_size=2,
                                   max_iter=12, progress=False, trajectory_samples=40)


@pytest.fixture(scope="module")
def paper_search():
    seeds = np.array([PAPER_P1 + 1e-3, PAPER_P1 - 2e-3, [20.0, 10.0, 40.0, 3.0]])
    # plain RK4 (the file format, not the accuracy at the kinks, is checked here): a fraction of
    # the kink-aware step's compile time
    return jg.find_periodic_orbits(jg.REDUCED, jg.paper_params(), seeds, period=1, max_iter=15, progress=False,
                                   trajectory_samples=50, integrator=jg.RK4(200))


# ---------------------------------------------------------------- round trips
@pytest.mark.parametrize("method", ["direct", "stroboscopic", "poincare-like"])
def test_global_result_round_trip_exact(duffing_results, method, tmp_path):
    r = duffing_results[method]
    assert r.method.name == method and sorted(a.period for a in r.attractors) == [1, 1]
    path = r.save(tmp_path / "r.nc")
    assert_same(jg.load(path), r)
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
        assert ds.attrs["jaxgear_format"] == FORMAT == 5
        for name, v in jg.paper_params().to_dict().items():  # the canonical set, one attribute each
            assert ds.attrs[f"param_{name}"] == v
        assert ds.attrs["system"] == jg.REDUCED.name and ds.attrs["version"] == jg.__version__


def test_attractor_multipliers_are_those_of_shooting(duffing_results, paper_result):
    """Each attractor's recorded multiplier (central differences of the k-fold map) is the
    largest |multiplier| that jax.jacfwd gives through the shooting module, whatever the
    method (both through the integrator of the analysis); the attractors found are stable."""
    cases = [(r, jg.DUFFING, DOUBLE_WELL) for r in duffing_results.values()]
    cases.append((paper_result, jg.REDUCED, jg.paper_params()))
    for r, system, params in cases:
        for a in r.attractors:
            mu = np.asarray(jg.floquet_multipliers(system, params, np.asarray(a.points)[0], period=a.period,
                                                   integrator=r.method.integrator))
            assert a.multiplier == pytest.approx(np.abs(mu).max(), abs=1e-4), (r.method.name, a.id)
            assert a.multiplier < 1
    assert "max |mu|" in paper_result.table()


def test_a_file_written_before_a_field_existed_loads_with_its_default(duffing_results, tmp_path):
    """A result file without the attractors' multiplier (as written before it was recorded,
    a later field) loads, the multiplier NaN and everything else as saved; any other field
    a file lacks (here the result's mean periods) is an error, not a silent default."""
    r = duffing_results["direct"]
    path = r.save(tmp_path / "r.nc")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        gone = [v for v in ds.variables if str(v).endswith("__multiplier")]
        assert gone and "mean_periods" in ds.attrs
        old = ds.drop_vars(gone).load()
        broken = ds.load().copy()
        del broken.attrs["mean_periods"]
    old.to_netcdf(tmp_path / "old.nc", engine="h5netcdf")
    q = jg.load(tmp_path / "old.nc")
    assert all(np.isnan(a.multiplier) for a in q.attractors)
    assert not any(np.isnan(a.multiplier) for a in r.attractors) and q.mean_periods == r.mean_periods
    assert [a.share for a in q.attractors] == [a.share for a in r.attractors]
    np.testing.assert_array_equal(q.labels, r.labels)
    broken.to_netcdf(tmp_path / "broken.nc", engine="h5netcdf")
    with pytest.raises(ValueError, match="'mean_periods': missing"):
        jg.load(tmp_path / "broken.nc")


def test_the_uncertainty_exponents_range_round_trips_and_older_files_load_without_it(duffing_results, tmp_path):
    """The scaling range of the uncertainty exponent, its reduced chi^2 and the reason for
    no exponent round-trip exactly; a file written before they were recorded loads with
    them unknown (None, NaN) and its alpha (then fitted to every fraction) as saved."""
    r = duffing_results["stroboscopic"]
    u = r.uncertainty
    nan = float("nan")
    none = dataclasses.replace(r, uncertainty=dataclasses.replace(
        u, alpha=nan, alpha_error=nan, alpha_range=None, alpha_chi2=nan,
        alpha_reason="no scaling range: fewer than 4 nonzero fractions in a row over 3 decades"))
    for i, res in enumerate((r, none)):
        assert_same(jg.load(res.save(tmp_path / f"r{i}.nc")), res)
    assert "over start moves 1e-07 to 1e-03 cell (reduced chi^2 0.71)" in r.table()
    assert "uncertainty exponent: no scaling range: fewer than 4" in jg.load(tmp_path / "r1.nc").table()
    new = ("uncertainty__alpha_range", "uncertainty__alpha_chi2", "uncertainty__alpha_reason")
    with xr.open_dataset(tmp_path / "r0.nc", engine="h5netcdf") as ds:
        schema = json.loads(ds.attrs["jaxgear_schema"])
        assert all(k in ds.attrs or k in schema for k in new)
    old = _rewrite(tmp_path / "r0.nc", tmp_path / "old.nc", **dict.fromkeys(new),
                   jaxgear_schema=json.dumps({k: v for k, v in schema.items() if k not in new}))
    q = jg.load(old).uncertainty
    assert q.alpha_range is None and np.isnan(q.alpha_chi2) and q.alpha_reason is None
    assert_same(q, dataclasses.replace(u, alpha_range=None, alpha_chi2=nan))
    assert q.describe().endswith(f"alpha = {u.alpha:.2f} +- {u.alpha_error:.2f} (1: smooth boundary)")


def test_orbit_search_round_trip_exact(duffing_search, tmp_path):
    s = duffing_search
    assert [o.period for o in s.orbits] == [1, 1, 1] and [o.stable for o in s.orbits].count(False) == 1
    st = s.shots[1].status
    assert np.any(st == jg.Status.CONVERGED) and np.any(st != jg.Status.CONVERGED)
    assert all(o.trajectory.shape == (41, 2) for o in s.orbits)
    path = s.save(tmp_path / "orbits.nc")
    assert_same(jg.load(path), s)
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
        assert ds["orbits__points"].dims == ("orbit", "point", "state")
        np.testing.assert_array_equal(ds["orbits__points"].sel(state="x3").values[0, :1], s.orbits[0].points[:, 2])
        assert json.loads(ds.attrs["params"]) == jg.paper_params().to_dict()
        assert ds.attrs["param_Omega"] == jg.paper_params().to_dict()["Omega"]
        assert str(ds["orbits__instability"].values[0]) == "flip"


def test_save_overwrites_atomically(duffing_results, tmp_path):
    a, b = duffing_results["direct"], duffing_results["stroboscopic"]
    path = tmp_path / "r.nc"
    a.save(path)
    b.save(path)
    assert_same(jg.load(path), b)
    assert [p.name for p in tmp_path.iterdir()] == ["r.nc"]


def test_summary_json(duffing_results, tmp_path):
    """``summary.json``: everything but the per-cell labels, strict JSON, shares summing to 1."""
    r = duffing_results["direct"]
    s = json.loads(r.write_summary(tmp_path / "summary.json").read_text())
    assert "labels" not in s and s["method"] == "direct" and s["n_cells"] == 30
    assert abs(sum(s["shares"].values()) - 1) < 1e-12
    assert [a["period"] for a in s["attractors"]] == [1, 1]
    assert [a["cell_count"] for a in s["attractors"]] == [int(np.sum(r.labels == a.id)) for a in r.attractors]


@dataclasses.dataclass(frozen=True, kw_only=True)
class _Options:
    stop: float | None = None
    bounds: tuple[float, float] | None = None
    note: str | None = None
    integrator: jg.AbstractIntegrator = custom_field(lambda i: i.to_dict(), integrator_from_dict)


@dataclasses.dataclass(frozen=True, kw_only=True)
class _Holder:
    values: np.ndarray = array_field(("value",))
    settings: _Options
    extra: _Options | None = None


def test_typed_settings_round_trip_with_none_and_text(monkeypatch):
    """A settings record saves field by field: an optional number, pair or text that is
    None loads as None (not the text 'null'), the text 'null' stays text, an integrator
    comes back as the same object, a missing record as None."""
    monkeypatch.setitem(RESULT_TYPES, "_Holder", _Holder)
    cases = [
        _Holder(values=np.arange(3.0), settings=_Options(integrator=jg.RK4(64))),
        _Holder(values=np.arange(2.0), settings=_Options(stop=1.5, bounds=(0.0, 2.0), note="null",
                                                         integrator=jg.KinkAwareRK4(300)),
                extra=_Options(note="", integrator=jg.Adaptive())),
    ]
    for h in cases:
        ds = to_dataset(h)
        q = from_dataset(ds, "_Holder")
        assert_same(q, h)
        assert q.settings == h.settings and type(q.settings.integrator) is type(h.settings.integrator)
    assert cases[0].settings.note is None and from_dataset(to_dataset(cases[0])).settings.note is None
    assert from_dataset(to_dataset(cases[1])).settings.note == "null"
    assert "settings__stop" in to_dataset(cases[1]).attrs and "settings__stop" not in to_dataset(cases[0]).attrs


@dataclasses.dataclass(frozen=True, kw_only=True)
class _Event:
    kind: jg.BifurcationKind
    at: float


@dataclasses.dataclass(frozen=True, kw_only=True)
class _Outcomes:
    status: jg.DesignStatus
    ended: jg.BranchStatus
    code: jg.Status
    events: tuple[_Event, ...] = items_field("event")


def test_outcomes_are_enums_stored_by_their_values(monkeypatch):
    """Statuses and kinds are enumerations: they round-trip as the same members, are stored
    as their plain values (what files written when they were strings hold, so those still
    load), and a value that is no member is refused naming the field."""
    monkeypatch.setitem(RESULT_TYPES, "_Outcomes", _Outcomes)
    h = _Outcomes(status=jg.DesignStatus.LOST_STABILITY, ended=jg.BranchStatus.CORRECTOR_FAILED,
                  code=jg.Status.DIVERGED, events=(_Event(kind=jg.BifurcationKind.PD, at=0.5),
                                                   _Event(kind=jg.BifurcationKind.NS, at=0.7)))
    ds = to_dataset(h)
    assert (ds.attrs["status"], ds.attrs["ended"], int(ds.attrs["code"])) == ("lost stability", "corrector_failed", 3)
    assert list(ds["events__kind"].values) == ["PD", "NS"]
    q = from_dataset(ds, "_Outcomes")
    assert q == h and type(q.status) is jg.DesignStatus and type(q.code) is jg.Status
    assert [type(e.kind) for e in q.events] == [jg.BifurcationKind] * 2
    bad = ds.copy()
    bad.attrs["status"] = "exploded"
    with pytest.raises(ValueError, match="'status'.*not a DesignStatus"):
        from_dataset(bad, "_Outcomes")


def _diagram(directions) -> jg.BifurcationDiagram:
    """A small bifurcation diagram of 2 values and 1 start per sweep (made by hand: the
    codec, not the sweep, is checked here)."""
    D, V = len(directions), 2
    return jg.BifurcationDiagram(
        param="omega", fields=("omega",), values=np.array([1.0, 1.1]), directions=directions,
        starts=np.zeros((1, 2)), points=np.zeros((D, V, 1, 3, 2)), period=np.ones((D, V, 1), np.int64),
        attractor=np.zeros((D, V, 1), np.int64), system="duffing", state_names=("x", "v"), params={},
        settings=jg.sweep.SequenceSettings(options=jg.SequenceOptions(max_period=1, record=3), integrator=jg.RK4(16)))


def _parameter_map(quantity) -> jg.ParameterMap:
    """A 2 x 1 two-parameter map of 1 start (made by hand)."""
    return jg.ParameterMap(
        param_x="omega", fields_x=("omega",), values_x=np.array([1.0, 1.1]), param_y="gamma", fields_y=("gamma",),
        values_y=np.array([0.3]), starts=np.zeros((1, 2)), quantity=quantity, period=np.ones((1, 2, 1), np.int64),
        attractor=np.zeros((1, 2, 1), np.int64), n_attractors=np.ones((1, 2), np.int64),
        last_point=np.zeros((1, 2, 1, 2)), system="duffing", state_names=("x", "v"), params={},
        settings=jg.sweep.SequenceSettings(options=jg.SequenceOptions(max_period=1, record=4), integrator=jg.RK4(16)))


def _rewrite(path, out, drop=(), **attrs):
    """The result file ``path`` written to ``out`` with the variables ``drop`` left out and
    the attributes ``attrs`` set (``None``: removed): an older or a damaged file."""
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        ds = ds.drop_vars([v for v in ds.variables if str(v).startswith(tuple(drop))]).load()
    for name, value in attrs.items():
        if value is None:
            ds.attrs.pop(name, None)
        else:
            ds.attrs[name] = value
    ds.to_netcdf(out, engine="h5netcdf")
    return out


def test_sweep_direction_and_map_quantity_are_enums_stored_by_their_texts(tmp_path):
    """A diagram's sweep directions and a map's quantity are enumerations: given as their
    texts they become the members, are stored as the texts (what files held when they were
    strings, so those load unchanged), load as the same members, and a text that is no
    member is refused naming the field and the allowed values."""
    d = _diagram(("independent", "up", "down"))
    assert d.directions == (jg.SweepDirection.INDEPENDENT, jg.SweepDirection.UP, jg.SweepDirection.DOWN)
    assert all(type(x) is jg.SweepDirection for x in d.directions) and d.directions == jg.SweepDirection.ALL.sweeps
    path = d.save(tmp_path / "d.nc")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert json.loads(ds.attrs["directions"]) == ["independent", "up", "down"]
        assert list(ds["direction"].values) == ["independent", "up", "down"]
    q = jg.load(path)
    assert_same(q, d)
    assert [type(x) for x in q.directions] == [jg.SweepDirection] * 3
    assert q.transitions("down") == q.transitions(jg.SweepDirection.DOWN) and q.summary()["directions"][1] == "up"
    bad = _rewrite(path, tmp_path / "bad.nc", directions='["independent", "sideways"]')
    with pytest.raises(ValueError, match=r"'directions'.*'sideways' is not a SweepDirection.*independent, up, down"):
        jg.load(bad)

    m = _parameter_map("n_attractors")
    assert m.quantity is jg.MapQuantity.N_ATTRACTORS and m.data is m.n_attractors
    path = m.save(tmp_path / "m.nc")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds.attrs["quantity"] == "n_attractors"
    q = jg.load(path)
    assert_same(q, m)
    assert q.quantity is jg.MapQuantity.N_ATTRACTORS and q.summary()["quantity"] == "n_attractors"
    bad = _rewrite(path, tmp_path / "badm.nc", quantity="periods")
    with pytest.raises(ValueError, match=r"'quantity'.*'periods' is not a MapQuantity.*period, n_attractors"):
        jg.load(bad)


def test_orbit_search_records_are_typed_and_files_of_format_4_load(duffing_search, tmp_path):
    """An orbit search's convergence and checks are tuples of typed records (one per period
    tried, one per orbit verified), stored as columns along their own dimensions; a file of
    format 4, which held them as dictionaries keyed by texts ("1", "0"), loads as the same
    records; the summary keeps the dictionaries."""
    checks = (jg.OrbitVerification(orbit=0, periods=50, kept=True, left_at=-1, consistent=True),
              jg.OrbitVerification(orbit=2, periods=50, kept=False, left_at=7, consistent=True))
    s = dataclasses.replace(duffing_search, checks=checks)
    assert [c.period for c in s.convergence] == [1, 2] and all(type(c) is jg.PeriodConvergence for c in s.convergence)
    c1 = s.convergence_of(1)
    assert c1.seeds == 5 and sum(c1.orbits.values()) == c1.converged and all(type(i) is int for i in c1.orbits)
    assert s.verification_of(2).left_at == 7 and s.verification_of(1) is None
    with pytest.raises(KeyError, match="period 3 was not tried"):
        s.convergence_of(3)
    path = s.save(tmp_path / "o.nc")
    q = jg.load(path)
    assert_same(q, s)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds["convergence__period"].dims == ("searched_period",) and list(ds["convergence__period"].values) == [1, 2]
        assert list(ds["checks__left_at"].values) == [-1, 7] and "convergence" not in ds.attrs
    old_convergence = {str(c.period): c.to_dict() for c in s.convergence}
    old_checks = {"0": dict(periods=50, kept=True, left_at=-1, consistent=True),
                  "2": dict(periods=50, kept=False, left_at=7, consistent=True)}
    assert set(old_convergence["1"]) == {"runs", "seeds", "converged", "seeds_converged", "first_round", "orbits"}
    assert s.summary()["convergence"] == old_convergence and s.summary()["checks"] == old_checks
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        schema = {k: v for k, v in json.loads(ds.attrs["jaxgear_schema"]).items()
                  if not k.startswith(("convergence", "checks"))}
    old = _rewrite(path, tmp_path / "old.nc", drop=("convergence__", "checks__"), jaxgear_format=4,
                   jaxgear_schema=json.dumps(schema), convergence=json.dumps(old_convergence),
                   checks=json.dumps(old_checks))
    assert_same(jg.load(old), s)
    empty = _rewrite(path, tmp_path / "old_empty.nc", drop=("convergence__", "checks__"), jaxgear_format=4,
                     jaxgear_schema=json.dumps(schema), convergence="{}", checks="{}")
    assert jg.load(empty).convergence == () and jg.load(empty).checks == ()


def test_a_direct_result_holds_its_pool_options_and_flat_files_of_format_4_load(duffing_results, tmp_path):
    """The direct method holds the lane pool's options as one record (``Direct.pool``, saved
    as one); a file of format 4, whose method held them flat (``chunk_size``,
    ``max_periods``, ...), loads as the same method."""
    r = dataclasses.replace(duffing_results["direct"],
                            method=jg.Direct(max_periods=3000, chunk_size=512, capture_radius=0.01, recurrence=None))
    assert r.method.pool == jg.PoolOptions(max_periods=3000, lanes=512, capture_radius=0.01)
    path = r.save(tmp_path / "r.nc")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        saved = json.loads(ds.attrs["method"])
    assert set(saved) == {"name", "integrator", "pool", "recurrence"}
    assert saved["pool"]["lanes"] == 512 and saved["pool"]["max_periods"] == 3000
    assert_same(jg.load(path), r)
    flat = dict(name="direct", integrator=saved["integrator"], max_period=16, period_tol=1e-6, merge_tol=1e-4,
                chunk_size=512, round_periods=5, max_periods=3000, capture_radius=0.01, escape_bound=1e6,
                recurrence=None)
    old = _rewrite(path, tmp_path / "old.nc", jaxgear_format=4, method=json.dumps(flat))
    q = jg.load(old)
    assert q.method == r.method and q.method.pool.max_periods == 3000 and q.method.chunk_size == 512
    assert_same(q, r)


# ---------------------------------------------------------------- jaxgear.load
def _registered_in_source() -> set[str]:
    """Names of the classes decorated ``@result_type`` anywhere in the package source."""
    names = set()
    for path in Path(jg.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and any(
                    (d.id if isinstance(d, ast.Name) else getattr(d, "attr", None)) == "result_type"
                    for d in node.decorator_list):
                names.add(node.name)
    return names


def test_chaotic_saddles_round_trip_and_older_files_load_without_them(duffing_results, tmp_path):
    """A result's chaotic saddles (cloud, lifetime and how it was measured) round-trip
    exactly and are printed; a file written before they were recorded loads with none."""
    r = duffing_results["direct"]
    saddle = jg.ChaoticSaddle(points=np.arange(12.0).reshape(6, 2), lifetime=416.2, lifetime_error=40.1,
                              starts=1024, periods=2016, left=1.0)
    one = dataclasses.replace(r, saddles=(saddle, dataclasses.replace(saddle, lifetime=np.inf,
                                                                      lifetime_error=np.nan, left=0.0)))
    q = jg.load(one.save(tmp_path / "r.nc"))
    assert_same(q, one)
    assert "a mean lifetime of 416 +- 40 periods" in q.table() and "beyond about 2016 periods" in q.table()
    assert q.summary()["saddles"][0]["lifetime"] == 416.2
    with xr.open_dataset(tmp_path / "r.nc", engine="h5netcdf") as ds:
        schema = json.loads(ds.attrs["jaxgear_schema"])
    old = _rewrite(tmp_path / "r.nc", tmp_path / "old.nc", drop=("saddles",),
                   jaxgear_schema=json.dumps({k: v for k, v in schema.items() if not k.startswith("saddles")}))
    assert jg.load(old).saddles == () and "chaotic saddle" not in jg.load(old).table()


def test_every_result_type_is_registered_and_exported():
    """Each class the source decorates with ``@result_type`` is known to the codec once
    ``jaxgear`` is imported (so :func:`jaxgear.load` finds it by the name in the file, the
    loader importing no result module itself) and exported from the package."""
    declared = _registered_in_source()
    assert {"GlobalResult", "OrbitSearch", "BifurcationDiagram", "BasinSweep", "BasinMap", "ParameterMap",
            "Branch", "DesignResult"} <= declared
    assert set(RESULT_TYPES) == declared
    for name, cls in RESULT_TYPES.items():
        assert getattr(jg, name) is cls, f"{name} is not exported from jaxgear"


def test_files_of_version_0_1_are_refused_with_the_reason(duffing_results, tmp_path):
    """A file of jaxgear 0.1 (its type recorded, no ``jaxgear_format``; or, older, no type
    at all but the labels and grid of a global analysis) is refused in one line that says
    so and what to do; it is not mistaken for another program's file."""
    with xr.open_dataset(duffing_results["direct"].save(tmp_path / "r.nc"), engine="h5netcdf") as ds:
        old = ds.load()
    del old.attrs["jaxgear_format"]
    old.to_netcdf(tmp_path / "old.nc", engine="h5netcdf")
    with pytest.raises(ValueError, match=r"holds a GlobalResult written by jaxgear 0\.1.*re-run") as info:
        jg.load(tmp_path / "old.nc")
    assert "\n" not in str(info.value)
    older = old.copy()
    del older.attrs["jaxgear_type"]
    older.attrs["grid"] = "{}"
    older.to_netcdf(tmp_path / "older.nc", engine="h5netcdf")
    with pytest.raises(ValueError, match=r"GlobalResult written by jaxgear 0\.1"):
        jg.load(tmp_path / "older.nc")


def test_load_errors_name_the_problem(duffing_results, tmp_path):
    """Anything that is not a whole jaxgear result file is refused with one line saying why."""
    cases = {"missing.nc": None, "folder": "dir", "empty.nc": b"", "text.json": b'{"a": 1}',
             "garbage.nc": b"\x00" * 64}
    for name, content in cases.items():
        p = tmp_path / name
        if content == "dir":
            p.mkdir()
        elif content is not None:
            p.write_bytes(content)
        with pytest.raises(ValueError, match="not a jaxgear result file") as info:
            jg.load(p)
        assert "\n" not in str(info.value)
    good = duffing_results["direct"].save(tmp_path / "r.nc")
    data = good.read_bytes()
    (tmp_path / "truncated.nc").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="not a jaxgear result file"):
        jg.load(tmp_path / "truncated.nc")
    xr.Dataset({"a": ("i", np.arange(3))}).to_netcdf(tmp_path / "foreign.nc", engine="h5netcdf")
    with pytest.raises(ValueError, match="another program"):
        jg.load(tmp_path / "foreign.nc")
    xr.Dataset(attrs={"jaxgear_type": "Nonsense", "jaxgear_format": FORMAT}).to_netcdf(tmp_path / "bad.nc",
                                                                                  engine="h5netcdf")
    with pytest.raises(ValueError, match="unknown jaxgear_type 'Nonsense'"):
        jg.load(tmp_path / "bad.nc")
    with pytest.raises(ValueError, match="OrbitSearch"):
        jg.load(good, expected="OrbitSearch")


# ---------------------------------------------------------------- plotting from disk
@pytest.fixture
def no_integration(monkeypatch):
    """Every integration entry point raises: a figure drawn now used stored data only."""
    import jaxgear.integrate as it
    import jaxgear.plotting._orbit as po

    def boom(*a, **k):
        raise AssertionError("integration during plotting")

    # every integration goes through an integrator object's operations
    for cls in (it.AbstractFixedStep, it.Adaptive):
        for n in ("advance", "trajectory", "flow", "step"):
            if n in vars(cls):
                monkeypatch.setattr(cls, n, boom)
    monkeypatch.setattr(it.RK4, "step", boom)
    for mod, names in ((po, ("sample_trajectory",)),
                       (jg, ("stroboscopic_map", "stroboscopic_orbit", "section_map", "sample_trajectory"))):
        for n in names:
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


# ---------------------------------------------------------------- a file is data
def _attrs_file(path, **attrs):
    base = {"jaxgear_type": "DesignResult", "jaxgear_format": FORMAT, "jaxgear_schema": "{}"}
    base.update(attrs)
    xr.Dataset(attrs=base).to_netcdf(path, engine="h5netcdf")
    return path


def test_a_crafted_file_runs_nothing(tmp_path, capfd):
    """A file naming a callable (``subprocess:run`` with a command) as its parameters' type is
    refused without running it, and a type named with numbers as values is not even imported
    (the standard library's ``this`` prints a poem when imported): parameters come back as
    a plain dict, and only the package's own classes are rebuilt."""
    import sys

    from jaxgear._params import params_from_dict, params_to_dict

    marker = tmp_path / "marker"
    cmd = json.dumps({"type": "subprocess:run", "values": {"args": ["sh", "-c", f"touch {marker}"]}})
    from jaxgear._io import NotAResultFile

    try:
        jg.load(_attrs_file(tmp_path / "crafted.nc", params=cmd))
    except Exception as exc:  # noqa: BLE001 (checked below, after the marker)
        error = exc
    else:
        error = None
    assert not marker.exists(), "loading a file ran the command it names"
    assert isinstance(error, NotAResultFile)
    assert params_from_dict("subprocess:run", {"args": ["sh", "-c", f"touch {marker}"]}) == {
        "args": ["sh", "-c", f"touch {marker}"]} and not marker.exists()
    sys.modules.pop("this", None)
    assert params_from_dict("this:Zen", {"a": 1.0}) == {"a": 1.0}
    assert "this" not in sys.modules and capfd.readouterr().out == ""
    # the package's own classes are rebuilt; a crafted value that does not fit them is refused
    back = params_from_dict("jaxgear._examples:DuffingParams", params_to_dict(DOUBLE_WELL))
    assert type(back) is jg.DuffingParams and params_to_dict(back) == params_to_dict(DOUBLE_WELL)
    with pytest.raises(ValueError, match="do not fit DuffingParams"):
        params_from_dict("jaxgear._examples:DuffingParams", {"nonsense": 1.0})


def test_crafted_fields_are_refused_naming_the_field(duffing_results, tmp_path):
    """Fields of the wrong kind, a schema that promises more items than the file holds, and a
    format that is not one integer: one ``NotAResultFile`` line naming the field, never a
    TypeError, AttributeError or IndexError."""
    from jaxgear._io import NotAResultFile

    cases = [({"jaxgear_format": np.array([4, 4])}, "jaxgear_format"),
             ({"jaxgear_schema": "[1, 2]"}, "jaxgear_schema")]
    for i, (attrs, field) in enumerate(cases):
        with pytest.raises(NotAResultFile, match=field) as info:
            jg.load(_attrs_file(tmp_path / f"a{i}.nc", **attrs))
        assert "\n" not in str(info.value)
    with xr.open_dataset(duffing_results["direct"].save(tmp_path / "r.nc"), engine="h5netcdf") as ds:
        good = ds.load()
    bad = good.copy()
    bad.attrs["method"] = "[1, 2, 3]"
    bad.to_netcdf(tmp_path / "method.nc", engine="h5netcdf")
    with pytest.raises(NotAResultFile, match="'method'"):
        jg.load(tmp_path / "method.nc")
    schema = json.loads(good.attrs["jaxgear_schema"])
    items = [k for k, v in schema.items() if "n" in v and v["n"] > 0]
    assert items, "the result has an item field (its attractors)"
    schema[items[0]]["n"] += 5
    bad = good.copy()
    bad.attrs["jaxgear_schema"] = json.dumps(schema)
    bad.to_netcdf(tmp_path / "count.nc", engine="h5netcdf")
    with pytest.raises(NotAResultFile, match=repr(items[0])):
        jg.load(tmp_path / "count.nc")


def test_only_the_fields_variables_are_read(duffing_results, tmp_path):
    """A small file declaring a large unused variable (its chunks never written) loads without
    reading it, and a used variable declared larger than a result can hold is refused before
    anything is allocated."""
    import tracemalloc

    import h5py

    path = duffing_results["direct"].save(tmp_path / "r.nc")
    with h5py.File(path, "a") as f:
        f.create_dataset("unused", shape=(40_000_000,), dtype="f8", chunks=(1_000_000,))
    assert path.stat().st_size < 1_000_000
    tracemalloc.start()
    try:
        back = jg.load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert_same(back.labels, duffing_results["direct"].labels)
    assert peak < 50e6, f"{peak / 1e6:.0f} MB read for a file whose result is a few kB"
    path = duffing_results["direct"].save(tmp_path / "huge.nc")
    with h5py.File(path, "a") as f:
        del f["labels"]
        f.create_dataset("labels", shape=(3_000_000_000,), dtype="i8", chunks=(1_000_000,))
    from jaxgear._io import NotAResultFile

    with pytest.raises(NotAResultFile, match="labels"):
        jg.load(path)


def test_a_basin_sweep_resumes_only_global_results(tmp_path):
    """A sweep part that holds another result type (a crafted design file, tagged with the
    sweep's settings) is not taken as the value's result: the runner computes it again."""
    from jaxgear.sweep._checkpoint import Checkpoint

    settings = {"kind": "basins", "param": "b", "values": [1.0, 2.0]}
    _attrs_file(Checkpoint(tmp_path, "basins", settings).path("value_00000.nc"))
    computed = []

    class Result:
        def save(self, path):
            pass

    def compute(block):
        computed.extend(block)
        return [Result() for _ in block]

    results = jg.Runner(out=tmp_path, progress=False).values(settings, 1, compute, 1, "basins b", "GlobalResult")
    assert computed == [0] and isinstance(results[0], Result)
