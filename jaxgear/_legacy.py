"""Readers for result files written by jaxgear 0.1 (before the field-driven codec).

Those files carry ``jaxgear_type`` but no ``jaxgear_format``; each reader below rebuilds
the current result object from the old layout (arrays bit-for-bit, metadata equal).
Nothing writes this layout any more.
"""

from __future__ import annotations

import json

import numpy as np

__all__ = ["legacy_type", "load_legacy"]


def legacy_type(ds, path) -> str:
    """The ``jaxgear_type`` of an old file; global-analysis results written before the
    attribute existed are recognised by their content."""
    kind = ds.attrs.get("jaxgear_type")
    if kind:
        return str(kind)
    if "labels" in ds.variables and "grid" in ds.attrs:
        return "GlobalResult"
    raise ValueError(f"not a jaxgear result file: {path} is a netCDF file without attrs['jaxgear_type'] (written by "
                     "another program: open it with xarray.open_dataset instead).")


def _complex(re, im) -> np.ndarray:
    z = np.empty(np.shape(re), dtype=np.complex128)
    z.real, z.imag = re, im
    return z


def _global(ds):
    from ._cells import CellGrid
    from .analysis import Attractor, GlobalResult

    attractors = []
    for i in range(ds.sizes.get("attractor", 0)):
        k, m, c = (int(ds[f"attractor_n_{x}"][i]) for x in ("points", "section", "cycle"))
        attractors.append(Attractor(
            id=int(ds["attractor_id"][i]), period=int(ds["attractor_period"][i]),
            points=ds["points"].values[i, :k], section_points=ds["section_points"].values[i, :m],
            cell_count=int(ds["attractor_cells"][i]), share=float(ds["attractor_share"][i]),
            residual=float(ds["attractor_residual"][i]), periodic_cells=ds["periodic_cells"].values[i, :c]))
    a = ds.attrs
    return GlobalResult(
        labels=ds["labels"].values.astype(np.int64), attractors=tuple(attractors),
        grid=CellGrid.from_dict(json.loads(a["grid"])), method=str(a["method"]), settings=json.loads(a["settings"]),
        params=json.loads(a["params"]), system=str(a["system"]), state_names=tuple(str(s) for s in ds["state"].values),
        n_sink=int(a["n_sink"]), n_unresolved=int(a["n_unresolved"]), runtime_s=float(a["runtime_s"]),
        version=str(a["version"]), mean_periods=float(a["mean_periods"]))


def _orbits(ds):
    from .shooting import OrbitSearch, PeriodicOrbit, ShootResult

    v = lambda name: ds[name].values  # noqa: E731
    orbits = []
    for i in range(ds.sizes.get("orbit", 0)):
        m, n_traj = int(v("period")[i]), int(v("trajectory_length")[i])
        orbits.append(PeriodicOrbit(
            points=v("points")[i, :m], period=m, multipliers=_complex(v("multipliers_real")[i],
                                                                      v("multipliers_imag")[i]),
            stable=bool(v("stable")[i]), instability=str(v("instability")[i]), residual=float(v("residual")[i]),
            n_seeds=int(v("n_seeds")[i]), t0=float(v("t0")[i]),
            trajectory=v("trajectory")[i, :n_traj] if n_traj else None))
    shots, seeds = {}, {}
    for k in json.loads(ds.attrs["shot_periods"]):
        g = lambda f, k=k: v(f"shot_k{k}_{f}")  # noqa: E731
        shots[k] = ShootResult(
            point=g("point"), orbit=g("orbit"), min_period=g("min_period"), monodromy=g("monodromy"),
            multipliers=_complex(g("multipliers_real"), g("multipliers_imag")), stable=g("stable"),
            instability=g("instability"), residual=g("residual"), iterations=g("iterations"), status=g("status"),
            history=g("history"), last_iterate=g("last_iterate"))
        seeds[k] = g("seeds")
    a = ds.attrs
    return OrbitSearch(
        orbits=tuple(orbits), shots=shots, status_counts=json.loads(a["status_counts"]), seeds=seeds,
        system=str(a["system"]), state_names=tuple(json.loads(a["state_names"])),
        section_index=json.loads(a["section_index"]), params=json.loads(a["params"]),
        settings=json.loads(a["settings"]), version=str(a["version"]), runtime_s=float(a["runtime_s"]))


def _bifurcation(ds):
    from .sweep import BifurcationDiagram

    a = ds.attrs
    return BifurcationDiagram(
        param=str(a["param"]), fields=tuple(json.loads(a["fields"])), values=ds[a["param_coord"]].values,
        directions=tuple(str(s) for s in ds["direction"].values), starts=ds["starts"].values,
        points=ds["points"].values, period=ds["period"].values.astype(np.int64),
        attractor=ds["attractor"].values.astype(np.int64), system=str(a["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), params=json.loads(a["params"]),
        settings=json.loads(a["settings"]), version=str(a["version"]))


def _basins(ds):
    from ._cells import CellGrid
    from .sweep import BasinSweep

    a = ds.attrs
    return BasinSweep(
        param=str(a["param"]), fields=tuple(json.loads(a["fields"])), values=ds[a["param_coord"]].values,
        shares=ds["shares"].values, sink_share=ds["sink_share"].values,
        unresolved_share=ds["unresolved_share"].values, period=ds["period"].values.astype(np.int64),
        points=ds["points"].values, n_points=ds["n_points"].values.astype(np.int64),
        labels=ds["labels"].values.astype(np.int16), grid=CellGrid.from_dict(json.loads(a["grid"])),
        method=str(a["method"]), match_tol=float(a["match_tol"]), system=str(a["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), params=json.loads(a["params"]),
        settings=json.loads(a["settings"]), version=str(a["version"]))


def _parameter_map(ds):
    from .sweep import ParameterMap

    a = ds.attrs
    return ParameterMap(
        param_x=str(a["param_x"]), fields_x=tuple(json.loads(a["fields_x"])), values_x=ds[a["coord_x"]].values,
        param_y=str(a["param_y"]), fields_y=tuple(json.loads(a["fields_y"])), values_y=ds[a["coord_y"]].values,
        starts=ds["starts"].values, quantity=str(a["quantity"]), period=ds["period"].values.astype(np.int64),
        attractor=ds["attractor"].values.astype(np.int64), n_attractors=ds["n_attractors"].values.astype(np.int64),
        last_point=ds["last_point"].values, system=str(a["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), params=json.loads(a["params"]),
        settings=json.loads(a["settings"]), version=str(a["version"]))


def _branch(ds):
    from .continuation import BifurcationPoint, Branch

    a = ds.attrs
    kinds = json.loads(a["bifurcation_kinds"])
    dim = ds.sizes["state"]
    bifs = tuple(BifurcationPoint(
        kind=kind, param_value=float(ds["bif_param"].values[i]),
        point=np.array(ds["bif_point"].values[i], dtype=float).reshape(dim),
        multipliers=ds["bif_multipliers_real"].values[i] + 1j * ds["bif_multipliers_imag"].values[i],
        index=int(ds["bif_index"].values[i]), orbit=np.array(ds["bif_orbit"].values[i], dtype=float),
        test_value=float(ds["bif_test_value"].values[i]), nonsmooth=bool(ds["bif_nonsmooth"].values[i]))
        for i, kind in enumerate(kinds))
    return Branch(
        param=str(a["param"]), values=np.asarray(ds["param_value"].values, dtype=float),
        points=np.asarray(ds["points"].values, dtype=float),
        multipliers=ds["multipliers_real"].values + 1j * ds["multipliers_imag"].values,
        stable=np.asarray(ds["stable"].values).astype(bool), residuals=np.asarray(ds["residual"].values, dtype=float),
        tangents=np.asarray(ds["tangent"].values, dtype=float), arclength=np.asarray(ds["arclength"].values,
                                                                                     dtype=float),
        status=str(a["status"]), bifurcations=bifs, period=int(a["period"]), system=str(a["system"]),
        state_names=tuple(json.loads(a["state_names"])), params=json.loads(a["params"]),
        settings=json.loads(a["settings"]), version=str(a["version"]))


def _design(ds):
    from ._params import params_from_dict
    from .design import DesignResult
    from .shooting import PeriodicOrbit

    a = ds.attrs
    names = [str(n) for n in ds["parameter"].values]
    hist = {}
    for k in json.loads(a["history_keys"]):
        if k == "objective":
            hist[k] = ds["objective"].values
        elif k in names:
            hist[k] = ds["parameter_value"].values[:, names.index(k)]
        else:
            hist[k] = ds[f"history_{k}"].values
    meta = json.loads(a["orbits"])
    orbits = {}
    for tag in ("orbit", "initial_orbit"):
        m = meta[tag]
        lam = ds[f"{tag}_multipliers_real"].values + 1j * ds[f"{tag}_multipliers_imag"].values
        orbits[tag] = PeriodicOrbit(points=ds[f"{tag}_points"].values, period=m["period"], multipliers=lam,
                                    stable=m["stable"], instability=m["instability"], residual=m["residual"],
                                    n_seeds=m["n_seeds"])
    return DesignResult(
        params=params_from_dict(str(a["params_type"]),
                                json.loads(a["params"])),
        orbit=orbits["orbit"], initial_orbit=orbits["initial_orbit"], history=hist,
        free={n: tuple(b) for n, b in json.loads(a["free"]).items()}, status=str(a["status"]),
        message=str(a["message"]), initial_params=json.loads(a["initial_params"]), system=str(a["system"]),
        state_names=tuple(str(s) for s in ds["state"].values), settings=json.loads(a["settings"]),
        version=str(a["version"]))


_READERS = {"GlobalResult": _global, "OrbitSearch": _orbits, "BifurcationDiagram": _bifurcation,
            "BasinSweep": _basins, "ParameterMap": _parameter_map, "Branch": _branch, "DesignResult": _design}


def load_legacy(ds, kind: str):
    """The result of type ``kind`` from a dataset in the jaxgear 0.1 layout."""
    if kind not in _READERS:
        raise ValueError(f"unknown jaxgear_type {kind!r}; known types: {', '.join(_READERS)}.")
    return _READERS[kind](ds)
