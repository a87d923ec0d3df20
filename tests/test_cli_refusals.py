"""The command line refuses what it cannot do before it starts: one line naming the option
or field, its value and what is allowed, exit status 2, nothing printed on stdout (no
header line), no output folder; work too large for the machine is refused in seconds.

Each row of the tables is a case of the hostile probe of the command line: argv (``{out}``
an output folder that must not appear), the exit status, the most lines the message may
have and a fragment it must contain.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import jaxgear as jg
from jaxgear.cli import build_parser, main

GIB = 1 << 30


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
                       (jaxgear.shooting, ("find_periodic_orbits", "verify_orbit", "seeds_in_box")),
                       (jaxgear.sweep, ("bifurcation_diagram", "basin_sweep", "basin_map")),
                       (jaxgear.continuation, ("continue_orbit",))):
        for n in names:
            monkeypatch.setattr(mod, n, forbidden)


@pytest.fixture
def machine_128gib(monkeypatch):
    """The memory estimate as on a machine of 128 GiB (the refusals do not depend on the
    machine the tests run on)."""
    import jaxgear._checks

    monkeypatch.setattr(jaxgear._checks, "physical_memory", lambda: 128 * GIB)


def _run(argv, capsys) -> tuple[int, str, str]:
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse
        rc = exc.code
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def _check_refusal(argv, rc_expected, max_lines, fragment, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a value such as --out -o names a folder here, never made
    out = tmp_path / "out"
    argv = [a.replace("{out}", str(out)) for a in argv]
    before = sorted(p.name for p in tmp_path.iterdir())
    t0 = time.perf_counter()
    rc, stdout, err = _run(argv, capsys)
    elapsed = time.perf_counter() - t0
    lines = err.strip().splitlines()
    assert rc == rc_expected, err
    assert 1 <= len(lines) <= max_lines, err
    assert fragment in lines[0] and "error" in lines[0], lines[0]
    assert stdout == "", stdout  # refused before the header line
    assert "Traceback" not in err and "_parse" not in err and "jaxgear._" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no folder, no staging folder, no probe
    return elapsed, lines[0]


# ----------------------------------------------------------------- unbounded work
HUGE_CASES = [
    (["sweep", "--param", "b_sp", "--values", "4:6:100000000", "--out", "{out}"], "--values=4:6:100000000"),
    (["sweep", "--param", "b_sp", "--values", "4:6:100000000", "--kind", "basins", "--out", "{out}"],
     "--values=4:6:100000000"),
    (["sweep", "--param", "b_sp", "--values", "4:6:1000000000000", "--out", "{out}"], "--values"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--starts", "1000000000", "--out", "{out}"],
     "--starts=1000000000"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--record", "2000000000", "--out", "{out}"], "--record"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "5000,5000,5000", "--out",
      "{out}"], "--grid=5000,5000,5000"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--param2", "Omega", "--values2", "0.5:1:100000000",
      "--kind", "basins", "--out", "{out}"], "--values2"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "continuation", "--from", "5,0,8,0",
      "--max-steps", "2000000000", "--out", "{out}"], "--max-steps"),
    (["shoot", "--random", "100000000"], "--random=100000000"),
    (["shoot", "--random", "3", "--periods", "1-2000000000"], "--periods"),
    (["shoot", "--from", "5,0,8,0", "--verify", "2000000000"], "--verify=2000000000"),
    (["analyze", "--grid", "100000,100000,100000", "--out", "{out}"], "--grid=100000,100000,100000"),
    (["analyze", "--max-period", "100000000", "--out", "{out}"], "--max-period=100000000"),
    # the cycle test of the lane pool holds K x K states (it passed the old, linear estimate)
    (["analyze", "--grid", "8,5,10", "--max-period", "10000", "--out", "{out}"], "--max-period=10000"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "8,5,10", "--max-period", "10000",
      "--out", "{out}"], "--max-period=10000"),
]


@pytest.mark.parametrize("argv, fragment", HUGE_CASES, ids=[" ".join(c[0]) for c in HUGE_CASES])
def test_huge_counts_are_refused_in_seconds(argv, fragment, tmp_path, capsys, monkeypatch, no_work,
                                            machine_128gib):
    elapsed, line = _check_refusal(argv, 2, 1, fragment, tmp_path, capsys, monkeypatch)
    assert elapsed < 5.0, elapsed
    assert "memory" in line and "at most" in line, line


def test_the_largest_count_named_fits_and_one_more_does_not(monkeypatch):
    """The bound of the message is the bound applied: the count it names is accepted and
    the next one refused (machine of 1 GiB: 512 MiB for the work)."""
    import re

    import jaxgear._checks
    from jaxgear._checks import check_memory

    monkeypatch.setattr(jaxgear._checks, "physical_memory", lambda: GIB)
    with pytest.raises(ValueError) as exc:
        check_memory("--random", 10**9, 10**9, 1000, "seeds")
    most = int(re.search(r"at most ([\d,]+) seeds", str(exc.value)).group(1).replace(",", ""))
    assert most == (GIB // 2) // 1000  # 536,870 seeds of 1000 bytes in half a GiB
    assert check_memory("--random", most, most, 1000, "seeds") == most
    with pytest.raises(ValueError, match="--random"):
        check_memory("--random", most + 1, most + 1, 1000, "seeds")


def test_ordinary_work_is_not_refused(capsys, monkeypatch):
    """The paper's analysis, a 41-value sweep with 16 starts and a 64-seed search fit a
    machine of 4 GiB: the estimates refuse only what cannot fit."""
    import jaxgear._checks
    from jaxgear.cli import analyze, sweep
    from jaxgear.cli.common import check_shoot_work

    monkeypatch.setattr(jaxgear._checks, "physical_memory", lambda: 4 * GIB)
    parser = build_parser()
    a = parser.parse_args(["analyze", "--out", "D"])
    method = analyze.build_method(a)
    analyze._check_work(a, method, (50, 30, 60))
    s = parser.parse_args(["sweep", "--param", "b", "--values", "3:7:41", "--out", "D"])
    sweep._check_bifurcation_work(s, 41)
    b = parser.parse_args(["sweep", "--param", "b", "--values", "3:7:41", "--kind", "basins", "--out", "D"])
    sweep._check_basins_work(b, (20, 12, 24), 41)
    r = parser.parse_args(["shoot", "--random", "64", "--periods", "1-8"])
    check_shoot_work(r, r.periods)


def test_cell_grid_refuses_what_it_cannot_number_or_hold(monkeypatch):
    import jaxgear._checks

    with pytest.raises(ValueError, match="counts"):
        jg.CellGrid.box([(0, 1)] * 4, (10**7,) * 4)  # 1e28 cells: beyond int64 cell numbers
    monkeypatch.setattr(jaxgear._checks, "physical_memory", lambda: 128 * GIB)
    grid = jg.CellGrid.paper((100000, 100000, 100000))
    assert grid.n_cells == 10**15  # exact (no int64 product wrapping)
    with pytest.raises(ValueError, match="counts") as exc:  # not numpy's MemoryError of 7 PiB
        grid.centres()
    assert "memory" in str(exc.value)
    np.testing.assert_allclose(grid.centres([0]), [[-25 + 2.5e-4, -10 + 1.5e-4, -10 + 3e-4, 0.0]])


# ----------------------------------------------------------------- refusals of the probe
PROBE_CASES = [
    # duplicate --set names (directly, through an alias, through dimless.)
    (["analyze", "--set", "b_sp=1", "--set", "b_sp=2", "--out", "{out}"], 2, 1, "b_sp is set twice"),
    (["params", "--set", "b=4", "--set", "b_rp=2"], 2, 1, "b_rp is set twice"),
    (["shoot", "--from", "5,0,8,0", "--set", "Omega=0.9", "--set", "dimless.Omega=1"], 2, 1, "Omega is set twice"),
    # values that begin with '-': taken as values (the row fails on another option) ...
    (["shoot", "--from", "5,0,8", "--out", "-o"], 2, 1, "--from"),
    (["analyze", "--grid", "2,2", "--out", "-dash"], 2, 1, "--grid"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "3,3", "--out", "-dash"],
     2, 1, "--grid"),
    # ... or, when the value is an option's name, the message says how to write it
    (["analyze", "--out", "-h"], 2, 1, "--out=-VALUE"),
    (["shoot", "--from", "5,0,8,0", "--out", "--quiet"], 2, 1, "--out=-VALUE"),
    # a range, not a non-finite vector field
    (["analyze", "--set", "Omega=1e300", "--out", "{out}"], 2, 1, "Omega=1e+300 is out of range"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--set", "c_sp=1e13", "--out", "{out}"], 2, 1,
     "c_sp=1e+13 is out of range"),
    # messages that leaked or misled
    (["shoot", "--periods", "8-1", "--random", "3"], 2, 1, "--periods needs 1 <= K1 <= K2 <= 2147483647, got '8-1'"),
    (["shoot", "--periods", "a-b", "--random", "3"], 2, 1, "--periods expects K1-K2"),
    (["shoot", "--from", "5,0,8,0", "--tol", "0"], 2, 1, "--tol=0 is out of range: it must be > 0."),
    # integers beyond the compiled kernels' 32-bit counters (the seed was an OverflowError traceback)
    (["shoot", "--random", "3", "--seed", str(10**30)], 2, 1, "--seed=" + str(10**30) + " is out of range: it "
     "must be an integer in [0, 2147483647]."),
    (["sweep", "--param", "b", "--values", "4:6:3", "--seed", str(2**31), "--out", "{out}"], 2, 1, "--seed"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--transient", str(2**31), "--out", "{out}"], 2, 1,
     "--transient"),
    (["analyze", "--steps-per-period", str(2**40), "--out", "{out}"], 2, 1, "--steps-per-period"),
    (["shoot", "--from", "5,0,8,0", "--period", str(2**31)], 2, 1, "--period"),
    (["shoot", "--random", "3", "--periods", f"1-{2**31}"], 2, 1, "--periods"),
    # questionable acceptance
    (["analyze", "--region", "-1e300:1e300,-1e300:1e300,-1e300:1e300", "--out", "{out}"], 2, 1,
     "beyond the escape bound"),
    (["analyze", "--region", "-2e6:2e6,-10:20,-10:50", "--out", "{out}"], 2, 1, "beyond the escape bound"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--region", "-1e300:1e300,-10:20,-10:50",
      "--out", "{out}"], 2, 1, "beyond the escape bound"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--region", "-1e7:1e7,-10:20,-10:50", "--out", "{out}"],
     2, 1, "beyond the escape bound"),
    (["analyze", "--method", "poincare-like", "--mapping-steps", "0", "--out", "{out}"], 2, 1,
     "--mapping-steps=0 is out of range"),
    # row 6: the check by direct integration shorter than the orbit (failed after the search)
    (["shoot", "--from", "5.3298,-0.0849,8.0966,-0.9659", "--period", "8", "--verify", "5"], 2, 1,
     "--verify=5 is shorter than the longest orbit: --period/--periods asks for period 8"),
    (["shoot", "--random", "3", "--periods", "1-400"], 2, 1, "--verify (default 300) is shorter"),
    # row 8: one cell on an axis (failed after the analysis, in its basin entropy)
    (["analyze", "--grid", "1,1,1", "--out", "{out}"], 2, 1, "needs at least 2 cells on every axis"),
    (["analyze", "--method", "stroboscopic", "--grid", "3,3,1,3", "--out", "{out}"], 2, 1,
     "needs at least 2 cells on every axis"),
    (["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "3,1,3", "--out", "{out}"], 2, 1,
     "needs at least 2 cells on every axis"),
    # row 15: digits grouped with '_' (Python reads 0_9 as 9)
    (["analyze", "--set", "Omega=0_9", "--out", "{out}"], 2, 1, "numbers are written without '_' (got '0_9')"),
    (["params", "--set", "b_sp=1_5"], 2, 1, "without '_'"),
    (["analyze", "--grid", "5_0,30,60", "--out", "{out}"], 2, 1, "without '_'"),
    (["analyze", "--region", "-2_5:25,-10:20,-10:50", "--out", "{out}"], 2, 1, "without '_'"),
    (["analyze", "--max-period", "1_6", "--out", "{out}"], 2, 1, "without '_'"),
    (["shoot", "--from", "5_0,0,8,0"], 2, 1, "without '_'"),
    (["shoot", "--random", "3", "--tol", "1e-1_0"], 2, 1, "without '_'"),
    (["shoot", "--random", "3", "--periods", "1-1_0"], 2, 1, "without '_'"),
    (["sweep", "--param", "b", "--values", "4:6:1_0", "--out", "{out}"], 2, 1, "without '_'"),
    (["sweep", "--param", "b", "--values", "4_0:60:3", "--out", "{out}"], 2, 1, "without '_'"),
]


@pytest.mark.parametrize("argv, rc, max_lines, fragment", PROBE_CASES, ids=[" ".join(c[0]) for c in PROBE_CASES])
def test_probe_refusals(argv, rc, max_lines, fragment, tmp_path, capsys, monkeypatch, no_work):
    _check_refusal(argv, rc, max_lines, fragment, tmp_path, capsys, monkeypatch)


@pytest.fixture(scope="module")
def duffing_result(tmp_path_factory):
    """A saved global result of another system (a Duffing oscillator)."""
    import jaxgear as jg

    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3, omega=1.3)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (4, 3), names=("x", "v"))
    r = jg.analyze_global(jg.DUFFING, p, grid, jg.Direct(integrator=jg.RK4(32), max_period=4), uncertainty=0)
    path = tmp_path_factory.mktemp("duffing") / "result.nc"
    r.save(path)
    return path


def test_seeds_from_a_result_of_another_system_name_it(duffing_result, tmp_path, capsys, monkeypatch, no_work):
    _check_refusal(["shoot", "--seeds-from", str(duffing_result)], 2, 1, "another system ('duffing')", tmp_path,
                   capsys, monkeypatch)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
def test_out_where_no_folder_can_be_made_is_refused_before_the_header(tmp_path, capsys, monkeypatch, no_work):
    _, line = _check_refusal(["analyze", "--out", "/proc/x"], 2, 1, "--out='/proc/x'", tmp_path, capsys,
                             monkeypatch)
    assert "cannot be written" in line or "not writable" in line, line


def test_values_beginning_with_a_dash_parse_as_values():
    parser = build_parser()
    assert parser.parse_args(["analyze", "--out", "-dash"]).out == "-dash"
    assert parser.parse_args(["shoot", "--random", "2", "--out", "-o"]).out == "-o"
    assert parser.parse_args(["sweep", "--param", "b", "--values", "4:6:3", "--out", "-x-y"]).out == "-x-y"
    assert parser.parse_args(["analyze", "--preset", "-p"]).preset == "-p"  # then refused as an unknown preset
    for argv in (["analyze", "-dash"], ["analyze", "--quiet", "-x"], ["analyze", "--nosuch"]):
        with pytest.raises(SystemExit):  # a word with a dash standing alone is still refused
            parser.parse_args(argv)


def test_set_once_per_parameter_keeps_distinct_ones():
    parser = build_parser()
    a = parser.parse_args(["analyze", "--set", "b_sp=1", "--set", "b_rp=2", "--set", "Omega=0.8"])
    assert a.overrides == ["b_sp=1", "b_rp=2", "Omega=0.8"]


# ----------------------------------------------------------------- resume mismatches
def _manifest(out: Path, kind: str, settings: dict) -> None:
    out.mkdir(parents=True)
    (out / "manifest.json").write_text(json.dumps({"kind": kind, "hash": "0" * 64, "settings": settings}))
    (out / "parts").mkdir()


def test_resume_with_another_grid_or_set_names_the_fields(tmp_path, capsys, no_work):
    """A basin sweep saved with 4 x 4 x 4 cells and c_sp = 0.05, resumed with --grid 3,3,3 and
    --set c_sp=0.07: refused before the header, naming exactly grid.counts and params.c_sp
    with both values (nothing cut off, nothing else listed)."""
    out = tmp_path / "S"
    _, p = jg.resolve_params("paper", [])
    params = p.uniform().to_dict()
    grid = {"axes": [0, 1, 2], "base": [0.0, 0.0, 0.0, 0.0], "counts": [4, 4, 4], "lower": [-25.0, -10.0, -10.0],
            "upper": [25.0, 20.0, 50.0], "names": ["x1", "x2", "x3", "x4"]}
    _manifest(out, "basins", {"kind": "basins", "system": "planetary-reduced", "param": "b",
                              "values": [4.0, 5.0, 6.0], "params": dict(params, c_sp=0.05), "grid": grid,
                              "match_tol": 1.0})
    rc, stdout, err = _run(["sweep", "--param", "b", "--values", "4:6:3", "--kind", "basins", "--grid", "3,3,3",
                            "--set", "c_sp=0.07", "--out", str(out)], capsys)
    assert rc == 2 and stdout == "", (stdout, err)
    line, = err.strip().splitlines()
    diff = line.split("differing: ")[1].split(");")[0]
    assert diff == "grid.counts: [4, 4, 4] saved vs [3, 3, 3] now; params.c_sp: 0.05 saved vs 0.07 now", line
    assert line.endswith("or restart (--restart) to discard it.")
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "parts"]  # untouched


def test_diff_settings_names_leaves_and_counts_long_lists():
    from jaxgear.sweep._checkpoint import diff_settings

    a = {"grid": {"axes": [0, 1, 2], "base": [0.0] * 4, "counts": [20, 12, 24], "lower": [-25.0, -10.0, -10.0]},
         "values": np.linspace(3, 7, 41).tolist(), "starts": [[1.0, 2.0, 3.0, 4.0]], "method": "direct"}
    b = dict(a, values=np.linspace(3, 8, 41).tolist(), starts=[[1.0, 2.5, 3.0, 4.0]])
    b["grid"] = dict(a["grid"], lower=[-25.0, -11.0, -10.0])
    text = diff_settings(a, b)
    parts = text.split("; ")
    assert parts[0] == "grid.lower: [-25.0, -10.0, -10.0] saved vs [-25.0, -11.0, -10.0] now"
    assert parts[1] == "starts: [[1.0, 2.0, 3.0, 4.0]] saved vs [[1.0, 2.5, 3.0, 4.0]] now"
    assert parts[2].startswith("values: 40 of 41 entries differ, first values[1]: 3.1 saved vs 3.125 now")
    assert len(parts) == 3 and "method" not in text
    assert diff_settings({"values": [1.0] * 50}, {"values": [1.0] * 60}) == "values: 50 entries saved vs 60 now"


class _Captured(Exception):
    pass


@pytest.mark.parametrize("kind", ["bifurcation", "basins", "basin_map"])
def test_resume_check_of_the_command_line_agrees_with_the_sweep(kind, tmp_path, capsys, monkeypatch):
    """The settings the command line compares before its header are those the sweep
    functions save in the manifest (so an unchanged command always resumes): both are
    captured from one command, the sweep stopped before it computes."""
    import jaxgear.cli.sweep as sweep_cli
    import jaxgear.sweep._basin_map
    import jaxgear.sweep._basins
    import jaxgear.sweep._runner

    seen = {}
    monkeypatch.setattr(sweep_cli, "check_resume", lambda out, now: seen.setdefault("cli", now))

    def stop(*args, **kw):
        seen["lib"] = next(a for a in args if isinstance(a, dict) and "kind" in a)
        raise _Captured

    monkeypatch.setattr(jaxgear.sweep._runner.Runner, "blocks", stop)
    monkeypatch.setattr(jaxgear.sweep._basins, "analyses_at", stop)
    monkeypatch.setattr(jaxgear.sweep._basin_map, "analyses_at", stop)
    argv = ["sweep", "--param", "b", "--values", "4:6:3", "--set", "c_sp=0.07", "--quiet", "--no-figures",
            "--out", str(tmp_path / "S")]
    argv += {"bifurcation": ["--starts", "3", "--record", "40", "--direction", "both"],
             "basins": ["--kind", "basins", "--grid", "3,2,3", "--uncertainty-samples", "7"],
             "basin_map": ["--kind", "basins", "--grid", "3,2,3", "--param2", "Omega", "--values2", "0.8:0.9:2"]}[kind]
    with pytest.raises(_Captured):
        main(argv)
    capsys.readouterr()
    lib = json.loads(json.dumps(seen["lib"]))
    cli = json.loads(json.dumps(seen["cli"]))
    assert cli["kind"] == lib["kind"] == kind
    assert {"params", "values" if kind != "basin_map" else "values_x"} <= set(cli)
    assert {"bifurcation": {"starts", "integrator"}, "basins": {"grid", "method", "uncertainty"},
            "basin_map": {"grid", "method", "values_y"}}[kind] <= set(cli)
    assert {k: lib[k] for k in cli} == cli


# ----------------------------------------------------------------- label uncertainty
def test_label_uncertainty_is_not_measured_without_resolved_cells():
    import jaxgear as jg
    from jaxgear.analysis import LabelUncertainty
    from jaxgear.cli.common import NOT_MEASURED, with_uncertainty_line

    u = LabelUncertainty(samples=64, step=0.0, start=0.0, perturbation=1e-3, refined_integrator=jg.KinkAwareRK4(400))
    table = "id period cells\nunresolved - 12 100.00 %\n" + u.describe()
    chaotic = SimpleNamespace(uncertainty=u, n_cells=12, n_unresolved=12)
    text = with_uncertainty_line(table, chaotic)
    assert text.splitlines()[-1] == NOT_MEASURED == "label uncertainty: not measured: no resolved cells"
    assert "0.0 %" not in text and text.splitlines()[:2] == table.splitlines()[:2]
    resolved = SimpleNamespace(uncertainty=u, n_cells=12, n_unresolved=11)  # one cell resolved: measured
    assert with_uncertainty_line(table, resolved) == table


def test_sweep_label_uncertainty_only_over_values_with_resolved_cells():
    from jaxgear.cli.common import NOT_MEASURED, shares_uncertainty_line

    sweep = SimpleNamespace(uncertainty_step=np.array([0.0, 0.25, 0.5, np.nan]),
                            uncertainty_start=np.array([0.0, 0.125, 0.25, np.nan]),
                            unresolved_share=np.array([1.0, 0.0, 0.5, 0.0]))
    line = shares_uncertainty_line(sweep)
    assert line.startswith("label uncertainty: at most 50.0 % of the sampled cells change label")
    assert "mean 37.5 % and 18.8 % over the 2 values with resolved cells" in line
    assert line.endswith("; not measured at 1 values: no resolved cells")
    chaotic = SimpleNamespace(uncertainty_step=np.zeros(3), uncertainty_start=np.zeros(3),
                              unresolved_share=np.ones(3))
    assert shares_uncertainty_line(chaotic) == NOT_MEASURED
    unmeasured = SimpleNamespace(uncertainty_step=np.full(3, np.nan), uncertainty_start=np.full(3, np.nan),
                                 unresolved_share=np.zeros(3))
    assert shares_uncertainty_line(unmeasured) == ""


def test_region_check_uses_the_farthest_corner_of_the_box():
    """The farthest corner of [-1, 1]^2 lies at sqrt(2) = 1.414; with a fixed third
    coordinate 1 at sqrt(3) = 1.732: a bound of 1.5 lies between the two."""
    from jaxgear.cli.common import check_region

    box = ((-1.0, 1.0), (-0.5, 1.0))
    check_region(box, "--region", 2, ("x", "y"), escape_bound=1.5)
    with pytest.raises(ValueError, match=r"reaches \|x\| = 1.73, beyond the escape bound 1.5"):
        check_region(box, "--region", 2, ("x", "y"), escape_bound=1.5, base=(1.0,))
    with pytest.raises(ValueError, match="the box -1e\\+300:1e\\+300,-0.5:1 reaches"):  # no overflow
        check_region(((-1e300, 1e300), (-0.5, 1.0)), "--region", 2, ("x", "y"), escape_bound=1e6)


# ----------------------------------------------------------------- row 6: --verify against --seeds-from
@pytest.mark.parametrize("period, verify, fragment", [
    (8, "5", "--verify=5 is shorter than the longest orbit: the attractors of --seeds-from R.nc have period 8"),
    (2**31 - 1, None, "--verify (default 300) is shorter than the longest orbit: the attractors of --seeds-from R.nc "
     "have period 2147483647"),  # a crafted file
])
def test_seeds_from_periods_longer_than_verify_are_refused(period, verify, fragment, tmp_path, capsys, monkeypatch,
                                                          no_work):
    import jaxgear.cli.shoot as shoot_cli

    monkeypatch.setattr(shoot_cli, "_load_seeds",
                        lambda path, system: (SimpleNamespace(params=None), {period: np.array([[5.3, -0.08, 8.1, -1.0]])}))
    argv = ["shoot", "--seeds-from", "R.nc"] + (["--verify", verify] if verify else [])
    _check_refusal(argv, 2, 1, fragment, tmp_path, capsys, monkeypatch)


# ----------------------------------------------------------------- rows 5, 13: --out a link
@pytest.mark.parametrize("kind", ["loop", "dangling"])
def test_out_a_link_that_leads_nowhere_is_refused_before_work(kind, tmp_path, capsys, monkeypatch, no_work):
    out = tmp_path / "out"
    if kind == "loop":
        (tmp_path / "back").symlink_to(out)
        out.symlink_to(tmp_path / "back")
    else:
        out.symlink_to(tmp_path / "gone")
    fragment = "a loop of symbolic links" if kind == "loop" else "which does not exist"
    for argv in (["analyze", "--out", "{out}"], ["sweep", "--param", "b", "--values", "4:6:3", "--out", "{out}"],
                 ["shoot", "--from", "5,0,8,0", "--out", "{out}"]):
        _check_refusal(argv, 2, 1, fragment, tmp_path, capsys, monkeypatch)
        assert out.is_symlink()
