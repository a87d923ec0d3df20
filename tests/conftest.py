import contextlib
import logging

import jax
import pytest

import jaxgear  # noqa: F401  (enables float64 before any test builds arrays)

# Modules whose tests run with strict dtype promotion: an implicit promotion between array
# dtypes (int32 with int64, float64 with an integer array, a float with a complex) raises
# instead of silently widening, so the engine's arithmetic stays float64 / int32 by
# construction (Python scalars are still weakly typed).
STRICT_PROMOTION = {"test_model", "test_poincare", "test_integrate", "test_native", "test_kink", "test_cellmap",
                    "test_result", "test_feedback", "test_any_system", "test_io", "test_cli_analyze",
                    "test_cli_params", "test_cli_validation", "test_outputs", "test_sweep", "test_smoke_package",
                    "test_params"}


@pytest.fixture(autouse=True)
def _strict_dtype_promotion(request):
    if request.module.__name__.rsplit(".", 1)[-1] in STRICT_PROMOTION:
        with jax.numpy_dtype_promotion("strict"):
            yield
    else:
        yield


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
