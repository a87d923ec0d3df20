"""Argument checks shared by every public function and the CLI.

Each raises ``ValueError`` with one line naming the parameter, the value given and what
is allowed, before any integration starts.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import numbers
import os
from collections.abc import Iterable
from typing import Any, TypeVar

import jax
import numpy as np

E = TypeVar("E", bound=enum.Enum)

__all__ = ["check_int", "check_number", "check_choice", "check_enum", "check_bool", "check_finite_array", "article",
           "physical_memory", "check_memory", "with_changes", "split_changes"]


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
        raise ValueError(f"{name}={v:g} is out of range: it must be "
                         f"{_range_text(minimum, maximum, strict_min, strict_max)[1:] or 'finite'}.")
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


def check_enum(value: Any, name: str, cls: type[E]) -> E:
    """``value`` as a member of the enumeration ``cls``: a member itself, or its value (the
    text of a ``StrEnum`` member: ``"up"`` for ``SweepDirection.UP``); anything else is
    refused naming the allowed values."""
    if isinstance(value, cls):
        return value
    if not isinstance(value, bool):
        try:
            return cls(value)
        except (TypeError, ValueError):
            pass
    raise ValueError(f"{name}={_show(value)} must be one of {', '.join(repr(m.value) for m in cls)}.")


def check_bool(value: Any, name: str) -> bool:
    """``value`` if it is a ``bool``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name}={_show(value)} must be True or False.")
    return bool(value)


def check_finite_array(value: Any, name: str, *, ndim: int | None = None, last: int | None = None) -> np.ndarray:
    """``value`` as a finite float64 array (``ndim`` dimensions, last axis of length ``last``)."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an array of numbers, got {_show(value)}.") from None
    if ndim is not None and a.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s), got shape {a.shape}.")
    if last is not None and (a.ndim == 0 or a.shape[-1] != last):
        raise ValueError(f"{name} must have shape (..., {last}), got shape {a.shape}.")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite values.")
    return a


def physical_memory() -> int:
    """Bytes of memory this process may use: the machine's physical memory
    (``os.sysconf``; 8 GiB where unknown), or the smaller limit of its control group
    (a container's ``memory.max``)."""
    try:
        total = int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        total = 0
    total = total if total > 0 else 8 << 30
    for limit in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(limit) as f:
                value = f.read().strip()
        except OSError:
            continue
        if value.isdigit() and 0 < int(value) < total:
            total = int(value)
    return total


def _bytes_text(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def check_memory(name: str, value: Any, count: int, unit_bytes: float, what: str, bytes_of=None) -> int:
    """``count`` if ``count`` units of ``what`` (cells, values, seeds) at ``unit_bytes``
    bytes each fit in half of this machine's physical memory (:func:`physical_memory`);
    otherwise ``ValueError`` naming ``name``, its ``value``, the memory it would need and
    the largest count that fits (checked before any work: no allocation, no minutes of
    silence before a failure). ``bytes_of(count)``: the bytes of ``count`` units where
    they do not grow in proportion (``unit_bytes`` is then ignored; increasing in
    ``count``)."""
    total = physical_memory()
    budget = total // 2
    need = float(bytes_of(count)) if bytes_of is not None else float(count) * float(unit_bytes)
    if need > budget:
        if bytes_of is None:
            most = int(budget // max(float(unit_bytes), 1.0))
        else:  # the largest count whose bytes fit: bisection
            lo, hi = 0, int(count)
            while lo < hi:
                mid = (lo + hi + 1) // 2
                lo, hi = (mid, hi) if float(bytes_of(mid)) <= budget else (lo, mid - 1)
            most = lo
        raise ValueError(f"{name}={_show(value) if not isinstance(value, str) else value}: {count:,} {what} need "
                         f"about {_bytes_text(need)}, more than half of this machine's memory "
                         f"({_bytes_text(total)}); at most {most:,} {what} fit.")
    return count


def _bound(x) -> str:
    """A bound as written: integers in full (2147483647, not 2.14748e+09)."""
    if isinstance(x, numbers.Integral) and not isinstance(x, bool):
        return str(int(x))
    return f"{x:g}"


def _range_text(lo, hi, strict_lo: bool = False, strict_hi: bool = False) -> str:
    if lo is not None and hi is not None:
        return f" in {'(' if strict_lo else '['}{_bound(lo)}, {_bound(hi)}{')' if strict_hi else ']'}"
    if lo is not None:
        return f" {'>' if strict_lo else '>='} {_bound(lo)}"
    if hi is not None:
        return f" {'<' if strict_hi else '<='} {_bound(hi)}"
    return ""


def is_traced(x) -> bool:
    """Whether ``x`` is an abstract value inside a JAX transformation (``jit``, ``vmap``,
    ``grad``) rather than a concrete number or array, told by JAX's public error for
    converting such a value to numpy."""
    if not isinstance(x, jax.Array):
        return False
    try:
        x.__array__()
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return True
    return False


# ------------------------------------------------------------------ options objects
def with_changes(options, cls, changes: dict):
    """``options`` (an instance of ``cls``, or ``None`` for its defaults) with the fields in
    ``changes`` replaced (checked again); an unknown name raises ``ValueError``."""
    if options is None:
        options = cls()
    elif not isinstance(options, cls):
        raise ValueError(f"options={options!r} must be a {cls.__name__} (or None for the defaults).")
    if not changes:
        return options
    names = [f.name for f in dataclasses.fields(options)]
    unknown = [n for n in changes if n not in names]
    if unknown:
        raise ValueError(f"unknown option {unknown[0]!r}; the fields of {type(options).__name__} are "
                         f"{', '.join(names)}.")
    return dataclasses.replace(options, **changes)


def split_changes(changes: dict, *classes) -> list[dict]:
    """``changes`` (keyword arguments naming fields of several options types) split into one
    dict per class of ``classes``, each name going to the first class that has it; an
    unknown name raises ``ValueError`` listing every field."""
    names = [[f.name for f in dataclasses.fields(c)] for c in classes]
    out: list[dict] = [{} for _ in classes]
    for key, value in changes.items():
        for i, fields in enumerate(names):
            if key in fields:
                out[i][key] = value
                break
        else:
            allowed = ", ".join(n for fields in names for n in fields)
            raise ValueError(f"unknown option {key!r}; the options are {allowed} "
                             f"(fields of {', '.join(c.__name__ for c in classes)}).")
    return out
