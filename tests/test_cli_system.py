"""``jaxgear analyze|shoot|sweep --system MODULE:ATTRIBUTE``: a user's ForcedSystem on the
command line (jaxgear/cli/_system_spec.py), run in-process with ``jaxgear.cli.main``.

References that do not come from the code: the forced linear oscillator
``x'' + delta x' + alpha x = gamma cos(omega t)`` has one P-1 motion whose state at phase 0
is ``(Re(H gamma), Re(i omega H gamma))`` with ``H = 1 / (alpha - omega^2 + i delta omega)``
and both Floquet multipliers of modulus ``exp(-delta T / 2)`` (``T = 2 pi / omega``), so
``lambda_1 = -delta T / 2`` per period; Ueda's oscillator ``x'' + 0.05 x' + x^3 = 7.5 cos t``
is chaotic, with exponents that add up to ``-delta T`` (the constant divergence of the
field; Ueda, J. Stat. Phys. 20, 181, 1979).
"""

from __future__ import annotations

import json
import math
import os
import re
import textwrap

import numpy as np
import pytest

from jaxgear.cli import main

MODULE = textwrap.dedent('''
    """A user's model file: the forced Duffing oscillator written from scratch."""
    from types import SimpleNamespace
    from typing import NamedTuple

    import jax.numpy as jnp
    import jaxgear as jg


    class Duffing(NamedTuple):
        delta: float
        alpha: float
        beta: float
        gamma: float
        omega: float


    def field(t, x, p):
        return jnp.stack([x[1], p.gamma * jnp.cos(p.omega * t) - p.delta * x[1] - p.alpha * x[0]
                          - p.beta * x[0] ** 3])


    SYSTEM = jg.ForcedSystem(field, period=lambda p: 2 * jnp.pi / p.omega, state_names=("x", "v"),
                             section_index=1, name="user-duffing")
    PARAMS = Duffing(delta=0.05, alpha=0.0, beta=1.0, gamma=7.5, omega=1.0)   # Ueda's chaotic oscillator
    REGION = ((-4.0, 4.0), (-8.0, 8.0))
    GRID = (3, 3)

    LINEAR = SimpleNamespace(system=SYSTEM, params=Duffing(delta=0.2, alpha=1.0, beta=0.0, gamma=1.0, omega=1.3),
                             region=((-3.0, 3.0), (-3.0, 3.0)), grid=(3, 3))


    def linear():
        return {"system": SYSTEM, "params": LINEAR.params, "region": LINEAR.region}


    def broken():
        raise RuntimeError("no licence for this model")


    NOT_A_SYSTEM = 3
    NO_PARAMS = {"system": SYSTEM}

    COMPLEX = SimpleNamespace(system=jg.ForcedSystem(lambda t, x, p: x.astype(jnp.complex128), period=lambda p: 1.0,
                                                     state_names=("x", "v")), params={"a": 1.0})
    INTEGER = SimpleNamespace(system=jg.ForcedSystem(lambda t, x, p: jnp.zeros(2, jnp.int32), period=lambda p: 1.0,
                                                     state_names=("x", "v")), params={"a": 1.0})
''')

DELTA, ALPHA, OMEGA = 0.2, 1.0, 1.3


def linear_point(gamma: float) -> np.ndarray:
    """The P-1 motion of the forced linear oscillator at phase 0 (closed form)."""
    h = gamma / (ALPHA - OMEGA**2 + 1j * DELTA * OMEGA)
    return np.array([h.real, (1j * OMEGA * h).real])


@pytest.fixture
def usermod(tmp_path, monkeypatch):
    """The folder holding ``usermod.py``, made the current folder (the module is found
    there, as the console script finds a model file next to the user)."""
    (tmp_path / "usermod.py").write_text(MODULE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    import sys

    for name in [n for n, m in sys.modules.items() if str(getattr(m, "__file__", "")).startswith(str(tmp_path))]:
        del sys.modules[name]  # the next test's usermod is another file


def _rows(text: str) -> dict[str, str]:
    """The attractor table's rows by id."""
    return {m.group(1): m.group(0) for m in re.finditer(r"^(\d+|sink|unresolved)\s.*$", text, flags=re.M)}


@pytest.mark.slow  # about 25 s on two cores, most of it compiling the lane pool
def test_analyze_runs_a_user_system_with_set_and_its_region(usermod, capsys):
    """The object's region and counts, --set on a field of its NamedTuple parameters: the
    table holds the closed-form P-1 point for gamma = 2 (twice the object's forcing) and
    lambda_1 = -delta T / 2."""
    out = usermod / "out"
    rc = main(["analyze", "--system", "usermod:LINEAR", "--set", "gamma=2", "--uncertainty-samples", "0",
               "--quiet", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "9 cells, system usermod:LINEAR (user-duffing)" in text
    rows = _rows(text)
    assert set(rows) == {"0", "sink"}, text
    row = rows["0"]
    assert re.search(r"\bP-1\s+9\s+100\.00 %", row), row
    point = np.array([float(v) for v in re.search(r"\[([^\]]+)\]", row).group(1).split(",")])
    np.testing.assert_allclose(point, linear_point(2.0), atol=2e-4)
    lam = float(re.search(r"([+-]\d\.\d+) \(Floquet\)", row).group(1))  # a cycle's exponent is exact
    assert lam == pytest.approx(-DELTA * math.pi / OMEGA, abs=2e-4)
    assert {p.name for p in out.iterdir()} >= {"result.nc", "domains.png", "attractors.png"}  # figures of 2 coordinates


def test_shoot_runs_a_user_system_given_by_a_function(usermod, capsys):
    """A function returning a dict provides the system; shooting finds the closed-form
    orbit and its multipliers, of modulus exp(-delta T / 2)."""
    rc = main(["shoot", "--system", "usermod:linear", "--from", "0,0", "--json", "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    report = json.loads(text)
    assert report["system"] == "user-duffing" and report["params"]["gamma"] == 1.0
    (orbit,) = report["orbits"]
    np.testing.assert_allclose(np.asarray(orbit["points"]).reshape(-1), linear_point(1.0), atol=1e-8)
    np.testing.assert_allclose(orbit["multipliers_abs"], [math.exp(-DELTA * math.pi / OMEGA)] * 2, rtol=1e-6)


@pytest.mark.slow
def test_analyze_finds_ueda_chaotic_attractor(usermod, capsys):
    """Ueda's oscillator from a bare ForcedSystem with the module's PARAMS, REGION and GRID:
    one chaotic attractor, lambda_1 > 0, exponents adding up to -delta T."""
    import jaxgear

    out = usermod / "out"
    rc = main(["analyze", "--system", "usermod:SYSTEM", "--uncertainty-samples", "0", "--no-figures", "--quiet",
               "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert re.search(r"^0\s+chaotic\s+9\s+100\.00 %", text, flags=re.M), text
    (a,) = jaxgear.load(out / "result.nc").attractors
    assert a.period == 0 and a.largest_exponent > 0.3
    assert a.exponents.sum() == pytest.approx(-0.05 * 2 * math.pi, abs=1e-4)  # to RK4's error at 200 steps


@pytest.mark.slow
def test_sweep_bifurcation_of_a_user_system_follows_the_closed_form(usermod, capsys):
    """A bifurcation sweep over the user's field gamma: the recorded points of the one
    start are the closed-form P-1 point at every value."""
    import jaxgear

    out = usermod / "sweep"
    rc = main(["sweep", "--system", "usermod:LINEAR", "--param", "gamma", "--values", "0.5:1.5:3", "--from", "0,0",
               "--direction", "independent", "--transient", "200", "--record", "5", "--max-period", "2",
               "--quiet", "--out", str(out)])
    assert rc == 0, capsys.readouterr().out
    assert (out / "bifurcation.png").is_file()
    d = jaxgear.load(out / "bifurcation.nc")
    assert d.system == "user-duffing" and list(d.period[0, :, 0]) == [1, 1, 1]
    for i, g in enumerate([0.5, 1.0, 1.5]):
        np.testing.assert_allclose(d.points[0, i, 0], np.tile(linear_point(g), (5, 1)), atol=1e-6)


REFUSALS = [
    (["--system", "usermod"], "--system expects MODULE:ATTRIBUTE"),
    (["--system", "usermod:"], "--system expects MODULE:ATTRIBUTE"),
    (["--system", ":SYSTEM"], "--system expects MODULE:ATTRIBUTE"),
    (["--system", "nosuchmodule_xyz:SYSTEM"], "no module named 'nosuchmodule_xyz'"),
    (["--system", "usermod:MISSING"], "usermod has no attribute 'MISSING' (its ForcedSystem attributes: SYSTEM)"),
    (["--system", "usermod.py:MISSING"], "usermod.py has no attribute 'MISSING'"),
    (["--system", "usermod:NOT_A_SYSTEM"], "NOT_A_SYSTEM is an object of type int, not a jaxgear.ForcedSystem"),
    (["--system", "usermod:Duffing"], "Duffing is the class Duffing, not a jaxgear.ForcedSystem"),
    (["--system", "usermod:NO_PARAMS"], "no parameters: define NO_PARAMS.params"),
    (["--system", "usermod:broken"], "calling broken() failed: RuntimeError: no licence for this model"),
    (["--system", "usermod:LINEAR", "--set", "kappa=1"], "unknown parameter 'kappa'"),
    (["--system", "usermod:LINEAR", "--set", "omega=-1"], "forcing period must be positive"),
    (["--system", "usermod:LINEAR", "--preset", "other"], "--preset other is a gear set"),
    (["--system", "usermod:LINEAR", "--region", "-1:1,-1:1,-1:1"], "user-duffing has 2 coordinates (x, v)"),
    (["--system", "usermod:LINEAR", "--grid", "3,3,3"], "--grid needs 2 counts (x, v)"),
    (["--system", "usermod:LINEAR", "--method", "poincare-like"], "give 1 --region ranges"),
    # row 11: a field that is not real floating point
    (["--system", "usermod:COMPLEX"], "must return real floating-point values (float64); it returned dtype complex128"),
    (["--system", "usermod:INTEGER"], "must return real floating-point values (float64); it returned dtype int32"),
    # row 12: a period whose time steps vanish in rounding
    (["--system", "usermod:LINEAR", "--set", "omega=1e300"], "the forcing period 6.28319e-300 is too small for "
     "float64 times"),
]


@pytest.mark.parametrize("argv, message", REFUSALS, ids=[" ".join(a) for a, _ in REFUSALS])
def test_analyze_refuses_a_bad_system_in_one_line(usermod, capsys, argv, message):
    """Every bad --system (and option that does not fit the system) is refused before any
    integration: exit 2, one line on stderr naming the problem, nothing on stdout, no
    output folder."""
    rc = main(["analyze", *argv, "--quiet", "--no-figures", "--out", str(usermod / "out")])
    cap = capsys.readouterr()
    assert rc == 2
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxgear analyze: error: "), cap.err
    assert message in lines[0], lines[0]
    assert cap.out == "" and not (usermod / "out").exists()


@pytest.mark.parametrize("command", [["shoot", "--from", "0,0"],
                                     ["sweep", "--param", "gamma", "--values", "1:2:3", "--out", "o"]])
def test_shoot_and_sweep_refuse_a_bad_system_in_one_line(usermod, capsys, command):
    rc = main([command[0], "--system", "usermod:NOT_A_SYSTEM", *command[1:], "--quiet"])
    cap = capsys.readouterr()
    assert rc == 2 and cap.out == ""
    (line,) = cap.err.strip().splitlines()
    assert line.startswith(f"jaxgear {command[0]}: error: --system usermod:NOT_A_SYSTEM: NOT_A_SYSTEM is"), line


def test_shoot_random_needs_a_box_over_every_coordinate(usermod, capsys):
    """``--random`` draws in the object's region only where it has one range per coordinate."""
    (usermod / "onsection.py").write_text("from usermod import SYSTEM, PARAMS\nREGION = ((-4.0, 4.0),)\n")
    rc = main(["shoot", "--system", "onsection:SYSTEM", "--random", "4", "--quiet"])
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and "--random needs a box over every coordinate: give --region with 2 LO:HI ranges (x, v)" in line
    assert line.endswith("gives 1.")


def test_sweep_refuses_a_parameter_the_system_does_not_have(usermod, capsys):
    rc = main(["sweep", "--system", "usermod:LINEAR", "--param", "b_sp", "--values", "1:2:3", "--kind", "basins",
               "--out", str(usermod / "o"), "--quiet"])
    cap = capsys.readouterr()
    assert rc == 2
    assert "unknown parameter 'b_sp'" in cap.err and "delta, alpha, beta, gamma, omega" in cap.err


def _bad_module(folder, kind: str) -> str:
    """A --system spec of a module with a problem of ``kind`` (written into ``folder``)."""
    if kind == "exits":
        (folder / "exits.py").write_text("import sys\nprint('a script')\nsys.exit(0)\n")
        return "exits:SYSTEM"
    if kind == "exits in a file":
        (folder / "exits2.py").write_text("import sys\nsys.exit(3)\n")
        return "./exits2.py:SYSTEM"
    if kind == "exits in a function":
        (folder / "exits3.py").write_text("import sys\ndef make():\n    sys.exit(0)\n")
        return "exits3:make"
    if kind == "stdlib name":
        (folder / "json.py").write_text("from usermod import SYSTEM, PARAMS, REGION\n")
        return "json:SYSTEM"
    if kind == "stdlib name, no file":
        return "string:SYSTEM"
    name = os.fsdecode(b"mod\xff")  # a non-UTF-8 file name
    (folder / f"{name}.py").write_text("from usermod import SYSTEM, PARAMS, REGION\n")
    return f"./{name}.py:SYSTEM"


@pytest.mark.parametrize("kind, message", [
    ("exits", "--system exits:SYSTEM: importing exits called sys.exit(0) (a script's exit): a module given to "
     "--system must only define things"),
    ("exits in a file", "loading ./exits2.py called sys.exit(3)"),
    ("exits in a function", "calling make() called sys.exit(0)"),
    ("stdlib name", "json is a module of Python's standard library, which Python imports instead of ./json.py: "
     "give the file, --system ./json.py:SYSTEM"),
    ("stdlib name, no file", "string has no attribute 'SYSTEM' (string is a module of Python's standard library"),
    ("non-UTF-8 name", "is not valid UTF-8 text"),
])
def test_a_module_that_exits_or_cannot_be_the_one_meant_is_named(usermod, capsys, kind, message):
    """Row 16: a module calling sys.exit (the run ended silently with status 0), a name of
    the standard library next to a file of that name (the standard module was loaded), a
    file name that is not UTF-8 (``std::bad_cast`` from deep inside JAX): one line, status 2."""
    spec = _bad_module(usermod, kind)
    rc = main(["analyze", "--system", spec, "--quiet", "--no-figures", "--out", str(usermod / "out")])
    cap = capsys.readouterr()
    assert rc == 2, cap
    (line,) = cap.err.strip().splitlines()
    assert line.startswith("jaxgear analyze: error: --system ") and message in line, line
    assert not (usermod / "out").exists()


def test_the_console_script_finds_modules_from_its_folder_and_names_each_failure(tmp_path):
    """The installed ``jaxgear`` command in a folder of the user's files (no fixture on
    ``sys.path``): a missing module, a missing file, a module that raises and one that
    declares no region are each one line naming --system, status 2."""
    import shutil
    import subprocess

    exe = shutil.which("jaxgear")
    assert exe, "the console script is installed with the package"
    (tmp_path / "raises.py").write_text('raise ImportError("cannot find libfoo")\n')
    (tmp_path / "noregion.py").write_text("import jaxgear as jg\nSYSTEM = jg.DUFFING\nPARAMS = jg.DuffingParams()\n")
    cases = [("nosuchmod:X", "no module named 'nosuchmod'"), ("./nosuch.py:X", "no file ./nosuch.py"),
             ("raises:SYSTEM", "importing raises failed: ImportError: cannot find libfoo"),
             ("noregion:SYSTEM", "no region: give --region")]
    for spec, message in cases:
        p = subprocess.run([exe, "analyze", "--system", spec, "--quiet", "--no-figures", "--out", "out"],
                           cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert p.returncode == 2, (spec, p.stdout, p.stderr)
        (line,) = p.stderr.strip().splitlines()
        assert line.startswith(f"jaxgear analyze: error: --system {spec}: ") and message in line, line
    assert not (tmp_path / "out").exists()  # (the last two were found in the folder and imported)
