"""The compiled CPU kernel of the reduced model equals the pure-JAX kink-aware steps.

The pure-JAX path (``KinkAwareRK4(native=False)``) is the reference: it is what runs on
GPUs and what supplies the derivatives. The kernel must give the same states to
round-off for random states and random parameters, both mesh-stiffness shapes,
``b = 0``, vmapped parameter batches and a partly active pool. (The N-planet model has
no compiled kernel: it always runs the pure-JAX steps.)
"""

import math
import os
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgear as jg
from jaxgear.integrate import KinkAwareRK4
from jaxgear.integrate._native import native_available, native_unavailable_reason

TURNED_OFF = os.environ.get("JAXGEAR_NATIVE", "1").lower() in ("0", "off", "false", "no")
COMPILER = os.environ.get("CXX") or shutil.which("g++")

# Where a compiler is present the kernel is required: a compile error (or a refused kernel
# folder) fails every test here instead of skipping them.
pytestmark = [pytest.mark.skipif(TURNED_OFF, reason="JAXGEAR_NATIVE=0 turns the compiled kernel off"),
              pytest.mark.skipif(COMPILER is None, reason="no C++ compiler: the compiled kernel is not built")]


@pytest.fixture(autouse=True, scope="module")
def _kernel_required():
    if not native_available():
        pytest.fail(f"a C++ compiler is present ({COMPILER}) but the compiled kernel is not available: "
                    f"{native_unavailable_reason()}", pytrace=False)


def test_the_kernel_is_built_where_a_compiler_is_present():
    assert native_available(), native_unavailable_reason()

TOL = 1e-12
LANES = 64
"""Lanes of the pure-JAX references (one compiled reference program serves most tests:
60 steps per period, one period, this many lanes)."""


def random_params(rng, shape):
    p = jg.paper_params()
    return p.replace(
        Omega=rng.uniform(0.5, 1.6), b_sp=rng.choice([0.0, rng.uniform(0.2, 4.0)]), b_rp=rng.uniform(0.0, 4.0),
        kappa_sp_amp=rng.uniform(0.0, 0.4), kappa_rp_amp=rng.uniform(0.0, 0.4), phi_sp=rng.uniform(0, 2 * math.pi),
        phi_rp=rng.uniform(0, 2 * math.pi), e_sp_amp=rng.uniform(0.0, 0.8), e_rp_amp=rng.uniform(0.0, 0.8),
        beta_sp=rng.uniform(0, 2 * math.pi), c_sp=rng.uniform(0.01, 0.2), c_rp=rng.uniform(0.01, 0.2),
        f_D=rng.uniform(0.0, 1.0), contact_ratio_sp=rng.uniform(1.1, 1.9), contact_ratio_rp=rng.uniform(1.1, 1.9),
        mesh_shape=shape)


def random_states(rng, n):
    return np.stack([rng.uniform(-25, 25, n), rng.uniform(-10, 20, n), rng.uniform(-10, 50, n), rng.uniform(-8, 8, n)])


def rel_diff(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.max(np.abs(a - b) / (1.0 + np.abs(b)))


@pytest.mark.parametrize("shape", ["sine", pytest.param("rectangular", marks=pytest.mark.slow)])
def test_kernel_equals_pure_jax_on_random_states_and_parameters(shape):
    rng = np.random.default_rng(7 if shape == "sine" else 8)
    # one compiled program per path: the parameters and the start time are traced
    kernel = jax.jit(lambda Y, p, t0: KinkAwareRK4(100).advance(jg.REDUCED, p, Y, t0, 2))
    pure = jax.jit(lambda Y, p, t0: KinkAwareRK4(100, native=False).advance(jg.REDUCED, p, Y, t0, 2))
    for _ in range(3):
        p = random_params(rng, shape)
        Y = jnp.asarray(random_states(rng, 700))  # not a multiple of the kernel's block
        t0 = jnp.asarray(rng.uniform(0, 10))
        native, ref = kernel(Y, p, t0), pure(Y, p, t0)
        assert np.all(np.isfinite(np.asarray(ref)))
        assert rel_diff(native, ref) <= TOL, (shape, rel_diff(native, ref))
        assert rel_diff(native, Y) > 1e-3  # the states moved


def test_tables_of_earlier_calls_serve_only_the_same_parameters_time_and_steps():
    """The kernel keeps the time-only terms of recent parameter rows between calls; a call
    that differs from the one before in a single parameter, the start time, the steps or the
    wave shape still equals the pure-JAX path (a table keyed on less would be reused)."""
    rng = np.random.default_rng(21)
    Y = jnp.asarray(random_states(rng, LANES))
    base = random_params(rng, "sine")
    kernel = jax.jit(lambda Y, p, t0: KinkAwareRK4(60).advance(jg.REDUCED, p, Y, t0, 1))
    pure = jax.jit(lambda Y, p, t0: KinkAwareRK4(60, native=False).advance(jg.REDUCED, p, Y, t0, 1))
    fields = ("Omega", "kappa_sp_amp", "kappa_rp_amp", "kappa_sp_mean", "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp",
              "beta_sp", "beta_rp", "gamma_sr", "f_D", "contact_ratio_sp", "b_sp")
    for name in fields:
        kernel(Y, base, jnp.asarray(0.0)).block_until_ready()  # the base row's table, cached
        p = base.replace(**{name: getattr(base, name) * 1.01 + 0.01})
        assert rel_diff(kernel(Y, p, jnp.asarray(0.0)), pure(Y, p, jnp.asarray(0.0))) <= TOL, name
    kernel(Y, base, jnp.asarray(0.0)).block_until_ready()
    assert rel_diff(kernel(Y, base, jnp.asarray(0.3)), pure(Y, base, jnp.asarray(0.3))) <= TOL  # another start
    a = KinkAwareRK4(61).advance(jg.REDUCED, base, Y, 0.0, 1)  # another step count
    assert rel_diff(a, KinkAwareRK4(61, native=False).advance(jg.REDUCED, base, Y, 0.0, 1)) <= TOL
    rect = base.replace(mesh_shape="rectangular")  # another wave, the same numbers
    a = KinkAwareRK4(60).advance(jg.REDUCED, rect, Y, 0.0, 1)
    assert rel_diff(a, KinkAwareRK4(60, native=False).advance(jg.REDUCED, rect, Y, 0.0, 1)) <= TOL


def test_kernel_equals_pure_jax_for_every_split_count():
    rng = np.random.default_rng(11)
    p = random_params(rng, "sine")
    Y = jnp.asarray(random_states(rng, LANES))
    for max_splits in (1, 2, 3):
        a = KinkAwareRK4(60, max_splits=max_splits).advance(jg.REDUCED, p, Y, 0.0, 1)
        b = KinkAwareRK4(60, max_splits=max_splits, native=False).advance(jg.REDUCED, p, Y, 0.0, 1)
        assert rel_diff(a, b) <= TOL, max_splits


def test_kernel_under_vmap_over_parameters_and_with_a_partly_active_pool():
    rng = np.random.default_rng(12)
    ps = [random_params(rng, "sine") for _ in range(3)]
    batch = jax.tree_util.tree_map(lambda *v: jnp.stack(v) if isinstance(v[0], jax.Array) else v[0], *ps)
    Y = jnp.asarray(random_states(rng, LANES))
    integ = KinkAwareRK4(60)
    out = jax.vmap(lambda p: integ.advance(jg.REDUCED, p, Y, 0.0, 1))(batch)
    for i, p in enumerate(ps):
        ref = KinkAwareRK4(60, native=False).advance(jg.REDUCED, p, Y, 0.0, 1)
        assert rel_diff(out[i], ref) <= TOL, i
    # lanes at or above n_active are returned unchanged, the others advanced as usual
    part = integ.advance(jg.REDUCED, ps[0], Y, 0.0, 1, n_active=20)
    np.testing.assert_array_equal(np.asarray(part[:, 20:]), np.asarray(Y[:, 20:]))
    assert rel_diff(part[:, :20], out[0][:, :20]) <= TOL


def test_kernel_derivatives_are_those_of_the_pure_jax_steps():
    p = jg.paper_params()
    x = jnp.asarray([5.36, -0.19, 8.28, -0.84])
    f = lambda native: (lambda x: KinkAwareRK4(100, native=native).advance(jg.REDUCED, p, x[:, None], 0.0, 1)[:, 0])  # noqa: E731
    np.testing.assert_allclose(np.asarray(jax.jacfwd(f(True))(x)), np.asarray(jax.jacfwd(f(False))(x)), rtol=1e-12)


def test_kernel_keeps_non_finite_lanes_to_themselves():
    p = jg.paper_params()
    Y = np.asarray(random_states(np.random.default_rng(3), LANES))
    finite = Y.copy()
    Y[:, 5] = np.nan
    Y[0, 9] = np.inf
    out = np.asarray(KinkAwareRK4(60).advance(jg.REDUCED, p, jnp.asarray(Y), 0.0, 1))
    assert not np.isfinite(out[:, 5]).any() and not np.isfinite(out[:, 9]).all()
    good = np.setdiff1d(np.arange(LANES), [5, 9])
    # the reference integrates the lanes as they were before two of them were spoilt
    ref = np.asarray(KinkAwareRK4(60, native=False).advance(jg.REDUCED, p, jnp.asarray(finite), 0.0, 1))
    assert rel_diff(out[:, good], ref[:, good]) <= TOL


def test_kernel_under_nested_vmap_with_mixed_batching():
    rng = np.random.default_rng(13)
    ps = [random_params(rng, "sine") for _ in range(2)]
    batch = jax.tree_util.tree_map(lambda *v: jnp.stack(v) if isinstance(v[0], jax.Array) else v[0], *ps)
    Ys = jnp.asarray(np.stack([random_states(rng, LANES) for _ in range(3)]))  # (3, 4, LANES)
    integ = KinkAwareRK4(60)
    out = jax.vmap(lambda p: jax.vmap(lambda Y: integ.advance(jg.REDUCED, p, Y, 0.0, 1))(Ys))(batch)
    assert out.shape == (2, 3, 4, LANES)
    for i, p in enumerate(ps):
        for j in range(3):
            ref = KinkAwareRK4(60, native=False).advance(jg.REDUCED, p, Ys[j], 0.0, 1)
            assert rel_diff(out[i, j], ref) <= TOL, (i, j)


def test_kernel_with_one_parameter_row_per_lane():
    """``advance_rows``: each lane advanced with its own parameter row (rows of several
    forcing periods, mixed inside the kernel's blocks and in runs), exactly as the whole
    batch advanced with that row; the pure-JAX path (lanes mapped) agrees to round-off."""
    from jaxgear.integrate import stack_params

    rng = np.random.default_rng(13)
    ps = [random_params(rng, "sine") for _ in range(3)]
    rows = np.concatenate([rng.integers(0, 3, 400), np.repeat([2, 0, 1], 100)]).astype(np.int32)
    Y = jnp.asarray(random_states(rng, len(rows)))
    stacked = stack_params(ps)
    out = jax.jit(lambda Y, r: KinkAwareRK4(80).advance_rows(jg.REDUCED, stacked, r, Y, 0.0, 2))(Y, rows)
    for r, p in enumerate(ps):
        same = KinkAwareRK4(80).advance(jg.REDUCED, p, Y, 0.0, 2)
        np.testing.assert_array_equal(np.asarray(out)[:, rows == r], np.asarray(same)[:, rows == r])
    ref = KinkAwareRK4(80, native=False).advance_rows(jg.REDUCED, stacked, jnp.asarray(rows), Y, 0.0, 2)
    assert rel_diff(out, ref) <= TOL
    part = KinkAwareRK4(80).advance_rows(jg.REDUCED, stacked, rows, Y, 0.0, 2, n_active=100)
    np.testing.assert_array_equal(np.asarray(part[:, 100:]), np.asarray(Y[:, 100:]))
    np.testing.assert_array_equal(np.asarray(part[:, :100]), np.asarray(out[:, :100]))


def test_a_lanes_result_does_not_depend_on_the_pool_it_is_in():
    """The kernel cuts a pool into blocks (short blocks for a small pool, so every core
    gets some): each lane's state after a period is bit for bit the same whether it is
    integrated alone, among a few lanes or in a large pool, in any position."""
    rng = np.random.default_rng(14)
    p = random_params(rng, "sine")
    Y = random_states(rng, 2000)
    integ = KinkAwareRK4(80)
    big = np.asarray(integ.advance(jg.REDUCED, p, jnp.asarray(Y), 0.0, 2))
    for m in (1, 5, 37, 130, 300, 700):
        pick = rng.choice(2000, size=m, replace=False)
        small = np.asarray(integ.advance(jg.REDUCED, p, jnp.asarray(Y[:, pick]), 0.0, 2))
        np.testing.assert_array_equal(small, big[:, pick], err_msg=f"{m} lanes")


def test_lane_rows_out_of_range_are_read_as_the_pure_jax_path_reads_them():
    """A lane's row is read as ``params[row]`` reads it in JAX (negative from the end,
    out of range clamped): the kernel never reads outside the parameter rows."""
    from jaxgear.integrate import stack_params

    rng = np.random.default_rng(15)
    ps = [random_params(rng, "sine") for _ in range(3)]
    stacked = stack_params(ps)
    rows = np.array([0, 1, 2, -1, 3, 99, -3, -40] * (LANES // 8), np.int32)
    Y = jnp.asarray(random_states(rng, len(rows)))
    out = np.asarray(KinkAwareRK4(60).advance_rows(jg.REDUCED, stacked, rows, Y, 0.0, 1))
    same = np.array([0, 1, 2, 2, 2, 2, 0, 0] * (LANES // 8))  # numpy's reading, clamped
    for r, p in enumerate(ps):
        ref = np.asarray(KinkAwareRK4(60, native=False).advance(jg.REDUCED, p, Y, 0.0, 1))
        assert rel_diff(out[:, same == r], ref[:, same == r]) <= TOL, r
