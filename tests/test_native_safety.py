"""Nothing executable is loaded from a folder another user could write, and a damaged
compiled kernel is built again.

A shared library runs its constructors when it is loaded, so each test plants a library
whose constructor (``__attribute__((constructor))``) writes a marker file, in a place an
attacker or a fault could reach, and runs the kernel's loader in a fresh process: the
marker must not appear, and the process must have mapped the verified kernel (read from
``/proc/self/maps``, not taken from the loader's word) or have said in one line why not.
The rebuilds use a stand-in compiler that copies the kernel this installation built
(fast); the real compiler's rebuild and the command line run under ``-m slow``.
"""

import hashlib
import json
import os
import shutil
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from jaxgear.integrate import _native

ROOT = Path(__file__).resolve().parents[1]
CC = shutil.which("gcc") or shutil.which("cc") or shutil.which("g++")

pytestmark = [
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/maps"),
    pytest.mark.skipif(CC is None or shutil.which("g++") is None, reason="no C/C++ compiler"),
    pytest.mark.skipif(os.environ.get("JAXGEAR_NATIVE", "1").lower() in ("0", "off", "false", "no"),
                       reason="JAXGEAR_NATIVE=0 turns the compiled kernel off"),
]

PROBE = textwrap.dedent("""
    import json, sys, warnings
    warnings.simplefilter("always")
    caught = []
    warnings.showwarning = lambda message, *a, **k: caught.append(str(message)) if "kernel" in str(message) else None
    {before}
    from jaxgear.integrate import _native
    ok = _native.native_available()
    {after}
    with open("/proc/self/maps") as fh:
        mapped = sorted({{line.split(None, 5)[-1].strip() for line in fh if ".so" in line}})
    print("PROBE" + json.dumps({{"ok": ok, "path": str(_native.library_path()), "warnings": caught,
                                "mapped": [m for m in mapped if "gear_kernel" in m or "planted" in m]}}))
""")


@pytest.fixture(scope="module")
def kernel() -> Path:
    """The kernel this installation built and verified (built once per user and machine)."""
    assert _native.native_available(), _native.native_unavailable_reason()
    return _native.library_path()


def probe(env_extra, tmp_path, before="", after="") -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("JAXGEAR_NATIVE", None)
    env.update(env_extra)
    r = subprocess.run([sys.executable, "-c", PROBE.format(before=before, after=after)], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("PROBE")]
    assert line, r.stdout[-2000:] + r.stderr[-2000:]
    return dict(json.loads(line[-1][len("PROBE"):]), stderr=r.stderr)


def planted_library(tmp_path: Path, marker: Path) -> Path:
    """A shared library whose constructor writes ``marker`` (and that exports the kernel's symbol)."""
    src = tmp_path / "planted.c"
    src.write_text(textwrap.dedent(f"""
        #include <stdio.h>
        __attribute__((constructor)) static void planted(void) {{
            FILE *f = fopen("{marker}", "a");
            if (f) {{ fputs("ran\\n", f); fclose(f); }}
        }}
        void *JaxgearReducedAdvance(void) {{ return 0; }}
    """))
    lib = tmp_path / "planted.so"
    subprocess.run([CC, "-shared", "-fPIC", str(src), "-o", str(lib)], check=True, capture_output=True, timeout=120)
    return lib


def plant(lib: Path, dest: Path, record: bool = True) -> None:
    """Copy ``lib`` to ``dest``, with a record of its SHA-256 beside it when ``record`` (a forged one)."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(lib, dest)
    if record:
        Path(str(dest) + ".sha256").write_text(hashlib.sha256(lib.read_bytes()).hexdigest() + "\n")


def copying_compiler(tmp_path: Path, good: Path) -> tuple[Path, Path]:
    """A stand-in for the C++ compiler: writes ``good`` to the ``-o`` file and logs each call."""
    log = tmp_path / "compiler.log"
    cxx = tmp_path / "fake-cxx"
    cxx.write_text(textwrap.dedent(f"""\
        #!{sys.executable}
        import shutil, sys
        with open({str(log)!r}, "a") as fh:
            fh.write("called\\n")
        shutil.copyfile({str(good)!r}, sys.argv[sys.argv.index("-o") + 1])
    """))
    cxx.chmod(0o755)
    return cxx, log


def calls(log: Path) -> int:
    return len(log.read_text().splitlines()) if log.exists() else 0


def private_copy(kernel: Path, xdg: Path) -> Path:
    """The verified kernel and its record copied into the private kernel folder under ``xdg``."""
    folder = xdg / "jaxgear" / "native"
    folder.mkdir(parents=True)
    folder.chmod(0o700)
    for src in (kernel, Path(str(kernel) + ".sha256")):
        shutil.copyfile(src, folder / src.name)
    return folder / kernel.name


def test_a_library_planted_in_the_cache_folder_is_never_loaded(kernel, tmp_path):
    """Every place under ``$JAXGEAR_CACHE_DIR`` where a kernel was (or could be) looked for
    holds a planted library with a matching forged record: the process loads the user's
    verified kernel, never the planted one."""
    marker = tmp_path / "marker"
    lib = planted_library(tmp_path, marker)
    cache = tmp_path / "cache"
    for dest in (cache / "native" / kernel.name, cache / kernel.name, cache / "jaxgear" / "native" / kernel.name,
                 cache / "native" / "gear_kernel.so", cache / "kept" / kernel.name, cache / "xla" / kernel.name):
        plant(lib, dest)
    out = probe({"JAXGEAR_CACHE_DIR": str(cache)}, tmp_path)
    assert not marker.exists(), "the planted library's constructor ran"
    assert out["ok"], out["warnings"]
    assert out["path"] == str(kernel)  # the kernel folder does not follow JAXGEAR_CACHE_DIR
    assert out["mapped"] == [str(kernel)], out["mapped"]
    assert out["warnings"] == []


@pytest.mark.parametrize("which", ["folder", "library", "record"])
def test_a_kernel_folder_or_file_writable_by_others_is_refused(kernel, tmp_path, which):
    """A planted library with a matching record in the private kernel folder, where the
    folder or one of the two files is writable by others: refused with one line naming the
    path and the mode, nothing loaded, nothing built (the pure-JAX path runs)."""
    marker = tmp_path / "marker"
    lib = planted_library(tmp_path, marker)
    xdg = tmp_path / "xdg"
    path = private_copy(kernel, xdg)
    plant(lib, path)
    target = {"folder": path.parent, "library": path, "record": Path(str(path) + ".sha256")}[which]
    target.chmod(stat.S_IMODE(target.stat().st_mode) | 0o022)
    cxx, log = copying_compiler(tmp_path, kernel)
    out = probe({"XDG_CACHE_HOME": str(xdg), "CXX": str(cxx)}, tmp_path)
    assert not marker.exists(), "the planted library's constructor ran"
    assert not out["ok"] and out["mapped"] == []
    assert len(out["warnings"]) == 1 and "writable by other users" in out["warnings"][0], out["warnings"]
    assert str(target) in out["warnings"][0] and "pure-JAX" in out["warnings"][0]
    assert calls(log) == 0


@pytest.mark.parametrize("damage", ["garbage", "replaced"])
def test_a_damaged_kernel_is_built_again_and_the_next_run_loads_it(kernel, tmp_path, damage):
    """The kernel file overwritten with garbage, or replaced by another library
    (the record untouched): the next process sees the mismatch, says so in one line, builds
    the kernel again and loads it; the process after that loads it without building."""
    marker = tmp_path / "marker"
    xdg = tmp_path / "xdg"
    path = private_copy(kernel, xdg)
    good = kernel.read_bytes()
    if damage == "garbage":  # (a truncated file: the real compiler's test below)
        path.write_bytes(os.urandom(len(good)))
    else:
        shutil.copyfile(planted_library(tmp_path, marker), path)
    cxx, log = copying_compiler(tmp_path, kernel)
    env = {"XDG_CACHE_HOME": str(xdg), "CXX": str(cxx)}

    first = probe(env, tmp_path)
    assert not marker.exists(), "the replaced library's constructor ran"
    assert first["ok"] and first["mapped"] == [str(path)], first
    assert len(first["warnings"]) == 1 and "does not match the SHA-256" in first["warnings"][0], first["warnings"]
    assert calls(log) == 1
    assert path.read_bytes() == good

    second = probe(env, tmp_path)
    assert second["ok"] and second["mapped"] == [str(path)] and second["warnings"] == []
    assert calls(log) == 1


def test_a_damaged_kernel_without_a_compiler_is_refused_with_one_line(kernel, tmp_path):
    """A replaced kernel and a compiler that fails: nothing loaded, one line that says the
    kernel is unavailable and why, the pure-JAX path."""
    marker = tmp_path / "marker"
    xdg = tmp_path / "xdg"
    path = private_copy(kernel, xdg)
    shutil.copyfile(planted_library(tmp_path, marker), path)
    out = probe({"XDG_CACHE_HOME": str(xdg), "CXX": shutil.which("false") or "/bin/false"}, tmp_path)
    assert not marker.exists(), "the replaced library's constructor ran"
    assert not out["ok"] and out["mapped"] == []
    assert len(out["warnings"]) == 2, out["warnings"]  # the mismatch, then the fallback
    assert "does not match the SHA-256" in out["warnings"][0]
    assert "compiling the CPU kernel failed" in out["warnings"][1] and "pure-JAX" in out["warnings"][1]


def test_a_new_kernel_folder_is_private_and_the_built_files_are_not_writable_by_others(kernel, tmp_path):
    """A first build creates the folder with mode 0700, even under a permissive umask, and
    leaves library and record writable by their owner only."""
    xdg = tmp_path / "xdg"
    cxx, log = copying_compiler(tmp_path, kernel)
    out = probe({"XDG_CACHE_HOME": str(xdg), "CXX": str(cxx)}, tmp_path, before="import os; os.umask(0)")
    path = xdg / "jaxgear" / "native" / kernel.name
    assert out["ok"] and out["mapped"] == [str(path)] and calls(log) == 1
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    for f in (path, Path(str(path) + ".sha256")):
        assert stat.S_IMODE(f.stat().st_mode) & 0o022 == 0, f
    assert Path(str(path) + ".sha256").read_text().strip() == hashlib.sha256(kernel.read_bytes()).hexdigest()


def test_jaxgear_native_0_loads_and_builds_nothing(kernel, tmp_path):
    xdg = tmp_path / "xdg"
    cxx, log = copying_compiler(tmp_path, kernel)
    out = probe({"XDG_CACHE_HOME": str(xdg), "CXX": str(cxx), "JAXGEAR_NATIVE": "0"}, tmp_path)
    assert not out["ok"] and out["mapped"] == [] and out["warnings"] == [] and calls(log) == 0
    assert not xdg.exists()


def test_without_a_compiler_the_pure_jax_path_runs_and_says_so_once(kernel, tmp_path):
    empty = tmp_path / "bin"
    empty.mkdir()
    xdg = tmp_path / "xdg"
    env = {"XDG_CACHE_HOME": str(xdg), "PATH": str(empty), "CXX": ""}
    out = probe(env, tmp_path, after="ok = _native.native_available() or _native.native_available()")
    assert not out["ok"] and out["mapped"] == []
    assert len(out["warnings"]) == 1, out["warnings"]
    assert "no C++ compiler found" in out["warnings"][0] and "pure-JAX" in out["warnings"][0]


@pytest.mark.slow
def test_a_truncated_kernel_is_rebuilt_by_the_compiler(kernel, tmp_path):
    """As above with the machine's real compiler: the rebuilt kernel loads, and the next
    process loads it without building (its file is not replaced)."""
    xdg = tmp_path / "xdg"
    path = private_copy(kernel, xdg)
    path.write_bytes(kernel.read_bytes()[:4096])
    first = probe({"XDG_CACHE_HOME": str(xdg)}, tmp_path)
    assert first["ok"] and first["mapped"] == [str(path)], first
    built = path.stat()
    second = probe({"XDG_CACHE_HOME": str(xdg)}, tmp_path)
    assert second["ok"] and second["mapped"] == [str(path)] and second["warnings"] == []
    assert (path.stat().st_ino, path.stat().st_mtime_ns) == (built.st_ino, built.st_mtime_ns)


@pytest.mark.slow
def test_jaxgear_analyze_with_a_planted_cache_folder_runs_the_verified_kernel(kernel, tmp_path):
    """``jaxgear analyze`` with ``JAXGEAR_CACHE_DIR`` pointing at a folder full of planted
    libraries: the analysis runs with the compiled kernel, no constructor runs."""
    marker = tmp_path / "marker"
    lib = planted_library(tmp_path, marker)
    cache = tmp_path / "cache"
    for dest in (cache / "native" / kernel.name, cache / kernel.name, cache / "kept" / kernel.name):
        plant(lib, dest)
    run_cli = ("from jaxgear.cli import main\n"
               f"rc = main(['analyze', '--grid', '4,3,4', '--no-figures', '--out', {str(tmp_path / 'out')!r}])\n"
               "assert rc == 0, rc")
    out = probe({"JAXGEAR_CACHE_DIR": str(cache)}, tmp_path, before=run_cli)  # the command loads the kernel
    assert not marker.exists(), "the planted library's constructor ran"
    assert out["ok"] and out["mapped"] == [str(kernel)] and out["warnings"] == [], out
    assert "kernel" not in out["stderr"], out["stderr"][-2000:]
    assert (tmp_path / "out" / "result.nc").exists()


def test_the_loader_loads_only_the_file_it_checked(kernel, tmp_path):
    """``_open`` hashes the open file and loads that file: a library that does not match its
    record at that moment (changed after the folder was checked) is not loaded."""
    marker = tmp_path / "marker"
    lib = planted_library(tmp_path, marker)
    folder = tmp_path / "k"
    folder.mkdir(mode=0o700)
    shutil.copyfile(lib, folder / kernel.name)
    shutil.copyfile(Path(str(kernel) + ".sha256"), folder / (kernel.name + ".sha256"))  # the real kernel's record
    with pytest.raises(_native._Changed):
        _native._open(folder / kernel.name)
    assert not marker.exists()


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="giving a file away needs root")
def test_a_kernel_file_of_another_user_is_refused(kernel, tmp_path):
    marker = tmp_path / "marker"
    folder = tmp_path / "k"
    folder.mkdir(mode=0o700)
    plant(planted_library(tmp_path, marker), folder / kernel.name)  # with a matching record
    os.chown(folder / kernel.name, 65534, 65534)
    with pytest.raises(_native._Refused, match="belongs to another user"):
        _native._verified(folder / kernel.name)
    with pytest.raises(_native._Refused, match="belongs to another user"):
        _native._open(folder / kernel.name)
    assert not marker.exists()
