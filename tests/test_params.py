"""Parameters: physical -> dimensionless (docs/model.md §1-§3, §7), presets, validation.

References are hand calculations from the model document (docs/model.md) written out in the tests (solid steel
disks of the pitch diameters, equivalent masses of §2, scaling of §3), never values
read back from the code.
"""

import json
import math

import numpy as np
import pytest

import jaxgear as jg
from jaxgear import PARAM_NAMES, GearParams, GearSet

# ----------------------------------------------------------------------------- hand calculation
RHO, WIDTH, J_C = 7850.0, 0.025, 0.01
ALPHA = math.radians(20.0)
K_SP, K_RP, K_AMP = 0.8256e9, 1.06e9, 0.3e9
B_C = 10e-6


def hand_paper_numbers(z_s=15, z_p=24, z_r=63, m=3e-3, N=3):
    """Equivalent masses and omega_n of docs/model.md §2 for solid steel disks (docs/model.md §7)."""
    r_s, r_p = m * z_s / 2, m * z_p / 2
    r_c = r_s + r_p
    J_s = 0.5 * RHO * math.pi * r_s**4 * WIDTH
    J_p = 0.5 * RHO * math.pi * r_p**4 * WIDTH
    M_p = RHO * math.pi * r_p**2 * WIDTH
    m_s = J_s / (r_s * math.cos(ALPHA)) ** 2
    m_p = J_p / (r_p * math.cos(ALPHA)) ** 2
    m_c = (J_C + N * M_p * r_c**2) / (r_c * math.cos(ALPHA)) ** 2
    m_eq1 = 1.0 / (1.0 / m_s + 1.0 / m_c)
    return dict(r_s=r_s, r_p=r_p, r_c=r_c, m_s=m_s, m_p=m_p, m_c=m_c, m_eq1=m_eq1,
                omega_n=math.sqrt(K_SP / m_eq1))


def test_paper_preset_matches_model_md_numbers():
    p = jg.paper_params()
    # docs/model.md §7 (independent exploration): rounded values
    assert p.N == 3
    assert abs(float(p.mu_s) - 0.9715) < 5e-4
    assert abs(float(p.mu_c) - 0.0285) < 5e-4
    assert abs(float(p.mu_p) - 0.3795) < 5e-4
    omega_n = jg.paper_gear_set().derived()["omega_n"]
    assert abs(omega_n - 69_300) / 69_300 < 2e-3


def test_paper_preset_matches_hand_calculation():
    h = hand_paper_numbers()
    p = jg.paper_params()
    np.testing.assert_allclose(float(p.mu_s), h["m_eq1"] / h["m_s"], rtol=1e-12)
    np.testing.assert_allclose(float(p.mu_c), h["m_eq1"] / h["m_c"], rtol=1e-12)
    np.testing.assert_allclose(float(p.mu_p), h["m_eq1"] / h["m_p"], rtol=1e-12)
    assert abs(float(p.mu_s) + float(p.mu_c) - 1.0) < 1e-14
    np.testing.assert_allclose(jg.paper_gear_set().derived()["omega_n"], h["omega_n"], rtol=1e-12)
    # stiffness, errors, backlash (docs/model.md §3-§5): ratios to k_msp and to b_c = 10 um
    np.testing.assert_allclose(float(p.kappa_sp_mean), 1.0, rtol=1e-15)
    np.testing.assert_allclose(float(p.kappa_rp_mean), K_RP / K_SP, rtol=1e-14)
    np.testing.assert_allclose(float(p.kappa_sp_amp), K_AMP / K_SP, rtol=1e-14)
    np.testing.assert_allclose(float(p.kappa_rp_amp), K_AMP / K_SP, rtol=1e-14)
    np.testing.assert_allclose([float(p.e_sp_amp), float(p.e_rp_amp)], [1.0, 1.0], rtol=1e-14)
    np.testing.assert_allclose([float(p.b_sp), float(p.b_rp)], [5.0, 5.0], rtol=1e-14)
    for n in ("phi_sp", "phi_rp", "beta_sp", "beta_rp", "gamma_sr"):
        assert float(getattr(p, n)) == 0.0
    # damping ratio 0.04: c = 2 zeta sqrt(k m_eq1) -> c/(m_eq1 omega_n) = 2 zeta sqrt(k/k_msp)
    np.testing.assert_allclose(float(p.c_sp), 2 * 0.04, rtol=1e-14)
    np.testing.assert_allclose(float(p.c_rp), 2 * 0.04 * math.sqrt(K_RP / K_SP), rtol=1e-14)
    # load: f_D = 2; torque balance T_L = T_D (1 + z_r/z_s) gives f_L = 2 f_D (docs/model.md §7)
    np.testing.assert_allclose(float(p.f_D), 2.0, rtol=1e-12)
    np.testing.assert_allclose(float(p.f_L), 2.0 * float(p.f_D), rtol=1e-12)
    np.testing.assert_allclose(float(p.Omega), 0.87, rtol=1e-15)


def test_torque_balance_gives_f_L_twice_f_D_for_other_sets():
    # r_s + r_r = 2 r_c for any 2K-H set with z_r = z_s + 2 z_p
    gs = GearSet(z_s=20, z_p=17, z_r=54, module=2e-3, T_D=123.0, N=4)
    p = gs.to_params()
    np.testing.assert_allclose(float(p.f_L), 2 * float(p.f_D), rtol=1e-12)
    h = hand_paper_numbers(z_s=20, z_p=17, z_r=54, m=2e-3, N=4)
    F_D = 123.0 / (h["r_s"] * math.cos(ALPHA))
    np.testing.assert_allclose(float(p.f_D), F_D / (K_SP * B_C), rtol=1e-12)
    np.testing.assert_allclose(float(p.mu_s), h["m_eq1"] / h["m_s"], rtol=1e-12)
    # an explicit T_L: F_L = T_L / (r_c cos alpha)
    p2 = gs.replace(T_L=500.0).to_params()
    np.testing.assert_allclose(float(p2.f_L), 500.0 / (h["r_c"] * math.cos(ALPHA)) / (K_SP * B_C), rtol=1e-12)


def test_input_rpm_gives_mesh_frequency():
    rpm = 3000.0
    gs = jg.paper_gear_set(input_rpm=rpm)
    assert gs.Omega is None
    p = gs.to_params()
    w_s = rpm * 2 * math.pi / 60
    w_carrier = w_s * 15 / (15 + 63)          # ring fixed: w_c = w_s z_s / (z_s + z_r)
    w_mesh = 63 * w_carrier                    # mesh frequency = z_r * w_c (= z_s (w_s - w_c))
    np.testing.assert_allclose(w_mesh, 15 * (w_s - w_carrier), rtol=1e-14)
    np.testing.assert_allclose(float(p.Omega), w_mesh / hand_paper_numbers()["omega_n"], rtol=1e-12)
    # and back: Omega set again replaces input_rpm
    assert float(gs.replace(Omega=0.5).to_params().Omega) == 0.5


def test_explicit_damping_coefficient():
    c = 1500.0  # N s/m
    gs = jg.paper_gear_set(c_sp_coef=c, zeta_sp=None)
    h = hand_paper_numbers()
    np.testing.assert_allclose(float(gs.to_params().c_sp), c / (h["m_eq1"] * h["omega_n"]), rtol=1e-12)


def test_explicit_inertias_and_planet_masses():
    J_s, J_p, J_c, M = 2e-4, 5e-4, 0.02, [1.5, 1.6, 1.7]
    p = jg.paper_gear_set(J_s=J_s, J_p=J_p, J_c=J_c, planet_mass=M).to_params()
    h = hand_paper_numbers()
    ca = math.cos(ALPHA)
    m_s = J_s / (h["r_s"] * ca) ** 2
    m_p = J_p / (h["r_p"] * ca) ** 2
    m_c = (J_c + sum(M) * h["r_c"] ** 2) / (h["r_c"] * ca) ** 2  # planets orbit with the carrier
    m_eq1 = m_s * m_c / (m_s + m_c)
    np.testing.assert_allclose([float(p.mu_s), float(p.mu_p), float(p.mu_c)],
                               [m_eq1 / m_s, m_eq1 / m_p, m_eq1 / m_c], rtol=1e-12)


def test_per_planet_arrays():
    k = [0.8256e9, 0.9e9, 0.7e9]
    J_p = [1e-4, 2e-4, 3e-4]
    phi = [0.0, 2 * math.pi / 3, 4 * math.pi / 3]
    gs = jg.paper_gear_set(k_sp_mean=k, J_p=J_p, phi_sp=phi, b_rp=[40.0, 50.0, 60.0])
    p = gs.to_params()
    h = hand_paper_numbers()
    r_bp = h["r_p"] * math.cos(ALPHA)
    for name in ("kappa_sp_mean", "mu_p", "phi_sp", "b_rp", "c_sp"):
        assert np.shape(getattr(p, name)) == (3,), name
    np.testing.assert_allclose(np.asarray(p.kappa_sp_mean), np.asarray(k) / k[0], rtol=1e-14)
    # m_eq1 uses planet 1's stiffness as reference k_msp1 and the carrier with the disk planet mass
    np.testing.assert_allclose(np.asarray(p.mu_p), h["m_eq1"] / (np.asarray(J_p) / r_bp**2), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(p.phi_sp), phi, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(p.b_rp), [4.0, 5.0, 6.0], rtol=1e-14)
    np.testing.assert_allclose(np.asarray(p.c_sp), 0.08 * np.sqrt(np.asarray(k) / k[0]), rtol=1e-14)
    assert not p.is_uniform
    with pytest.raises(ValueError, match="identical planets"):
        p.uniform()
    # identical per-planet values collapse to scalars
    p_same = jg.paper_gear_set(k_sp_mean=[K_SP] * 3).to_params()
    assert np.ndim(p_same.kappa_sp_mean) == 0
    # a GearParams built with equal arrays is uniform and collapses
    q = jg.paper_params().replace(b_sp=[5.0, 5.0, 5.0])
    assert q.is_uniform and np.ndim(q.uniform().b_sp) == 0


def test_replace_and_dict_round_trip():
    p = jg.paper_params()
    q = p.replace(Omega=0.9, b_sp=4.0)
    assert float(q.Omega) == 0.9 and float(q.b_sp) == 4.0
    assert float(p.Omega) == 0.87  # immutable original
    d = q.to_dict()
    assert list(d) == [*PARAM_NAMES, "mesh_shape"]
    assert GearParams.from_dict(d).to_dict() == d
    # per-planet arrays survive the round trip
    r = p.replace(phi_sp=[0.0, 1.0, 2.0], mu_p=[0.3, 0.4, 0.5])
    r2 = GearParams.from_dict(r.to_dict())
    np.testing.assert_array_equal(np.asarray(r2.phi_sp), [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(np.asarray(r2.mu_p), [0.3, 0.4, 0.5])
    # the JSON form too
    assert GearParams.from_dict(json.loads(r.to_json())).to_dict() == r.to_dict()
    with pytest.raises(ValueError, match="missing"):
        GearParams.from_dict({k: v for k, v in d.items() if k != "Omega"})
    with pytest.raises(ValueError, match="bogus"):
        p.replace(bogus=1.0)
    # GearSet.replace
    gs = jg.paper_gear_set()
    gs2 = gs.replace(face_width=0.03)
    assert gs2.face_width == 0.03 and gs.face_width == 0.025
    assert gs2.notes["face_width"] == "set by the user"
    with pytest.raises(ValueError, match="bogus"):
        gs.replace(bogus=1.0)


def test_resolve_params_both_kinds_of_names():
    base = jg.paper_params()
    # physical field: face width changes every mass ratio
    _, p = jg.resolve_params("paper", {"face_width": 0.05})
    assert abs(float(p.mu_s) - float(base.mu_s)) > 1e-4
    # physical stiffness amplitude in N/m
    gs, p = jg.resolve_params("paper", ["k_sp_amp=2e8"])
    np.testing.assert_allclose(float(p.kappa_sp_amp), 2e8 / K_SP, rtol=1e-14)
    assert gs.k_sp_amp == 2e8
    # canonical dimensionless names, including those shared with physical fields (b_sp, e_sp_amp)
    _, p = jg.resolve_params("paper", ["Omega=0.9", "b_sp=4", "kappa_rp_amp=0.2", "c_rp=0.1", "e_sp_amp=0.5"])
    assert float(p.Omega) == 0.9 and float(p.b_sp) == 4.0 and float(p.kappa_rp_amp) == 0.2
    assert float(p.c_rp) == 0.1 and float(p.e_sp_amp) == 0.5
    assert float(p.b_rp) == 5.0  # untouched
    # per-planet comma lists
    _, p = jg.resolve_params("paper", ["phi_sp=0,1,2"])
    np.testing.assert_array_equal(np.asarray(p.phi_sp), [0.0, 1.0, 2.0])
    # the physical N changes the structure
    _, p = jg.resolve_params("paper", {"N": 4})
    assert p.N == 4
    # mapping form and paper_params(**overrides) agree
    assert jg.paper_params(Omega=0.9, b_sp=4.0).to_dict() == jg.resolve_params("paper", ["Omega=0.9", "b_sp=4"])[1].to_dict()


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    "kw, name",
    [
        ({"module": 0.0}, "module"),
        ({"module": -3e-3}, "module"),
        ({"J_s": -1.0}, "J_s"),
        ({"J_p": 0.0}, "J_p"),
        ({"J_c": 0.0}, "J_c"),
        ({"planet_mass": -2.0}, "planet_mass"),
        ({"face_width": 0.0}, "face_width"),
        ({"density": -1.0}, "density"),
        ({"k_sp_mean": 0.0}, "k_sp_mean"),
        ({"k_rp_mean": -1e9}, "k_rp_mean"),
        ({"k_sp_amp": 0.9e9}, "k_sp_amp"),     # > k_sp_mean: negative stiffness in time
        ({"k_rp_amp": -1.1e9}, "k_rp_amp"),
        ({"b_sp": -1.0}, "b_sp"),
        ({"b_rp": [50.0, -1.0, 50.0]}, "b_rp"),
        ({"zeta_sp": -0.01}, "zeta_sp"),
        ({"c_rp_coef": -5.0}, "c_rp_coef"),
        ({"e_sp_amp": -1.0}, "e_sp_amp"),
        ({"z_r": 60}, "z_r"),                  # z_r != z_s + 2 z_p
        ({"z_p": 20}, "z_r"),
        ({"N": 0}, "parameter N=0"),
        ({"face_width": float("nan")}, "face_width"),
        ({"k_sp_mean": float("inf")}, "k_sp_mean"),
        ({"phi_sp": float("nan")}, "phi_sp"),
        ({"k_sp_mean": [0.8e9, 0.8e9]}, "k_sp_mean"),  # two values for three planets
        ({"T_D": 0.0}, "T_D"),
        ({"Omega": -0.5}, "Omega"),
        ({"input_rpm": -10.0}, "input_rpm"),
        ({"pressure_angle_deg": 50.0}, "pressure_angle_deg"),
    ],
)
def test_gear_set_rejects_bad_input(kw, name):
    with pytest.raises(ValueError, match=name):
        jg.paper_gear_set(**kw)


def test_gear_set_needs_exactly_one_speed():
    with pytest.raises(ValueError, match="Omega.*input_rpm"):
        GearSet(Omega=None, input_rpm=None)
    with pytest.raises(ValueError, match="Omega.*input_rpm"):
        GearSet(Omega=0.87, input_rpm=3000.0)
    with pytest.raises(ValueError, match="zeta_sp|c_sp_coef"):
        GearSet(zeta_sp=None, c_sp_coef=None)


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"mu_p": 0.0}, "mu_p"),
        ({"mu_p": [0.3, -0.1, 0.3]}, "mu_p"),
        ({"mu_s": -0.5, "mu_c": 1.5}, "mu_s"),
        ({"mu_s": 0.9}, "mu_s \\+ mu_c"),
        ({"kappa_sp_mean": 0.0}, "kappa_sp_mean"),
        ({"kappa_rp_mean": -1.0}, "kappa_rp_mean"),
        ({"kappa_sp_amp": 1.5}, "kappa_sp_amp"),    # > kappa_sp_mean = 1
        ({"kappa_rp_amp": -1.3}, "kappa_rp_amp"),   # |amp| > 1.284
        ({"b_sp": -0.1}, "b_sp"),
        ({"b_rp": -1.0}, "b_rp"),
        ({"c_sp": -0.01}, "c_sp"),
        ({"c_rp": -0.01}, "c_rp"),
        ({"e_rp_amp": -1.0}, "e_rp_amp"),
        ({"Omega": 0.0}, "Omega"),
        ({"f_D": float("nan")}, "f_D"),
        ({"f_L": float("inf")}, "f_L"),
        ({"gamma_sr": float("nan")}, "gamma_sr"),
        ({"b_sp": [1.0, 2.0]}, "b_sp"),             # two values for three planets
    ],
)
def test_gear_params_rejects_bad_input(kw, name):
    with pytest.raises(ValueError, match=name):
        jg.paper_params().replace(**kw)


def test_gear_params_rejects_bad_N():
    d = jg.paper_params().to_dict()
    d["N"] = 0
    with pytest.raises(ValueError, match="parameter N=0"):
        GearParams.from_dict(d)


def test_unknown_preset_and_override_names():
    with pytest.raises(ValueError, match="nosuch"):
        jg.resolve_params("nosuch")
    with pytest.raises(ValueError, match="nosuch"):
        jg.get_preset("nosuch")
    with pytest.raises(ValueError, match="bogus"):
        jg.resolve_params("paper", ["bogus=1"])
    with pytest.raises(ValueError, match="NAME=VALUE"):
        jg.resolve_params("paper", ["Omega0.9"])
    with pytest.raises(ValueError, match="abc"):
        jg.resolve_params("paper", ["Omega=abc"])
    with pytest.raises(ValueError, match="b_sp"):
        jg.resolve_params("paper", ["b_sp=-1"])
    with pytest.raises(ValueError, match="Omega.*input_rpm"):
        jg.resolve_params("paper", ["Omega=0.9", "input_rpm=3000"])


def test_tables_name_every_parameter():
    p = jg.paper_params()
    t = p.table()
    for n in PARAM_NAMES:
        assert n in t
    gt = jg.paper_gear_set().table()
    for n in ("module", "J_c", "omega_n", "assumed"):
        assert n in gt


def test_override_values_refuse_python_literal_extras():
    """``0_9`` is not 0.9 (Python's ``float`` reads it as 9): refused, in a list too."""
    from jaxgear._presets import parse_value

    assert parse_value("0.9") == 0.9 and parse_value("1,2.5") == [1.0, 2.5]
    for text in ("0_9", "1,0_5"):
        with pytest.raises(ValueError, match="without '_'"):
            parse_value(text)
