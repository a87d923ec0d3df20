"""Batching helpers shared by every analysis: fixed-size chunks, padding, progress bars.

Heavy kernels are compiled for one batch shape; work larger than a chunk is cut into
equal chunks (the last one padded), so memory is bounded by the chunk and not by the
grid, and the results do not depend on the chunk size.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Iterator

import numpy as np

__all__ = ["DEFAULT_CHUNK_CELLS", "SMALL_BATCH", "chunks", "equal_chunk_size", "pad_rows", "progress_bar"]

DEFAULT_CHUNK_CELLS = 131072
"""Cells (or trajectories) integrated in one batch by default. On a 2-core CPU batches
below ~65,000 lanes run single-threaded in XLA's loops, about twice slower per lane."""


SMALL_BATCH = 64
"""Lanes of every small batch of the pure-JAX step: the cycles' one-period Jacobians,
their samples and their located crossings (section points, contact changes) run on
batches padded to a power of two of at least this many lanes, so one process traces the
step once for all of them (a traced step is reused wherever its shapes recur)."""


def chunks(n: int, size: int) -> Iterator[tuple[int, int]]:
    """``(start, stop)`` of consecutive chunks of at most ``size`` covering ``range(n)``."""
    for start in range(0, n, size):
        yield start, min(start + size, n)


def equal_chunk_size(n: int, size: int) -> int:
    """The smallest chunk size that splits ``n`` items into as many equal chunks as
    chunks of at most ``size`` would need (so padding is spread, not piled on the last)."""
    n, size = int(n), int(size)
    if n <= 0:
        return max(1, size)
    return -(-n // -(-n // size))


def power_of_two_at_least(n: int, minimum: int = 1) -> int:
    """The smallest power of two that is at least ``n`` and at least ``minimum`` (sizes
    padded to it take few distinct values: few compiled shapes)."""
    return max(int(minimum), 1 << max(0, int(n) - 1).bit_length())


def pad_rows(X: np.ndarray, size: int, axis: int = 0) -> np.ndarray:
    """Pad ``X`` along ``axis`` to ``size`` entries by repeating its first entry there (one
    compiled shape)."""
    k = size - X.shape[axis]
    return X if k == 0 else np.concatenate([X, np.repeat(np.take(X, [0], axis=axis), k, axis=axis)], axis=axis)


@functools.cache
def _bar_class():
    """tqdm's bar class (a widget in notebooks when ipywidgets is installed) without its
    monitor thread (tqdm starts one for every bar class that leaves ``monitor_interval``
    set, even for disabled bars): jaxgear starts no thread of its own."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # tqdm.auto warns when ipywidgets is missing, then falls back
        from tqdm.auto import tqdm

    return type("ProgressBar", (tqdm,), {"monitor_interval": 0})


def progress_bar(total: int, desc: str, enabled: bool, unit: str = "cell"):
    """A tqdm bar (a widget in notebooks when ipywidgets is installed) with time left."""
    return _bar_class()(total=total, desc=desc, unit=unit, unit_scale=True, disable=not enabled, leave=False)
