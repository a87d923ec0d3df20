"""Parameter sweeps (issue 5): bifurcation diagrams, basin sweeps, parameter maps, resume, CLI.

References that do not come from jaxgear's sweep code:
- the first parametric-resonance tongue of the damped Mathieu equation from one-harmonic
  balance (perturbation theory, error O(eps^2));
- the jump-up/jump-down frequencies of the hardening Duffing oscillator from harmonic
  balance (fold points of [(alpha - w^2 + 3/4 beta A^2)^2 + (delta w)^2] A^2 = gamma^2,
  computed here with numpy) and its two branch amplitudes;
- the foundation's stroboscopic_orbit one value at a time (vmap versus loop);
- an uninterrupted run (kill-and-resume).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear import basin_sweep, bifurcation_diagram, parameter_map
from jaxgear.analysis import DEFAULT_SAMPLES
from jaxgear.sweep import APERIODIC, ESCAPED
from jaxgear.sweep import _basins as basins_module
from jaxgear.sweep import _bifurcation as bifurcation_module
from jaxgear.sweep import _checkpoint as checkpoint_module


def load_bifurcation(path):
    return jg.load(path, expected="BifurcationDiagram")


def load_basin_sweep(path):
    return jg.load(path, expected="BasinSweep")


def load_parameter_map(path):
    return jg.load(path, expected="ParameterMap")

ROOT = Path(__file__).resolve().parent.parent
QUIET = jg.Runner(progress=False)  # nothing written, no progress bars


# ----------------------------------------------------------------- a user-defined system
class ParamDuffing(eqx.Module):
    """x'' + 2 zeta x' + (1 + eps cos(Omega t)) x + beta x^3 = 0 (all float64 arrays)."""

    zeta: Any = eqx.field(converter=lambda x: jnp.asarray(x, jnp.float64))
    eps: Any = eqx.field(converter=lambda x: jnp.asarray(x, jnp.float64))
    beta: Any = eqx.field(converter=lambda x: jnp.asarray(x, jnp.float64))
    Omega: Any = eqx.field(converter=lambda x: jnp.asarray(x, jnp.float64))


def _param_duffing(t, x, p):
    return jnp.stack([x[1], -2.0 * p.zeta * x[1] - (1.0 + p.eps * jnp.cos(p.Omega * t)) * x[0] - p.beta * x[0] ** 3])


PARAM_DUFFING = jg.ForcedSystem(vector_field=_param_duffing, period=lambda p: 2.0 * jnp.pi / p.Omega,
                                state_names=("x", "v"), name="param-duffing")


def mathieu_tongue(eps, zeta):
    """Edges (Omega_-, Omega_+) of the first tongue: x = a cos(Omega t/2) + b sin(Omega t/2)
    in the linearisation gives (1 - w^2)^2 + 4 zeta^2 w^2 = eps^2/4, w = Omega/2 (error O(eps^2))."""
    c = 1.0 - 2.0 * zeta**2
    r = np.sqrt(eps**2 / 4.0 - 4.0 * zeta**2 + 4.0 * zeta**4)
    return 2.0 * np.sqrt(c - r), 2.0 * np.sqrt(c + r)


def duffing_hb(delta, alpha, beta, gamma, w):
    """Real positive amplitudes A of the one-harmonic balance at frequency w (ascending)."""
    c = [(0.75 * beta) ** 2, 1.5 * beta * (alpha - w**2), (alpha - w**2) ** 2 + (delta * w) ** 2, -gamma**2]
    z = np.roots(c)
    z = np.sort(z[(np.abs(z.imag) < 1e-9) & (z.real > 0)].real)
    return np.sqrt(z)


def duffing_folds(delta, alpha, beta, gamma):
    w = np.linspace(0.8, 2.5, 17001)
    three = np.array([len(duffing_hb(delta, alpha, beta, gamma, x)) == 3 for x in w])
    i = np.nonzero(three)[0]
    return w[i[0]], w[i[-1]]


DUFF = dict(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3)


# ----------------------------------------------------------------- bifurcation diagrams
def test_period_doubling_of_the_trivial_orbit_at_the_mathieu_tongue():
    """Sweeping Omega up, the trivial P-1 of the parametric Duffing oscillator gives way to
    a P-2 where perturbation theory puts the first tongue's lower edge (a flip: the P-2
    motion has half the forcing frequency)."""
    eps, zeta = 0.2, 0.01
    lower, _ = mathieu_tongue(eps, zeta)  # 1.8993
    res = 0.005
    values = np.round(np.arange(1.85, 1.95 + 1e-9, res), 6)
    p = ParamDuffing(zeta=zeta, eps=eps, beta=1.0, Omega=2.0)
    d = bifurcation_diagram(PARAM_DUFFING, p, "Omega", values, [[0.1, 0.0]], transient=3000, record=40,
                            integrator=jg.RK4(64), max_period=8, runner=QUIET)
    per = d.period[0, :, 0]
    assert set(per.tolist()) == {1, 2}, per
    first = int(np.argmax(per == 2))
    assert np.all(per[:first] == 1) and np.all(per[first:] == 2)  # one change, P-1 -> P-2
    change = 0.5 * (values[first - 1] + values[first])
    theory_err = eps**2 / 16  # the O(eps^2) term of the undamped expansion is ~eps^2/27 in Omega
    assert abs(change - lower) <= res + theory_err, (change, lower)
    # below: the trivial orbit (x = 0); above: a P-2 of non-zero amplitude alternating in sign
    x = d.points[0, :, 0, -2:, 0]
    assert np.all(np.abs(x[:first]) < 1e-8)
    assert np.all(np.abs(x[first:]).min(axis=1) > 1e-3) and np.all(x[first:, 0] * x[first:, 1] < 0)
    assert d.transitions()[0]["from"] == ["P-1"] and d.transitions()[0]["to"] == ["P-2"]


def test_hysteresis_of_the_hardening_duffing_oscillator():
    """Up and down sweeps in omega differ inside the harmonic-balance jump interval
    (different branches, amplitudes near the upper and lower HB roots) and agree outside."""
    w_up, w_down = duffing_folds(**DUFF)  # jump-up (lower fold) 1.261, jump-down (upper fold) 1.551
    values = np.round(np.linspace(1.0, 1.8, 41), 6)
    p = jg.DuffingParams(**DUFF, omega=1.0)
    d = bifurcation_diagram(jg.DUFFING, p, "omega", values, [[0.0, 0.0]], transient=400, record=40,
                            direction="both", integrator=jg.RK4(64), max_period=8, runner=QUIET)
    assert d.directions == ("up", "down")
    assert np.all(d.period == 1)
    up, down = d.points[0, :, 0, -1], d.points[1, :, 0, -1]
    gap = np.linalg.norm(up - down, axis=1)
    margin = 0.02 + 0.01 * values  # one sweep step + 1 % for the one-harmonic approximation
    inside = (values > w_up + margin) & (values < w_down - margin)
    outside = (values < w_up - margin) | (values > w_down + margin)
    assert inside.sum() >= 8 and outside.sum() >= 15
    assert np.all(gap[inside] > 0.3), gap[inside]
    assert np.all(gap[outside] < 1e-6), gap[outside]
    diff = d.differs("up", "down")
    assert diff[inside].all() and not diff[outside].any()
    # the up sweep rides the upper branch, the down sweep the lower one (amplitude of the harmonic)
    for i in np.nonzero(inside)[0]:
        roots = duffing_hb(**DUFF, w=values[i])
        amp = lambda x, w=values[i]: np.hypot(x[0], x[1] / w)  # noqa: E731
        assert abs(amp(up[i]) - roots[-1]) < 0.1 * roots[-1]
        assert abs(amp(down[i]) - roots[0]) < 0.1 * roots[-1]


def test_sweep_equals_one_value_at_a_time():
    """Batched values (vmap over values, a period per value when omega is swept) equal the
    stroboscopic_orbit run at each value separately."""
    p = jg.DuffingParams(**DUFF, omega=1.3)
    X0 = np.array([[0.5, 0.0], [-2.0, 1.0]])
    integ = jg.RK4(32)
    for name, vals in (("gamma", [0.2, 0.3, 0.4]), ("omega", [1.1, 1.3, 1.5])):
        d = bifurcation_diagram(jg.DUFFING, p, name, vals, X0, transient=5, record=17, integrator=integ,
                                max_period=8, runner=QUIET)
        for i, v in enumerate(vals):
            pv = jg.with_param(p, name, v)
            x = jg.stroboscopic_map(jg.DUFFING, pv, X0, periods=5, integrator=integ)
            ref = np.asarray(jg.stroboscopic_orbit(jg.DUFFING, pv, x, n_points=17, integrator=integ))
            np.testing.assert_allclose(d.points[0, i], ref, rtol=1e-11, atol=1e-11)


def test_escaped_and_aperiodic_codes():
    """Unbounded motion is 'escaped' (never a silent NaN); no recurrence is 'aperiodic'."""
    # negative linear stiffness, no cubic term: x grows without bound
    p = jg.DuffingParams(delta=0.1, alpha=-1.0, beta=0.0, gamma=0.0, omega=1.0)
    d = bifurcation_diagram(jg.DUFFING, p, "gamma", [0.0, 0.1], [[0.1, 0.0]], transient=60, record=17,
                            max_period=8, integrator=jg.RK4(32), runner=QUIET)
    assert np.all(d.period == ESCAPED) and np.all(d.attractor == -1)
    # a classic chaotic Duffing (Ueda-type): x'' + 0.05 x' + x^3 = 7.5 cos t
    p = jg.DuffingParams(delta=0.05, alpha=0.0, beta=1.0, gamma=7.5, omega=1.0)
    d = bifurcation_diagram(jg.DUFFING, p, "gamma", [7.5], [[0.5, 0.0]], transient=100, record=40,
                            max_period=16, integrator=jg.RK4(100), runner=QUIET)
    assert d.period[0, 0, 0] == APERIODIC
    assert "chaotic" in d.table()


# ----------------------------------------------------------------- basin sweep: matching
def test_basin_sweep_keeps_attractor_identities():
    """In the hysteresis interval of the hardening Duffing the shares of its two P-1
    attractors cross; each global id stays on one HB branch and moves continuously."""
    p = jg.DuffingParams(**DUFF, omega=1.3)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (12, 12), names=("x", "v"))
    values = np.linspace(1.30, 1.46, 5)
    s = basin_sweep(jg.DUFFING, p, "omega", values, grid, method=jg.Direct(integrator=jg.RK4(64), max_period=4),
                    runner=QUIET, uncertainty=0)
    assert s.n_attractors == 2 and np.all(s.present) and np.all(s.period == 1)
    np.testing.assert_allclose(s.shares.sum(axis=1) + s.sink_share + s.unresolved_share, 1.0)
    # the shares cross (so the per-value results, sorted by share, swap their local ids)
    assert (s.shares[0, 0] - s.shares[0, 1]) * (s.shares[-1, 0] - s.shares[-1, 1]) < 0
    amp = np.hypot(s.points[:, :, 0, 0], s.points[:, :, 0, 1] / values[:, None])  # (V, G)
    for i, w in enumerate(values):
        lo, hi = duffing_hb(**DUFF, w=w)[[0, -1]]
        big = int(np.argmax(amp[i]))
        assert big == int(np.argmax(amp[0]))  # the same global id is the large-amplitude one throughout
        assert abs(amp[i, big] - hi) < 0.1 * hi and abs(amp[i, 1 - big] - lo) < 0.1 * hi
    step = np.linalg.norm(np.diff(s.points[:, :, 0], axis=0), axis=-1)  # (V-1, G)
    apart = np.linalg.norm(s.points[:, 0, 0] - s.points[:, 1, 0], axis=-1)
    assert step.max() < 0.25 * apart.min()
    assert [e["event"] for e in s.events() if e["event"] in ("appears", "vanishes")] == []


def test_matching_is_set_distance_and_cyclic_shift_invariant():
    """The matcher follows attractors by the distance of their point sets, whatever the
    order of the points or of the attractors, and starts a new id beyond match_tol."""
    from jaxgear import Attractor

    def res(*atts):
        a = tuple(Attractor(id=i, period=len(pts), points=np.asarray(pts, float), section_points=np.zeros((0, 2)),
                            cell_count=1, share=0.5, residual=0.0, periodic_cells=np.zeros(0, np.int64))
                  for i, pts in enumerate(atts))
        return type("R", (), {"attractors": a})()

    A = [[0.0, 0.0], [1.0, 1.0]]
    B = [[5.0, 5.0]]
    r0 = res(A, B)
    r1 = res([[5.1, 5.0]], [[1.05, 1.0], [0.0, 0.05]])  # order of attractors and of A's points swapped
    r2 = res([[9.0, 9.0]], [[1.05, 1.0], [0.0, 0.05]])  # B vanished, a new one far away
    ids = basins_module.match_across_values([r0, r1, r2], match_tol=0.5)
    assert ids[0].tolist() == [0, 1] and ids[1].tolist() == [1, 0] and ids[2].tolist() == [2, 0]


# ----------------------------------------------------------------- kill and resume
class _Kill(BaseException):
    pass


def _interrupt_after(monkeypatch, n):
    real = checkpoint_module._save_part
    calls = {"n": 0}

    def save(path, arrays):
        calls["n"] += 1
        if calls["n"] > n:
            raise _Kill()  # killed after n blocks were written
        real(path, arrays)

    monkeypatch.setattr(checkpoint_module, "_save_part", save)


def _assert_same_file(a, b, roundoff: bool = False):
    """The two result files hold the same data; with ``roundoff``, floating-point values
    may differ by round-off (integers, names and attributes still equal)."""
    import xarray as xr

    with xr.open_dataset(a, engine="h5netcdf") as da, xr.open_dataset(b, engine="h5netcdf") as db:
        if not roundoff:
            assert da.identical(db)
            return
        assert da.attrs == db.attrs and set(da.variables) == set(db.variables)
        for name in da.variables:
            _assert_same_array(db[name].values, da[name].values, name)


def _assert_same_array(actual, desired, name: str = ""):
    """Equal, floating-point values to round-off (a batch split another way may round otherwise)."""
    actual, desired = np.asarray(actual), np.asarray(desired)
    if np.issubdtype(desired.dtype, np.floating) or np.issubdtype(desired.dtype, np.complexfloating):
        np.testing.assert_allclose(actual, desired, rtol=1e-12, atol=1e-12, err_msg=name)
    else:
        np.testing.assert_array_equal(actual, desired, err_msg=name)


def _counting(monkeypatch, name, seen):
    real = getattr(bifurcation_module, name)

    def wrapper(system, params, names, V, *a, **k):
        seen.extend(np.asarray(V).reshape(len(V), -1)[:, 0].tolist())  # (the up value of a two-way scan)
        return real(system, params, names, V, *a, **k)

    monkeypatch.setattr(bifurcation_module, name, wrapper)


@pytest.mark.parametrize("direction", ["both", "independent"])
def test_kill_and_resume_bifurcation(tmp_path, monkeypatch, direction):
    p = jg.DuffingParams(**DUFF, omega=1.0)
    kw = dict(transient=30, record=17, direction=direction, integrator=jg.RK4(32), max_period=8, chunk_size=8)
    values = np.linspace(1.0, 1.6, 12)
    X0 = [[0.0, 0.0], [2.0, 0.0]]
    run = jg.Runner(out=tmp_path / "run", progress=False)
    full = bifurcation_diagram(jg.DUFFING, p, "omega", values, X0,
                               runner=jg.Runner(out=tmp_path / "full", progress=False), **kw)
    with monkeypatch.context() as m:
        _interrupt_after(m, 2)  # killed after two blocks were written
        with pytest.raises(_Kill):
            bifurcation_diagram(jg.DUFFING, p, "omega", values, X0, runner=run, **kw)
    assert len(list((tmp_path / "run" / "parts").glob("*.npz"))) == 2
    B = json.loads((tmp_path / "run" / "manifest.json").read_text())["settings"]["block_values"][direction]
    assert 1 < B < 6  # several blocks of several values
    computed = []
    _counting(monkeypatch, "independent_points" if direction == "independent" else "sequential_points", computed)
    resumed = run.run(bifurcation_diagram, jg.DUFFING, p, "omega", values, X0, **kw)
    assert sorted(computed) == values[2 * B:].tolist()  # every unfinished value once, no finished one again
    _assert_same_file(tmp_path / "full" / "bifurcation.nc", tmp_path / "run" / "bifurcation.nc")
    np.testing.assert_array_equal(resumed.points, full.points)
    computed.clear()  # a finished sweep: nothing is computed again, its exponents neither
    with monkeypatch.context() as m:
        m.setattr(bifurcation_module, "aperiodic_types", lambda *a, **k: pytest.fail("exponents computed again"))
        again = bifurcation_diagram(jg.DUFFING, p, "omega", values, X0, runner=run, **kw)
    assert computed == []
    np.testing.assert_array_equal(again.points, full.points)
    np.testing.assert_array_equal(again.largest_exponent, full.largest_exponent)
    # the same folder with another setting: a clear error, or a restart
    with pytest.raises(ValueError, match="transient"):
        bifurcation_diagram(jg.DUFFING, p, "omega", values, X0, runner=run, **dict(kw, transient=31))
    bifurcation_diagram(jg.DUFFING, p, "omega", values[:4], X0, runner=dataclasses.replace(run, restart=True), **kw)
    assert sorted(computed) == values[:4].tolist()


def test_kill_and_resume_basin_sweep(tmp_path, monkeypatch):
    p = jg.DuffingParams(**DUFF, omega=1.3)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (5, 5), names=("x", "v"))
    values = [1.30, 1.35, 1.40, 1.45]
    kw = dict(method=jg.Direct(integrator=jg.RK4(32), max_period=4), uncertainty=0)
    run = jg.Runner(out=tmp_path / "run", progress=False)
    basin_sweep(jg.DUFFING, p, "omega", values, grid, runner=jg.Runner(out=tmp_path / "full", progress=False), **kw)
    real = basins_module._analyze_values
    calls = []

    def analyze(system, params_list, *a, **k):
        calls.append([float(q.omega) for q in params_list])
        if kill and len(calls) == 2:
            raise _Kill()
        return real(system, params_list, *a, **k)

    monkeypatch.setattr(basins_module, "_analyze_values", analyze)
    monkeypatch.setattr(basins_module, "BLOCK_CELLS", 2 * grid.n_cells)  # blocks of two values
    kill = True
    with pytest.raises(_Kill):
        basin_sweep(jg.DUFFING, p, "omega", values, grid, runner=run, **kw)
    assert calls == [values[:2], values[2:]]
    calls.clear()
    kill = False
    run.run(basin_sweep, jg.DUFFING, p, "omega", values, grid, **kw)
    assert calls == [values[2:]]  # the killed block only
    _assert_same_file(tmp_path / "full" / "basins.nc", tmp_path / "run" / "basins.nc")


def _assert_sweep_is_separate_analyses(s, system, p, param, values, grid, method, uncertainty=DEFAULT_SAMPLES):
    """Every value of the (one-pool) basin sweep ``s`` holds what :func:`analyze_global`
    gives at that value alone: the same shares, periods, uncertainty and labels."""
    for i, v in enumerate(values):
        r = jg.analyze_global(system, jg.with_param(p, param, v), grid, method, progress=False, uncertainty=uncertainty)
        present = np.flatnonzero(s.present[i])
        assert len(present) == len(r.attractors)
        # the local attractor of each global id, read off the labels
        lut = {}
        for a, b in zip(np.asarray(r.labels).ravel(), s.labels[i].ravel()):
            assert lut.setdefault(int(a), int(b)) == int(b)
        for a in r.attractors:
            g = lut[a.id]
            assert s.shares[i, g] == a.share and s.period[i, g] == a.period
            # central differences of the k-fold map amplify the round-off of the cycle's points (refined
            # from another lane's recurrence in the one pool) about a million times
            assert s.multiplier[i, g] == pytest.approx(a.multiplier, rel=1e-6, nan_ok=True)  # NaN: an aperiodic attractor
        assert np.isnan(s.multiplier[i, ~s.present[i]]).all()
        assert s.sink_share[i] == r.n_sink / r.n_cells and s.unresolved_share[i] == r.n_unresolved / r.n_cells
        assert s.uncertainty_step[i] == r.uncertainty.step and s.uncertainty_start[i] == r.uncertainty.start


@pytest.mark.slow
def test_basin_sweep_in_one_pool_is_each_value_alone():
    """The basin sweep runs all values of the gear model in one lane pool (each lane with
    its value's parameters, in the compiled kernel); every value's labels and shares are
    those of the global analysis at that value alone."""
    p = jg.paper_params()
    grid = jg.CellGrid.paper((10, 6, 12))
    values = [4.5, 5.5]
    s = basin_sweep(jg.REDUCED, p, "b", values, grid, runner=QUIET, batched=True, uncertainty=64)
    assert not np.allclose(s.shares[0], s.shares[-1])  # the values differ
    _assert_sweep_is_separate_analyses(s, jg.REDUCED, p, "b", values, grid, jg.Direct(), uncertainty=64)


@pytest.mark.slow
def test_basin_sweep_uncertainty_is_optional_and_older_files_load(tmp_path):
    """``uncertainty=0`` skips the label uncertainty (NaN) and changes nothing else; a file
    written before the sweep recorded it loads with NaN and every other field as saved."""
    import xarray as xr

    p = jg.DuffingParams(delta=0.1, alpha=1.0, beta=0.5, gamma=0.3, omega=1.3)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (6, 6), names=("x", "v"))
    kw = dict(method=jg.Direct(integrator=jg.RK4(32), max_period=4), runner=QUIET)
    with_u = basin_sweep(jg.DUFFING, p, "omega", [1.3, 1.4], grid, uncertainty=16, **kw)
    without = basin_sweep(jg.DUFFING, p, "omega", [1.3, 1.4], grid, uncertainty=0, **kw)
    assert np.isfinite(with_u.uncertainty_step).all() and np.isfinite(with_u.uncertainty_start).all()
    assert np.isnan(without.uncertainty_step).all() and np.isnan(without.uncertainty_start).all()
    np.testing.assert_array_equal(with_u.labels, without.labels)
    np.testing.assert_array_equal(with_u.shares, without.shares)
    assert "unc. step" in with_u.shares_table() and "unc. step" not in without.shares_table()
    # 16 samples of 36 cells: too few uncertain ones for an uncertainty exponent, which the table says
    assert np.isnan(with_u.uncertainty_exponent).all() and np.isnan(with_u.uncertainty_exponent_low).all()
    assert "no scaling range" in with_u.shares_table() or not np.isfinite(with_u.boundary_basin_entropy).any()
    assert with_u.uncertainty_note() and not without.uncertainty_note()
    path = with_u.save(tmp_path / "new.nc")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        ds.load().drop_vars(["uncertainty_step", "uncertainty_start", "multiplier"]).to_netcdf(
            tmp_path / "old.nc", engine="h5netcdf")
    old = load_basin_sweep(tmp_path / "old.nc")
    assert np.isnan(old.uncertainty_step).all() and old.uncertainty_step.shape == (2,)
    assert np.isnan(old.multiplier).all() and old.multiplier.shape == with_u.shares.shape
    _assert_equal_results(dataclasses.replace(old, uncertainty_step=with_u.uncertainty_step,
                                              uncertainty_start=with_u.uncertainty_start,
                                              multiplier=with_u.multiplier), with_u)
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="uncertainty"):
            basin_sweep(jg.DUFFING, p, "omega", [1.3, 1.4], grid, uncertainty=bad, **kw)
    # a resume folder records the option only when it is not the default, so that a folder begun
    # before the option existed (its analyses measured the default) resumes; another value is
    # another sweep
    kw["runner"] = jg.Runner(out=tmp_path / "run", progress=False)
    basin_sweep(jg.DUFFING, p, "omega", [1.3, 1.4], grid, **kw)
    assert "uncertainty" not in json.loads((tmp_path / "run" / "manifest.json").read_text())["settings"]
    with pytest.raises(ValueError, match="other settings"):
        basin_sweep(jg.DUFFING, p, "omega", [1.3, 1.4], grid, uncertainty=0, **kw)


@pytest.mark.slow
def test_basin_sweep_in_one_pool_pure_jax():
    """The same through the pure-JAX integrator (each lane's parameters mapped over the
    lanes), with a value where one of the Duffing's two attractors is gone."""
    p = jg.DuffingParams(**DUFF, omega=1.3)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (10, 10), names=("x", "v"))
    values = [1.0, 1.3, 1.4]
    method = jg.Direct(integrator=jg.RK4(64), max_period=4)
    s = basin_sweep(jg.DUFFING, p, "omega", values, grid, method=method, runner=QUIET, batched=True)
    assert s.present.sum(axis=1).tolist() != [s.present.shape[1]] * 3
    _assert_sweep_is_separate_analyses(s, jg.DUFFING, p, "omega", values, grid, method)


def test_one_pool_rows_decide_against_their_own_tables():
    """Lanes of several values share the pool's rounds (a pool smaller than a value's
    cells) while the values' tables differ: the same Duffing attractors seeded in two
    orders, and a third value (one attractor fewer) seeded with none. Each value gets the
    labels and attractor periods of its own pool, so the second value's labels are the first's
    with the two slots swapped."""
    from jaxgear.analysis._pool import run_pool, run_pools

    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (10, 10), names=("x", "v"))
    X = np.asarray(grid.centres(), np.float64)
    m = jg.Direct(integrator=jg.RK4(64), max_period=4)
    m = jg.Direct(integrator=jg.RK4(64), max_period=4, chunk_size=64)
    kw = dict(options=m.pool_options(pilot=0), progress=False)
    p13, p10 = jg.DuffingParams(**DUFF, omega=1.3), jg.DuffingParams(**DUFF, omega=1.0)
    _, atts, *_ = run_pool(jg.DUFFING, p13, X, m.integrator, **kw)
    assert len(atts) == 2
    rows = [(p13, atts), (p13, atts[::-1]), (p10, ())]
    alone = [run_pool(jg.DUFFING, p, X, m.integrator, attractors=a, **kw) for p, a in rows]
    pooled = run_pools(jg.DUFFING, [p for p, _ in rows], [X] * 3, m.integrator, attractors=[a for _, a in rows], **kw)
    assert len(alone[2][1]) != 2  # the third value's table differs in length
    for (lab, att, *_), (lab1, att1, *_) in zip(pooled, alone):
        np.testing.assert_array_equal(lab, lab1)
        assert [k for _, k in att] == [k for _, k in att1]  # the points: of the lane that found it first
    swap = np.array([1, 0])
    np.testing.assert_array_equal(pooled[1][0], np.where(pooled[0][0] >= 0, swap[np.clip(pooled[0][0], 0, 1)],
                                                         pooled[0][0]))


def test_a_value_whose_pilot_missed_an_attractor_is_analysed_alone(monkeypatch):
    """The pool says, per value, whether its pilot found all of its attractors: with a
    pilot of all cells but one it did, with a pilot of one cell the bistable Duffing's second
    attractor is found later. A sweep in one pool analyses such a value again alone (its
    labels could depend on the other values'), and keeps the pooled result of the others."""
    from jaxgear.analysis import _global as global_module
    from jaxgear.analysis._pool import run_pool

    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (10, 10), names=("x", "v"))
    X = np.asarray(grid.centres(), np.float64)
    p13 = jg.DuffingParams(**DUFF, omega=1.3)
    m = jg.Direct(integrator=jg.RK4(64), max_period=4, chunk_size=64)
    whole = run_pool(jg.DUFFING, p13, X, m.integrator, options=m.pool_options(pilot=len(X) - 1), progress=False)
    one = run_pool(jg.DUFFING, p13, X, m.integrator, options=m.pool_options(pilot=1), progress=False)
    assert len(whole.attractors) == len(one.attractors) == 2
    assert whole.pilot_complete and not one.pilot_complete
    alone = []
    real = global_module.analyze_global

    def spy(system, params, *a, **k):
        alone.append(float(params.omega))
        return real(system, params, *a, **k)

    monkeypatch.setattr(global_module, "analyze_global", spy)
    values = [1.3, 1.0]
    for pilot, want in ((len(X) - 1, []), (1, [1.3])):
        alone.clear()
        global_module.analyze_global_values(jg.DUFFING, [jg.with_param(p13, "omega", v) for v in values], grid,
                                            jg.Direct(integrator=jg.RK4(64), max_period=4, chunk_size=64, pilot=pilot),
                                            uncertainty=0)
        assert alone == want, (pilot, alone)


# ----------------------------------------------------------------- parameter map
def test_parameter_map_period_follows_the_mathieu_tongue():
    """Period reached from a small start on an (Omega, eps) grid: P-2 inside the tongue,
    P-1 outside (grid points closer than the theory error to an edge are not judged)."""
    zeta = 0.01
    Om = np.linspace(1.7, 2.3, 9)
    eps = np.array([0.1, 0.3, 0.5])
    p = ParamDuffing(zeta=zeta, eps=0.2, beta=1.0, Omega=2.0)
    m = parameter_map(PARAM_DUFFING, p, "Omega", Om, "eps", eps, [[0.1, 0.0], [-1.5, 0.0]], transient=1500,
                      integrator=jg.RK4(48), max_period=4, runner=QUIET)
    assert m.period.shape == (3, 9, 2) and m.n_attractors.shape == (3, 9)
    judged = 0
    for j, e in enumerate(eps):
        lo, hi = mathieu_tongue(e, zeta)
        for i, w in enumerate(Om):
            margin = e**2 / 8 + 0.01
            if lo + margin < w < hi - margin:
                assert m.data[j, i] == 2, (e, w)
                judged += 1
            elif w < lo - margin or w > hi + margin:
                assert m.period[j, i, 0] == 1, (e, w)
                judged += 1
    assert judged >= 18
    assert np.all(m.n_attractors >= 1) and m.n_attractors.max() <= 2
    assert m.quantity == "period" and "attractors reached" in m.table()


# ----------------------------------------------------------------- bad input
def test_bad_input_raises_value_error():
    p = jg.paper_params()
    x0 = np.zeros(4)
    with pytest.raises(ValueError, match="valid names: .*kappa_amp"):
        bifurcation_diagram(jg.REDUCED, p, "backlash", [1.0, 2.0], x0)
    with pytest.raises(ValueError, match="empty"):
        bifurcation_diagram(jg.REDUCED, p, "b", [], x0)
    with pytest.raises(ValueError, match="b_sp"):
        bifurcation_diagram(jg.REDUCED, p, "b", [-1.0, 2.0], x0, runner=QUIET)
    with pytest.raises(ValueError, match="direction"):
        bifurcation_diagram(jg.REDUCED, p, "b", [1.0, 2.0], x0, direction="sideways")
    with pytest.raises(ValueError, match="record"):
        bifurcation_diagram(jg.REDUCED, p, "b", [1.0, 2.0], x0, record=10, max_period=16)
    with pytest.raises(ValueError, match="distinct"):
        bifurcation_diagram(jg.REDUCED, p, "b", [2.0, 2.0], x0)
    with pytest.raises(ValueError, match="same field"):
        parameter_map(jg.REDUCED, p, "b", [1, 2], "b_sp", [1, 2], x0)
    with pytest.raises(ValueError, match="period"):
        bifurcation_diagram(jg.DUFFING, jg.DuffingParams(), "omega", [0.0, 1.0], [0.0, 0.0])


# ----------------------------------------------------------------- save, load, plot
@pytest.fixture(scope="module")
def small_results(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweeps")
    p = jg.DuffingParams(**DUFF, omega=1.3)
    bif = bifurcation_diagram(jg.DUFFING, p, "omega", np.linspace(1.2, 1.6, 5), [[0.0, 0.0], [2.0, 0.0]],
                              direction="both", integrator=jg.RK4(32),
                              options=jg.SequenceOptions(transient=100, record=17, max_period=8), runner=QUIET)
    grid = jg.CellGrid.box([(-3, 3), (-3, 3)], (6, 6), names=("x", "v"))
    bas = basin_sweep(jg.DUFFING, p, "omega", [1.3, 1.4], grid, method=jg.Direct(integrator=jg.RK4(32), max_period=4),
                      runner=QUIET)
    pm = parameter_map(jg.DUFFING, p, "omega", [1.2, 1.4, 1.6], "gamma", [0.2, 0.3], [[0.0, 0.0], [2.0, 0.0]],
                       quantity="n_attractors", transient=100, integrator=jg.RK4(32), max_period=4, runner=QUIET)
    paths = {k: r.save(d / f"{k}.nc") for k, r in (("bif", bif), ("bas", bas), ("pm", pm))}
    return dict(bif=bif, bas=bas, pm=pm, paths=paths)


def _assert_equal_results(a, b):
    import dataclasses

    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, f.name
            np.testing.assert_array_equal(x, y, err_msg=f.name)  # NaN == NaN, bit for bit otherwise
        else:
            assert x == y, f.name


def test_save_load_round_trip(small_results):
    import xarray as xr

    for key, load, kind in (("bif", load_bifurcation, "BifurcationDiagram"), ("bas", load_basin_sweep, "BasinSweep"),
                            ("pm", load_parameter_map, "ParameterMap")):
        orig, path = small_results[key], small_results["paths"][key]
        _assert_equal_results(orig, load(path))
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            assert ds.attrs["jaxgear_type"] == kind and ds.attrs["system"] == "duffing"
            assert json.loads(ds.attrs["params"])["beta"] == 0.5 and ds.attrs["version"] == jg.__version__
            assert "omega" in ds.coords and "state" in ds.coords
    with pytest.raises(ValueError, match="not a BasinSweep"):
        load_basin_sweep(small_results["paths"]["bif"])
    for key, kind in (("bif", jg.BifurcationDiagram), ("bas", jg.BasinSweep), ("pm", jg.ParameterMap)):
        assert type(jg.load(small_results["paths"][key])) is kind  # the generic loader dispatches here
    bif = load_bifurcation(small_results["paths"]["bif"])
    assert bif.points.flags.writeable is False  # immutable results
    assert "omega" in bif.table() and json.dumps(bif.summary())
    assert json.dumps(small_results["bas"].summary()) and small_results["pm"].table()


def test_options_are_typed_and_are_the_settings(small_results):
    """A sweep's settings are its options object (``record`` as used: ``2 max_period + 2``
    for a parameter map given none) and its integrator; the keywords are the same fields;
    a bad or unknown option is refused naming it."""
    bif, pm, bas = small_results["bif"], small_results["pm"], small_results["bas"]
    assert bif.settings == jg.sweep.SequenceSettings(
        options=jg.SequenceOptions(transient=100, record=17, max_period=8), integrator=jg.RK4(32))
    assert pm.settings.options == jg.SequenceOptions(transient=100, record=10, max_period=4)
    assert bas.match_tol == pytest.approx(0.05 * np.hypot(6.0, 6.0)) and bas.uncertainty_samples == 1024
    assert jg.SequenceOptions(max_period=4).with_record(64).record == 64
    for bad, match in ((dict(record=8, max_period=4), "record"), (dict(tol=0.0), "tol"),
                       (dict(escape_bound=-1.0), "escape_bound"), (dict(chunk_size=0), "chunk_size")):
        with pytest.raises(ValueError, match=match):
            jg.SequenceOptions(**bad)
    with pytest.raises(ValueError, match="match_tol"):
        jg.BasinOptions(match_tol=0.0)
    with pytest.raises(ValueError, match="unknown option 'transients'.*transient"):
        bifurcation_diagram(jg.DUFFING, jg.DuffingParams(**DUFF, omega=1.3), "omega", [1.2, 1.3], [0.0, 0.0],
                            transients=10)


def test_plots_draw_from_loaded_results(small_results):
    from matplotlib.collections import PathCollection, PolyCollection, QuadMesh

    from jaxgear import plotting

    bif = load_bifurcation(small_results["paths"]["bif"])
    fig = plotting.plot_bifurcation(bif, "x")
    ax = fig.axes[0]
    sc = [c for c in ax.collections if isinstance(c, PathCollection)]
    assert len(sc) >= 2 and sum(len(c.get_offsets()) for c in sc) > 0  # up and down sweeps
    assert ax.get_legend() is not None and "omega" in ax.get_xlabel()
    with pytest.raises(ValueError, match="coordinate"):
        plotting.plot_bifurcation(bif, "x9")
    bas = load_basin_sweep(small_results["paths"]["bas"])
    fig = plotting.plot_basin_shares(bas)
    assert any(isinstance(c, PolyCollection) for c in fig.axes[0].collections)
    fig = plotting.plot_basin_shares(bas, multipliers=True)  # a panel of the multipliers below
    lines = fig.axes[1].get_lines()
    assert len(lines) == bas.n_attractors + 1 and lines[-1].get_ydata()[0] == 1.0  # one per attractor, the limit
    for g in range(bas.n_attractors):
        np.testing.assert_array_equal(lines[g].get_ydata(), bas.multiplier[:, g])
    assert np.isfinite(bas.multiplier[bas.present]).all() and (bas.multiplier[bas.present] < 1).all()
    pm = load_parameter_map(small_results["paths"]["pm"])
    for q in ("period", "n_attractors"):
        fig = plotting.plot_parameter_map(pm, q)
        assert any(isinstance(c, QuadMesh) for c in fig.axes[0].collections)


# ----------------------------------------------------------------- command line
@pytest.mark.slow
def test_cli_sweep_writes_files(tmp_path):
    out = tmp_path / "sw"
    cmd = [sys.executable, "-m", "jaxgear", "sweep", "--param", "b", "--values", "4:6:3", "--starts", "2",
           "--transient", "20", "--record", "33", "--steps-per-period", "50", "--out", str(out), "--quiet"]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "sweep" in r.stdout and "up" in r.stdout and "down" in r.stdout
    for f in ("bifurcation.nc", "summary.json", "bifurcation.png", "manifest.json"):
        assert (out / f).is_file(), f
    d = load_bifurcation(out / "bifurcation.nc")
    assert d.param == "b" and d.fields == ("b_sp", "b_rp") and d.values.tolist() == [4.0, 5.0, 6.0]
    assert json.loads((out / "summary.json").read_text())["kind"] == "bifurcation"


def test_cli_bad_input_exit_codes(tmp_path, capsys, monkeypatch):
    from jaxgear.cli import main

    base = ["sweep", "--param", "b", "--out", str(tmp_path / "x")]
    for values, msg in (("3:7", "START:STOP:COUNT"), ("3:7:1", "COUNT must be >= 2"), ("5:5:3", "empty"),
                        ("a:7:3", "numbers"), ("3:7:2.5", "integer")):
        assert main(base + ["--values", values]) == 2
        assert msg in capsys.readouterr().err
    assert main(["sweep", "--param", "backlash", "--values", "3:7:3", "--out", str(tmp_path / "x")]) == 2
    assert "valid names" in capsys.readouterr().err
    assert main(base + ["--values", "3:7:3", "--kind", "continuation"]) == 2  # no --from
    assert "--from" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_basins(tmp_path, capsys):
    from jaxgear.cli import main

    out = tmp_path / "bs"
    rc = main(["sweep", "--param", "kappa_amp", "--values", "0.36:0.37:2", "--kind", "basins", "--grid", "3,2,3",
               "--steps-per-period", "50", "--max-period", "8", "--out", str(out), "--quiet",
               "--no-figures", "--uncertainty-samples", "8"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "sink" in text and "present" in text and "unc. step" in text and "label uncertainty" in text
    s = load_basin_sweep(out / "basins.nc")
    assert s.labels.shape == (2, 3, 2, 3) and s.fields == ("kappa_sp_amp", "kappa_rp_amp")
    assert np.isfinite(s.uncertainty_step).all() and s.uncertainty_samples == 8
    base = ["sweep", "--param", "b", "--values", "4:5:2", "--out", str(tmp_path / "x"), "--quiet"]
    assert main(base + ["--kind", "basins", "--uncertainty-samples", "-1"]) == 2
    assert "--uncertainty-samples" in capsys.readouterr().err
    assert main(base + ["--uncertainty-samples", "8"]) == 2  # --kind bifurcation
    assert "--kind basins" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_sweep_killed_and_restarted(tmp_path):
    """A real kill (SIGKILL) in the middle of `jaxgear sweep`, then the same command again:
    the file equals that of an uninterrupted run and the finished blocks are kept."""
    import os
    import signal
    import time

    def cmd(out):
        return [sys.executable, "-m", "jaxgear", "sweep", "--param", "b", "--values", "3:7:24", "--starts", "4",
                "--transient", "300", "--record", "33", "--out", str(out), "--quiet", "--no-figures"]

    env = dict(os.environ, JAXGEAR_CACHE_DIR=str(tmp_path / "cache"))  # a killed run may leave a half-written entry
    assert subprocess.run(cmd(tmp_path / "full"), cwd=ROOT, capture_output=True, timeout=600, env=env).returncode == 0
    run = tmp_path / "run"
    proc = subprocess.Popen(cmd(run), cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    t0 = time.time()
    while time.time() - t0 < 300 and proc.poll() is None and not list((run / "parts").glob("*.npz")):
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    kept = sorted(p.name for p in (run / "parts").glob("*.npz"))
    assert proc.returncode == -signal.SIGKILL and 0 < len(kept) < 8, kept  # 24 values in blocks of 3
    stamps = {n: (run / "parts" / n).stat().st_mtime_ns for n in kept}
    assert subprocess.run(cmd(run), cwd=ROOT, capture_output=True, timeout=600).returncode == 0
    assert all((run / "parts" / n).stat().st_mtime_ns == t for n, t in stamps.items())  # not recomputed
    _assert_same_file(tmp_path / "full" / "bifurcation.nc", run / "bifurcation.nc")


def test_kill_and_resume_parameter_map(tmp_path, monkeypatch):
    """A parameter map killed after two blocks resumes from its parts: every unfinished
    grid point computed once, no finished one again, and the file equals that of an
    uninterrupted run; the same folder with another setting is refused, naming it."""
    from jaxgear.sweep import _parameter_map as map_module

    p = jg.DuffingParams(**DUFF, omega=1.0)
    kw = dict(transient=30, record=17, integrator=jg.RK4(32), max_period=8, chunk_size=4)
    args = (jg.DUFFING, p, "omega", np.linspace(1.0, 1.6, 4), "gamma", [0.2, 0.3, 0.4], [[0.0, 0.0], [2.0, 0.0]])
    run = jg.Runner(out=tmp_path / "run", progress=False)
    full = parameter_map(*args, runner=jg.Runner(out=tmp_path / "full", progress=False), **kw)
    with monkeypatch.context() as m:
        _interrupt_after(m, 2)
        with pytest.raises(_Kill):
            parameter_map(*args, runner=run, **kw)
    assert len(list((tmp_path / "run" / "parts").glob("*.npz"))) == 2
    B = json.loads((tmp_path / "run" / "manifest.json").read_text())["settings"]["block_points"]
    assert B == 2  # (4 lanes, 2 starts) six blocks of two points
    seen = []
    real = map_module.independent_points

    def counting(system, params, names, V, *a, **k):
        seen.extend(map(tuple, np.asarray(V).tolist()))
        return real(system, params, names, V, *a, **k)

    monkeypatch.setattr(map_module, "independent_points", counting)
    resumed = run.run(parameter_map, *args, **kw)
    assert len(seen) == 12 - 2 * B  # every unfinished point once, no finished one again
    _assert_same_file(tmp_path / "full" / "parameter_map.nc", tmp_path / "run" / "parameter_map.nc")
    np.testing.assert_array_equal(resumed.period, full.period)
    with pytest.raises(ValueError, match="transient"):
        parameter_map(*args, runner=run, **dict(kw, transient=31))


def test_a_matched_attractor_keeps_its_decided_type_where_the_test_cannot_decide():
    """Along a sweep an attractor left undetermined at a value takes the type decided for
    it at the nearest value (the earlier on a tie); one never decided stays undetermined,
    and a decided type is never replaced."""
    from jaxgear import AttractorType as T
    from jaxgear.sweep._classify import carry_decided_types

    C, Q, U, P, X = (int(T.CHAOTIC), int(T.QUASI_PERIODIC), int(T.UNDETERMINED), int(T.PERIODIC), int(T.UNKNOWN))
    kind = np.array([[C, Q, U, X],
                     [U, U, U, X],
                     [U, C, U, P],
                     [C, U, U, X]])
    got = carry_decided_types(kind)
    want = np.array([[C, Q, U, X],
                     [C, Q, U, X],
                     [C, C, U, P],
                     [C, C, U, X]])  # attractor 1 at value 1: values 0 (Q) and 2 (C) are as near: the earlier
    np.testing.assert_array_equal(got, want)
    tie = carry_decided_types(np.array([[Q], [U], [C]]))
    assert tie[1, 0] == Q  # the earlier of two equally near values
    np.testing.assert_array_equal(carry_decided_types(kind)[kind != U], kind[kind != U])
