"""Differentiable periodic response and gradient-based design through the periodic orbit.

- :mod:`._objectives` — sampled orbits and the scalars to design for (mesh forces,
  transmission error, largest multiplier);
- :mod:`._design` — :func:`design` (optax, projection onto bounds) and :class:`DesignResult`.
"""

from ._design import DesignOptions, DesignResult, DesignSettings, DesignStatus, design
from ._objectives import (
    GearMesh,
    MeshForces,
    OrbitSamples,
    max_multiplier,
    mesh_force_ptp,
    mesh_force_rms,
    mesh_forces,
    peak_to_peak,
    rms,
    sample_orbit,
    transmission_error,
    transmission_error_rms,
)

__all__ = ["design", "DesignResult", "DesignOptions", "DesignSettings", "DesignStatus", "OrbitSamples", "sample_orbit", "MeshForces", "GearMesh", "mesh_forces",
           "transmission_error", "peak_to_peak", "rms", "max_multiplier", "mesh_force_ptp", "mesh_force_rms",
           "transmission_error_rms"]
