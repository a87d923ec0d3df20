"""The code passes ruff with the repository's configuration (pyproject.toml)."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_ruff_passes():
    ruff = shutil.which("ruff")
    cmd = [ruff] if ruff else [sys.executable, "-m", "ruff"]
    try:
        proc = subprocess.run([*cmd, "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True, timeout=300)
    except FileNotFoundError:
        pytest.fail("ruff is not installed (it is in the test extra: pip install -e '.[test]')")
    assert proc.returncode == 0, proc.stdout + proc.stderr
