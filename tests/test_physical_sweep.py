"""Sweeps in physical units (jaxgear/sweep/_physical.py): a GearSet field mapped to the
dimensionless fields it changes, checked against GearSet.to_params computed here."""

from __future__ import annotations

import json

import numpy as np
import pytest

import jaxgear as jg

QUIET = jg.Runner(progress=False)  # nothing written, no progress bars

GS = jg.paper_gear_set()
BASE = GS.to_params().uniform()


def converted(**changes) -> dict:
    """The dimensionless set of the paper gear set with physical ``changes``."""
    return GS.replace(**changes).to_params().to_dict()


@pytest.mark.parametrize("name, values, changes, fields", [
    ("b_sp", [30.0, 50.0, 70.0], lambda v: dict(b_sp=v), ("b_sp",)),
    ("b", [20.0, 60.0], lambda v: dict(b_sp=v, b_rp=v), ("b_sp", "b_rp")),
    ("k_sp_amp", [2e8, 3e8], lambda v: dict(k_sp_amp=v), ("kappa_sp_amp",)),
    ("input_rpm", [1500.0, 3000.0], lambda v: dict(input_rpm=v), ("Omega",)),
    ("T_D", [200.0, 349.0, 500.0], lambda v: dict(T_D=v), ("f_D", "f_L")),
])
def test_physical_axis_is_the_gear_sets_conversion(name, values, changes, fields):
    """Each physical value sets exactly the dimensionless fields GearSet.to_params changes,
    at the converted values (bit for bit); the axis keeps the name, unit and values."""
    ax = jg.sweep_axis(BASE, name, values, GS)
    assert ax.physical and ax.name == name and ax.fields == fields
    assert ax.unit == jg.GearSet.UNITS[fields[0] if name not in ("b", "T_D", "input_rpm", "k_sp_amp") else
                                       {"b": "b_sp"}.get(name, name)]
    np.testing.assert_array_equal(ax.values, np.sort(values))
    for v, row in zip(ax.values, ax.rows):
        d = converted(**changes(float(v)))
        assert row.tolist() == [d[f] for f in fields]
        assert all(d[k] == BASE.to_dict()[k] for k in d if k not in fields and k != "N")  # nothing else changes
    names, rows = ax.applied()
    assert names == fields and rows is ax.rows


def test_dimensionless_names_keep_their_meaning():
    ax = jg.sweep_axis(BASE, "b", [4.0, 5.0])
    assert not ax.physical and ax.fields == ("b_sp", "b_rp") and ax.applied()[0] == ("b",)
    np.testing.assert_array_equal(ax.rows, [[4.0, 4.0], [5.0, 5.0]])


@pytest.mark.parametrize("name, values, match", [
    ("k_rp_mean", [0.9e9, 1.1e9], r"changes the dimensionless kappa_rp_mean, c_rp, of which c_rp not in proportion"),
    ("module", [3e-3, 4e-3], r"mu_s, mu_p, mu_c, .*not in proportion to module"),
    ("b_c", [8.0, 12.0], r"not in proportion to b_c"),
    ("N", [3, 4], r"unknown gear-set parameter 'N'.*valid names: module, .*input_rpm, .*k_amp"),
    ("backlash", [1.0], r"valid names: module"),
    ("b_sp", [-5.0, 5.0], r"sweep value b_sp=-5: .*must be >= 0"),
])
def test_a_change_off_one_line_is_refused(name, values, match):
    """A quantity whose dimensionless fields do not all move in proportion to it (masses,
    omega_n, the scale b_c) is refused naming them, before any integration; so are unknown
    names (listing the valid ones) and values the gear set refuses."""
    with pytest.raises(ValueError, match=match):
        jg.sweep_axis(BASE, name, values, GS)
    with pytest.raises(ValueError, match=match):  # the sweeps refuse it the same way, before integrating
        jg.basin_sweep(None, None, name, values, jg.CellGrid.paper(counts=(2, 2, 2)), gear_set=GS, runner=QUIET)


def test_a_map_of_two_physical_parameters_sets_both_conversions():
    """Every point of a physical map sets the fields the gear set converted at both values
    at once; two quantities that act on the same field are refused."""
    from jaxgear.sweep._physical import joint_rows

    a, b = jg.sweep_axis(BASE, "T_D", [300.0, 400.0], GS), jg.sweep_axis(BASE, "b", [40.0, 60.0], GS)
    VV = np.array([[300.0, 40.0], [400.0, 40.0], [300.0, 60.0], [400.0, 60.0]])
    rows = joint_rows(GS, (a, b), VV)
    for v, row in zip(VV, rows):
        d = converted(T_D=v[0], b_sp=v[1], b_rp=v[1])
        assert row.tolist() == [d["f_D"], d["f_L"], d["b_sp"], d["b_rp"]]
    with pytest.raises(ValueError, match="set the same field"):
        jg.basin_map(None, None, "b", [40.0, 50.0], "b_sp", [40.0, 50.0], jg.CellGrid.paper(counts=(2, 2, 2)),
                     gear_set=GS, runner=QUIET)


class _Stop(Exception):
    pass


@pytest.fixture
def analysed(monkeypatch):
    """The parameter sets the basin sweeps hand to the global analyses (the first block),
    as dicts; the sweep stops there."""
    from jaxgear.sweep import _basins

    seen = []

    def capture(system, params_list, *a, **k):
        seen.extend(p.to_dict() for p in params_list)
        raise _Stop

    monkeypatch.setattr(_basins, "_analyze_values", capture)
    return seen


def test_the_analyses_run_at_the_converted_parameters(analysed):
    """A physical basin sweep analyses, at each value, exactly the dimensionless set the
    gear set converts to (to_params here, all fields); a physical map at each point the
    set converted at both values."""
    grid = jg.CellGrid.paper(counts=(2, 2, 2))
    with pytest.raises(_Stop):
        jg.basin_sweep(None, None, "b_sp", [30.0, 60.0], grid, gear_set=GS, runner=QUIET)
    assert analysed == [converted(b_sp=30.0), converted(b_sp=60.0)]
    analysed.clear()
    with pytest.raises(_Stop):
        jg.basin_map(None, None, "input_rpm", [2000.0, 2500.0], "T_D", [300.0, 400.0], grid, gear_set=GS,
                     runner=QUIET)
    assert analysed == [converted(input_rpm=r, T_D=t) for t in (300.0, 400.0) for r in (2000.0, 2500.0)]


def test_sweep_command_hands_the_gear_set_and_prints_units(tmp_path, capsys, analysed):
    """``jaxgear sweep --param gear.b`` (and the physical-only ``k_sp_amp``) sweep the preset's
    gear set in its units: the first line gives the values in µm with the dimensionless
    fields they set, and the analyses run at the converted parameters."""
    from jaxgear.cli import main

    common = ["--kind", "basins", "--grid", "2,2,2", "--quiet", "--no-figures", "--out", str(tmp_path / "o")]
    with pytest.raises(_Stop):
        main(["sweep", "--param", "gear.b", "--values", "40:50:2", *common])
    assert "basins in b = 40 .. 50 um (half) (2 values; b_sp = 4 .. 5, b_rp = 4 .. 5)" in capsys.readouterr().out
    assert analysed == [converted(b_sp=40.0, b_rp=40.0), converted(b_sp=50.0, b_rp=50.0)]
    analysed.clear()
    with pytest.raises(_Stop):
        main(["sweep", "--param", "k_sp_amp", "--values", "2e8:3e8:2", *common, "--restart"])
    assert "k_sp_amp = 2e+08 .. 3e+08 N/m (2 values; kappa_sp_amp = 0.2422 .. 0.3634)" in capsys.readouterr().out
    assert analysed == [converted(k_sp_amp=2e8), converted(k_sp_amp=3e8)]


@pytest.mark.slow  # about 30 s: two basin sweeps of two values on 90 cells and their contact regimes
def test_sweep_command_in_physical_units(tmp_path, capsys):
    """``jaxgear sweep --param gear.b`` sweeps both half backlashes in µm: it prints the
    values in µm with the dimensionless b they mean, labels the tables in µm, keeps the
    physical values with their dimensionless ones, and finds what the dimensionless sweep
    at the converted values finds (the same grid and analyses as the analyze tests)."""
    from jaxgear.cli import main

    common = ["--kind", "basins", "--grid", "5,3,6", "--uncertainty-samples", "0", "--quiet", "--no-figures"]
    assert main(["sweep", "--param", "gear.b", "--values", "40:50:2", *common, "--out", str(tmp_path / "um")]) == 0
    text = capsys.readouterr().out
    assert "in b = 40 .. 50 um (half) (2 values; b_sp = 4 .. 5, b_rp = 4 .. 5)" in text
    assert "b [µm, half]" in text  # the tables' value column
    phys = jg.load(tmp_path / "um" / "basins.nc", expected="BasinSweep")
    assert phys.physical and phys.unit == "um (half)" and phys.values.tolist() == [40.0, 50.0]
    expect = [[converted(b_sp=v, b_rp=v)[f] for f in ("b_sp", "b_rp")] for v in (40.0, 50.0)]
    np.testing.assert_array_equal(phys.field_values, expect)
    summary = json.loads((tmp_path / "um" / "summary.json").read_text())
    assert summary["unit"] == "um (half)" and summary["field_values"] == expect
    assert summary["contact_regimes"]["label"] == "b [µm, half]"
    assert main(["sweep", "--param", "b", "--values", "4:5:2", *common, "--out", str(tmp_path / "dimless")]) == 0
    capsys.readouterr()
    dimless = jg.load(tmp_path / "dimless" / "basins.nc", expected="BasinSweep")
    np.testing.assert_array_equal(phys.labels, dimless.labels)
    np.testing.assert_array_equal(phys.shares, dimless.shares)
    assert summary["contact_regimes"]["shares"] == json.loads(
        (tmp_path / "dimless" / "summary.json").read_text())["contact_regimes"]["shares"]


@pytest.mark.slow  # about 20 s: two bifurcation diagrams of the gear model
def test_a_physical_diagram_is_the_dimensionless_one_at_the_converted_values():
    """A bifurcation diagram over the input speed in rpm records the points of the diagram
    over Omega at the converted values, and labels its axis in rpm."""
    x0 = np.array([[1.0, 0.0, 5.0, 0.0], [-3.0, 1.0, 10.0, 0.0]])
    kw = dict(runner=QUIET, transient=20, record=10, max_period=4)
    rpm = [1000.0, 2000.0]
    a = jg.bifurcation_diagram(None, None, "input_rpm", rpm, x0, gear_set=GS, **kw)
    b = jg.bifurcation_diagram(None, None, "Omega", [converted(input_rpm=v)["Omega"] for v in rpm], x0, **kw)
    np.testing.assert_array_equal(a.points, b.points)
    assert a.axis_label == "input_rpm [rpm]" and a.values.tolist() == rpm and a.fields == ("Omega",)


def test_sweep_command_refuses_bad_physical_names(tmp_path, capsys):
    from jaxgear.cli import main

    for argv, match in (
            (["--param", "gear.backlash", "--values", "1:2:2"], "physical names (gear.NAME): module"),
            (["--param", "backlash", "--values", "1:2:2"], "physical gear-set names: module"),
            (["--param", "k_rp_mean", "--values", "9e8:1e9:2"], "not in proportion"),
            (["--param", "gear.b", "--values", "40:50:2", "--set", "b_sp=4"], "which --set overrides"),
            (["--kind", "basins", "--param", "gear.b", "--values", "40:50:2", "--param2", "kappa_amp",
              "--values2", "0.3:0.4:2"], "both in physical units"),
            (["--kind", "continuation", "--param", "T_D", "--values", "300:400:2", "--from", "1,2,3,0"],
             "continue in f_D")):
        assert main(["sweep", *argv, "--out", str(tmp_path / "x")]) == 2, argv
        assert match in capsys.readouterr().err, argv
    assert not (tmp_path / "x").exists()  # refused before --out is touched
