"""jaxgear: global analysis of nonlinear planetary gear trains in JAX.

Every coexisting periodic motion of a forced gear model and the share of the state
space each attracts, by Poincaré-like cell mapping, Hsu's simple cell mapping and
direct integration, with shooting/Floquet for exact orbits (the method of
"Global Analysis of a Planetary Gear Train"). Float64 is enabled on import.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._system import ForcedSystem as ForcedSystem, check_system as check_system
from ._params import (
    GearParams as GearParams,
    GearSet as GearSet,
    PARAM_NAMES as PARAM_NAMES,
    paper_gear_set as paper_gear_set,
    get_preset as get_preset,
    resolve_params as resolve_params,
)
from ._model import (
    REDUCED as REDUCED,
    backlash as backlash,
    nplanet_system as nplanet_system,
    reduced_vector_field as reduced_vector_field,
    nplanet_vector_field as nplanet_vector_field,
    reduced_to_nplanet as reduced_to_nplanet,
)
from ._integrate import RK4 as RK4, Adaptive as Adaptive, advance as advance
from ._poincare import (
    stroboscopic_map as stroboscopic_map,
    stroboscopic_orbit as stroboscopic_orbit,
    section_map as section_map,
    SectionHit as SectionHit,
    sample_trajectory as sample_trajectory,
    STATUS_OK as STATUS_OK,
    STATUS_DIVERGED as STATUS_DIVERGED,
    STATUS_NO_CROSSING as STATUS_NO_CROSSING,
)

__version__ = "0.1.0"


def paper_params(**overrides) -> GearParams:
    """Dimensionless parameters of the ``paper`` preset (MODEL.md §4, §7).

    ``overrides`` may name physical fields of :class:`GearSet` or canonical
    dimensionless names (see :func:`resolve_params`).
    """
    return resolve_params("paper", overrides)[1]


from ._examples import (  # noqa: E402
    DUFFING as DUFFING,
    DuffingParams as DuffingParams,
    SPUR_PAIR as SPUR_PAIR,
    SpurPairParams as SpurPairParams,
    PARAM_DUFFING as PARAM_DUFFING,
    ParamDuffingParams as ParamDuffingParams,
)

from ._cells import CellGrid as CellGrid, PAPER_REGION as PAPER_REGION  # noqa: E402
from ._result import (  # noqa: E402
    Attractor as Attractor,
    GlobalResult as GlobalResult,
    load_result as load_result,
    SINK as SINK,
    UNRESOLVED as UNRESOLVED,
)
from ._cellmap import (  # noqa: E402
    analyze_global as analyze_global,
    analyze_cell_map as analyze_cell_map,
    cell_images as cell_images,
    detect_period as detect_period,
    compare_with_direct as compare_with_direct,
)

from ._shooting import (  # noqa: E402
    periodic_orbit as periodic_orbit,
    find_periodic_orbits as find_periodic_orbits,
    verify_orbit as verify_orbit,
    monodromy as monodromy,
    floquet_multipliers as floquet_multipliers,
    seeds_from_result as seeds_from_result,
    seeds_in_box as seeds_in_box,
    ShootResult as ShootResult,
    PeriodicOrbit as PeriodicOrbit,
    OrbitSearch as OrbitSearch,
    OrbitCheck as OrbitCheck,
    load_orbits as load_orbits,
)

from ._params import with_param as with_param, get_param as get_param, param_names as param_names  # noqa: E402
from ._continuation import (  # noqa: E402
    continue_orbit as continue_orbit,
    switch_branch as switch_branch,
    Branch as Branch,
    BifurcationPoint as BifurcationPoint,
    load_branch as load_branch,
)
from ._io import load as load  # noqa: E402
from ._design import (  # noqa: E402
    design as design,
    replace_params as replace_params,
    DesignResult as DesignResult,
    load_design as load_design,
    OrbitSamples as OrbitSamples,
    sample_orbit as sample_orbit,
    MeshForces as MeshForces,
    mesh_forces as mesh_forces,
    transmission_error as transmission_error,
    peak_to_peak as peak_to_peak,
    rms as rms,
    max_multiplier as max_multiplier,
    mesh_force_ptp as mesh_force_ptp,
    mesh_force_rms as mesh_force_rms,
    transmission_error_rms as transmission_error_rms,
)

from ._sweep import (  # noqa: E402
    bifurcation_diagram as bifurcation_diagram,
    basin_sweep as basin_sweep,
    parameter_map as parameter_map,
    BifurcationDiagram as BifurcationDiagram,
    BasinSweep as BasinSweep,
    ParameterMap as ParameterMap,
    load_bifurcation as load_bifurcation,
    load_basin_sweep as load_basin_sweep,
    load_parameter_map as load_parameter_map,
)


def __getattr__(name):
    # ``jaxgear.plotting`` is imported on first use (keeps matplotlib out of import time).
    if name == "plotting":
        import importlib

        return importlib.import_module(".plotting", __name__)
    raise AttributeError(f"module 'jaxgear' has no attribute {name!r}")
