"""The compiled CPU kernel of the kink-aware RK4 for the reduced gear model (XLA FFI).

``native/gear_kernel.cc`` is the kink-aware step of :mod:`._kink` for the reduced 2-DOF
model of paper §4.1, written for the CPU (blocks of lanes kept in cache, time-only
terms tabulated once per stage time, the trial step vectorised, the few lanes with a
backlash crossing split one by one, blocks on every core). It is compiled with the
machine's C++ compiler on first use into ``$JAXGEAR_CACHE_DIR/native`` (default
``~/.cache/jaxgear/native``), registered as an XLA FFI target, and called inside
``jit`` like any other operation. The pure-JAX path stays the reference: it runs on
GPUs (:func:`jax.lax.platform_dependent`), it supplies the derivatives (a
``jax.custom_jvp``), and it takes over with one warning when no compiler is found or
``JAXGEAR_NATIVE=0`` is set. Both agree to round-off (``tests/test_native.py``).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._cache import native_dir

__all__ = ["native_available", "native_advance", "PARAM_ORDER", "pack_params", "library_path"]

PARAM_ORDER = ("N", "mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp",
               "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr", "b_sp", "b_rp",
               "c_sp", "c_rp", "f_D", "f_L", "Omega", "contact_ratio_sp", "contact_ratio_rp")
"""Order of the packed parameter row read by the kernel (its ``enum P``)."""

TARGET = "jaxgear_reduced_advance"
_SOURCE = Path(__file__).parent / "native" / "gear_kernel.cc"
_FLAGS = ("-O3", "-march=native", "-fopenmp", "-shared", "-fPIC", "-std=c++17", "-Wno-attributes",
          "-Wno-return-type")


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith(("model name", "flags")):
                    return line
    except OSError:
        pass
    return platform.processor() or platform.machine()


def library_path() -> Path:
    """Where the compiled kernel for this source, jax version, compiler flags and CPU lives."""
    key = hashlib.sha256(b"\0".join([_SOURCE.read_bytes(), jax.__version__.encode(), " ".join(_FLAGS).encode(),
                                     _cpu_model().encode()])).hexdigest()[:16]
    return native_dir() / f"gear_kernel-{key}.so"


def _compile(path: Path) -> None:
    cxx = os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++") or shutil.which("clang++")
    if cxx is None:
        raise RuntimeError("no C++ compiler found (set CXX, or install g++)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".gear_kernel-", suffix=".so", dir=path.parent)
    os.close(fd)
    cmd = [cxx, *_FLAGS, f"-I{jax.ffi.include_dir()}", str(_SOURCE), "-o", tmp]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        if proc.returncode != 0:
            raise RuntimeError(f"compiling the CPU kernel failed: {proc.stderr.strip()[-500:]}")
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


@functools.cache
def _load() -> bool:
    """Build (if needed), load and register the kernel once; False (and one warning) if that fails."""
    if os.environ.get("JAXGEAR_NATIVE", "1").lower() in ("0", "off", "false", "no"):
        return False
    try:
        path = library_path()
        if not path.exists():
            _compile(path)
        lib = ctypes.cdll.LoadLibrary(str(path))
        jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(lib.JaxgearReducedAdvance), platform="cpu")
        return True
    except Exception as exc:  # no compiler, a read-only cache, an incompatible toolchain
        warnings.warn(f"jaxgear: the compiled CPU kernel is not available ({exc}); using the pure-JAX integrator "
                      "(slower on CPUs, same results).", RuntimeWarning, stacklevel=3)
        return False


def native_available() -> bool:
    """True when the compiled CPU kernel is built and registered (it is built on first call)."""
    return _load()


def pack_params(params) -> jax.Array:
    """The reduced model's parameters as one row ``(24,)`` in :data:`PARAM_ORDER` (identical
    planets: per-planet fields must hold one value)."""
    cols = []
    for name in PARAM_ORDER:
        v = jnp.asarray(params.N if name == "N" else getattr(params, name), jnp.float64)
        cols.append(v if v.ndim == 0 else v.reshape(-1)[0])
    return jnp.stack(cols)


def _shape_code(params) -> int:
    return {"sine": 0, "rectangular": 1}[params.mesh_shape]


def native_advance(integrator, system, params, Y, t0, periods: int, n_active=None, rows=None):
    """``integrator.advance`` through the compiled kernel on CPUs (the pure-JAX steps on other
    platforms, for derivatives, and when the kernel is unavailable). With ``rows (n,)``:
    ``integrator.advance_rows`` (``params`` holds ``V`` stacked rows, lane j uses row
    ``rows[j]``)."""
    from ._base import AbstractFixedStep, AbstractIntegrator

    def jax_path(Y, t0, params, active=None, rows=None):
        if rows is None:
            return AbstractFixedStep.advance(integrator, system, params, Y, t0, periods)
        return AbstractIntegrator.advance_rows(integrator, system, params, rows, Y, t0, periods)

    if not _load() or Y.ndim != 2 or Y.shape[0] != 4 or system.native != "reduced":
        return jax_path(Y, t0, params, None, rows)
    active = jnp.asarray(Y.shape[1] if n_active is None else n_active, jnp.int32)
    steps, max_splits, shape = int(integrator.steps_per_period), int(integrator.max_splits), _shape_code(params)
    if rows is None:
        rows = jnp.zeros((Y.shape[1],), jnp.int32)
        packed = lambda params: pack_params(params)[None]  # noqa: E731
        jax_rows = lambda Y, t0, params, active, rows: jax_path(Y, t0, params)  # noqa: E731
    else:
        rows = jnp.asarray(rows, jnp.int32)
        packed = jax.vmap(pack_params)
        jax_rows = jax_path

    def cpu_path(Y, t0, params, active, rows):
        call = jax.ffi.ffi_call(TARGET, jax.ShapeDtypeStruct(Y.shape, Y.dtype), vmap_method="broadcast_all")
        return call(Y, packed(params), rows, jnp.reshape(jnp.asarray(t0, jnp.float64), (1,)),
                    jnp.reshape(active, (1,)), periods=np.int64(periods), steps=np.int64(steps),
                    max_splits=np.int64(max_splits), shape=np.int64(shape))

    @jax.custom_jvp
    def advance(Y, t0, params, active, rows):
        if jax.default_backend() == "cpu":  # CPU devices only: the pure-JAX steps need not be traced
            return cpu_path(Y, t0, params, active, rows)
        return jax.lax.platform_dependent(Y, t0, params, active, rows, cpu=cpu_path, default=jax_rows)

    @advance.defjvp
    def advance_jvp(primals, tangents):  # derivatives from the pure-JAX steps (the reference)
        rows = primals[4]
        return jax.jvp(lambda Y, t0, params: jax_rows(Y, t0, params, None, rows), primals[:3], tangents[:3])

    return advance(Y, jnp.asarray(t0, jnp.float64), params, active, rows)
