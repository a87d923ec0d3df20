"""``--system MODULE:ATTRIBUTE``: a user's :class:`~jaxgear.ForcedSystem` on the command line.

``jaxgear analyze|shoot|sweep --system mymodel:SYSTEM`` imports ``mymodel`` (a module on
``sys.path``, the current folder included, or a file ``path/to/mymodel.py``) and takes
its attribute ``SYSTEM`` (a dotted path such as ``models.DUFFING`` is followed). The
attribute is one of

1. a :class:`~jaxgear.ForcedSystem`; its parameters, region and cell counts are then the
   module's optional attributes ``PARAMS``, ``REGION`` and ``GRID``;
2. an object or a mapping with the field ``system`` (a ``ForcedSystem``) and the optional
   fields ``params``, ``region`` and ``grid`` (a ``types.SimpleNamespace``, a dict, a
   ``NamedTuple``, ...): several systems can then live in one module;
3. a function of no arguments returning 1. or 2. (it may build the system on demand).

``params``/``PARAMS`` is the parameter pytree (an ``eqx.Module``, a ``NamedTuple`` or a
dict of numbers; required); ``--set NAME=VALUE`` replaces its fields. ``region``/``REGION``
is a sequence of ``(lo, hi)`` pairs: one per state coordinate (a grid over the whole
state, as the stroboscopic map needs), or one per coordinate but the section coordinate
``system.section_index`` (cells on the section ``{x_i = 0}``, as the paper's region D
for the gear model); ``--region`` replaces it. ``grid``/``GRID`` is the cell count per
gridded coordinate; ``--grid`` replaces it, and without either the counts are
:func:`default_counts`.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import math
import os
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._system import ForcedSystem, check_system

__all__ = ["UserSystem", "resolve_system", "apply_overrides", "user_grid", "default_counts", "axes_of"]

_SPEC = re.compile(r"^(?P<module>[^:]+):(?P<attr>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)$")
CELLS_PER_AXIS = {1: 400, 2: 40, 3: 20}
"""Default cells per gridded axis by the number of gridded axes (10 from four axes on)."""


@dataclasses.dataclass(frozen=True)
class UserSystem:
    """A system given on the command line: the :class:`~jaxgear.ForcedSystem`, its
    parameter pytree (``--set`` applied), and the object's region (``(lo, hi)`` pairs)
    and cell counts, each ``None`` where the object gives none. ``spec`` is the
    ``MODULE:ATTRIBUTE`` text as given."""

    spec: str
    system: ForcedSystem
    params: Any
    region: tuple[tuple[float, float], ...] | None = None
    grid: tuple[int, ...] | None = None


def _text_name(name: str, spec: str, what: str) -> None:
    """Refuse a file or module name that is not valid UTF-8 text (bytes a file system
    allows in names, read as surrogates): JAX records the source file of every traced
    function and fails on such a name deep inside (``std::bad_cast``)."""
    try:
        os.fsencode(name).decode("utf-8")
    except UnicodeError:
        shown = os.fsencode(spec).decode("utf-8", "backslashreplace")
        raise ValueError(f"--system {shown}: the {what} {os.fsencode(name).decode('utf-8', 'backslashreplace')!r} is "
                         "not valid UTF-8 text, which JAX cannot trace code from: rename it with UTF-8 (or ASCII) "
                         "characters.") from None


def _exit_message(spec: str, doing: str, exc: SystemExit) -> str:
    return (f"--system {spec}: {doing} called sys.exit({exc.code!r}) (a script's exit): a module given to --system "
            "must only define things; put the script part under if __name__ == '__main__':.")


def _import(module: str, spec: str):
    """The module ``module``: a file path (``.py``) or an importable name (the current
    folder searched first, as ``python -m`` does). A name of the standard library with a
    file of that name in the current folder is refused (Python would import its own)."""
    _text_name(module, spec, "module file name" if module.endswith(".py") else "module name")
    if module.endswith(".py") or "/" in module or "\\" in module:
        path = Path(module).expanduser()
        if not path.is_file():
            raise ValueError(f"--system {spec}: no file {module}.")
        name = path.stem
        loader_spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(loader_spec)
        try:
            loader_spec.loader.exec_module(mod)
        except SystemExit as exc:
            raise ValueError(_exit_message(spec, f"loading {module}", exc)) from None
        except Exception as exc:  # the user's code failed while loading
            raise ValueError(f"--system {spec}: loading {module} failed: {type(exc).__name__}: {exc}") from exc
        return mod
    top = module.split(".")[0]
    if top in getattr(sys, "stdlib_module_names", ()) and (Path.cwd() / f"{top}.py").is_file():
        attr = spec.rsplit(":", 1)[1]
        raise ValueError(f"--system {spec}: {top} is a module of Python's standard library, which Python imports "
                         f"instead of ./{top}.py: give the file, --system ./{top}.py:{attr} (or rename it).")
    added = False
    if "" not in sys.path and str(Path.cwd()) not in sys.path:  # the console script does not search the
        sys.path.insert(0, str(Path.cwd()))  # current folder; python -m does
        added = True
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name is not None and (module == exc.name or module.startswith(exc.name + ".")):
            raise ValueError(f"--system {spec}: no module named {module!r} (run from the folder that holds "
                             f"{module.split('.')[0]}.py, put that folder on PYTHONPATH, or give the file: "
                             f"--system path/to/{module.split('.')[-1]}.py:{spec.rsplit(':', 1)[1]}).") from exc
        raise ValueError(f"--system {spec}: importing {module} failed: {type(exc).__name__}: {exc}") from exc
    except SystemExit as exc:
        raise ValueError(_exit_message(spec, f"importing {module}", exc)) from None
    except Exception as exc:  # the user's code failed while importing
        raise ValueError(f"--system {spec}: importing {module} failed: {type(exc).__name__}: {exc}") from exc
    finally:
        if added:
            sys.path.remove(str(Path.cwd()))
    if getattr(mod, "__file__", None):
        _text_name(mod.__file__, spec, "module file")
    return mod


def _field(obj, name: str):
    """``obj[name]`` for a mapping, else ``getattr(obj, name)``; ``None`` where absent."""
    if isinstance(obj, Mapping):
        return obj.get(name)
    return getattr(obj, name, None)


def _region(value, spec: str, where: str):
    if value is None:
        return None
    try:
        region = tuple((float(lo), float(hi)) for lo, hi in value)
    except (TypeError, ValueError):
        raise ValueError(f"--system {spec}: {where} must be a sequence of (lo, hi) pairs, got {value!r}.") from None
    if not region:
        raise ValueError(f"--system {spec}: {where} is empty; give one (lo, hi) pair per gridded coordinate.")
    for i, (lo, hi) in enumerate(region):
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ValueError(f"--system {spec}: {where}[{i}] = ({lo:g}, {hi:g}); it must be finite with lo < hi.")
    return region


def _counts(value, spec: str, where: str):
    if value is None:
        return None
    try:
        counts = tuple(int(c) for c in value)
        ok = counts and all(c >= 1 and c == float(v) for c, v in zip(counts, value))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"--system {spec}: {where} must be a sequence of positive cell counts, got {value!r}.")
    return counts


def _describe(value) -> str:
    """``an object of type NAME`` (``a class NAME`` for a class)."""
    if isinstance(value, type):
        return f"the class {value.__qualname__}"
    return f"an object of type {type(value).__qualname__}"


def resolve_system(spec: str, overrides: Sequence[str] = ()) -> UserSystem:
    """The system of ``--system MODULE:ATTRIBUTE`` (see the module docstring for what the
    attribute may be) with the parameter overrides ``overrides`` (``["NAME=VALUE", ...]``,
    the fields of its parameter pytree; a comma list for an array field) applied, checked
    with :func:`~jaxgear.check_system`.

    Raises:
        ValueError: a malformed spec, a module that cannot be imported or raises, a
            missing attribute, an attribute that is not (and provides no) system, a
            system without parameters, an unknown parameter name, or a system that fails
            :func:`~jaxgear.check_system` on its parameters; the message names ``--system``
            and the spec.
    """
    m = _SPEC.match(spec.strip()) if isinstance(spec, str) else None
    if m is None:
        raise ValueError(f"--system expects MODULE:ATTRIBUTE (e.g. mymodel:SYSTEM or path/to/mymodel.py:SYSTEM), "
                         f"got {spec!r}.")
    module, attr = m.group("module").strip(), m.group("attr")
    mod = _import(module, spec)
    obj = mod
    for i, part in enumerate(attr.split(".")):
        if not hasattr(obj, part):
            where = module if i == 0 else f"{module}:{'.'.join(attr.split('.')[:i])}"
            systems = sorted(k for k, v in vars(mod).items() if isinstance(v, ForcedSystem) and not k.startswith("_"))
            hint = f" (its ForcedSystem attributes: {', '.join(systems)})" if systems and i == 0 else ""
            top = module.split(".")[0]
            if i == 0 and not hint and top in getattr(sys, "stdlib_module_names", ()) and not module.endswith(".py"):
                hint = (f" ({top} is a module of Python's standard library; for your own file give its path: "
                        f"--system ./{module.replace('.', '/')}.py:{attr})")
            raise ValueError(f"--system {spec}: {where} has no attribute {part!r}{hint}.")
        obj = getattr(obj, part)
    if callable(obj) and not isinstance(obj, (ForcedSystem, type)):
        try:
            obj = obj()
        except SystemExit as exc:
            raise ValueError(_exit_message(spec, f"calling {attr}()", exc)) from None
        except Exception as exc:  # the user's function failed
            raise ValueError(f"--system {spec}: calling {attr}() failed: {type(exc).__name__}: {exc}") from exc
    if isinstance(obj, ForcedSystem):
        system, params = obj, getattr(mod, "PARAMS", None)
        region, grid, source = getattr(mod, "REGION", None), getattr(mod, "GRID", None), f"{module}."
    else:
        system = _field(obj, "system")
        if not isinstance(system, ForcedSystem):
            raise ValueError(f"--system {spec}: {attr} is {_describe(obj)}, not a jaxgear.ForcedSystem, an object "
                             "with a field 'system' holding one, or a function of no arguments returning either.")
        params, region, grid, source = _field(obj, "params"), _field(obj, "region"), _field(obj, "grid"), f"{attr}."
    upper = source == f"{module}."
    if params is None:
        raise ValueError(f"--system {spec}: no parameters: define {'PARAMS in ' + module if upper else attr + '.params'}"
                         " (a parameter pytree: an eqx.Module, a NamedTuple or a dict of numbers).")
    region = _region(region, spec, source + ("REGION" if upper else "region"))
    grid = _counts(grid, spec, source + ("GRID" if upper else "grid"))
    params = apply_overrides(params, overrides)
    check_system(system, params, batched=False)
    return UserSystem(spec=spec, system=system, params=params, region=region, grid=grid)


def apply_overrides(params, overrides: Sequence[str]):
    """``params`` with every ``--set NAME=VALUE`` of ``overrides`` applied to the field
    ``NAME`` of the pytree (a comma list gives an array; :func:`jaxgear.with_param`).
    ``ValueError`` for an item without ``=`` or a name that is not a field (naming the
    valid ones)."""
    from .._params import with_param
    from .._presets import parse_value

    for item in overrides:
        if "=" not in item:
            raise ValueError(f"--set expects NAME=VALUE, got {item!r}.")
        name, text = (s.strip() for s in item.split("=", 1))
        value = parse_value(text)
        if value is None:
            raise ValueError(f"--set {item}: give a number (or comma-separated numbers) for {name}.")
        try:
            params = with_param(params, name, value)
        except ValueError as exc:
            raise ValueError(f"--set {item}: {exc}") from None
    return params


def axes_of(system: ForcedSystem, n_ranges: int, flag: str = "--region") -> tuple[tuple[int, ...], tuple[float, ...]]:
    """The gridded coordinates and the base point of a region of ``n_ranges`` ranges:
    every coordinate (``n_ranges == dim``), or every one but the section coordinate
    ``system.section_index`` with the cells on the section ``{x_i = 0}``
    (``n_ranges == dim - 1``). ``ValueError`` for any other count."""
    dim = system.dim
    base = (0.0,) * dim
    if n_ranges == dim:
        return tuple(range(dim)), base
    idx = system.section_index
    if idx is not None and n_ranges == dim - 1:
        return tuple(i for i in range(dim) if i != idx), base
    names = ", ".join(system.state_names)
    also = (f", or {dim - 1} for the cells on the section {system.state_names[idx]} = 0"
            if idx is not None and dim > 1 else "")
    raise ValueError(f"{flag}: {system.name} has {dim} coordinates ({names}); give {dim} LO:HI ranges{also}, "
                     f"got {n_ranges}.")


def default_counts(n_axes: int) -> tuple[int, ...]:
    """Cells per gridded axis when neither ``--grid`` nor the object gives them:
    :data:`CELLS_PER_AXIS` (400 on a line, 40 x 40, 20 x 20 x 20, else 10 per axis)."""
    return (CELLS_PER_AXIS.get(n_axes, 10),) * n_axes


def user_grid(user: UserSystem, region=None, counts=None, method_name: str | None = None):
    """The :class:`~jaxgear.CellGrid` of an analysis of ``user``: ``region`` (``--region``)
    or the object's region, over the axes :func:`axes_of` gives; ``counts`` (``--grid``)
    or the object's or :func:`default_counts`. ``ValueError`` naming ``--region`` where
    neither gives a region, and naming ``--grid`` where the counts do not match."""
    from .._cells import CellGrid

    region = region or user.region
    system = user.system
    if region is None:
        raise ValueError(f"--system {user.spec}: no region: give --region LO:HI,... ({system.dim} ranges over "
                         f"{', '.join(system.state_names)}) or define REGION in the module (region in the object).")
    axes, base = axes_of(system, len(region), "--region")
    names = tuple(system.state_names[i] for i in axes)
    if counts is None:
        counts = user.grid if user.grid is not None and len(user.grid) == len(axes) else default_counts(len(axes))
    if len(counts) != len(axes):
        raise ValueError(f"--grid needs {len(axes)} counts ({', '.join(names)}), got {len(counts)}: "
                         f"{','.join(map(str, counts))}.")
    if method_name == "poincare-like" and len(axes) == system.dim:
        raise ValueError(f"--method poincare-like puts the cells on the section {system.state_names[system.section_index]}"
                         f" = 0: give {system.dim - 1} --region ranges (all coordinates but that one)."
                         if system.section_index is not None else
                         f"--method poincare-like needs a section: {system.name} has no section_index.")
    if method_name == "stroboscopic" and len(axes) != system.dim:
        raise ValueError(f"--method stroboscopic needs a grid over every coordinate: give {system.dim} --region "
                         f"ranges ({', '.join(system.state_names)}).")
    return CellGrid.box(region, counts, axes=axes, base=base, names=system.state_names)
