"""``jaxgear analyze`` end to end on a reduced grid of the paper preset."""

import inspect
import json

import numpy as np
import pytest

import jaxgear as jg
from jaxgear.cli import main


def test_analyze_writes_result_summary_and_figures(tmp_path, capsys, gear_reference):
    out = tmp_path / "out"
    # 70 compared cells: a queue of the analysis's padded length (128), so its compiled pool is reused
    rc = main(["analyze", "--grid", "5,3,6", "--quiet", "--out", str(out), "--compare", "70"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "P-4" in text and "agreement with the direct method" in text
    for f in ("result.nc", "summary.json", "compare.json", "domains.png", "shares.png", "domains_3d.png",
              "attractors.png"):
        assert (out / f).is_file(), f
    s = json.loads((out / "summary.json").read_text())
    assert s["params"] == jg.paper_params().to_dict()
    r = jg.load(out / "result.nc")
    # every reported attractor is periodic under an independent, accurate integration (scipy
    # DOP853 at rtol 1e-11, restarted at every backlash kink: tests/conftest.py), within the
    # default integrator's accuracy (about 5e-7 per period)
    p = jg.paper_params()
    assert r.attractors
    for a in r.attractors:
        pts = np.asarray(a.points)
        image = np.array([gear_reference(p, x, 1) for x in pts])
        np.testing.assert_allclose(image, np.roll(pts, -1, axis=0), rtol=0, atol=1e-6)
    assert json.loads((out / "compare.json").read_text())["agreement"] > 0.9
    # the label uncertainty, measured on every cell of a grid smaller than the default sample
    assert r.uncertainty.samples == 90 and 0 <= r.uncertainty.step <= 1 and 0 <= r.uncertainty.start <= 1
    assert "label uncertainty (90 sampled cells)" in text


def test_analyze_bad_input_exit_code(capsys):
    with pytest.raises(SystemExit) as exc:  # argparse rejects malformed options with exit code 2
        main(["analyze", "--grid", "0,3,6", "--quiet", "--no-figures"])
    assert exc.value.code == 2
    assert main(["analyze", "--grid", "5,3", "--quiet", "--no-figures"]) == 2
    assert main(["analyze", "--set", "Omega=-1", "--quiet", "--no-figures"]) == 2
    assert "Omega" in capsys.readouterr().err


def test_library_cli_and_readme_share_the_default_method_and_integrator():
    """analyze_global() without a method, `jaxgear analyze` without --method and the README
    all use the same method and integrator."""
    import argparse
    from pathlib import Path

    from jaxgear.cli.analyze import add_parser, build_method

    sub = argparse.ArgumentParser().add_subparsers()
    add_parser(sub)
    args = sub.choices["analyze"].parse_args([])
    cli = build_method(args)
    lib = jg.analysis.default_method()
    assert type(cli) is type(lib) and cli.to_dict() == lib.to_dict()
    assert lib.integrator == jg.default_integrator()
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    assert f"jaxgear analyze: {lib.name}, 90000 cells" in readme
    assert f"`jaxgear.{type(lib.integrator).__name__}({lib.integrator.steps_per_period})`" in readme


@pytest.mark.slow
def test_sweep_in_one_pool_writes_the_sweep_of_separate_analyses(tmp_path, monkeypatch):
    """``jaxgear sweep --kind basins --one-pool`` (all values in one lane pool) writes the
    labels and shares of the sweep that analyses the values one after another."""
    from jaxgear.sweep import _basins

    pooled, real = [], _basins._analyze_values
    batched = lambda *a, **k: inspect.signature(real).bind(*a, **k).arguments.get("batched", False)  # noqa: E731
    monkeypatch.setattr(_basins, "_analyze_values", lambda *a, **k: pooled.append(batched(*a, **k)) or real(*a, **k))
    base = ["sweep", "--kind", "basins", "--param", "b", "--values", "4:6:2", "--grid", "6,4,6", "--no-figures",
            "--quiet"]
    assert main([*base, "--out", str(tmp_path / "separate")]) == 0
    assert main([*base, "--one-pool", "--out", str(tmp_path / "pool")]) == 0
    assert pooled == [False, True]
    a, b = jg.load(tmp_path / "separate" / "basins.nc"), jg.load(tmp_path / "pool" / "basins.nc")
    assert not np.allclose(a.shares[0], a.shares[-1])  # the two values differ
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.shares, b.shares)
