"""``jaxgear params``: the canonical dimensionless set as JSON, --set, exit codes."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import jaxgear as jg
from jaxgear.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _run(capsys, *args):
    rc = main(["params", *args])
    out, err = capsys.readouterr()
    return rc, out, err


def test_params_json_is_the_canonical_set(capsys):
    rc, out, err = _run(capsys, "--preset", "paper", "--json")
    assert rc == 0
    d = json.loads(out)  # exactly one JSON object, nothing else on stdout
    assert isinstance(d, dict)
    assert list(d) == [*jg.PARAM_NAMES, "mesh_shape"]
    # model document §4 names (and the mesh-stiffness shape of §3), written out independently of the code
    assert set(d) == {
        "N", "mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp",
        "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr", "b_sp", "b_rp",
        "c_sp", "c_rp", "f_D", "f_L", "Omega", "contact_ratio_sp", "contact_ratio_rp", "mesh_shape",
    }
    assert d == jg.paper_params().to_dict()
    # and it rebuilds the same parameters
    assert jg.GearParams.from_dict(d).to_dict() == d


def test_params_set_overrides(capsys):
    rc, out, _ = _run(capsys, "--json", "--set", "Omega=0.9", "--set", "b_sp=4", "--set", "phi_rp=0,0.5,1")
    assert rc == 0
    d = json.loads(out)
    assert d["Omega"] == 0.9 and d["b_sp"] == 4.0 and d["b_rp"] == 5.0
    assert d["phi_rp"] == [0.0, 0.5, 1.0]
    assert d == jg.paper_params(Omega=0.9, b_sp=4.0, phi_rp=[0.0, 0.5, 1.0]).to_dict()
    # a physical field
    rc, out, _ = _run(capsys, "--json", "--set", "k_sp_amp=2e8")
    assert rc == 0 and abs(json.loads(out)["kappa_sp_amp"] - 2e8 / 0.8256e9) < 1e-15


def test_params_tables(capsys):
    rc, out, _ = _run(capsys)
    assert rc == 0
    for word in ("physical", "dimensionless", "omega_n", "kappa_rp_mean", "assumed"):
        assert word in out


@pytest.mark.parametrize(
    "setting, name",
    [("bogus=1", "bogus"), ("b_sp=-1", "b_sp"), ("kappa_sp_amp=3", "kappa_sp_amp"),
     ("z_r=60", "z_r"), ("Omega=abc", "abc"), ("input_rpm=3000", None)],
)
def test_params_bad_set_exit_code_2(capsys, setting, name):
    args = ["--json", "--set", setting]
    if name is None:  # two operating speeds
        args += ["--set", "Omega=0.9"]
        name = "input_rpm"
    rc, out, err = _run(capsys, *args)
    assert rc == 2
    assert out == ""
    assert name in err and "Traceback" not in err


def test_params_unknown_preset(capsys):
    rc, _, err = _run(capsys, "--preset", "nosuch", "--json")
    assert rc == 2 and "nosuch" in err


def test_python_dash_m_jaxgear_params_json():
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-m", "jaxgear", "params", "--json"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == jg.paper_params().to_dict()


def test_python_dash_m_jaxgear_exit_code_and_message_of_bad_input():
    """The command's quick exit keeps the exit code and flushes what was printed."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-m", "jaxgear", "params", "--preset", "nosuch", "--json"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "nosuch" in r.stderr and "Traceback" not in r.stderr
