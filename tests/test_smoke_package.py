import jax.numpy as jnp

import jaxgear as jg


def test_float64_enabled_on_import():
    assert jnp.zeros(1).dtype == jnp.float64


def test_paper_mass_ratios_match_model_md():
    # docs/model.md §7, derived independently: mu_s ~ 0.9715, mu_c ~ 0.0285, mu_p ~ 0.3795
    p = jg.paper_params()
    assert abs(float(p.mu_s) - 0.9715) < 5e-4
    assert abs(float(p.mu_c) - 0.0285) < 5e-4
    assert abs(float(p.mu_p) - 0.3795) < 5e-4
