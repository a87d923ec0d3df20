"""Bad input is refused before any work: every command-line option and every public
parameter, with one line naming the parameter, and no result file written.

The table runs each case of the probing report in-process with the heavy entry points
replaced by functions that fail the test: a refusal must come before any integration.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxgear as jg
from jaxgear.cli import build_parser, main


@pytest.fixture
def no_work(monkeypatch):
    """Any integration the command would start fails the test."""
    import jaxgear.analysis
    import jaxgear.continuation
    import jaxgear.shooting
    import jaxgear.sweep

    def forbidden(*a, **k):
        raise AssertionError("the command started working before refusing its input")

    for mod, names in ((jaxgear.analysis, ("analyze_global", "compare_with_direct")),
                       (jaxgear.shooting, ("find_periodic_orbits", "verify_orbit")),
                       (jaxgear.sweep, ("bifurcation_diagram", "basin_sweep")),
                       (jaxgear.continuation, ("continue_orbit",))):
        for n in names:
            monkeypatch.setattr(mod, n, forbidden)


def _run(argv, capsys) -> tuple[int, str]:
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse
        rc = exc.code
    return rc, capsys.readouterr().err


def _bad_files(tmp_path):
    """Files that are not jaxgear results: (name, path)."""
    empty = tmp_path / "empty.nc"
    empty.write_bytes(b"")
    js = tmp_path / "result.json"
    js.write_text('{"a": 1}')
    trunc = tmp_path / "truncated.nc"
    trunc.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(200))
    garbage = tmp_path / "garbage.nc"
    garbage.write_bytes(bytes(range(256)) * 4)
    return {"missing": tmp_path / "nope.nc", "folder": tmp_path, "empty": empty, "json": js,
            "truncated": trunc, "garbage": garbage}


SWEEP = ["sweep", "--param", "b", "--values", "4:6:3"]
# (argv with {out} for the output folder, text the one-line message must contain)
CLI_CASES = [
    # refused when valid -> the valid forms run (below); these are the wrong ones
    (["analyze", "--grid", "-10,6,12", "--out", "{out}"], "--grid"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "-10,6,12", "--out", "{out}"],
     "--grid"),
    # accepted when wrong, or failing late
    (["analyze", "--steps-per-period", "0", "--out", "{out}"], "--steps-per-period"),
    (["analyze", "--steps-per-period", "-5", "--out", "{out}"], "--steps-per-period"),
    (["shoot", "--from", "5,0,8,0", "--verify", "0", "--out", "{out}"], "--verify"),
    (["shoot", "--from", "5,0,8,0", "--verify", "-3", "--out", "{out}"], "--verify"),
    (["sweep", "--param", "b", "--values", "1:0:5", "--out", "{out}"], "--values"),
    (["sweep", "--param", "b", "--values", "1:0:5", "--kind", "basins", "--out", "{out}"], "--values"),
    (["analyze", "--compare=-5", "--out", "{out}"], "--compare"),
    (["analyze", "--compare", "-5", "--out", "{out}"], "--compare"),
    (["analyze", "--compare", "0", "--out", "{out}"], "--compare"),
    (["analyze", "--out", "{file}"], "--out"),
    (["analyze", "--out", "{file}/sub"], "--out"),
    (["shoot", "--from", "5,0,8,0", "--out", "{file}"], "--out"),
    (["sweep", *SWEEP[1:], "--out", "{file}"], "--out"),
    # every other option of analyze
    (["analyze", "--chunk-size", "0", "--out", "{out}"], "--chunk-size"),
    (["analyze", "--max-period", "0", "--out", "{out}"], "--max-period"),
    (["analyze", "--uncertainty-samples", "-1", "--out", "{out}"], "--uncertainty-samples"),
    (["analyze", "--method", "poincare-like", "--mapping-steps", "-1", "--out", "{out}"], "--mapping-steps"),
    (["analyze", "--direction", "1", "--out", "{out}"], "--direction"),
    (["analyze", "--method", "stroboscopic", "--direction", "1", "--out", "{out}"], "--direction"),
    (["analyze", "--grid", "4,4", "--out", "{out}"], "--grid"),
    (["analyze", "--grid", "2.5,4,4", "--out", "{out}"], "--grid"),
    (["analyze", "--method", "stroboscopic", "--grid", "4,4,4", "--out", "{out}"], "--grid"),
    (["analyze", "--region", "1:0,0:1,0:1", "--out", "{out}"], "--region"),
    (["analyze", "--region", "nan:1,0:1,0:1", "--out", "{out}"], "--region"),
    (["analyze", "--region", "0:1,0:1", "--out", "{out}"], "--region"),
    (["analyze", "--region", "0:1,0-1,0:1", "--out", "{out}"], "--region"),
    (["analyze", "--set", "Omega=-1", "--out", "{out}"], "Omega"),
    (["analyze", "--set", "Omega=nan", "--out", "{out}"], "Omega"),
    (["analyze", "--set", "input_rpm=fast", "--out", "{out}"], "input_rpm"),
    (["analyze", "--set", "nosuch=1", "--out", "{out}"], "nosuch"),
    (["analyze", "--set", "b", "--out", "{out}"], "--set"),
    (["analyze", "--preset", "nosuch", "--out", "{out}"], "nosuch"),
    # shoot
    (["shoot", "--from", "5,0,8,0", "--period", "0", "--out", "{out}"], "--period"),
    (["shoot", "--from", "5,0,8,0", "--tol", "-1", "--out", "{out}"], "--tol"),
    (["shoot", "--from", "5,0,8,0", "--tol", "nan", "--out", "{out}"], "--tol"),
    (["shoot", "--from", "5,0,8,0", "--max-iter", "0", "--out", "{out}"], "--max-iter"),
    (["shoot", "--from", "5,0,8,0", "--steps-per-period", "0", "--out", "{out}"], "--steps-per-period"),
    (["shoot", "--from", "5,0,8", "--out", "{out}"], "--from"),
    (["shoot", "--from", "nan,0,8,0", "--out", "{out}"], "--from"),
    (["shoot", "--from", "5;0;8;0", "--out", "{out}"], "--from"),
    (["shoot", "--random", "0", "--out", "{out}"], "--random"),
    (["shoot", "--random", "3", "--seed", "-1", "--out", "{out}"], "--seed"),
    (["shoot", "--random", "3", "--region", "1:0,0:1,0:1,0:1", "--out", "{out}"], "--region"),
    (["shoot", "--random", "3", "--region", "0:1,0:1,0:1", "--out", "{out}"], "--region"),
    # sweep
    ([*SWEEP, "--transient", "-1", "--out", "{out}"], "--transient"),
    ([*SWEEP, "--record", "10", "--out", "{out}"], "--record"),
    ([*SWEEP, "--starts", "0", "--out", "{out}"], "--starts"),
    ([*SWEEP, "--seed", "-2", "--out", "{out}"], "--seed"),
    ([*SWEEP, "--max-period", "0", "--out", "{out}"], "--max-period"),
    ([*SWEEP, "--steps-per-period", "0", "--out", "{out}"], "--steps-per-period"),
    ([*SWEEP, "--from", "1,2,3", "--out", "{out}"], "--from"),
    ([*SWEEP, "--region", "0:1,0:1", "--out", "{out}"], "--region"),
    ([*SWEEP, "--kind", "continuation", "--out", "{out}"], "--from"),
    ([*SWEEP, "--kind", "continuation", "--from", "5,0,8,0", "--period", "0", "--out", "{out}"], "--period"),
    ([*SWEEP, "--kind", "continuation", "--from", "5,0,8,0", "--max-steps", "0", "--out", "{out}"],
     "--max-steps"),
    ([*SWEEP, "--kind", "basins", "--grid", "3,3", "--out", "{out}"], "--grid"),
    ([*SWEEP, "--kind", "basins", "--method", "stroboscopic", "--grid", "3,3,3", "--out", "{out}"], "--grid"),
    ([*SWEEP, "--kind", "basins", "--region", "0:1,1:0,0:1", "--out", "{out}"], "--region"),
    (["sweep", "--param", "b", "--values", "4:4:3", "--out", "{out}"], "--values"),
    (["sweep", "--param", "b", "--values", "4:6:1", "--out", "{out}"], "--values"),
    (["sweep", "--param", "b", "--values", "a:6:3", "--out", "{out}"], "--values"),
    (["sweep", "--param", "b", "--values", "4:inf:3", "--out", "{out}"], "--values"),
    (["sweep", "--param", "b", "--values", "-1:6:3", "--out", "{out}"], "b"),
    (["sweep", "--param", "nosuch", "--values", "4:6:3", "--out", "{out}"], "nosuch"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "nosuch", "--out", "{out}"], "--kind"),
]


@pytest.mark.parametrize("argv, names", CLI_CASES, ids=[" ".join(c[0]) for c in CLI_CASES])
def test_cli_refuses_bad_input_before_any_work(argv, names, tmp_path, capsys, no_work):
    out = tmp_path / "out"
    file = tmp_path / "a-file.txt"
    file.write_text("keep me")
    argv = [a.replace("{out}", str(out)).replace("{file}", str(file)) for a in argv]
    rc, err = _run(argv, capsys)
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert len(lines) == 1, err
    assert names in lines[0] and "error" in lines[0], lines[0]
    assert "Traceback" not in err
    assert not out.exists()  # no folder, no result file
    assert file.read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file.txt"]  # no staging folder left


@pytest.mark.parametrize("kind", ["missing", "folder", "empty", "json", "truncated", "garbage"])
def test_seeds_from_and_load_refuse_non_results(kind, tmp_path, capsys, no_work):
    path = _bad_files(tmp_path)[kind]
    rc, err = _run(["shoot", "--seeds-from", str(path)], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert "not a jaxgear result file" in err
    with pytest.raises(ValueError, match="not a jaxgear result file") as exc:
        jg.load(path)
    assert "\n" not in str(exc.value)


# ----------------------------------------------------------------- API cases
def _api_cases():
    p = jg.paper_params()
    return [
        (lambda: jg.stroboscopic_map(jg.REDUCED, p, [1.0, 0, 5, 0], periods=-1), "periods"),
        (lambda: jg.stroboscopic_map(jg.REDUCED, p, [1.0, 0, 5, 0], periods=1.5), "periods"),
        (lambda: jg.CellGrid.box([(0, 1), (0, 1)], (2.5, 3)), "counts"),
        (lambda: jg.CellGrid.box([(0, 1), (0, 1)], (2, 0)), "counts"),
        (lambda: jg.CellGrid.box([(0, "x"), (0, 1)], (2, 2)), "bounds"),
        (lambda: jg.CellGrid.box([(0, 1, 2)], (2,)), "bounds"),
        (lambda: jg.paper_gear_set(input_rpm="3000"), "input_rpm"),
        (lambda: jg.paper_gear_set(face_width=True), "face_width"),
        (lambda: jg.paper_gear_set(k_sp_amp=[1e8, "a", 1e8]), "k_sp_amp"),
        (lambda: jg.analyze_global(jg.REDUCED, p, [[0, 1]], progress=False), "grid"),
        (lambda: jg.analyze_global(jg.REDUCED, p, jg.CellGrid.paper((2, 2, 2)), "nosuch"), "method"),
        (lambda: jg.analyze_global(jg.REDUCED, p, jg.CellGrid.paper((2, 2, 2)), uncertainty=-1), "uncertainty"),
        (lambda: jg.default_integrator(0), "steps_per_period"),
        (lambda: jg.RK4(2.5), "steps_per_period"),
        (lambda: jg.Direct(max_period=0), "max_period"),
        (lambda: jg.Direct(chunk_size=0), "chunk_size"),
        (lambda: jg.Runner(save="yes"), "save"),
        (lambda: jg.bifurcation_diagram(jg.REDUCED, p, "b", ["a"], [[1.0, 0, 5, 0]]), "values"),
        (lambda: jg.bifurcation_diagram(jg.REDUCED, p, "b", [4, 5], [[1.0, 0, 5, 0]], transient=-1), "transient"),
        (lambda: jg.Runner(restart=1), "restart"),
        (lambda: jg.find_periodic_orbits(jg.REDUCED, p, [[1.0, 0, 5, 0]], tol=-1), "tol"),
        (lambda: jg.find_periodic_orbits(jg.REDUCED, p, [[1.0, 0, 5, 0]], period=0), "period"),
    ]


API_IDS = ["strobo-periods-neg", "strobo-periods-frac", "box-count-frac", "box-count-zero", "box-bound-str",
           "box-bound-triple", "rpm-str", "face-width-bool", "amp-list-str", "grid-list", "method-name",
           "uncertainty", "integrator-0", "rk4-frac", "direct-max-period", "direct-chunk", "runner-save",
           "bif-values", "bif-transient", "runner-restart", "shoot-tol", "shoot-period"]


@pytest.mark.parametrize("i", range(len(API_IDS)), ids=API_IDS)
def test_api_refuses_bad_parameters(i):
    call, name = _api_cases()[i]
    with pytest.raises(ValueError) as exc:
        call()
    msg = str(exc.value)
    assert name in msg and "\n" not in msg, msg


# ----------------------------------------------------------------- valid values that were refused
def test_values_starting_with_a_dash_are_values():
    parser = build_parser()
    a = parser.parse_args(["analyze", "--grid", "10,6,12", "--region", "-25:25,-10:20,-10:50", "--out", "D"])
    assert a.region == ((-25.0, 25.0), (-10.0, 20.0), (-10.0, 50.0))
    s = parser.parse_args(["shoot", "--from", "-5,0,8,0", "--period", "1", "--region", "-1:1,-.5:.5,-2:2,-3:3"])
    assert s.points == [(-5.0, 0.0, 8.0, 0.0)] and s.region[1] == (-0.5, 0.5)
    w = parser.parse_args(["sweep", "--param", "gamma_sr", "--values", "-0.1:0.1:3", "--out", "D"])
    assert w.values == "-0.1:0.1:3"
    c = parser.parse_args(["analyze", "--compare", "-5"])
    assert c.compare == -5  # a value (refused later for its range), not an unknown option
    with pytest.raises(SystemExit):
        parser.parse_args(["analyze", "--quiet", "-x"])  # a real unknown option is still refused


def test_help_defaults_parse():
    """The defaults that --help prints are accepted as they are printed."""
    parser = build_parser()
    helps = {}
    for cmd in ("analyze", "shoot", "sweep"):
        sub = parser._subparsers._group_actions[0].choices[cmd]
        helps[cmd] = " ".join(a.help or "" for a in sub._actions)
    assert "-25:25,-10:20,-10:50" in helps["analyze"]
    parser.parse_args(["analyze", "--region", "-25:25,-10:20,-10:50"])
    assert "-25:25,-10:20,-10:50,-5:5" in helps["shoot"]
    parser.parse_args(["shoot", "--random", "2", "--region", "-25:25,-10:20,-10:50,-5:5"])
    parser.parse_args(["sweep", "--param", "b", "--values", "3:7:41", "--region", "-25:25,-10:20,-10:50",
                       "--out", "D"])
    assert "default 1" in helps["analyze"].split("crossing direction")[1][:60]
    assert "poincare-like" in helps["analyze"].split("crossing direction")[0][-80:]


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"jaxgear {jg.__version__}"


def test_set_accepts_sweep_aliases():
    _, p = jg.resolve_params("paper", ["b=4"])
    assert float(p.b_sp) == 4.0 and float(p.b_rp) == 4.0
    _, p = jg.resolve_params("paper", ["kappa_amp=0.2"])
    assert float(p.kappa_sp_amp) == 0.2 and float(p.kappa_rp_amp) == 0.2


def test_warnings_are_one_line(capsys, monkeypatch):
    """A warning raised while a command runs prints as one line, without a source line."""
    import warnings

    import jaxgear.cli.params as params_cli

    def run(args):
        warnings.warn("something to know\nabout this run", UserWarning, stacklevel=2)
        return 0

    monkeypatch.setattr(params_cli, "run", run)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(["params"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["jaxgear params: warning: something to know about this run"]


def test_grammar_of_messages(tmp_path):
    from jaxgear._checks import article

    assert article("OrbitSearch") == "an OrbitSearch" and article("GlobalResult") == "a GlobalResult"
    import xarray as xr

    path = tmp_path / "o.nc"
    xr.Dataset(attrs={"jaxgear_type": "OrbitSearch", "jaxgear_format": 2}).to_netcdf(path, engine="h5netcdf")
    with pytest.raises(ValueError, match="holds an OrbitSearch, not a GlobalResult"):
        jg.load(path, expected="GlobalResult")


# ----------------------------------------------------------------- property tests
INT_OPTIONS = [  # (command prefix, option, smallest valid value)
    (["analyze"], "--steps-per-period", 1), (["analyze"], "--max-period", 1), (["analyze"], "--chunk-size", 1),
    (["analyze"], "--uncertainty-samples", 0), (["analyze"], "--compare", 1),
    (["shoot", "--from", "5,0,8,0"], "--max-iter", 1), (["shoot", "--from", "5,0,8,0"], "--verify", 1),
    (["shoot", "--from", "5,0,8,0"], "--period", 1), (["shoot"], "--random", 1),
    (SWEEP, "--transient", 0), (SWEEP, "--starts", 1), (SWEEP, "--max-period", 1), (SWEEP, "--seed", 0),
    (SWEEP, "--steps-per-period", 1),
]


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(INT_OPTIONS), st.integers(min_value=-10**6, max_value=-1))
def test_property_integer_options_below_range_are_refused(tmp_path_factory, capsys, opt, below):
    prefix, flag, low = opt
    out = tmp_path_factory.mktemp("prop") / "out"
    rc, err = _run([*prefix, flag, str(low + below), "--out", str(out)], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert flag in err and str(low + below) in err
    assert not out.exists()


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(["nan", "inf", "-inf", "0", "-1e-300", "-3.5", "abc"]))
def test_property_tolerance_outside_range_is_refused(capsys, tmp_path_factory, tol):
    out = tmp_path_factory.mktemp("prop") / "out"
    rc, err = _run(["shoot", "--from", "5,0,8,0", "--tol", tol, "--out", str(out)], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "--tol" in err, err
    assert not out.exists()


PHYSICAL_RANGES = {  # name: (low, high) inside the allowed range
    "Omega": (0.3, 2.0), "b": (0.0, 8.0), "kappa_amp": (0.0, 0.4), "c_sp": (0.0, 0.3), "face_width": (0.01, 0.08),
    "input_rpm": (100.0, 5000.0), "zeta_sp": (0.0, 0.2), "gamma_sr": (-3.0, 3.0),
}
OUTSIDE = {"Omega": -1.0, "b": -0.5, "face_width": 0.0, "input_rpm": -10.0, "zeta_sp": -0.1, "c_sp": -1.0}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(sorted(PHYSICAL_RANGES)), st.floats(0, 1), min_size=1, max_size=4))
def test_property_parameters_inside_range_give_finite_strict_json(capsys, draw):
    sets = [f"{k}={PHYSICAL_RANGES[k][0] + u * (PHYSICAL_RANGES[k][1] - PHYSICAL_RANGES[k][0])!r}"
            for k, u in draw.items()]
    if "Omega" in draw and "input_rpm" in draw:
        sets = [s for s in sets if not s.startswith("input_rpm")]
    argv = ["params", "--json"] + [a for s in sets for a in ("--set", s)]
    rc = main(argv)
    text = capsys.readouterr().out
    assert rc == 0, text
    d = json.loads(text, parse_constant=lambda c: pytest.fail(f"bare {c} in JSON"))
    assert all(math.isfinite(v) for v in _numbers(d))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(sorted(OUTSIDE)), st.floats(1.0, 100.0))
def test_property_parameters_outside_range_are_refused(capsys, tmp_path_factory, name, scale):
    out = tmp_path_factory.mktemp("prop") / "out"
    value = OUTSIDE[name] * scale
    rc, err = _run(["analyze", "--set", f"{name}={value!r}", "--out", str(out)], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert name in err or (name == "b" and "b_sp" in err) or (name == "c_sp" and "c_sp" in err), err
    assert not out.exists()


def _numbers(obj):
    if isinstance(obj, bool):
        return
    if isinstance(obj, (int, float)):
        yield float(obj)
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from _numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _numbers(v)


@pytest.mark.slow
@settings(max_examples=3, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.floats(0.75, 1.0), st.floats(2.0, 6.0))
def test_property_analysis_inside_range_has_no_nan_and_strict_json(tmp_path_factory, capsys, omega, b):
    """A small analysis of drawn parameters: finite labels and shares, a summary that is
    strict JSON (NaN written as null)."""
    out = tmp_path_factory.mktemp("prop") / "out"
    rc = main(["analyze", "--grid", "3,2,3", "--set", f"Omega={omega!r}", "--set", f"b={b!r}",
               "--steps-per-period", "40", "--uncertainty-samples", "0", "--no-figures", "--quiet",
               "--out", str(out)])
    capsys.readouterr()
    assert rc == 0
    s = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(f"bare {c}"))
    r = jg.load(out / "result.nc")
    assert np.all(np.isin(np.unique(r.labels), np.arange(-2, len(r.attractors))))
    shares = [a.share for a in r.attractors]
    assert all(math.isfinite(x) for x in shares)
    assert s["params"]["Omega"] == pytest.approx(omega)


def test_readme_synopses_match_help():
    """Every option of each command's --help is in the README's synopsis; required ones
    are shown without brackets, optional ones inside them."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    block = text[text.index("```text\njaxgear --version"):]
    block = block[: block.index("```\n", 8)]
    synopses, cmd = {}, None
    for line in block.splitlines()[1:]:
        m = re.match(r"jaxgear (\w+)", line)
        if m:
            cmd = m.group(1)
        if cmd:
            synopses[cmd] = synopses.get(cmd, "") + " " + line
    parser = build_parser()
    subs = parser._subparsers._group_actions[0].choices
    assert set(synopses) == set(subs)
    for cmd, sub in subs.items():
        for action in sub._actions:
            longs = [o for o in action.option_strings if o.startswith("--") and o != "--help"]
            if not longs:
                continue
            opt = longs[0]
            assert re.search(re.escape(opt) + r"\b", synopses[cmd]), (cmd, opt)
            bracketed = re.search(r"\[[^\]]*" + re.escape(opt) + r"\b", synopses[cmd]) is not None
            in_group = re.search(r"\([^)]*" + re.escape(opt) + r"\b", synopses[cmd]) is not None
            assert bracketed != (action.required or in_group), (cmd, opt)
