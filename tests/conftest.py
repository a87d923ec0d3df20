import contextlib
import logging

import jax
import pytest

import jaxgear  # noqa: F401  (enables float64 before any test builds arrays)


@pytest.fixture(autouse=True, scope="session")
def _strict_dtype_promotion():
    """Every test runs with strict dtype promotion: an implicit promotion between array dtypes
    (int32 with int64, float64 with an integer array, a float with a complex) raises instead
    of silently widening, so the engine's arithmetic stays float64 / int32 by construction
    (Python scalars are still weakly typed). Set for the whole session, so module fixtures
    and threads the code starts are covered too, and through ``JAX_NUMPY_DTYPE_PROMOTION``
    for the processes the tests start (the command line, the notebooks' kernels)."""
    old = jax.config.jax_numpy_dtype_promotion
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("JAX_NUMPY_DTYPE_PROMOTION", "strict")
        jax.config.update("jax_numpy_dtype_promotion", "strict")
        try:
            yield
        finally:
            jax.config.update("jax_numpy_dtype_promotion", old)


@contextlib.contextmanager
def count_compilations(name: str):
    """Collect JAX's "Compiling <name> ..." log messages while the block runs (a list that
    grows as functions whose name contains ``name`` are compiled)."""
    found: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record):
            msg = record.getMessage()
            if msg.startswith("Compiling") and name in msg.split(" for ")[0].split(" with ")[0]:
                found.append(msg)

    handler = Collect(level=logging.DEBUG)
    logger = logging.getLogger("jax")
    logger.addHandler(handler)
    old = jax.config.jax_log_compiles
    jax.config.update("jax_log_compiles", True)
    try:
        yield found
    finally:
        jax.config.update("jax_log_compiles", old)
        logger.removeHandler(handler)
