"""GlobalResult: save -> load round trip, summary.json, labelled arrays."""

import json

import numpy as np
import xarray as xr

import jaxgear as jg


def _small_result():
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (8, 6), names=("x", "v"))
    p = jg.DuffingParams(delta=0.5, alpha=-1.0, beta=1.0, gamma=0.0, omega=1.0)
    return jg.analyze_global(jg.DUFFING, p, grid, method=jg.Direct(), progress=False)


def test_save_load_round_trip_exact(tmp_path):
    r = _small_result()
    path = r.save(tmp_path / "r.nc")
    q = jg.load(path)
    assert np.array_equal(q.labels, r.labels) and q.labels.dtype == r.labels.dtype
    assert q.grid == r.grid and q.method == r.method and q.params == r.params
    assert q.settings == r.settings and q.state_names == r.state_names
    assert (q.n_sink, q.n_unresolved, q.version, q.runtime_s) == (r.n_sink, r.n_unresolved, r.version, r.runtime_s)
    assert len(q.attractors) == len(r.attractors)
    for a, b in zip(q.attractors, r.attractors):
        assert (a.id, a.period, a.cell_count, a.share) == (b.id, b.period, b.cell_count, b.share)
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.section_points, b.section_points)
        np.testing.assert_array_equal(a.periodic_cells, b.periodic_cells)


def test_file_opens_as_labelled_arrays(tmp_path):
    r = _small_result()
    r.save(tmp_path / "r.nc")
    ds = xr.open_dataset(tmp_path / "r.nc", engine="h5netcdf")
    assert ds["labels"].dims == ("x", "v")
    np.testing.assert_allclose(ds["x"].values, r.grid.axis_centres(0))
    assert json.loads(ds.attrs["params"])["delta"] == 0.5
    ds.close()


def test_summary_json(tmp_path):
    r = _small_result()
    s = json.loads(r.write_summary(tmp_path / "summary.json").read_text())
    assert "labels" not in s
    assert s["method"] == "direct" and s["n_cells"] == 48
    assert sum(s["shares"].values()) == 1.0 or abs(sum(s["shares"].values()) - 1) < 1e-12
    assert [a["period"] for a in s["attractors"]] == [a.period for a in r.attractors]
