"""Saved results: one netCDF convention for every result type, and :func:`load`.

Every result type ``R`` of jaxgear has ``R.to_xarray() -> xarray.Dataset`` and
``R.save(path)``, which writes that dataset to a netCDF-4 file (``engine="h5netcdf"``)
atomically, and a module-level ``load_<thing>(path)`` that restores it exactly
(arrays bit-for-bit, metadata equal). The file carries

- ``attrs["jaxgear_type"]``: the class name (what :func:`load` dispatches on),
- ``attrs["params"]``: the full canonical parameter set as JSON (MODEL.md §4 names for
  the gear models), ``attrs["system"]``: the system's name,
  ``attrs["version"]``: the jaxgear version that wrote it,
- coordinates named after the state variables (and parameters, for sweeps), units in
  the attributes,

so any file opens as labelled arrays with ``xarray.open_dataset(path)`` and plotting a
loaded result needs no recomputation.
"""

from __future__ import annotations

import importlib
import os
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["load", "LOADERS"]

LOADERS: dict[str, str] = {
    "GlobalResult": "jaxgear._result:load_result",
    "OrbitSearch": "jaxgear._shooting:load_orbits",
    "BifurcationDiagram": "jaxgear._sweep:load_bifurcation",
    "BasinSweep": "jaxgear._sweep:load_basin_sweep",
    "ParameterMap": "jaxgear._sweep:load_parameter_map",
    "Branch": "jaxgear._continuation:load_branch",
    "DesignResult": "jaxgear._design:load_design",
}
"""Result type (``attrs["jaxgear_type"]``) -> ``"module:function"`` that loads it."""


def _atomic_write(path: str | Path, write) -> Path:
    """Call ``write(tmp)`` on a temporary file in ``path``'s folder, then ``os.replace`` it
    onto ``path``: a reader never sees a half-written file and a failed write leaves an
    existing file untouched. Creates missing parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _write_netcdf(ds, path: str | Path) -> Path:
    """Write ``ds`` to ``path`` (netCDF-4 via h5netcdf) atomically (:func:`_atomic_write`)."""
    return _atomic_write(path, lambda tmp: ds.to_netcdf(tmp, engine="h5netcdf"))


def _read_netcdf(path: str | Path):
    """The dataset at ``path`` fully read into memory (the file is closed on return)."""
    import xarray as xr

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no result file at {path}")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return ds.load()


def _check_type(ds, expected: str, path) -> None:
    """Raise ``ValueError`` when the file says it holds another result type."""
    kind = ds.attrs.get("jaxgear_type")
    if kind is not None and kind != expected:
        raise ValueError(f"{path} holds a {kind}, not a {expected}; open it with jaxgear.load(path).")


def result_type(ds) -> str:
    """The ``jaxgear_type`` of a dataset; files written before the attribute existed
    (global-analysis results of jaxgear 0.1) are recognised by their content."""
    kind = ds.attrs.get("jaxgear_type")
    if kind:
        return str(kind)
    if "labels" in ds.variables and "grid" in ds.attrs:
        return "GlobalResult"
    raise ValueError("this netCDF file has no attrs['jaxgear_type']: it was not written by jaxgear "
                     "(open it with xarray.open_dataset instead).")


def load(path: str | Path) -> Any:
    """Load any saved jaxgear result (``GlobalResult``, ``OrbitSearch``, sweeps, branches).

    Reads ``attrs["jaxgear_type"]`` of the netCDF file and calls the matching loader of
    :data:`LOADERS` (e.g. :func:`jaxgear.load_result`, :func:`jaxgear.load_orbits`); the
    returned object equals the saved one (arrays bit-for-bit, metadata equal).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: the file is not a jaxgear result, or names an unknown type.
        ImportError: the type's module is not part of this build of jaxgear.
    """
    import xarray as xr

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no result file at {path}")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        kind = result_type(ds)
    if kind not in LOADERS:
        raise ValueError(f"{path}: unknown jaxgear_type {kind!r}; known types: {', '.join(LOADERS)}.")
    module, func = LOADERS[kind].split(":")
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name != module:
            raise
        raise ImportError(f"{path} holds a {kind}, which needs the module {module} "
                          f"(loader {LOADERS[kind]}); it is not present in this build of jaxgear.") from exc
    loader = getattr(mod, func, None)
    if loader is None:
        raise ImportError(f"{path} holds a {kind}, but {module} has no loader {func}() in this build of jaxgear.")
    return loader(path)


def _write_json(obj, path: str | Path, indent: int = 2) -> Path:
    """Write ``obj`` as JSON to ``path`` (parent folders created); returns the path."""
    import json

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=indent))
    return path
