"""Output folders of the command line, replaced as a whole.

A command writes all of its files (result, ``summary.json``, figures) into a fresh
staging folder beside ``--out`` (``.jaxgear-tmp-<name>.run-*`` in the same parent
folder) and, once every file is written, swaps the staging folder in for ``--out`` in
one step (``renameat2(RENAME_EXCHANGE)`` on Linux; elsewhere two renames, undone by the
next run if a kill falls between them). Files of ``--out`` that the command does not
write (another command's results, the user's own files, a sweep's resume parts) are
carried over into the staging folder as hard links before the swap. So at any moment
— after a finished, failed or killed run — ``--out`` holds either the complete previous
result or the complete new one, never a mix: figures of an earlier run that the new run
does not draw are gone with it, and leftover temporary files are removed by the next
run.

When the swap cannot be used (``--out`` is the current folder or one above it, a mount
point, or its parent folder is not writable) the files are moved in one by one, each
atomically, and the command's stale files are removed afterwards: every file is whole,
but a kill during those few renames can leave a mix.

Several runs may share one output folder: each staging folder is named with its owner's
process id and holds a lock file (``.jaxgear-owner``, the pid, locked with ``flock``
while the run lasts), and the start-up clean-up removes only staging folders whose owner
is gone (the lock is free, or without a lock file the pid is not alive). Each run swaps
in its own whole result; the last to finish wins.
"""

from __future__ import annotations

import ctypes
import errno
import fnmatch
import os
import re
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

from ._io import TMP_PREFIX, remove_stale_temporaries

__all__ = ["OutputFolder", "check_output_folder"]

try:
    import fcntl
except ImportError:  # not POSIX: the pid alone tells whether the owner runs
    fcntl = None

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100
OWNER_FILE = ".jaxgear-owner"
"""Lock file of a staging folder: its owner's pid, ``flock``-ed while the owner runs."""
_PID = re.compile(r"\.run-(\d+)-[a-z0-9_]+(?:\.old)?$")  # the last .run-PID-XXXXXXXX of the name


def _pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (``os.kill(pid, 0)``; one of another user counts)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def owner_alive(folder: Path) -> bool:
    """Whether the run that made the staging folder ``folder`` still runs: its lock file
    is locked, or, without a lock file (a folder just made, or where ``flock`` is missing),
    the pid in its name is alive. Folders of neither kind (older versions) have no owner."""
    lock = Path(folder) / OWNER_FILE
    if fcntl is not None:
        try:
            fd = os.open(lock, os.O_RDONLY)
        except FileNotFoundError:
            fd = None
        except OSError:  # unreadable: not ours to judge, keep it
            return True
        if fd is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except OSError as exc:
                return exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES)
            finally:
                os.close(fd)  # closing releases the probe's own lock
            return False
    m = _PID.search(Path(folder).name)
    if m is None and lock.is_file():
        try:
            m = re.match(r"\s*(\d+)", lock.read_text())
        except OSError:
            return True
    return m is not None and _pid_alive(int(m.group(1)))


def _take_lock(folder: Path):
    """Write this process's pid into ``folder``'s lock file and lock it (the descriptor,
    to be closed when the run ends; ``None`` where ``flock`` is missing)."""
    fd = os.open(folder / OWNER_FILE, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        os.write(fd, f"{os.getpid()}\n".encode())
        if fcntl is None:
            os.close(fd)
            return None
        fcntl.flock(fd, fcntl.LOCK_EX)
    except BaseException:
        os.close(fd)
        raise
    return fd


def check_output_folder(path, name: str = "--out") -> Path:
    """``path`` as a ``Path`` if it can be an output folder: not an existing file, and
    its nearest existing ancestor is a folder where a folder can be made (``ValueError``
    naming ``name`` otherwise). Nothing is left behind (an empty probe folder is made and
    removed at once)."""
    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise ValueError(f"{name}={path!r} must name a folder.")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{name}={str(p)!r} is an existing file, not a folder: give a folder for the results.")
    anc = p.absolute()
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise ValueError(f"{name}={str(p)!r}: {anc} is a file, so the folder cannot be created.")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise ValueError(f"{name}={str(p)!r} is not writable ({anc} does not allow writing).")
    try:  # permissions are not all (/proc, a read-only mount): try a folder there, removed at once
        probe = tempfile.mkdtemp(prefix=f"{TMP_PREFIX}probe-{os.getpid()}-", dir=anc)
    except OSError as exc:
        raise ValueError(f"{name}={str(p)!r} cannot be written: no folder can be made in {anc} "
                         f"({exc.strerror or exc}).") from None
    try:
        os.rmdir(probe)
    except OSError:  # already removed (another run's clean-up of --out)
        pass
    return p


def _exchange(a: Path, b: Path) -> bool:
    """Swap the two paths atomically (Linux ``renameat2``); ``False`` where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP if hasattr(errno, "EOPNOTSUPP") else errno.EINVAL):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _link_tree(src: Path, dst: Path) -> None:
    """Hard-link (or copy, where links fail) the file or folder ``src`` to ``dst``."""
    def link(s, d):
        try:
            os.link(s, d)
        except OSError:
            shutil.copy2(s, d)

    if src.is_dir() and not src.is_symlink():
        shutil.copytree(src, dst, symlinks=True, copy_function=link)
    elif src.is_symlink():
        os.symlink(os.readlink(src), dst)
    else:
        link(src, dst)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class OutputFolder:
    """``with OutputFolder(out, owned) as work:`` write the run's files into ``work``;
    on leaving the block without an error they replace ``out``'s ``owned`` files as a
    whole (see the module); on an error (or a kill) ``out`` is left as it was.

    Args:
        path: the output folder (``--out``).
        owned: glob patterns of the file names the command writes; the previous run's
            files matching them are replaced (or removed when the new run does not
            write them), every other entry of ``path`` is kept.
        create: create ``path`` (empty) on entering, for commands that keep resume
            state in it while they run (sweeps).
    """

    def __init__(self, path, owned: Iterable[str], *, create: bool = False, name: str = "--out"):
        self.path = check_output_folder(path, name).absolute()
        self.owned = tuple(owned)
        self.create = create
        self.work: Path | None = None
        self.swap = False
        self._lock = None

    # ---------------------------------------------------------------- helpers
    def _prefix(self) -> str:
        return f"{TMP_PREFIX}{self.path.name}.run-"

    def _owned(self, name: str) -> bool:
        return any(fnmatch.fnmatchcase(name, pat) for pat in self.owned)

    def _can_swap(self) -> bool:
        cwd = Path.cwd().absolute()
        parent = self.path.parent
        if self.path == cwd or self.path in cwd.parents or self.path == parent:
            return False
        if self.path.exists() and os.path.ismount(self.path):
            return False
        return parent.is_dir() and os.access(parent, os.W_OK | os.X_OK)

    def _recover(self) -> None:
        """Undo an interrupted two-rename swap, remove staging folders of killed runs."""
        parent = self.path.parent
        if not parent.is_dir():
            return
        olds = sorted(p for p in parent.glob(f"{self._prefix()}*.old") if p.is_dir() and not owner_alive(p))
        if olds and not self.path.exists():
            os.rename(olds[-1], self.path)
        for p in parent.glob(f"{self._prefix()}*"):
            if not owner_alive(p):  # a running run's staging folder is left to it
                shutil.rmtree(p, ignore_errors=True)

    # ---------------------------------------------------------------- protocol
    def __enter__(self) -> Path:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"--out={str(self.path)!r} cannot be created ({exc.strerror}).") from None
        self.swap = self._can_swap()
        if self.swap:
            self._recover()
        if self.create or not self.swap:
            self.path.mkdir(parents=True, exist_ok=True)
        for folder in (self.path, self.path / "parts"):  # files of killed writes
            if folder.is_dir() and not folder.is_symlink():
                remove_stale_temporaries(folder)
                for p in folder.glob(f"{TMP_PREFIX}*"):
                    if p.is_dir() and not owner_alive(p):
                        shutil.rmtree(p, ignore_errors=True)
        host = self.path.parent if self.swap else self.path
        host.mkdir(parents=True, exist_ok=True)
        try:  # the pid in the name marks the folder as taken until the lock file is in place
            self.work = Path(tempfile.mkdtemp(prefix=f"{self._prefix()}{os.getpid()}-", dir=host))
            self._lock = _take_lock(self.work)
        except OSError as exc:
            raise ValueError(f"--out={str(self.path)!r} is not writable ({exc.strerror}).") from None
        mode = (os.stat(self.path).st_mode & 0o7777) if self.path.is_dir() else 0o777 & ~_umask()
        os.chmod(self.work, mode)
        return self.work

    def __exit__(self, kind, exc, tb) -> bool:
        try:
            if kind is not None:
                shutil.rmtree(self.work, ignore_errors=True)
                return False
            # the lock file is not part of the result; the pid in the name keeps the folder
            # this run's until the swap
            (self.work / OWNER_FILE).unlink(missing_ok=True)
            if self.swap:
                self._commit_swap()
            else:
                self._commit_in_place()
            return False
        finally:
            if self._lock is not None:
                os.close(self._lock)
                self._lock = None

    def _commit_swap(self) -> None:
        work, path = self.work, self.path
        if path.is_dir():
            for entry in path.iterdir():
                if entry.name.startswith(TMP_PREFIX) or self._owned(entry.name) or (work / entry.name).exists():
                    continue
                _link_tree(entry, work / entry.name)
            if not _exchange(work, path):
                old = Path(str(work) + ".old")
                os.rename(path, old)
                os.rename(work, path)
                work = old
            shutil.rmtree(work, ignore_errors=True)
        else:
            os.rename(work, path)

    def _commit_in_place(self) -> None:
        new = {p.name for p in self.work.iterdir()}
        for p in self.work.iterdir():
            os.replace(p, self.path / p.name)
        for p in self.path.iterdir():
            if self._owned(p.name) and p.name not in new and p.is_file():
                p.unlink(missing_ok=True)
        shutil.rmtree(self.work, ignore_errors=True)
