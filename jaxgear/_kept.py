"""Lowered computations kept from one command to the next: a warm start skips tracing.

JAX's persistent compilation cache (``<cache root>/xla``) saves XLA's compilation, but
to find a computation in it a new process first traces the Python function and lowers
it to a module. For the direct analysis's lane pools and the section crossings that is
about 2 CPU-seconds at every start of ``jaxgear analyze``, paid again by every process of
a distributed run. A function made by :func:`kept_jit` is ``jax.jit`` that, once keeping
is on (:func:`enable`), exports each of its computations (:mod:`jax.export`: the lowered
module, serialised) into ``<cache root>/kept`` under a key of what determines it:

- jaxgear's own source files (every ``.py`` and the CPU kernel's source), the versions
  of jax, jaxlib and equinox, whether the compiled CPU kernel is in use, the numeric
  configuration (float64, dtype promotion);
- the platform and kind of the devices, the function, its static arguments, and the
  tree, shapes and dtypes of its array arguments.

A later process loads the module and calls it (``Exported.call`` in ``jax.jit``): it
lowers in a few milliseconds and XLA's cache holds its compilation. The computation is
the same whether it was exported in this process or loaded: the first and every later
command give the same results.

Static arguments must be plain values (numbers, strings, tuples, named tuples) or
objects built of jaxgear's own module-level functions and classes (the built-in
systems, integrators, options). Anything else — a system defined by the user, a
closure — cannot be told apart from a changed one by its source, so its computations
are traced as usual and never kept. Only :func:`jaxgear.cli.console` (a process running
one command) turns keeping on: a library user's process, or a test that changes a module
constant, always traces. Whatever cannot be exported or loaded runs through ``jax.jit``
unchanged: keeping only ever skips work.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import inspect
import os
import pickle
import tempfile
import types
import weakref
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from ._cache import cache_root

__all__ = ["kept_jit", "KeptFunction", "enable", "disable", "fingerprint", "Unkeepable"]

_FORMAT = b"jaxgear-kept-1"
_STATE: dict = {"dir": None}


class Unkeepable(Exception):
    """A static argument (or an argument tree) without a text that is the same in every
    process: its computation is not kept."""


def enable(folder: Path | None = None) -> Path | None:
    """Keep exported computations in ``folder`` (default ``<cache root>/kept``) for the rest
    of the process; ``None`` (nothing kept) when ``JAXGEAR_CACHE_DIR`` turns caching off or
    the folder cannot be made."""
    if folder is None:
        root = cache_root()
        if root is None:
            return None
        folder = root / "kept"
    try:
        Path(folder).mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    _STATE["dir"] = Path(folder)
    return _STATE["dir"]


def disable() -> None:
    """Stop keeping (computations loaded so far stay in use)."""
    _STATE["dir"] = None


@functools.cache
def _environment() -> bytes:
    """What every kept computation depends on besides its function and arguments (with
    whether the compiled CPU kernel is in use: it is built and registered here, as the
    loaded modules call it)."""
    import equinox
    import jaxlib

    from .integrate._native import native_available

    h = hashlib.sha256(_FORMAT)
    pkg = Path(__file__).resolve().parent
    for path in sorted(p for p in pkg.rglob("*") if p.suffix in (".py", ".cc", ".h") and p.is_file()):
        h.update(str(path.relative_to(pkg)).encode() + b"\0" + path.read_bytes())
    for part in (jax.__version__, jaxlib.__version__, equinox.__version__, native_available(),
                 jax.config.jax_enable_x64, jax.config.jax_numpy_dtype_promotion, jax.config.jax_default_matmul_precision):
        h.update(b"\0" + str(part).encode())
    return h.digest()


def _ours(obj) -> bool:
    mod = getattr(obj, "__module__", "") or ""
    return (mod == "jaxgear" or mod.startswith("jaxgear.")) and "<locals>" not in getattr(obj, "__qualname__", "<")


def fingerprint(x) -> str:
    """A text that is the same in every process for equal static arguments built of plain
    values and jaxgear's own module-level functions and classes; raises
    :class:`Unkeepable` for anything else."""
    if x is None or isinstance(x, (bool, int, float, str, bytes, np.integer, np.floating, np.bool_)):
        return f"{type(x).__name__}:{x!r}"
    if isinstance(x, types.FunctionType):
        if not _ours(x) or x.__closure__:
            raise Unkeepable(f"{x.__qualname__} is not one of jaxgear's module-level functions")
        return f"fn:{x.__module__}.{x.__qualname__}"
    if isinstance(x, tuple) and hasattr(x, "_fields"):  # a named tuple
        if not _ours(type(x)):
            raise Unkeepable(f"{type(x).__qualname__} is not one of jaxgear's classes")
        return f"{type(x).__module__}.{type(x).__qualname__}({','.join(fingerprint(v) for v in x)})"
    if type(x) in (tuple, list):
        return f"{type(x).__name__}({','.join(fingerprint(v) for v in x)})"
    if dataclasses.is_dataclass(x) and not isinstance(x, type):  # eqx.Module and frozen dataclasses
        if not _ours(type(x)):
            raise Unkeepable(f"{type(x).__qualname__} is not one of jaxgear's classes")
        fields = ",".join(f"{f.name}={fingerprint(getattr(x, f.name))}" for f in dataclasses.fields(x))
        return f"{type(x).__module__}.{type(x).__qualname__}({fields})"
    raise Unkeepable(f"a static argument of type {type(x).__qualname__} has no fingerprint")


def _aval(leaf) -> jax.ShapeDtypeStruct:
    """Shape, dtype and weak type of an argument leaf (an array, a ``ShapeDtypeStruct`` or
    a number), without its placement."""
    if isinstance(leaf, (jax.ShapeDtypeStruct, jax.Array)):
        return jax.ShapeDtypeStruct(leaf.shape, leaf.dtype, weak_type=bool(leaf.weak_type))
    if isinstance(leaf, (bool, int, float, complex)):
        return jax.ShapeDtypeStruct((), jax.numpy.asarray(leaf).dtype, weak_type=True)
    leaf = np.asarray(leaf)
    return jax.ShapeDtypeStruct(leaf.shape, leaf.dtype)


def _device(leaf):
    """The device an argument leaf is placed on (the default device when it has none; an
    argument over several devices is not one a kept computation takes)."""
    sharding = getattr(leaf, "sharding", None)
    if sharding is None:
        return jax.local_devices()[0]
    devices = sharding.device_set
    if len(devices) != 1:
        raise Unkeepable("an argument placed on several devices")
    return next(iter(devices))


_COMMITTED: dict[int, tuple] = {}
"""Committed aliases of the uncommitted arrays passed to loaded computations, by ``id`` of
the array (a pool passes the same cells and parameters at every call), each entry dropped
when its array is."""


def _committed(leaf, device):
    """``leaf`` committed to ``device`` (an alias, no copy, made once per array): a loaded
    computation returns committed arrays, so its calls always pass committed ones and find
    the one compilation made ahead."""
    if isinstance(leaf, jax.Array):
        if leaf.committed:
            return leaf
        found = _COMMITTED.get(id(leaf))
        if found is not None and found[0]() is leaf and found[1].sharding.device_set == {device}:
            return found[1]
    out = jax.device_put(leaf, jax.sharding.SingleDeviceSharding(device))
    if isinstance(leaf, jax.Array):
        key = id(leaf)
        _COMMITTED[key] = (weakref.ref(leaf, lambda _, key=key: _COMMITTED.pop(key, None)), out)
    return out


class KeptFunction:
    """``jax.jit`` of ``fun`` whose computations are kept across processes once keeping is
    on (see the module). Called like the jitted function (``jitted``); :meth:`prepare`
    makes a computation ready ahead (loaded, or exported and kept, or compiled)."""

    def __init__(self, fun: Callable, static_argnames: tuple[str, ...], donate_argnums: tuple[int, ...]):
        self._fun = fun
        self._signature = inspect.signature(fun)
        self._static = tuple(static_argnames)
        self._donate = tuple(donate_argnums)
        self.jitted = jax.jit(fun, static_argnames=self._static, donate_argnums=self._donate)
        self._runners: dict[tuple, tuple[Callable, object]] = {}
        functools.update_wrapper(self, fun)

    def _split(self, args, kwargs):
        """``(static (name, value) pairs, dynamic arguments, which of them are donated)``."""
        bound = self._signature.bind(*args, **kwargs)
        bound.apply_defaults()
        static, dynamic, donated = [], [], []
        for i, (name, value) in enumerate(bound.arguments.items()):
            if name in self._static:
                static.append((name, value))
            else:
                dynamic.append(value)
                donated.append(i in self._donate)
        return tuple(static), tuple(dynamic), donated

    def _key(self, static, dynamic):
        """The in-process key of a computation (static values, argument tree, each leaf's
        shape, dtype and device), the tree, the leaves and their devices; ``None`` for the
        key when called inside another trace (the jitted function is traced there)."""
        leaves, tree = jax.tree.flatten(dynamic)
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            return None, tree, leaves, None
        devices = [_device(x) for x in leaves]
        return (static, tree, tuple((_aval(x), d.id) for x, d in zip(leaves, devices))), tree, leaves, devices

    def __call__(self, *args, **kwargs):
        if self._runners:
            static, dynamic, _ = self._split(args, kwargs)
            try:
                key, _, leaves, devices = self._key(static, dynamic)
            except Unkeepable:
                key = None
            found = self._runners.get(key)
            if found is not None:
                runner, out_tree = found
                return jax.tree.unflatten(out_tree, runner(*map(_committed, leaves, devices)))
        return self.jitted(*args, **kwargs)

    def prepare(self, *args, **kwargs) -> None:
        """Make the computation for these arguments (arrays or ``ShapeDtypeStruct``\\ s placed
        as the call's will be) ready: loaded from the kept computations, or exported and
        kept, or (not keepable) lowered and compiled by ``jax.jit``."""
        static, dynamic, donated = self._split(args, kwargs)
        try:
            key, tree, leaves, devices = self._key(static, dynamic)
            kept = None if key is None or key in self._runners else self._kept(static, tree, leaves)
        except Unkeepable:
            key, kept = None, None
        if key is not None and key in self._runners:
            return
        if kept is None:
            self.jitted.lower(*args, **kwargs).compile()
            return
        exported, out_tree = kept
        counts = [len(jax.tree.leaves(d)) for d in dynamic]
        flat_donated = tuple(i for i, d in enumerate(np.repeat(donated, counts)) if d)
        runner = jax.jit(exported.call, donate_argnums=flat_donated)
        runner.lower(*(jax.ShapeDtypeStruct(a.shape, a.dtype, weak_type=a.weak_type,
                                            sharding=jax.sharding.SingleDeviceSharding(d))
                       for a, d in zip(map(_aval, leaves), devices))).compile()
        self._runners[key] = (runner, out_tree)

    def _kept(self, static, tree, leaves):
        """``(exported, output tree)`` of the computation of the arguments ``tree`` (with
        ``leaves``) from the folder, or exported now and written there; ``None`` when keeping
        is off or the computation cannot be kept."""
        folder = _STATE["dir"]
        if folder is None:
            return None
        avals = [_aval(x) for x in leaves]
        try:
            text = str(tree)
            if " at 0x" in text:
                raise Unkeepable("the arguments' tree holds objects without a stable text")
            h = hashlib.sha256(_environment())
            platform = jax.default_backend()
            kinds = sorted({d.device_kind for d in jax.local_devices()})
            for part in (platform, repr(kinds), f"{self._fun.__module__}.{self._fun.__qualname__}",
                         fingerprint(static), text, repr([(a.shape, str(a.dtype), a.weak_type) for a in avals])):
                h.update(b"\0" + part.encode())
        except Unkeepable:
            return None
        path = folder / f"{h.hexdigest()[:40]}.bin"
        if path.exists():
            found = _read(path)
            if found is not None:
                return found
        made = self._export(static, tree, avals)
        if made is not None:
            _write(path, *made)
        return made

    def _export(self, static, tree, avals):
        """The computation exported over the flat list of its argument leaves (jaxgear's
        CPU kernel allowed as a custom call), with its output tree; ``None`` when it cannot
        be exported (a host callback, a custom call of another library, ...)."""
        from .integrate._native import TARGET

        box = []

        def flat(*leaves):
            out = self._call_with_static(static, jax.tree.unflatten(tree, leaves))
            out_leaves, out_tree = jax.tree.flatten(out)
            box.append(out_tree)
            return out_leaves

        flat.__name__ = flat.__qualname__ = self._fun.__name__  # what JAX's logs and profiles name

        try:
            exported = jax.export.export(jax.jit(flat),  # for the default backend's platform
                                         disabled_checks=[jax.export.DisabledSafetyCheck.custom_call(TARGET)])(*avals)
        except Exception:  # noqa: BLE001  (not exportable: traced and compiled as usual)
            return None
        return exported, box[-1]

    def _call_with_static(self, static, dynamic):
        """The jitted function called with the static values and the dynamic arguments put
        back in their places."""
        values = dict(static)
        args, it = [], iter(dynamic)
        for name in self._signature.parameters:
            args.append(values[name] if name in values else next(it))
        return self.jitted(*args)


def _write(path: Path, exported, out_tree) -> None:
    """Write the serialised module and a skeleton of its output tree (leaves replaced by
    0); nothing when either cannot be written and read back."""
    tmp = None
    try:
        skeleton = pickle.dumps(jax.tree.unflatten(out_tree, [0] * out_tree.num_leaves))
        if jax.tree.structure(pickle.loads(skeleton)) != out_tree:
            return
        fd, tmp = tempfile.mkstemp(prefix=".kept-", dir=path.parent)
        with os.fdopen(fd, "wb") as fh:
            pickle.dump((_FORMAT, bytes(exported.serialize()), skeleton), fh)
        os.replace(tmp, path)
        tmp = None
    except Exception:  # noqa: BLE001  (keeping is an optimisation: never fail the computation)
        pass
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)


def _read(path: Path):
    """``(exported, output tree)`` kept in ``path``; ``None`` (and the file removed) when it
    cannot be read."""
    try:
        with open(path, "rb") as fh:
            fmt, payload, skeleton = pickle.load(fh)
        if fmt != _FORMAT:
            raise ValueError("another format")
        return jax.export.deserialize(bytearray(payload)), jax.tree.structure(pickle.loads(skeleton))
    except Exception:  # noqa: BLE001  (a broken or foreign file: export again)
        path.unlink(missing_ok=True)
        return None


def kept_jit(fun: Callable | None = None, *, static_argnames=(), donate_argnums=()):
    """``jax.jit`` whose computations a command keeps across processes (see the module);
    used as ``@kept_jit(static_argnames=(...), donate_argnums=(...))``."""
    if fun is None:
        return functools.partial(kept_jit, static_argnames=static_argnames, donate_argnums=donate_argnums)
    return KeptFunction(fun, tuple(static_argnames), tuple(donate_argnums))
