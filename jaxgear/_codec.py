"""One field-driven codec: every result dataclass <-> an ``xarray.Dataset``.

A result type is a frozen dataclass registered with :func:`result_type`. Its fields
decide how they are stored, from their type annotations and their ``metadata``:

- arrays (``np.ndarray``, optionally ``None``) become variables; ``array_field(dims)``
  names their dimensions (strings, or a callable of the object for dimensions named
  at run time, such as the grid axes ``x1, x2, x3``); complex arrays are stored as
  ``<name>__real`` and ``<name>__imag``;
- ``int``, ``float``, ``str`` and ``bool`` become attributes, and so do enumerations
  (outcomes such as a status or a kind: stored as their value, rebuilt by their class;
  a tuple of them, such as a diagram's sweep directions, is a JSON list of values);
- nested result dataclasses and ``NamedTuple`` s are stored under ``<name>__<field>``;
- a tuple of dataclasses (``items_field(dim)``: attractors, orbits, bifurcation points)
  becomes one variable per item field along the item dimension, arrays padded to the
  largest item with their true shapes in ``<name>__<field>__shape``;
- a dict whose values are arrays or dataclasses becomes one group of variables per key;
- anything else (dicts of settings, parameter sets, tuples of numbers) is stored as a
  JSON attribute; ``custom_field(encode, decode)`` converts values that are not
  JSON-able (a user's parameter pytree).

A result type registers itself where it is defined (``@result_type`` on the class);
this module imports no result module. Every file carries ``jaxgear_type`` (the class
name, what :func:`jaxgear.load` dispatches on), ``jaxgear_format`` (:data:`FORMAT`) and a ``jaxgear_schema`` attribute
with what the annotations cannot say (``None`` fields, dictionary keys, lengths). A
result type may add labelled coordinates (grid-cell centres, parameter values, state
names) with a ``_coords()`` method; they are written for readers and ignored on load.
Saving and loading is an exact round trip: arrays bit-for-bit with their dtypes, every
other field equal.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import types
import typing
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from ._checks import article

__all__ = ["FORMAT", "TYPED_SETTINGS_FORMAT", "result_type", "array_field", "items_field", "custom_field", "to_dataset", "from_dataset",
           "RESULT_TYPES", "plain", "FieldError"]

FORMAT = 5
"""Layout version written into every file: 5 since the direct method's pool options are
one record (``Direct.pool``) and an orbit search's convergence and checks are tuples of
typed records (4, still read: the direct method's options flat, the search's records as
dictionaries keyed by text; 4 since every result's settings are typed records holding the
options objects; 3: the same with the settings of orbit searches and designs as
dictionaries; 2: every result's settings as dictionaries; files of jaxgear 0.1 have none
and are not read)."""

TYPED_SETTINGS_FORMAT = 4
"""The first layout whose files this version reads (:data:`FORMAT` and the layouts since
this one)."""

RESULT_TYPES: dict[str, type] = {}
"""Registered result types by class name."""


def result_type(cls):
    """Class decorator: register a result dataclass with the codec (by its class name)."""
    RESULT_TYPES[cls.__name__] = cls
    return cls


def array_field(dims=None, *, later: bool = False, **kw):
    """A dataclass field holding an array; ``dims``: a tuple of dimension names or a
    callable ``obj -> tuple`` (default names ``<field>_0, <field>_1, ...``). ``later``:
    the field was added after files of its type were first written (see
    :func:`later_field`; its default, typically ``None``, is what such a file loads with)."""
    return dataclasses.field(metadata={"dims": dims, "later": later}, **kw)


def items_field(dim: str, *, legacy: Callable[[Any], tuple] | None = None, later: bool = False, **kw):
    """A dataclass field holding a tuple of dataclasses, stored along dimension ``dim``.
    ``legacy``: how a file that holds the field in an earlier form, one JSON attribute
    (a dictionary), is read: ``legacy(json value) -> tuple of the dataclasses``. ``later``:
    added after files of its type were first written (they load with its default)."""
    return dataclasses.field(metadata={"item_dim": dim, "legacy": legacy, "later": later}, **kw)


def later_field(default, **kw):
    """A scalar field added to a result type after files of it were first written: a file
    without it loads with ``default`` (every other field a file lacks is an error; an
    array field added later is declared with ``array_field(..., later=True)``)."""
    return dataclasses.field(default=default, metadata={"later": True}, **kw)


def custom_field(encode: Callable[[Any], Any], decode: Callable[[Any], Any], **kw):
    """A field stored as JSON through ``encode(value) -> JSON-able`` and ``decode(json) -> value``."""
    return dataclasses.field(metadata={"encode": encode, "decode": decode}, **kw)


def plain(v):
    """``v`` as JSON-able values, for summaries: a settings dataclass as a dict of its
    fields, an object with ``to_dict`` (an integrator, a method) as that, tuples as lists."""
    if hasattr(v, "to_dict"):
        return v.to_dict()
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
    if isinstance(v, (tuple, list)):
        return [plain(x) for x in v]
    return v


# ------------------------------------------------------------------------ helpers
def _hints(cls) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _strip_optional(hint):
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return hint


def _is_array_hint(hint) -> bool:
    hint = _strip_optional(hint)
    return hint is np.ndarray or hint is jax.Array


def _is_record(cls) -> bool:
    return isinstance(cls, type) and (dataclasses.is_dataclass(cls) or (issubclass(cls, tuple) and
                                                                         hasattr(cls, "_fields")))


def _record_fields(cls) -> list[tuple[str, Any, dict]]:
    hints = _hints(cls)
    if dataclasses.is_dataclass(cls):
        return [(f.name, hints[f.name], dict(f.metadata)) for f in dataclasses.fields(cls)]
    return [(name, hints.get(name, Any), {}) for name in cls._fields]


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, tuple):
        return list(o)
    raise TypeError(f"not JSON-able: {type(o).__name__}")


def _is_enum(hint) -> bool:
    return isinstance(hint, type) and issubclass(hint, enum.Enum)


def _enum(cls, value):
    """The member of the enumeration ``cls`` stored as ``value`` (its value: a string for a
    ``StrEnum``, an integer code otherwise); ``ValueError`` naming the members if none."""
    try:
        return cls(str(value) if issubclass(cls, str) else int(value))
    except (TypeError, ValueError):
        raise ValueError(f"{value!r} is not a {cls.__name__} (one of {', '.join(str(m.value) for m in cls)})") \
            from None


def _to_json(v) -> str:
    return json.dumps(v, default=_json_default)


def _from_json(text: str, hint):
    return _retype(json.loads(text), hint)


def _retype(v, hint):
    """JSON value -> the annotated Python type (tuples from lists, int keys, ...)."""
    hint = _strip_optional(hint)
    origin = typing.get_origin(hint)
    if v is None:
        return None
    if origin is tuple or hint is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_retype(x, args[0]) for x in v)
        if args:
            return tuple(_retype(x, a) for x, a in zip(v, args))
        return tuple(v)
    if origin is dict:
        kt, vt = (typing.get_args(hint) + (Any, Any))[:2]
        return {(_retype(k, kt) if kt is not str else k): _retype(x, vt) for k, x in v.items()}
    if _is_enum(hint):  # an enumeration inside a JSON value (a tuple of directions): by its value
        return _enum(hint, v)
    if hint is int and not isinstance(v, bool):
        return int(v)
    if hint is float:
        return float(v)
    if _is_record(hint) and isinstance(v, dict):
        return hint(**{name: _retype(v[name], h) for name, h, _ in _record_fields(hint)})
    return v


def _dims_for(meta, obj, name: str, ndim: int, prefix: tuple[str, ...] = ()) -> tuple[str, ...]:
    dims = meta.get("dims")
    if callable(dims):
        dims = dims(obj)
    dims = tuple(dims) if dims is not None else tuple(f"{name}_{i}" for i in range(ndim - len(prefix)))
    dims = prefix + dims
    if len(dims) != ndim:
        raise ValueError(f"codec: field {name} has {ndim} dimensions, its dims are {dims}.")
    return dims


def _key_tags(keys) -> list[str]:
    """Names of the variables of a dict's values: the keys themselves when they are
    identifiers (``history__objective``), else their positions."""
    if all(isinstance(k, str) and k.isidentifier() for k in keys):
        return list(keys)
    return [str(i) for i in range(len(keys))]


# ------------------------------------------------------------------------ encode
class _Writer:
    def __init__(self):
        self.data: dict[str, tuple] = {}
        self.attrs: dict[str, Any] = {}
        self.schema: dict[str, Any] = {}

    def array(self, path, dims, a, attrs=None):
        a = np.asarray(a)
        if a.dtype.kind == "c":
            self.data[f"{path}__real"] = (dims, np.ascontiguousarray(a.real), attrs or {})
            self.data[f"{path}__imag"] = (dims, np.ascontiguousarray(a.imag), attrs or {})
            self.schema[path] = {"complex": str(a.dtype)}
        else:
            self.data[path] = (dims, a, attrs or {})


def _encode_record(w: _Writer, obj, path: str, root) -> None:
    for name, hint, meta in _record_fields(type(obj)):
        _encode_value(w, getattr(obj, name), hint, meta, f"{path}{name}", root if path else obj)


def _encode_value(w: _Writer, v, hint, meta, path, owner) -> None:
    if "encode" in meta:
        w.attrs[path] = _to_json(meta["encode"](v))
        return
    if v is None:
        w.schema[path] = {"none": True}
        return
    if _is_array_hint(hint):
        a = np.asarray(v)
        w.array(path, _dims_for(meta, owner, path, a.ndim), a)
        return
    h = _strip_optional(hint)
    if "item_dim" in meta:
        _encode_items(w, tuple(v), typing.get_args(h)[0], meta["item_dim"], path)
        return
    if _is_record(h):
        _encode_record(w, v, f"{path}__", owner)
        return
    if typing.get_origin(h) is dict:
        vt = (typing.get_args(h) + (Any, Any))[1]
        if _is_array_hint(vt) or _is_record(_strip_optional(vt)):
            keys = list(v.keys())
            w.schema[path] = {"keys": _to_json(keys)}
            for k, tag in zip(keys, _key_tags(keys)):
                _encode_value(w, v[k], vt, {}, f"{path}__{tag}", owner)
            return
    if _is_enum(h):  # an outcome: stored as its value (a name or a code), rebuilt by its class
        w.attrs[path] = h(v).value
        return
    if h in (int, float, str) and not isinstance(v, bool):
        w.attrs[path] = v
        return
    w.attrs[path] = _to_json(v)


def _encode_items(w: _Writer, items: tuple, cls, dim: str, path: str) -> None:
    w.schema[path] = {"n": len(items)}
    if not items:
        return
    for name, hint, meta in _record_fields(cls):
        vals = [getattr(it, name) for it in items]
        p = f"{path}__{name}"
        if _is_array_hint(hint):
            arrays = [None if x is None else np.asarray(x) for x in vals]
            ndim = max([a.ndim for a in arrays if a is not None], default=1)
            shapes = np.array([[-1] * ndim if a is None else list(a.shape) for a in arrays], dtype=np.int64)
            shapes = shapes.reshape(len(items), ndim)
            size = tuple(int(max(1, shapes[:, j].max(initial=1))) for j in range(ndim))
            dtype = np.result_type(*[a.dtype for a in arrays if a is not None]) if any(
                a is not None for a in arrays) else np.dtype(np.float64)
            fill = np.nan if dtype.kind in "fc" else (False if dtype.kind == "b" else ("" if dtype.kind in "OUS"
                                                                                     else -1))
            stacked = np.full((len(items),) + size, fill, dtype=dtype if dtype.kind not in "US" else object)
            for i, a in enumerate(arrays):
                if a is not None:
                    stacked[(i,) + tuple(slice(0, s) for s in a.shape)] = a
            named = meta.get("dims") is not None and not callable(meta.get("dims")) and any(
                a is not None for a in arrays)  # all None: one placeholder axis of its own
            dims = _dims_for(meta, None, p, stacked.ndim, prefix=(dim,)) if named else \
                (dim,) + tuple(f"{p}_{j}" for j in range(ndim))
            w.array(p, dims, stacked)
            w.data[f"{p}__shape"] = ((dim, f"{p}__ndim"), shapes, {})
        elif _strip_optional(hint) in (int, float, bool) and all(x is not None for x in vals):
            t = _strip_optional(hint)
            dt = {int: np.int64, float: np.float64, bool: np.bool_}[t]
            w.data[p] = ((dim,), np.array(vals, dtype=dt).reshape(len(items)), {})
        elif _is_enum(_strip_optional(hint)) and all(x is not None for x in vals):
            h = _strip_optional(hint)
            w.data[p] = ((dim,), np.array([h(x).value for x in vals], dtype=object).reshape(len(items)), {})
        elif _strip_optional(hint) is str and all(x is not None for x in vals):
            w.data[p] = ((dim,), np.array(vals, dtype=object).reshape(len(items)), {})
        else:
            w.data[p] = ((dim,), np.array([_to_json(x) for x in vals], dtype=object).reshape(len(items)), {})


def to_dataset(obj):
    """The result ``obj`` (a registered dataclass) as an ``xarray.Dataset`` (see the module)."""
    import xarray as xr

    cls = type(obj)
    if cls.__name__ not in RESULT_TYPES:
        raise TypeError(f"{cls.__name__} is not a registered result type.")
    w = _Writer()
    _encode_record(w, obj, "", obj)
    coords = obj._coords() if hasattr(obj, "_coords") else {}
    attrs = dict(w.attrs)
    attrs.update(jaxgear_type=cls.__name__, jaxgear_format=FORMAT, jaxgear_schema=_to_json(w.schema))
    if hasattr(obj, "_attrs"):
        attrs.update(obj._attrs())
    params = getattr(obj, "params", None)
    if isinstance(params, dict):  # the scalar parameters one attribute each, for readers of the file
        attrs.update({f"param_{k}": v for k, v in params.items()
                      if isinstance(v, (int, float, str)) and not isinstance(v, bool)})
    data = {}
    for name, (dims, a, at) in w.data.items():
        if np.asarray(a).dtype.kind == "U":
            a = np.asarray(a, dtype=object)
        data[name] = (dims, a, at)
    return xr.Dataset(data, coords=coords, attrs=attrs)


# ------------------------------------------------------------------------ decode
class FieldError(ValueError):
    """A field of a result file that cannot be decoded: ``field`` names it (its path in the
    file), the message says why."""

    def __init__(self, field: str, why: str):
        super().__init__(f"field {field!r}: {why}")
        self.field = field


MAX_ARRAY_BYTES = 1 << 34
"""Largest array a result file may ask the reader to allocate (16 GiB); a larger one is
refused before it is read."""


class _Reader:
    """Reads the fields of a dataset that may still be on disk: only the variables a
    field asks for are read, each after its size is checked."""

    def __init__(self, ds):
        self.ds = ds
        schema = ds.attrs.get("jaxgear_schema", "{}")
        try:
            self.schema = json.loads(schema) if isinstance(schema, str) else None
        except ValueError:
            self.schema = None
        if not isinstance(self.schema, dict) or not all(isinstance(v, dict) for v in self.schema.values()):
            raise FieldError("jaxgear_schema", "not a JSON object of field records")

    def values(self, name):
        v = self.ds[name]
        nbytes = int(np.prod(v.shape, dtype=np.float64)) * v.dtype.itemsize
        if nbytes > MAX_ARRAY_BYTES:
            raise FieldError(name, f"{nbytes / 2**30:.3g} GiB, more than a result holds ({MAX_ARRAY_BYTES >> 30} GiB)")
        return v.values

    def array(self, path):
        info = self.schema.get(path, {})
        if "complex" in info:
            re = self.values(f"{path}__real")
            im = self.values(f"{path}__imag")
            z = np.empty(re.shape, dtype=np.dtype(info["complex"]))
            z.real, z.imag = re, im
            return z
        return _native(self.values(path))


def _native(a: np.ndarray) -> np.ndarray:
    if a.dtype.kind == "O":
        return np.array([str(x) for x in a.ravel()], dtype=object).reshape(a.shape)
    return a


def _stored(r: _Reader, path: str) -> bool:
    """Whether the file holds the field at ``path`` (itself, its schema entry, or parts
    ``path__...``)."""
    if path in r.ds.variables or path in r.ds.attrs or path in r.schema:
        return True
    pre = f"{path}__"
    return any(str(k).startswith(pre) for k in (*r.ds.variables, *r.ds.attrs))


def _missing(r: _Reader, meta: dict, path: str) -> bool:
    """A :func:`later_field` that the file does not hold (written before the field was
    added): it takes its default. Any other field must be there."""
    return bool(meta.get("later")) and not _stored(r, path)


def _decode_record(r: _Reader, cls, path: str):
    values = {}
    for name, hint, meta in _record_fields(cls):
        if not _missing(r, meta, f"{path}{name}"):
            try:
                values[name] = _decode_value(r, hint, meta, f"{path}{name}")
            except FieldError:
                raise
            except KeyError:
                raise FieldError(f"{path}{name}", "missing from the file") from None
            except Exception as exc:  # a crafted or damaged file: any decoding failure names its field
                why = str(exc).strip().splitlines()[0].rstrip(".") if str(exc).strip() else ""
                raise FieldError(f"{path}{name}", f"{type(exc).__name__}{': ' + why if why else ''}") from None
    try:
        return cls(**values)
    except Exception as exc:
        raise FieldError(path.rstrip("_") or cls.__name__, f"does not make {article(cls.__name__)} ({exc})") from None


def _decode_value(r: _Reader, hint, meta, path):
    info = r.schema.get(path, {})
    if "decode" in meta:
        return meta["decode"](json.loads(r.ds.attrs[path]))
    if info.get("none"):
        return None
    if _is_array_hint(hint):
        return r.array(path)
    h = _strip_optional(hint)
    if "item_dim" in meta:
        if meta.get("legacy") is not None and "n" not in info and path in r.ds.attrs:  # an earlier layout's JSON
            return tuple(meta["legacy"](json.loads(r.ds.attrs[path])))
        return _decode_items(r, typing.get_args(h)[0], path)
    if _is_record(h):
        return _decode_record(r, h, f"{path}__")
    if typing.get_origin(h) is dict and "keys" in info:
        kt, vt = (typing.get_args(h) + (Any, Any))[:2]
        raw = json.loads(info["keys"])
        return {_retype(k, kt): _decode_value(r, vt, {}, f"{path}__{tag}") for k, tag in zip(raw, _key_tags(raw))}
    a = r.ds.attrs[path]
    if _is_enum(h):
        return _enum(h, a)
    if h is int:
        return int(a)
    if h is float:
        return float(a)
    if h is str:
        return str(a)
    return _from_json(a, hint)


def _decode_items(r: _Reader, cls, path: str) -> tuple:
    n = int(r.schema[path]["n"])
    if n == 0:
        return ()
    cols = {}
    for name, hint, _meta in _record_fields(cls):
        p = f"{path}__{name}"
        if _missing(r, _meta, p):
            continue
        if _is_array_hint(hint):
            stacked = r.array(p)
            shapes = r.values(f"{p}__shape")
            out = []
            for i in range(n):
                if np.any(shapes[i] < 0):
                    out.append(None)
                else:
                    out.append(np.ascontiguousarray(stacked[(i,) + tuple(slice(0, int(s)) for s in shapes[i])]))
            cols[name] = out
        else:
            raw = r.values(p)
            h = _strip_optional(hint)
            if _is_enum(h):
                cols[name] = [_enum(h, x) for x in raw]
            elif h in (int, float, bool):
                cols[name] = [h(x) for x in raw]
            elif h is str:
                cols[name] = [str(x) for x in raw]
            else:
                cols[name] = [_from_json(str(x), hint) for x in raw]
    return tuple(cls(**{k: v[i] for k, v in cols.items()}) for i in range(n))


def from_dataset(ds, expected: str | None = None):
    """Rebuild the result stored in ``ds`` (written by :func:`to_dataset`)."""
    kind = str(ds.attrs.get("jaxgear_type", ""))
    if expected is not None and kind != expected:
        raise ValueError(f"the file holds {article(kind) if kind else 'a file of another kind'}, "
                         f"not {article(expected)}; "
                         "open it with jaxgear.load(path).")
    if kind not in RESULT_TYPES:
        raise ValueError(f"unknown jaxgear_type {kind!r}; known types: {', '.join(sorted(RESULT_TYPES))}.")
    return _decode_record(_Reader(ds), RESULT_TYPES[kind], "")
