"""The accuracy references under XLA's default flags: the suite compiles with XLA's older
CPU emitters (and the default tier without LLVM optimisation) to save compile time
(tests/conftest.py), so here a set of the checks against answers that do not come from the
code run again in a fresh process that compiles as a user's does: states against an
event-located integration (fourth order), the forced linear oscillator's closed form,
exponents against scipy twin trajectories, and the labels of an analysis against a brute
force integration."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

REFERENCES = [
    "tests/test_kink.py::test_paper_preset_states_fourth_order_against_event_located_reference",
    "tests/test_kink.py::test_dead_zone_states_fourth_order_multipliers_at_least_third",
    "tests/test_integrate.py::test_rk4_fourth_order_forced_linear_oscillator",
    "tests/test_lyapunov.py::test_chaotic_duffing_matches_scipy_twin_trajectories",
    "tests/test_attractors.py::test_chaotic_and_periodic_attractors_coexist",
    "tests/test_contact.py::test_double_sided_motion_matches_an_event_located_integration",
]


@pytest.mark.slow  # about 3 min on two cores: a fresh process compiling with XLA's default (slower) pipeline
def test_accuracy_references_pass_as_users_compile():
    root = Path(__file__).resolve().parent.parent
    # a choice already in XLA_FLAGS wins over the suite's (tests/conftest.py): XLA's defaults, said explicitly
    env = dict(os.environ, XLA_FLAGS="--xla_cpu_use_fusion_emitters=true --xla_backend_optimization_level=3")
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider", "-m",
                        "slow or not slow", *REFERENCES], cwd=root, env=env, capture_output=True, text=True,
                       timeout=1800)
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]
    assert f"{len(REFERENCES)} passed" in p.stdout, p.stdout[-2000:]
