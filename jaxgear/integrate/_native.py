"""The compiled CPU kernel of the kink-aware RK4 for the reduced gear model (XLA FFI).

``native/gear_kernel.cc`` is the kink-aware step of :mod:`._kink` for the reduced 2-DOF
model of paper §4.1, written for the CPU (blocks of lanes kept in cache; time-only terms
tabulated once per stage time and kept for the next calls with the same parameters, the
last 64 rows, since a call on a few lanes is mostly that tabulation; the trial step
vectorised; the few lanes with a backlash crossing gathered and split together, eight at a
time; blocks on every core). It is compiled with the
machine's C++ compiler on first use, registered as an XLA FFI target, and called inside
``jit`` like any other operation. The pure-JAX path stays the reference: it runs on
GPUs (:func:`jax.lax.platform_dependent`), it supplies the derivatives (a
``jax.custom_jvp``), and it takes over with one warning when no compiler is found or
``JAXGEAR_NATIVE=0`` is set. Both agree to round-off (``tests/test_native.py``).

A shared library runs code as soon as it is loaded, so the kernel is only ever loaded
from a folder private to the user, :func:`jaxgear._cache.native_dir` (default
``~/.cache/jaxgear/native``, created ``0700``; never under ``$JAXGEAR_CACHE_DIR``, which
the processes of a run may share). Before every load the folder and the files must
belong to the user (or root) and be writable by nobody else, and the library must match
the SHA-256 recorded beside it when it was built (``gear_kernel-<key>.so.sha256``): a
folder or file writable by others is refused with one warning; a missing, damaged or
replaced library is built again (once; then the pure-JAX path, with one warning). The
kernel is built once per user and machine (the file name holds a hash of the source,
the jax version, the flags and the CPU), whatever the cache folder.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import hashlib
import os
import platform
import shutil
import stat
import subprocess
import tempfile
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._cache import native_dir
from .._system import NativeKernel

__all__ = ["native_available", "native_advance", "PARAM_ORDER", "pack_params", "library_path"]

PARAM_ORDER = ("N", "mu_s", "mu_p", "mu_c", "kappa_sp_mean", "kappa_sp_amp", "kappa_rp_mean", "kappa_rp_amp",
               "phi_sp", "phi_rp", "e_sp_amp", "e_rp_amp", "beta_sp", "beta_rp", "gamma_sr", "b_sp", "b_rp",
               "c_sp", "c_rp", "f_D", "f_L", "Omega", "contact_ratio_sp", "contact_ratio_rp")
"""Order of the packed parameter row read by the kernel (its ``enum P``)."""

TARGET = "jaxgear_reduced_advance"
_SOURCE = Path(__file__).parent / "native" / "gear_kernel.cc"
_FLAGS = ("-O3", "-march=native", "-fopenmp", "-shared", "-fPIC", "-std=c++17", "-Wno-attributes",
          "-Wno-return-type")
_RECORD = ".sha256"  # suffix of the file holding the SHA-256 of the library, written when it is built


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
    """Where the compiled kernel for this source, jax version, compiler flags and CPU lives
    (in :func:`jaxgear._cache.native_dir`, the user's private kernel folder)."""
    key = hashlib.sha256(b"\0".join([_SOURCE.read_bytes(), jax.__version__.encode(), " ".join(_FLAGS).encode(),
                                     _cpu_model().encode()])).hexdigest()[:16]
    return native_dir() / f"gear_kernel-{key}.so"


def _record_path(path: Path) -> Path:
    return path.with_name(path.name + _RECORD)


class _Refused(Exception):
    """A kernel folder or file that others could have written: nothing is loaded from it."""


def _trusted_owners() -> set[int]:
    return {os.geteuid(), 0} if hasattr(os, "geteuid") else set()


def _check_private(path: Path, what: str, st: os.stat_result) -> None:
    """Refuse ``path`` unless it belongs to this user (or root) and nobody else can write it."""
    owners = _trusted_owners()
    if owners and st.st_uid not in owners:
        raise _Refused(f"the kernel {what} {path} belongs to another user (uid {st.st_uid}); nothing is loaded "
                       f"from it")
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        fix = f"chmod 700 {path} and delete the files in it" if what == "folder" else f"delete {path}"
        raise _Refused(f"the kernel {what} {path} is writable by other users (mode {stat.S_IMODE(st.st_mode):04o}); "
                       f"nothing is loaded from it ({fix})")


def _private_folder(folder: Path) -> None:
    """Create ``folder`` (mode 0700) if it is missing; refuse it if others can write it."""
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    st = os.stat(folder)
    if not stat.S_ISDIR(st.st_mode):
        raise _Refused(f"the kernel folder {folder} is not a folder")
    _check_private(folder, "folder", st)


def _private_file(path: Path) -> bool:
    """Whether ``path`` exists as a regular file (not a link) of this user that others cannot write;
    refuses one that others could have written."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return False
    if not stat.S_ISREG(st.st_mode):
        raise _Refused(f"the kernel file {path} is not a regular file")
    _check_private(path, "file", st)
    return True


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _recorded(path: Path) -> str:
    return _record_path(path).read_bytes()[:200].decode("ascii", "replace").strip()


def _verified(path: Path) -> bool | None:
    """``True`` when ``path`` and its record are private and the library matches the record;
    ``False`` when either is missing; ``None`` when the library does not match (damaged or replaced)."""
    if not (_private_file(path) and _private_file(_record_path(path))):
        return False
    return True if _recorded(path) == _sha256(path) else None


@contextlib.contextmanager
def _locked(folder: Path):
    """Hold an exclusive lock on ``folder/.lock`` (processes building the same kernel wait for the first)."""
    try:
        import fcntl
    except ImportError:  # no POSIX locks: concurrent builds each replace the files whole
        yield
        return
    fd = os.open(folder / ".lock", os.O_RDWR | os.O_CREAT, 0o600)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # a file system without locks: as above
            pass
        yield
    finally:
        os.close(fd)  # releases the lock


def _compile(path: Path) -> None:
    """Compile the kernel into ``path`` and record its SHA-256 beside it (both replaced whole)."""
    cxx = os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++") or shutil.which("clang++")
    if cxx is None:
        raise RuntimeError("no C++ compiler found (set CXX, or install g++)")
    fd, tmp = tempfile.mkstemp(prefix=".gear_kernel-", suffix=".so", dir=path.parent)
    os.close(fd)
    fd, tmp_record = tempfile.mkstemp(prefix=".gear_kernel-", suffix=_RECORD, dir=path.parent)
    os.close(fd)
    cmd = [cxx, *_FLAGS, f"-I{jax.ffi.include_dir()}", str(_SOURCE), "-o", tmp]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if proc.returncode != 0:
            raise RuntimeError(f"compiling the CPU kernel failed: {proc.stderr.strip()[-500:]}")
        os.chmod(tmp, 0o644)  # the linker's mode follows the umask, which may let others write
        Path(tmp_record).write_text(_sha256(Path(tmp)) + "\n")
        os.chmod(tmp_record, 0o644)
        os.replace(tmp, path)
        os.replace(tmp_record, _record_path(path))
    finally:
        Path(tmp).unlink(missing_ok=True)
        Path(tmp_record).unlink(missing_ok=True)


def _build_if_needed(path: Path, rebuild: bool = False) -> None:
    """Make ``path`` a verified kernel: build it when it is missing, damaged, replaced or ``rebuild``."""
    _private_folder(path.parent)
    state = None if rebuild else _verified(path)
    if state:
        return
    with _locked(path.parent):
        state = None if rebuild else _verified(path)  # another process may have built it meanwhile
        if state:
            return
        if state is None and not rebuild:
            warnings.warn(f"jaxgear: the compiled CPU kernel {path} does not match the SHA-256 recorded when it "
                          "was built (damaged or replaced); building it again.", RuntimeWarning, stacklevel=4)
        _compile(path)
    if not _verified(path):
        raise RuntimeError(f"the kernel built into {path} does not match its record")


class _Changed(Exception):
    """The library changed between its check and its load."""


def _open(path: Path) -> None:
    """Load and register the library at ``path``: the open file is checked (owner, mode) and
    hashed, and that same file is loaded (through ``/proc/self/fd``), so nothing swapped in
    after the check is ever loaded."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _Refused(f"the kernel file {path} is not a regular file")
        _check_private(path, "file", st)
        digest = hashlib.sha256()
        while chunk := os.read(fd, 1 << 20):
            digest.update(chunk)
        if digest.hexdigest() != _recorded(path):
            raise _Changed(f"{path} changed after it was checked")
        proc = f"/proc/self/fd/{fd}"
        lib = ctypes.CDLL(proc if os.path.exists(proc) else str(path))
    finally:
        os.close(fd)
    jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(lib.JaxgearReducedAdvance), platform="cpu")


@functools.cache
def _state() -> tuple[bool, str | None]:
    """Build (if needed), verify, load and register the kernel once: ``(True, None)``, or
    ``(False, why)`` after one warning (``why`` is ``None`` when ``JAXGEAR_NATIVE=0``)."""
    if os.environ.get("JAXGEAR_NATIVE", "1").lower() in ("0", "off", "false", "no"):
        return False, None
    try:
        path = library_path()
        _build_if_needed(path)
        try:
            _open(path)
        except (OSError, _Changed):  # not loadable (another toolchain's build) or changed: build it again, once
            _build_if_needed(path, rebuild=True)
            _open(path)
        return True, None
    except Exception as exc:  # a refused folder, no compiler, a compile error, an unwritable home
        why = str(exc)
        warnings.warn(f"jaxgear: the compiled CPU kernel is not available ({why}); using the pure-JAX integrator "
                      "(slower on CPUs, same results).", RuntimeWarning, stacklevel=4)
        return False, why


def _load() -> bool:
    """Whether the compiled kernel is loaded (building, verifying and loading it on the first call)."""
    return _state()[0]


def native_available() -> bool:
    """True when the compiled CPU kernel is built and registered (it is built on first call)."""
    return _load()


def native_unavailable_reason() -> str | None:
    """Why the compiled kernel is not loaded (the compiler's error, a refused folder), or ``None``
    when it is loaded or ``JAXGEAR_NATIVE=0`` turned it off."""
    return _state()[1]


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

    if not _load() or Y.ndim != 2 or Y.shape[0] != 4 or system.native is not NativeKernel.REDUCED:
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
