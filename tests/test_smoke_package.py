import jax.numpy as jnp

import jaxgear as jg


def test_float64_enabled_on_import():
    assert jg.__version__  # the package imports and names its version
    assert jnp.zeros(1).dtype == jnp.float64
    assert float(jnp.ones(1)[0] + 2.0**-52) > 1.0  # float32 would round this sum to 1
