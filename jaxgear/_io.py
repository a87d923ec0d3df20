"""Saved results and output files: atomic writes, one loader for every result type.

Every result type saves through the one codec of :mod:`jaxgear._codec` to a netCDF-4
file (``engine="h5netcdf"``) and :func:`load` restores it exactly. A result type
registers itself with the codec where it is defined; this module imports no result
module (importing any ``jaxgear`` module first runs the package ``__init__``, which
imports them all, so every type is known before :func:`load` can run).

Every file jaxgear writes (netCDF, JSON, figures, checkpoint parts) is written to a
temporary file in the target folder and moved onto its name (``os.replace``), so a
reader never sees a half-written file and a failed or killed write leaves the previous
file untouched; files get the permissions of the user's umask.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ._checks import article
from ._codec import FORMAT, TYPED_SETTINGS_FORMAT, FieldError, from_dataset, to_dataset

__all__ = ["load", "save_result", "atomic_write", "write_json", "write_text", "save_figure", "read_dataset",
           "strict_json", "TMP_PREFIX", "remove_stale_temporaries", "NotAResultFile"]

TMP_PREFIX = ".jaxgear-tmp-"
"""Name prefix of temporary files (removed on success, cleaned up by later runs)."""


class NotAResultFile(ValueError):
    """The path does not hold a readable jaxgear result."""


def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write(path: str | Path, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file in ``path``'s folder, then ``os.replace`` it
    onto ``path``; creates missing parent folders; the file's mode follows the umask.
    A failed write removes the temporary file and leaves an existing ``path`` untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f"{TMP_PREFIX}{path.name}.", dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, path)
    except OSError as exc:  # (a full disk, a quota): the error names the file being written
        Path(tmp).unlink(missing_ok=True)
        if exc.filename is None and exc.errno is not None:
            raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def remove_stale_temporaries(folder: str | Path) -> None:
    """Remove temporary files a killed run left in ``folder`` (names starting with
    :data:`TMP_PREFIX`)."""
    folder = Path(folder)
    if folder.is_dir():
        for p in folder.glob(f"{TMP_PREFIX}*"):
            try:
                p.unlink() if p.is_file() else None
            except OSError:
                pass


def strict_json(obj: Any) -> Any:
    """``obj`` with every NaN or infinite float replaced by ``None`` (JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if hasattr(obj, "item") and getattr(obj, "ndim", None) == 0:  # numpy scalar
        return strict_json(obj.item())
    if hasattr(obj, "tolist"):
        return strict_json(obj.tolist())
    return obj


def write_text(text: str, path: str | Path) -> Path:
    """Write ``text`` to ``path`` atomically."""
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text))


def write_json(obj: Any, path: str | Path, indent: int = 2) -> Path:
    """Write ``obj`` as strict JSON (NaN and infinities as ``null``) to ``path`` atomically."""
    return write_text(json.dumps(strict_json(obj), indent=indent, allow_nan=False), path)


def save_figure(fig, path: str | Path, **kw) -> Path:
    """Save a matplotlib figure atomically (the format from ``path``'s suffix)."""
    fmt = Path(path).suffix.lstrip(".") or "png"
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, **kw))


def save_result(result, path: str | Path) -> Path:
    """Write a result object to a netCDF file atomically through the codec; large arrays
    are compressed. The file is built in memory first (a result is at most a few times
    the size of its labels)."""
    ds = to_dataset(result)
    for k in ds.data_vars:
        if ds[k].size > 4096 and ds[k].dtype.kind in "biuf":
            ds[k].encoding.update(zlib=True, complevel=4)
    # built in memory, then written with plain file I/O: a full disk is one OSError from
    # the write, never a half-written HDF5 file whose native finaliser runs later
    data = ds.to_netcdf(engine="h5netcdf")
    return atomic_write(path, lambda tmp: Path(tmp).write_bytes(data))


def _check_result_path(path: Path) -> None:
    """Raise :class:`NotAResultFile` with the reason unless ``path`` is a readable file that
    starts like netCDF-4/HDF5."""
    if not path.exists():
        raise NotAResultFile(f"not a jaxgear result file: {path} does not exist.")
    if path.is_dir():
        raise NotAResultFile(f"not a jaxgear result file: {path} is a folder (give the .nc file inside it).")
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError as exc:
        raise NotAResultFile(f"not a jaxgear result file: {path} cannot be read ({exc.strerror}).") from None
    if size == 0:
        raise NotAResultFile(f"not a jaxgear result file: {path} is empty.")
    if not head.startswith(b"\x89HDF\r\n\x1a\n"):
        what = "a JSON file" if head.lstrip()[:1] in (b"{", b"[") else "not a netCDF-4/HDF5 file"
        raise NotAResultFile(f"not a jaxgear result file: {path} is {what}.")


@contextlib.contextmanager
def _open_dataset(path: Path):
    """The netCDF dataset at ``path`` opened lazily (variables are read when asked for);
    :class:`NotAResultFile` when it is not one."""
    import xarray as xr

    _check_result_path(path)
    try:
        ds = xr.open_dataset(path, engine="h5netcdf", phony_dims="sort")
    except Exception as exc:  # truncated or corrupted HDF5: h5py raises many kinds
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise NotAResultFile(f"not a jaxgear result file: {path} is damaged or truncated ({first}).") from None
    with ds:
        yield ds


def read_dataset(path: str | Path):
    """The netCDF dataset at ``path`` fully read into memory (the file is closed on return).

    Raises :class:`NotAResultFile` (a ``ValueError``) with the reason when ``path`` is
    missing, a folder, empty, truncated or not netCDF.
    """
    path = Path(path)
    with _open_dataset(path) as ds:
        try:
            return ds.load()
        except Exception as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise NotAResultFile(f"not a jaxgear result file: {path} is damaged or truncated ({first}).") from None


def load(path: str | Path, expected: str | None = None, *, params_type: type | None = None) -> Any:
    """Load any saved jaxgear result (``GlobalResult``, ``OrbitSearch``, sweeps, branches,
    designs), exactly as it was saved.

    Reads ``attrs["jaxgear_type"]`` of the netCDF file and rebuilds the object through the
    codec (the class registered under that name). A file is data: nothing it names is
    imported or called, and only the variables of the result's fields are read (each
    after its size is checked). Parameters of a type that is not the package's own come
    back as a plain dict of their values, unless ``params_type`` (the class of your
    system's parameters, e.g. a ``NamedTuple``) is given: then they are rebuilt as
    ``params_type(**values)``. ``expected``: a type name the file must hold. Files of
    jaxgear 0.1 (no ``jaxgear_format``) are not read.

    Raises:
        NotAResultFile: (a ``ValueError``) the path is not a readable jaxgear result file;
            the message says why (missing, a folder, empty, truncated, not netCDF, another
            program's file, an unknown or unexpected result type, the field that cannot
            be read).
    """
    path = Path(path)
    with _open_dataset(path) as ds:
        fmt = ds.attrs.get("jaxgear_format")
        if fmt is None:
            kind = ds.attrs.get("jaxgear_type")
            if kind is None and not ("labels" in ds.variables and "grid" in ds.attrs):
                raise NotAResultFile(f"not a jaxgear result file: {path} is a netCDF file without "
                                     "attrs['jaxgear_type'] (written by another program: open it with "
                                     "xarray.open_dataset instead).")
            kind = str(kind or "GlobalResult")
            raise NotAResultFile(f"{path} holds {article(kind)} written by jaxgear 0.1, whose files this version "
                                 "no longer reads: re-run the analysis with this version (or load it with jaxgear "
                                 "0.1 and save the arrays you need with xarray).")
        fmt = _format_number(fmt)
        if fmt is None:
            raise NotAResultFile(f"not a jaxgear result file: {path}: field 'jaxgear_format' is not an integer.")
        if fmt > FORMAT:
            raise NotAResultFile(f"{path} was written by a newer jaxgear (format {fmt}, this one reads up to "
                                 f"{FORMAT}): upgrade jaxgear.")
        try:
            return _with_params_type(from_dataset(ds, expected), params_type)
        except FieldError as exc:
            if fmt < TYPED_SETTINGS_FORMAT:
                raise NotAResultFile(f"{path} was written by an earlier development version of jaxgear (format "
                                     f"{fmt}, before typed settings; this one writes {FORMAT} and reads "
                                     f"{TYPED_SETTINGS_FORMAT} to {FORMAT}) and cannot be read: re-run the analysis "
                                     "with this version.") from None
            raise NotAResultFile(f"not a jaxgear result file: {path}: {exc}.") from None
        except ValueError as exc:  # an unknown or unexpected result type
            raise NotAResultFile(f"{path}: {exc}") from None


def _with_params_type(result, params_type: type | None):
    """``result`` with its parameter fields that loaded as plain dicts (a user's parameter
    type) rebuilt as ``params_type(**values)``."""
    if params_type is None:
        return result
    changes = {}
    for f in dataclasses.fields(result):
        value = getattr(result, f.name)
        if f.name.endswith("params") and isinstance(value, dict) and params_type is not dict:
            try:
                changes[f.name] = params_type(**value)
            except (TypeError, ValueError) as exc:
                raise FieldError(f.name, f"does not fit params_type={params_type.__name__} ({exc})") from None
    return dataclasses.replace(result, **changes) if changes else result


def _format_number(value) -> int | None:
    """The file's ``jaxgear_format`` as an int, or ``None`` when it is not one integer."""
    a = np.asarray(value)
    if a.ndim != 0 or a.dtype.kind not in "iu":
        return None
    return int(a)
