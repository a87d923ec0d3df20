"""The gear view of an attractor (jaxgear/_contact.py): contact shares, impacts, dynamic
transmission error, mesh force and spectrum, checked against answers that do not come from
the code: the closed form of the linear forced oscillator, an event-located integration
by scipy, and a DFT over a longer window."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxgear as jg
import jaxgear._contact as contact
from jaxgear._contact import ContactRegime, GearView, GearViewOptions, MeshSpec, gear_view
from jaxgear.analysis import Attractor

QUIET = jg.Runner(progress=False)  # nothing written, no progress bars

# the single spur pair of jaxgear.SPUR_PAIR, declared as a user system with one mesh:
# switching functions x - b (drive flank) and x + b (back flank)
SPUR = jg.ForcedSystem(vector_field=jg.SPUR_PAIR.vector_field, period=jg.SPUR_PAIR.period, state_names=("x", "v"),
                       section_index=1, name="spur-mesh", switching=lambda t, x, p: jnp.stack([x[0] - p.b, x[0] + p.b]))


def spur_force(t, x, p):
    """The mesh force of the spur pair: stiffness through the backlash plus damping."""
    return jnp.reshape((1.0 + p.kappa * jnp.sin(p.Omega * t)) * jg.backlash(x[0], p.b) + 2.0 * p.zeta * x[1], (1,))


def attractor(points, period, id=0):
    points = np.atleast_2d(np.asarray(points, dtype=float))
    return Attractor(id=id, period=period, points=points, section_points=np.zeros((0, points.shape[1])))


# a P-2 with double-sided impacts (small backlash, large excitation): its stroboscopic
# points from an adaptive integration (rtol 1e-12) over 100 periods
P2_PARAMS = jg.SpurPairParams(zeta=0.05, kappa=0.0, b=0.1, f_m=0.1, e_amp=0.3, Omega=1.8)
P2_POINTS = [[0.164390327329, -0.311488197674], [0.030744445103, -1.12295573442]]


@pytest.fixture(scope="module")
def p2_view():
    return gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2), meshes=MeshSpec(force=spur_force, static_force=0.1))


def event_reference(p, x, periods):
    """Contact shares and falls through +-b per period by scipy with located events: the
    spur pair integrated piece by piece (drive flank, gap, back flank), every change of
    piece an event (DOP853, rtol 1e-12)."""
    b = float(p.b)
    W, z, fm, e, kap = (float(v) for v in (p.Omega, p.zeta, p.f_m, p.e_amp, p.kappa))
    T = 2 * math.pi / W

    def piece(side):
        def f(t, y):
            d = y[0] - b if side == 1 else (y[0] + b if side == -1 else 0.0)
            return [y[1], fm + e * W * W * math.sin(W * t) - 2 * z * y[1] - (1 + kap * math.sin(W * t)) * d]
        return f

    def event(level, direction):
        g = lambda t, y: y[0] - level  # noqa: E731
        g.terminal, g.direction = True, direction
        return g

    t, t_end, x = 0.0, periods * T, np.asarray(x, dtype=float)
    side = 1 if x[0] > b else (-1 if x[0] < -b else 0)
    time = {1: 0.0, 0: 0.0, -1: 0.0}
    losses = impacts = 0
    while t < t_end:
        events = {1: [event(b, -1)], 0: [event(b, 1), event(-b, -1)], -1: [event(-b, 1)]}[side]
        sol = solve_ivp(piece(side), (t, t_end), x, events=events, rtol=1e-12, atol=1e-13, method="DOP853")
        time[side] += sol.t[-1] - t
        if sol.status == 1:
            if side == 1:
                side, losses = 0, losses + 1
            elif side == -1:
                side = 0
            elif len(sol.t_events[0]):
                side = 1
            else:
                side, impacts = -1, impacts + 1
        t, x = sol.t[-1], sol.y[:, -1]
    return {k: v / t_end for k, v in time.items()}, losses / periods, impacts / periods


def test_static_load_above_the_dynamic_amplitude_is_the_linear_oscillator():
    """(a) Zero stiffness variation and a static deflection larger than the dynamic
    amplitude: the mesh never leaves the drive flank and is the forced linear oscillator
    x'' + 2 zeta x' + (x - b) = f_m + e Omega^2 sin(Omega t), whose steady state is
    x = b + f_m + A sin(Omega t - phi), A = e Omega^2 / sqrt((1 - Omega^2)^2 + (2 zeta Omega)^2),
    and whose mesh force f_m + A sqrt(1 + (2 zeta Omega)^2) sin(...) peaks at the dynamic factor."""
    z, W, e, fm, b = 0.05, 0.8, 0.1, 1.0, 0.1
    p = jg.SpurPairParams(zeta=z, kappa=0.0, b=b, f_m=fm, e_amp=e, Omega=W)
    A = e * W**2 / math.hypot(1 - W**2, 2 * z * W)
    phi = math.atan2(2 * z * W, 1 - W**2)
    x0 = [b + fm - A * math.sin(phi), A * W * math.cos(phi)]
    view = gear_view(SPUR, p, attractor(x0, 1), meshes=MeshSpec(force=spur_force, static_force=fm))
    (m,) = view.meshes
    assert m.regime is ContactRegime.NO_IMPACT and m.regime.text == "no impact"
    assert (m.drive_share, m.gap_share, m.back_share) == (1.0, 0.0, 0.0)
    assert m.losses_per_period == 0 and m.impacts_per_period == 0
    assert m.te_mean == pytest.approx(b + fm, abs=1e-8)
    assert m.te_rms == pytest.approx(A / math.sqrt(2), rel=1e-7)
    assert m.te_ptp == pytest.approx(2 * A, rel=1e-7)
    assert m.force_mean == pytest.approx(fm, abs=1e-8)
    assert m.force_max == pytest.approx(fm + A * math.hypot(1, 2 * z * W), rel=1e-7)
    assert m.dynamic_factor == pytest.approx(1 + A * math.hypot(1, 2 * z * W) / fm, rel=1e-7)
    one = np.argmin(np.abs(m.orders - 1.0))
    assert m.orders[one] == 1.0 and m.amplitudes[one] == pytest.approx(A, rel=1e-7)
    assert view.length_unit == "state unit" and math.isnan(view.mesh_frequency_hz)


def test_double_sided_motion_matches_an_event_located_integration(p2_view):
    """(b) Contact shares and impacts per period equal those of scipy's event-located
    integration from the same start to 1e-6."""
    (m,) = p2_view.meshes
    shares, losses, impacts = event_reference(P2_PARAMS, p2_view.start, 2)
    assert m.regime is ContactRegime.DOUBLE_SIDED
    assert m.drive_share == pytest.approx(shares[1], abs=1e-6)
    assert m.gap_share == pytest.approx(shares[0], abs=1e-6)
    assert m.back_share == pytest.approx(shares[-1], abs=1e-6)
    assert (m.losses_per_period, m.impacts_per_period) == (losses, impacts) == (1.0, 0.5)


def test_shares_sum_to_one_and_a_pk_spectrum_has_only_its_harmonics(p2_view):
    """(c) The three shares partition the time; the P-2's spectrum equals a DFT over three
    times its period, which holds energy only at multiples of 1/2 of the forcing frequency."""
    (m,) = p2_view.meshes
    assert min(m.drive_share, m.gap_share, m.back_share) > 0
    assert m.drive_share + m.gap_share + m.back_share == pytest.approx(1.0, abs=1e-14)
    assert np.allclose(np.diff(m.orders), 0.5)
    s = p2_view.samples_per_period
    _, xs = jg.sample_trajectory(SPUR, P2_PARAMS, p2_view.start, periods=6, samples_per_period=s,
                                 integrator=p2_view.integrator)
    x = np.asarray(xs)[:-1, 0]
    X = np.abs(np.fft.rfft(x)) / len(x)
    X[1:] *= 2
    harmonic = np.arange(len(X)) % 3 == 0  # bin j of 6 periods is order j / 6
    assert np.max(X[~harmonic]) < 1e-7 * np.max(X)
    assert m.amplitudes[1] > 0.1  # the subharmonic 1/2 is there
    n = len(m.orders)
    assert np.allclose(X[harmonic][:n], m.amplitudes, rtol=1e-6, atol=1e-9)


def test_views_of_several_attractors_equal_views_of_each_and_compile_once(p2_view):
    """gear_views of attractors of different periods equals gear_view of each (to
    round-off) and compiles one sampling program and one bisection for all of them: a
    second P-k of a new period adds no program (a per-attractor loop traces one sampling
    program per period)."""
    from tests.conftest import count_compilations

    spec = MeshSpec(force=spur_force, static_force=0.1)
    p1 = attractor(P2_POINTS[:1], 1, id=1)  # one point of the P-2 taken as a P-1: any stretch will do here
    p2 = attractor(P2_POINTS, 2, id=0)
    p2_rot = attractor(P2_POINTS[::-1], 2, id=2)
    jg.gear_views(SPUR, P2_PARAMS, [p2], meshes=spec)  # warm: the programs of one P-2
    with count_compilations("_sample_kernel") as sampling, count_compilations("_one_period") as one, \
            count_compilations("_locate") as bisection:
        views = jg.gear_views(SPUR, P2_PARAMS, [p1, p2, p2_rot], meshes=spec)
    assert sampling == [] and one == [], "a new period compiled a new sampling program"
    assert len(bisection) <= 1, bisection
    assert [v.attractor_id for v in views] == [1, 0, 2]
    one = gear_view(SPUR, P2_PARAMS, p1, meshes=spec)
    for got, ref in ((views[0], one), (views[1], p2_view), (views[2], p2_view)):
        for m, r in zip(got.meshes, ref.meshes):
            assert m.regime == r.regime
            for field in ("drive_share", "gap_share", "back_share", "losses_per_period", "impacts_per_period",
                          "te_rms", "te_ptp", "force_max"):
                assert getattr(m, field) == pytest.approx(getattr(r, field), rel=1e-9, abs=1e-12), field
    assert views[1].period == 2 and views[0].period == 1


def test_an_analysis_and_the_gear_view_of_its_cycles_share_one_program_of_one_period():
    """A cycle's section points and Floquet multipliers come from one program (one jvp of a
    period sampled at every step): an analysis compiles it once, with no separate sampling
    or derivative program, and the gear view of its cycles (one sample per step of the same
    integrator) compiles no sampling program of its own."""
    from tests.conftest import count_compilations

    method = jg.Direct(integrator=jg.RK4(54))  # a step count no other test compiles
    grid = jg.CellGrid.box([(-1.5, 1.5), (-2, 2)], (8, 8), names=("x", "v"))
    with count_compilations("_one_period") as one, count_compilations("_sample_kernel") as sampling:
        r = jg.analyze_global(SPUR, P2_PARAMS, grid, method=method, progress=False, uncertainty=0)
    cycles = [a for a in r.attractors if a.period > 0]
    assert cycles and all(len(a.section_points) for a in cycles)
    assert len(one) == 1 and sampling == [], (one, sampling)
    spec = MeshSpec(force=spur_force, static_force=0.1)
    with count_compilations("_one_period") as again, count_compilations("_sample_kernel") as sampling:
        views = jg.gear_views(SPUR, P2_PARAMS, cycles, meshes=spec, samples_per_period=54,
                              integrator=method.integrator)
    assert again == [] and sampling == [] and len(views) == len(cycles), (again, sampling)
    from jaxgear._poincare import one_period  # its samples: those of sample_trajectory, its last one P

    X = np.asarray(cycles[0].points)
    ts, xs, J = one_period(SPUR, P2_PARAMS, X, method.integrator)
    t_ref, x_ref = jg.sample_trajectory(SPUR, P2_PARAMS, X, samples_per_period=54, integrator=method.integrator)
    np.testing.assert_allclose(ts, t_ref, rtol=1e-15)
    np.testing.assert_allclose(xs, x_ref, rtol=1e-12, atol=1e-13)
    h = 1e-6  # and the Jacobian: central differences of the map
    fd = [(jg.stroboscopic_map(SPUR, P2_PARAMS, X[0] + h * e, integrator=method.integrator)
           - jg.stroboscopic_map(SPUR, P2_PARAMS, X[0] - h * e, integrator=method.integrator)) / (2 * h)
          for e in np.eye(2)]
    np.testing.assert_allclose(J[0], np.stack(fd, axis=1), rtol=1e-6, atol=1e-8)


def test_aperiodic_run_of_the_gear_model_reads_design_forces_and_units():
    """An aperiodic attractor is followed over stretches (errors from their spread); the
    transmission error and mesh forces of the gear model are those of jaxgear.mesh_forces and
    jaxgear.transmission_error on the same samples; a GearSet gives um, N and Hz."""
    gs = jg.paper_gear_set()
    p = gs.to_params()
    a = attractor([1.0, 0.5, 3.0, 0.0], 0)
    view = gear_view(jg.REDUCED, p, a, gs, stretches=2, stretch_periods=2, samples_per_period=64)
    assert [m.name for m in view.meshes] == ["sun-planet", "ring-planet"]
    assert (view.length_unit, view.force_unit, view.stretches, view.periods_covered) == ("um", "N", 2, 4)
    _, xs = jg.sample_trajectory(jg.REDUCED, p, a.points[0], periods=4, samples_per_period=64,
                                 integrator=view.integrator)
    ts = np.arange(4 * 64) * (2 * np.pi / float(p.Omega)) / 64 % (2 * np.pi / float(p.Omega))
    orbit = (jnp.asarray(ts), xs[:-1])
    f = jg.mesh_forces(p, orbit)
    k_ref, b_c = 0.8256e9, 10.0
    for m, g, mesh in zip(view.meshes, (f.sp, f.rp), ("sp", "rp")):
        te = np.asarray(jg.transmission_error(p, orbit, mesh)) * b_c
        assert m.te_mean == pytest.approx(np.mean(te), rel=1e-9, abs=1e-9)
        assert m.force_mean == pytest.approx(np.mean(g) * k_ref * b_c * 1e-6, rel=1e-9)
        assert m.static_force == pytest.approx(float(p.f_D) / 3 * k_ref * b_c * 1e-6)
        assert m.drive_share + m.gap_share + m.back_share == pytest.approx(1.0, abs=1e-12)
        assert np.allclose(np.diff(m.orders), 0.5)  # stretches of 2 periods
    assert view.mesh_frequency_hz == pytest.approx(gs.derived()["mesh_frequency_hz"], rel=1e-12)
    assert "sun-planet" in view.table() and "um" in view.lines()[0]


def test_save_load_round_trip(p2_view, tmp_path):
    path = p2_view.save(tmp_path / "view.nc")
    back = jg.load(path)
    assert isinstance(back, GearView)
    assert back.meshes[0].regime is ContactRegime.DOUBLE_SIDED
    for field in ("attractor_id", "label", "period", "periods_covered", "length_unit", "system", "params",
                  "integrator"):
        assert getattr(back, field) == getattr(p2_view, field), field
    np.testing.assert_array_equal(back.start, p2_view.start)
    for a, b in zip(back.meshes, p2_view.meshes):
        np.testing.assert_array_equal(a.amplitudes, b.amplitudes)
        assert (a.name, a.drive_share, a.impacts_per_period, a.dynamic_factor) == \
            (b.name, b.drive_share, b.impacts_per_period, b.dynamic_factor)


@pytest.mark.parametrize("call, name", [
    (lambda: gear_view(jg.SPUR_PAIR, P2_PARAMS, attractor(P2_POINTS, 2)), "switching"),
    (lambda: gear_view("spur", P2_PARAMS, attractor(P2_POINTS, 2)), "system="),
    (lambda: gear_view(SPUR, P2_PARAMS, P2_POINTS), "attractor="),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor([[0.1, 0.2, 0.3]], 1)), "attractor"),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2), jg.paper_gear_set()), "gear_set"),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2), meshes=MeshSpec(pairs=((0, 2),))), "meshes"),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2), meshes={"pairs": ((0, 1),)}), "meshes="),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2), samples_per_period=4), "samples_per_period"),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2), max_order=1000.0), "max_order"),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2), stepz=3), "stepz"),
    (lambda: gear_view(SPUR, P2_PARAMS, attractor(P2_POINTS, 2),
                       meshes=MeshSpec(force=lambda t, x, p: jnp.zeros(2))), "meshes"),
    (lambda: MeshSpec(static_force=-1.0), "static_force"),
    (lambda: GearViewOptions(stretches=1), "stretches"),
])
def test_bad_input_is_refused_before_any_integration(call, name, monkeypatch):
    """(d) Every bad argument raises ValueError naming it, before anything is integrated."""
    def no_work(*a, **k):
        raise AssertionError("integrated before the arguments were checked")

    monkeypatch.setattr(contact, "sample_trajectory", no_work)
    monkeypatch.setattr(contact, "stroboscopic_map", no_work)
    with pytest.raises(ValueError, match=name):
        call()


class _Result:
    """What ``jaxgear analyze`` hands to its mesh lines: the attractors of a result."""

    def __init__(self, attractors):
        self.attractors = attractors


def test_analyze_prints_one_line_per_attractor_and_mesh(capsys):
    from jaxgear.cli.analyze import _print_meshes

    _print_meshes(_Result([attractor(P2_POINTS, 2)]), SPUR, P2_PARAMS, None)
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0] == "meshes (jaxgear.gear_view):"
    assert lines[1].startswith("  attractor 0 (P-2), mesh 1: double-sided impact, RMS TE ")
    assert lines[1].endswith("state unit, dynamic factor -")  # a user system without a force
    _print_meshes(_Result([attractor([0.1, 0.2], 1)]), jg.DUFFING, jg.DuffingParams(), None)
    assert capsys.readouterr().out == ""  # no switching functions: no meshes
    odd = jg.ForcedSystem(vector_field=SPUR.vector_field, period=SPUR.period, state_names=("x", "v"),
                          switching=lambda t, x, p: jnp.stack([x[0] - p.b]))
    _print_meshes(_Result([attractor(P2_POINTS, 2)]), odd, P2_PARAMS, None)
    assert "not shown: meshes:" in capsys.readouterr().out


@pytest.mark.slow
def test_analyze_paper_preset_prints_meshes_in_micrometres(tmp_path, capsys):
    from jaxgear.cli import main

    rc = main(["analyze", "--grid", "5,3,6", "--quiet", "--no-figures", "--uncertainty-samples", "0",
               "--out", str(tmp_path / "out")])
    assert rc == 0
    text = capsys.readouterr().out
    assert "meshes (jaxgear.gear_view, physical units):" in text
    lines = [s for s in text.splitlines() if "RMS TE" in s]
    assert lines and all(" um, dynamic factor " in s for s in lines)
    assert any("sun-planet" in s for s in lines) and any("ring-planet" in s for s in lines)
    # summary.json and one gear_view_<id>.nc per attractor hold the same views
    import json

    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    views = summary["gear_views"]
    assert [v["attractor_id"] for v in views] == [a["id"] for a in summary["attractors"]]
    for v in views:
        saved = jg.load(tmp_path / "out" / f"gear_view_{v['attractor_id']}.nc")
        assert [m.name for m in saved.meshes] == [m["name"] for m in v["meshes"]] == ["sun-planet", "ring-planet"]
        for m, d in zip(saved.meshes, v["meshes"]):
            assert m.te_rms == pytest.approx(d["te_rms"], rel=1e-12) and m.regime.text == d["regime"]
        line = f"attractor {v['attractor_id']} (P-{v['period']}), ring-planet: "
        assert any(s.strip().startswith(line) for s in lines)


def test_the_figure_shades_the_contact_states_the_view_counted(p2_view):
    """plot_gear_view draws one row per mesh: over the P-2's two periods the shaded gap and
    back-flank time equal the view's gap and back shares (to the sample spacing), and the
    spectrum's stems are the view's amplitudes."""
    from jaxgear.plotting import plot_gear_view

    assert p2_view.meshes[0].back_share > 0.01  # (the fixture's mesh reaches the back flank)
    fig = plot_gear_view(p2_view, SPUR, P2_PARAMS)
    ax, sp = fig.axes[0], fig.axes[1]
    gap, back = ax.collections[0], ax.collections[1]  # fill_between, in that order
    (m,) = p2_view.meshes

    def shaded_share(poly):
        # the shaded intervals of the phase axis (vertices of the filled polygons)
        covered = 0.0
        for path in poly.get_paths():
            x = path.vertices[:, 0]
            covered += x.max() - x.min() if len(x) else 0.0
        return covered / p2_view.period

    tol = 3.0 / p2_view.samples_per_period  # a sample interval at each end of each shaded piece
    assert shaded_share(gap) == pytest.approx(m.gap_share, abs=tol)
    assert shaded_share(back) == pytest.approx(m.back_share, abs=tol)
    stems = sp.collections[0].get_segments()
    np.testing.assert_allclose([s[1][1] for s in stems], m.amplitudes)
    with pytest.raises(ValueError, match="must be a jaxgear.GearView"):
        plot_gear_view("view", SPUR, P2_PARAMS)


@pytest.mark.slow  # about 20 s: a basin sweep of two values
def test_regime_shares_across_a_sweep_partition_the_state_space():
    """Over an excitation sweep of the spur pair: at a small excitation the mesh keeps
    contact from every start (the linear oscillator's amplitude 0.014 is below the static
    deflection 0.1: closed form, see the first test), at the P-2's excitation every motion
    hits the back flank (the P-2 is the event-counted double-sided motion); each value's
    regimes and the cells on no attractor add to 1; a map is refused."""
    grid = jg.CellGrid.box([(-1.0, 1.5), (-2.0, 2.0)], (6, 6), names=("x", "v"))
    sweep = jg.basin_sweep(SPUR, P2_PARAMS, "e_amp", [0.01, 0.3], grid, runner=QUIET, uncertainty=0)
    rs = jg.regime_shares(sweep, SPUR, P2_PARAMS, meshes=MeshSpec(force=spur_force, static_force=0.1))
    assert rs.meshes == ("mesh 1",) and rs.param == "e_amp"
    np.testing.assert_allclose(rs.shares.sum(axis=2)[:, 0] + rs.no_attractor, 1.0, atol=1e-12)
    assert rs.share("mesh 1", ContactRegime.NO_IMPACT)[0] == pytest.approx(1.0)
    p2 = [g for g in range(sweep.n_attractors) if sweep.period[1, g] == 2]
    assert p2 and rs.share("mesh 1", ContactRegime.DOUBLE_SIDED)[1] >= float(sweep.shares[1, p2[0]]) > 0
    assert set(rs.summary()) >= {"param", "values", "meshes", "regimes", "shares", "no_attractor"}
    from jaxgear.plotting import plot_regime_shares

    fig = plot_regime_shares(rs)
    (ax,) = fig.axes
    bands = ax.collections  # stacked: no impact, single-sided, double-sided, no attractor
    assert len(bands) == 4
    top = np.cumsum(np.concatenate([rs.shares[:, 0], rs.no_attractor[:, None]], axis=1), axis=1)  # (V, 4)
    for j, band in enumerate(bands):
        verts = np.concatenate([path.vertices for path in band.get_paths()])
        for x, y in zip(rs.values, top[:, j]):  # each band's upper edge passes through its cumulative share
            assert np.any(np.isclose(verts[:, 0], x) & np.isclose(verts[:, 1], y)), (j, x, y)
    with pytest.raises(ValueError, match="must be a jaxgear.BasinSweep"):
        jg.regime_shares("sweep", SPUR, P2_PARAMS)


@pytest.mark.slow  # about a minute: two values of the gear model, one chaotic
def test_sweep_command_prints_and_keeps_the_regime_shares(tmp_path, capsys):
    """``jaxgear sweep --kind basins`` over the backlash of the gear model: at b = 2 the
    chaotic motion hits the ring-planet back flanks, at b = 5 (the paper's P-4 and P-8)
    the ring-planet mesh rattles without; summary.json holds the table and regimes.png
    is drawn."""
    import json

    from jaxgear.cli import main

    out = tmp_path / "out"
    rc = main(["sweep", "--kind", "basins", "--param", "b", "--values", "2:5:2", "--grid", "3,2,3",
               "--uncertainty-samples", "0", "--quiet", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "share of the cells in each contact regime" in text
    reg = json.loads((out / "summary.json").read_text())["contact_regimes"]
    ring = reg["meshes"].index("ring-planet")
    shares = np.asarray(reg["shares"])[:, ring]
    assert reg["values"] == [2.0, 5.0]
    assert shares[0, int(ContactRegime.DOUBLE_SIDED)] > 0.5  # chaotic rattle with back-flank impacts
    assert shares[1, int(ContactRegime.SINGLE_SIDED)] == pytest.approx(1.0 - reg["no_attractor"][1])
    assert (out / "regimes.png").exists()


def _synthetic_map():
    """A basin map of the spur mesh over ``e_amp x b`` (2 x 2 points) written by hand: the
    P-2 of the double-sided motion everywhere, and a P-1 from a point near the static
    deflection at two of the points, with shares that leave some cells on no attractor;
    at b = 0.1 the motions hit the back flank, at b = 5 they stay in the gap (so each
    point's regimes depend on its own parameters)."""
    grid = jg.CellGrid.box([(-1.0, 1.5), (-2.0, 2.0)], (2, 2), names=("x", "v"))
    vx, vy = np.array([0.25, 0.3]), np.array([0.1, 5.0])  # at b = 5 the orbits are in the gap
    pts = np.full((2, 2, 2, 2, 2), np.nan)
    pts[:, :, 0] = P2_POINTS
    pts[:, :, 1, 0] = [0.2, 0.0]
    period = np.array([[[2, 1], [2, -1]], [[2, -1], [2, 1]]])
    n_points = np.where(period > 0, period, 0)
    shares = np.where(period > 0, np.array([[[0.5, 0.25], [0.75, 0.0]], [[1.0, 0.0], [0.25, 0.5]]]), 0.0)
    rest = 1.0 - shares.sum(axis=-1)
    return jg.BasinMap(param_x="e_amp", fields_x=("e_amp",), values_x=vx, param_y="b", fields_y=("b",), values_y=vy,
                       shares=shares, sink_share=rest, unresolved_share=np.zeros((2, 2)), period=period, points=pts,
                       n_points=n_points, labels=np.zeros((2, 2, 2, 2), dtype=np.int16), grid=grid, method=jg.Direct(),
                       system="spur-mesh", state_names=("x", "v"))


def test_regime_map_is_each_points_gear_views():
    """On a basin map (here written by hand), every point's regime shares are those of the
    gear views of that point's attractors at that point's parameters (computed here with
    gear_views and with_param, not through the map), the regime of the dominant attractor
    is that attractor's, and the figure draws both panels per mesh."""
    bmap = _synthetic_map()
    spec = MeshSpec(force=spur_force, static_force=0.1)
    rm = jg.regime_shares(bmap, SPUR, P2_PARAMS, meshes=spec)
    assert isinstance(rm, jg.RegimeMap) and rm.meshes == ("mesh 1",) and rm.shares.shape == (2, 2, 1, 3)
    for iy, b in enumerate(bmap.values_y):
        for ix, e in enumerate(bmap.values_x):
            p = jg.with_param(jg.with_param(P2_PARAMS, "e_amp", e), "b", b)
            here = [g for g in range(2) if bmap.period[iy, ix, g] > 0]
            views = jg.gear_views(SPUR, p, [attractor(bmap.points[iy, ix, g, : bmap.period[iy, ix, g]],
                                                      int(bmap.period[iy, ix, g]), id=g) for g in here], meshes=spec)
            expect = np.zeros(3)
            for g, v in zip(here, views):
                expect[int(v.meshes[0].regime)] += bmap.shares[iy, ix, g]
            np.testing.assert_allclose(rm.shares[iy, ix, 0], expect, atol=1e-15, err_msg=f"point {iy}, {ix}")
            dom = int(bmap.dominant[iy, ix])
            assert rm.dominant_regime[iy, ix, 0] == int(views[here.index(dom)].meshes[0].regime)
    np.testing.assert_allclose(rm.shares.sum(axis=-1)[..., 0] + rm.no_attractor, 1.0, atol=1e-12)
    assert set(rm.summary()) >= {"values_x", "values_y", "shares", "no_attractor", "dominant_regime"}
    assert "dominant at" in rm.table()
    from jaxgear.plotting import plot_regime_map

    fig = plot_regime_map(rm)
    left, right = fig.axes[0], fig.axes[1]
    np.testing.assert_array_equal(left.collections[0].get_array().reshape(2, 2), rm.dominant_regime[..., 0] + 1)
    np.testing.assert_allclose(right.collections[0].get_array().reshape(2, 2),
                               100 * rm.share("mesh 1", ContactRegime.DOUBLE_SIDED))
    assert left.get_xlabel() == "e_amp" and left.get_ylabel() == "b"
    with pytest.raises(ValueError, match="must be a jaxgear.RegimeMap"):
        plot_regime_map(rm.summary())


@pytest.mark.slow  # about 30 s: a 2 x 2 basin map and a basin sweep of the spur mesh
def test_regime_map_row_is_the_regime_shares_of_a_basin_sweep():
    """A row of a real basin map is a basin sweep: its regime shares equal regime_shares of
    the basin sweep over the same values at the row's parameter."""
    grid = jg.CellGrid.box([(-1.0, 1.5), (-2.0, 2.0)], (6, 6), names=("x", "v"))
    spec = MeshSpec(force=spur_force, static_force=0.1)
    bmap = jg.basin_map(SPUR, P2_PARAMS, "e_amp", [0.01, 0.3], "zeta", [0.05, 0.06], grid, runner=QUIET,
                        uncertainty=0)
    rm = jg.regime_shares(bmap, SPUR, P2_PARAMS, meshes=spec)
    sweep = jg.basin_sweep(SPUR, jg.with_param(P2_PARAMS, "zeta", 0.06), "e_amp", [0.01, 0.3], grid, runner=QUIET,
                           uncertainty=0)
    rs = jg.regime_shares(sweep, SPUR, jg.with_param(P2_PARAMS, "zeta", 0.06), meshes=spec)
    np.testing.assert_allclose(rm.shares[1], rs.shares, atol=1e-12)
    np.testing.assert_allclose(rm.no_attractor[1], rs.no_attractor, atol=1e-12)
