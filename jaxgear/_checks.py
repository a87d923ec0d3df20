"""Argument checks shared by every public function and the CLI.

Each raises ``ValueError`` with one line naming the parameter, the value given and what
is allowed, before any integration starts.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = ["check_int", "check_number", "check_choice", "check_bool", "article"]


def article(word: str) -> str:
    """``word`` with its indefinite article: ``"an OrbitSearch"``, ``"a GlobalResult"``."""
    return f"{'an' if word[:1].lower() in 'aeiou' and word[:1] else 'a'} {word}"


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_int(value: Any, name: str, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an ``int`` (integral numbers only: ``2.5`` and ``True`` are refused),
    within ``[minimum, maximum]``."""
    rng = _range_text(minimum, maximum)
    ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    if not ok and isinstance(value, numbers.Real) and not isinstance(value, bool):
        ok = math.isfinite(float(value)) and float(value).is_integer()
    if not ok:
        raise ValueError(f"{name}={_show(value)} must be an integer{rng}.")
    v = int(value)
    if (minimum is not None and v < minimum) or (maximum is not None and v > maximum):
        raise ValueError(f"{name}={v} is out of range: it must be an integer{rng}.")
    return v


def check_number(value: Any, name: str, minimum: float | None = None, maximum: float | None = None, *,
                 strict_min: bool = False, strict_max: bool = False) -> float:
    """``value`` as a finite ``float`` within the given bounds (``strict_*``: bound excluded)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise ValueError(f"{name}={_show(value)} must be a finite number"
                         f"{_range_text(minimum, maximum, strict_min, strict_max)}.")
    v = float(value)
    low = minimum is not None and (v <= minimum if strict_min else v < minimum)
    high = maximum is not None and (v >= maximum if strict_max else v > maximum)
    if low or high:
        raise ValueError(f"{name}={v:g} is out of range: it must be"
                         f"{_range_text(minimum, maximum, strict_min, strict_max)[1:] or ' finite'}.")
    return v


def check_choice(value: Any, name: str, choices: Iterable[Any]):
    """``value`` if it is one of ``choices``."""
    choices = tuple(choices)
    if isinstance(value, bool) and not any(isinstance(c, bool) for c in choices):
        raise ValueError(f"{name}={_show(value)} must be one of {', '.join(map(repr, choices))}.")
    try:
        if value in choices:
            return value
    except TypeError:
        pass
    raise ValueError(f"{name}={_show(value)} must be one of {', '.join(map(repr, choices))}.")


def check_bool(value: Any, name: str) -> bool:
    """``value`` if it is a ``bool``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name}={_show(value)} must be True or False.")
    return bool(value)


def _range_text(lo, hi, strict_lo: bool = False, strict_hi: bool = False) -> str:
    if lo is not None and hi is not None:
        return f" in {'(' if strict_lo else '['}{lo:g}, {hi:g}{')' if strict_hi else ']'}"
    if lo is not None:
        return f" {'>' if strict_lo else '>='} {lo:g}"
    if hi is not None:
        return f" {'<' if strict_hi else '<='} {hi:g}"
    return ""
