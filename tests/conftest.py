import contextlib
import logging

import jax

import jaxgear  # noqa: F401  (enables float64 before any test builds arrays)


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
