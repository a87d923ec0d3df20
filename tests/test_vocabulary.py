"""One vocabulary at the public boundary: a sweep's direction, a map's quantity and a design
scalar's mesh are enumerations (``SweepDirection``, ``MapQuantity``, ``GearMesh``) that the
functions also take as their texts; a text that is no member is refused before anything is
integrated, naming the allowed values. A sweep's direction (a text) and a Poincaré
section's crossing direction (a signed number) refuse each other's values. The direct
method holds the lane pool's options as one ``PoolOptions``, and still takes them one by
one. (How the enumerations and records are stored: tests/test_io.py.)"""

import numpy as np
import pytest

import jaxgear as jg
from jaxgear._checks import check_enum

QUIET = jg.Runner(progress=False)  # nothing written, no progress bars

DUFF = jg.DuffingParams(delta=0.1, alpha=1.0, beta=1.0, gamma=0.3, omega=1.4)
X0 = np.zeros((1, 2))


def test_a_member_or_its_text_is_taken_and_anything_else_refused_naming_the_values():
    for cls in (jg.SweepDirection, jg.MapQuantity, jg.GearMesh):
        for m in cls:
            assert check_enum(m, "x", cls) is m and check_enum(m.value, "x", cls) is m and m == m.value
    allowed = "'independent', 'up', 'down', 'both', 'all'"
    for bad in ("sideways", "UP", 1, None, True, jg.MapQuantity.PERIOD):
        with pytest.raises(ValueError, match=f"direction={bad!r} must be one of {allowed}"):
            check_enum(bad, "direction", jg.SweepDirection)


def test_sweep_directions_run_their_sweeps():
    D = jg.SweepDirection
    assert [d.sweeps for d in D] == [(D.INDEPENDENT,), (D.UP,), (D.DOWN,), (D.UP, D.DOWN),
                                     (D.INDEPENDENT, D.UP, D.DOWN)]
    assert jg.sweep.DIRECTIONS == ("independent", "up", "down", "both", "all")


def test_a_bad_direction_or_quantity_is_refused_before_integrating(monkeypatch):
    from jaxgear.sweep import _bifurcation, _parameter_map

    def no_integration(*args, **kw):
        raise AssertionError("integrated before the arguments were checked")

    for module, name in ((_bifurcation, "independent_points"), (_bifurcation, "sequential_points"),
                         (_parameter_map, "independent_points")):
        monkeypatch.setattr(module, name, no_integration)
    for bad in ("sideways", 1, -1):  # the sweep's direction is no signed crossing direction
        with pytest.raises(ValueError, match=r"direction=.* must be one of 'independent', 'up', 'down', 'both', 'all'"):
            jg.bifurcation_diagram(jg.DUFFING, DUFF, "omega", [1.3, 1.4], X0, direction=bad, runner=QUIET)
    with pytest.raises(ValueError, match="quantity='periods' must be one of 'period', 'n_attractors'"):
        jg.parameter_map(jg.DUFFING, DUFF, "omega", [1.3, 1.4], "gamma", [0.2, 0.3], X0, quantity="periods",
                         runner=QUIET)


def test_a_poincare_direction_is_a_signed_number_not_a_sweep_direction():
    for bad in ("up", jg.SweepDirection.UP, "independent"):
        with pytest.raises(ValueError, match="direction=.* must be one of 1, -1, 0"):
            jg.PoincareCellMap(direction=bad)
    assert jg.PoincareCellMap(direction=-1).direction == -1


def test_gear_mesh_is_an_enum_taken_as_its_text():
    """The mesh-force scalars take ``GearMesh`` members or their texts (the same number);
    a transmission error is of one mesh; any other text is refused naming the values."""
    p = jg.paper_params()
    ts = np.linspace(0.0, 2 * np.pi / float(p.Omega), 16, endpoint=False)
    xs = np.stack([0.8 + 0.1 * np.sin(ts), np.cos(ts), 1.0 + 0.2 * np.cos(ts), np.sin(ts)], axis=1)
    orbit = (ts, xs)
    for f in (jg.mesh_force_ptp, jg.mesh_force_rms, jg.transmission_error_rms):
        for m in ((jg.GearMesh.SP, jg.GearMesh.RP, jg.GearMesh.BOTH) if f is not jg.transmission_error_rms
                  else (jg.GearMesh.SP, jg.GearMesh.RP)):
            assert float(f(p, orbit, mesh=m)) == float(f(p, orbit, mesh=m.value))
    both = float(jg.mesh_force_ptp(p, orbit, mesh="both"))
    assert both == float(jg.mesh_force_ptp(p, orbit, mesh="sp")) + float(jg.mesh_force_ptp(p, orbit, mesh="rp"))
    with pytest.raises(ValueError, match="mesh='planet' must be one of 'sp', 'rp', 'both'"):
        jg.mesh_force_rms(p, orbit, mesh="planet")
    with pytest.raises(ValueError, match="mesh='both' must be one of 'sp', 'rp'"):
        jg.transmission_error(p, orbit, mesh="both")


def test_direct_holds_pool_options_and_takes_them_one_by_one():
    """``Direct(max_periods=...)`` is ``Direct(pool=PoolOptions(max_periods=...))``; the
    options every method has read the pool's (``chunk_size`` its ``lanes``); ``replace``
    and ``like`` change the pool; an option of no pool is refused naming the options."""
    d = jg.Direct(max_periods=4000, max_period=8, chunk_size=64)
    assert d.pool == jg.PoolOptions(max_periods=4000, max_period=8, lanes=64)
    assert d == jg.Direct(pool=jg.PoolOptions(max_periods=4000, max_period=8, lanes=64))
    assert (d.max_period, d.chunk_size, d.period_tol, d.merge_tol) == (8, 64, 1e-6, 1e-4)
    assert d.max_periods == 4000 and d.round_periods == 5 and d.capture_radius is None  # the pool's, read through
    assert jg.Direct().pool == jg.PoolOptions() and jg.Direct().pool_options(pilot=0).pilot == 0
    e = d.replace(round_periods=10, integrator=jg.RK4(32))
    assert e.pool == jg.PoolOptions(max_periods=4000, max_period=8, lanes=64, round_periods=10)
    assert e.integrator == jg.RK4(32) and jg.Direct(pool=d.pool, max_periods=10).pool.max_periods == 10
    like = jg.Direct.like(jg.PoincareCellMap(max_period=3, chunk_size=99))
    assert like.pool == jg.PoolOptions(max_period=3, lanes=99)
    assert jg.analysis.method_from_dict(e.to_dict()) == e and e.to_dict()["pool"]["round_periods"] == 10
    with pytest.raises(TypeError, match="unexpected option 'mapping_steps'.*max_periods"):
        jg.Direct(mapping_steps=3)
    with pytest.raises(ValueError, match="chunk_size"):
        jg.Direct(chunk_size=0)
    with pytest.raises(ValueError, match="max_periods"):
        jg.Direct(max_periods=0)
    with pytest.raises(ValueError, match="pool=.* must be a jaxgear.analysis.PoolOptions"):
        jg.Direct(pool={"max_periods": 10})
    with pytest.raises(AttributeError, match="mapping_steps"):
        _ = jg.Direct().mapping_steps
