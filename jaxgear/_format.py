"""Plain-text tables and number formatting for printed results."""

from __future__ import annotations

import numpy as np

__all__ = ["format_table", "fmt_value"]


def fmt_value(v) -> str:
    """A number (6 significant digits), a bracketed list of numbers, or a string as it is."""
    if isinstance(v, str):
        return v
    a = np.asarray(v)
    if a.ndim == 0:
        return f"{float(a):.6g}"
    return "[" + ", ".join(f"{float(t):.6g}" for t in a.ravel()) + "]"


def format_table(rows, header) -> str:
    """Plain-text table with aligned columns."""
    rows = [tuple(str(c) for c in r) for r in rows]
    widths = [max([len(h)] + [len(r[i]) for r in rows]) for i, h in enumerate(header)]
    line = lambda r: "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip()
    return "\n".join([line(header), line(tuple("-" * w for w in widths))] + [line(r) for r in rows])


