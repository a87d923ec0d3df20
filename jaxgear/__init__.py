"""jaxgear: global analysis of nonlinear planetary gear trains in JAX.

Every coexisting periodic motion of a forced gear model and the share of the state
space each attracts, by direct integration, the paper's Poincaré-like cell mapping and
Hsu's simple cell mapping, with shooting/Floquet for exact orbits (the method of
"Global Analysis of a Planetary Gear Train"). Float64 is enabled on import.

The package is a picture of the method: systems and parameters (``_system``,
``_model``, ``_params``, ``_gearset``, ``_presets``), integration (``integrate``),
Poincaré maps (``_poincare``), the cell space (``_cells``), global analysis
(``analysis``), shooting (``shooting``), continuation (``continuation``), sweeps
(``sweep``), design (``design``), saving (``_codec``, ``_io``), plotting (``plotting``)
and the command line (``cli``). Every public name is re-exported here.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._version import __version__ as __version__
from ._status import Status as Status
from ._system import ForcedSystem as ForcedSystem, check_system as check_system
from ._params import (
    GearParams as GearParams,
    PARAM_NAMES as PARAM_NAMES,
    PARAM_ALIASES as PARAM_ALIASES,
    with_param as with_param,
    get_param as get_param,
    param_names as param_names,
    replace_params as replace_params,
)
from ._gearset import GearSet as GearSet
from ._presets import (
    paper_gear_set as paper_gear_set,
    paper_params as paper_params,
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
from ._examples import (
    DUFFING as DUFFING,
    DuffingParams as DuffingParams,
    SPUR_PAIR as SPUR_PAIR,
    SpurPairParams as SpurPairParams,
    PARAM_DUFFING as PARAM_DUFFING,
    ParamDuffingParams as ParamDuffingParams,
    VAN_DER_POL as VAN_DER_POL,
    VanDerPolParams as VanDerPolParams,
)
from .integrate import (
    AbstractIntegrator as AbstractIntegrator,
    KinkAwareRK4 as KinkAwareRK4,
    RK4 as RK4,
    Adaptive as Adaptive,
    default_integrator as default_integrator,
)
from ._poincare import (
    stroboscopic_map as stroboscopic_map,
    stroboscopic_orbit as stroboscopic_orbit,
    section_map as section_map,
    SectionHit as SectionHit,
    sample_trajectory as sample_trajectory,
)
from ._cells import CellGrid as CellGrid, PAPER_REGION as PAPER_REGION
from ._lyapunov import (
    AttractorType as AttractorType,
    LyapunovSpectrum as LyapunovSpectrum,
    LyapunovOptions as LyapunovOptions,
    lyapunov_spectrum as lyapunov_spectrum,
    classify_attractor as classify_attractor,
    type_reason as type_reason,
    kaplan_yorke as kaplan_yorke,
    ensemble_spectrum as ensemble_spectrum,
)
from .analysis import (
    AbstractGlobalMethod as AbstractGlobalMethod,
    Direct as Direct,
    PoincareCellMap as PoincareCellMap,
    StroboscopicCellMap as StroboscopicCellMap,
    analyze_global as analyze_global,
    default_method as default_method,
    analyze_cell_map as analyze_cell_map,
    cell_images as cell_images,
    compare_with_direct as compare_with_direct,
    label_uncertainty as label_uncertainty,
    with_label_uncertainty as with_label_uncertainty,
    detect_period as detect_period,
    Attractor as Attractor,
    ChaoticSaddle as ChaoticSaddle,
    GlobalResult as GlobalResult,
    SINK as SINK,
    UNRESOLVED as UNRESOLVED,
    RecurrenceOptions as RecurrenceOptions,
    PoolOptions as PoolOptions,
    basin_entropy as basin_entropy,
    BasinEntropy as BasinEntropy,
    uncertainty_exponent as uncertainty_exponent,
    UncertaintyExponent as UncertaintyExponent,
    uncertain_fraction as uncertain_fraction,
    scaling_range as scaling_range,
    ScalingRange as ScalingRange,
)
from .shooting import (
    periodic_orbit as periodic_orbit,
    find_periodic_orbits as find_periodic_orbits,
    verify_orbit as verify_orbit,
    monodromy as monodromy,
    floquet_multipliers as floquet_multipliers,
    seeds_from_result as seeds_from_result,
    seeds_in_box as seeds_in_box,
    Instability as Instability,
    ShootResult as ShootResult,
    ShootOptions as ShootOptions,
    SearchOptions as SearchOptions,
    VerifyOptions as VerifyOptions,
    PeriodicOrbit as PeriodicOrbit,
    OrbitSearch as OrbitSearch,
    SearchSettings as SearchSettings,
    PeriodConvergence as PeriodConvergence,
    OrbitVerification as OrbitVerification,
    OrbitCheck as OrbitCheck,
)
from .continuation import (
    continue_orbit as continue_orbit,
    switch_branch as switch_branch,
    ContinuationOptions as ContinuationOptions,
    Branch as Branch,
    BifurcationPoint as BifurcationPoint,
    BifurcationKind as BifurcationKind,
    BranchStatus as BranchStatus,
)
from .sweep import (
    bifurcation_diagram as bifurcation_diagram,
    basin_sweep as basin_sweep,
    basin_map as basin_map,
    parameter_map as parameter_map,
    Runner as Runner,
    SequenceOptions as SequenceOptions,
    BasinOptions as BasinOptions,
    BifurcationDiagram as BifurcationDiagram,
    BasinSweep as BasinSweep,
    BasinMap as BasinMap,
    ParameterMap as ParameterMap,
    SweepDirection as SweepDirection,
    MapQuantity as MapQuantity,
    SweepAxis as SweepAxis,
    sweep_axis as sweep_axis,
)
from .design import (
    design as design,
    DesignResult as DesignResult,
    DesignOptions as DesignOptions,
    DesignSettings as DesignSettings,
    DesignStatus as DesignStatus,
    OrbitSamples as OrbitSamples,
    sample_orbit as sample_orbit,
    MeshForces as MeshForces,
    GearMesh as GearMesh,
    mesh_forces as mesh_forces,
    transmission_error as transmission_error,
    peak_to_peak as peak_to_peak,
    rms as rms,
    max_multiplier as max_multiplier,
    mesh_force_ptp as mesh_force_ptp,
    mesh_force_rms as mesh_force_rms,
    transmission_error_rms as transmission_error_rms,
)
from ._contact import (
    gear_view as gear_view,
    gear_views as gear_views,
    regime_shares as regime_shares,
    RegimeShares as RegimeShares,
    RegimeMap as RegimeMap,
    GearView as GearView,
    MeshView as MeshView,
    ContactRegime as ContactRegime,
    MeshSpec as MeshSpec,
    GearViewOptions as GearViewOptions,
)
from ._io import load as load
from ._cache import enable_compilation_cache as enable_compilation_cache


def __getattr__(name):
    # ``jaxgear.plotting`` is imported on first use (keeps matplotlib out of import time).
    if name == "plotting":
        import importlib

        return importlib.import_module(".plotting", __name__)
    raise AttributeError(f"module 'jaxgear' has no attribute {name!r}")
