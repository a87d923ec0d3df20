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

One run owns an output folder at a time: on entering, a run takes an exclusive ``flock``
on ``--out/.jaxgear-lock`` (holding its pid; released by the kernel when the run ends or
is killed) and a second run on the same folder is refused at once, naming the folder and
the owner's pid. Every clean-up of ``--out`` (temporary files of killed writes, in
``--out`` and ``--out/parts``) happens under that lock. Each staging folder is named with
its owner's process id and holds its own lock file (``.jaxgear-owner``), so the start-up
clean-up of the parent folder removes only staging folders whose owner is gone.

A symbolic link given as ``--out`` stands for its target folder: the results are written
there and the link is kept; a link that leads nowhere (a loop, a missing target) or to a
file is refused before any work.
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

__all__ = ["OutputFolder", "check_output_folder", "FolderInUse"]

try:
    import fcntl
except ImportError:  # not POSIX: the pid alone tells whether the owner runs
    fcntl = None

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100
OWNER_FILE = ".jaxgear-owner"
"""Lock file of a staging folder: its owner's pid, ``flock``-ed while the owner runs."""
FOLDER_LOCK = ".jaxgear-lock"
"""Lock file of an output folder: its owner's pid, ``flock``-ed (exclusive) while the run
lasts and removed when it ends (not a temporary file: the swap carries it over)."""


class FolderInUse(ValueError):
    """The output folder is held by another run (its lock is taken)."""
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


def _link_target(p: Path, name: str) -> Path | None:
    """The folder a symbolic link ``p`` leads to (``None`` when ``p`` is no link);
    ``ValueError`` naming ``name`` for a loop, a missing target or a file."""
    if not os.path.islink(p):
        return None
    try:
        target = Path(os.path.realpath(p, strict=True))
    except OSError as exc:
        why = ("a loop of symbolic links" if exc.errno == errno.ELOOP
               else f"a symbolic link to {os.readlink(p)!r}, which does not exist")
        raise ValueError(f"{name}={str(p)!r} is {why}: give a folder.") from None
    except RuntimeError:  # Python < 3.13 reports a loop so
        raise ValueError(f"{name}={str(p)!r} is a loop of symbolic links: give a folder.") from None
    if not target.is_dir():
        raise ValueError(f"{name}={str(p)!r} is a symbolic link to {str(target)!r}, which is not a folder: "
                         "give a folder for the results.")
    return target


def check_output_folder(path, name: str = "--out") -> Path:
    """``path`` as a ``Path`` if it can be an output folder: not an existing file, and
    its nearest existing ancestor is a folder where a folder can be made (``ValueError``
    naming ``name`` otherwise). A symbolic link to a folder gives its target; a link
    that leads nowhere (a loop, a missing target), also among the ancestors, is refused.
    Nothing is left behind (an empty probe folder is made and removed at once)."""
    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise ValueError(f"{name}={path!r} must name a folder.")
    p = Path(path)
    target = _link_target(p, name)
    if target is not None:
        p = target
    if p.exists() and not p.is_dir():
        raise ValueError(f"{name}={str(p)!r} is an existing file, not a folder: give a folder for the results.")
    anc = p.absolute()
    while not anc.exists():
        if os.path.islink(anc):  # a link that leads nowhere above the folder
            _link_target(anc, f"{name}={str(path)!r}: {anc}")
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


def _lock_folder(folder: Path, name: str):
    """Take ``folder``'s lock (:data:`FOLDER_LOCK`, exclusive, not waiting) and write this
    process's pid into it: the descriptor, to be closed when the run ends (``None`` where
    ``flock`` is missing). :class:`FolderInUse` naming the folder and the owner's pid when
    another run holds it."""
    lock = folder / FOLDER_LOCK
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o600)
        if fcntl is None:
            os.close(fd)
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            try:
                owner = lock.read_text().strip()
            except OSError:
                owner = ""
            pid = f" (pid {owner})" if owner.isdigit() else ""
            raise FolderInUse(f"{name}={str(folder)!r} is in use by another jaxgear run{pid}: wait for it to end, "
                              "or give another folder.") from None
        try:  # the owner before us may have removed the file as it ended: lock the one in place
            same = os.path.samestat(os.fstat(fd), os.stat(lock))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    return fd


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
        self.name = name
        self._lock = None
        self._folder_lock = None
        self._made = False

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
            raise ValueError(f"{self.name}={str(self.path)!r} cannot be created ({exc.strerror}).") from None
        self.swap = self._can_swap()
        if self.swap:
            self._recover()
        self._made = not self.path.exists()
        try:
            self.path.mkdir(parents=True, exist_ok=True)  # to hold its lock
            self._folder_lock = _lock_folder(self.path, self.name)
        except FolderInUse:
            raise
        except OSError as exc:
            raise ValueError(f"{self.name}={str(self.path)!r} is not writable ({exc.strerror}).") from None
        try:
            return self._stage()
        except BaseException:
            self._release(failed=True)
            raise

    def _stage(self) -> Path:
        """Under the folder's lock: remove the files of killed writes, make the staging folder."""
        for folder in (self.path, self.path / "parts"):  # files of killed writes
            if folder.is_dir() and not folder.is_symlink():
                remove_stale_temporaries(folder)
                for p in folder.glob(f"{TMP_PREFIX}*"):
                    if p.is_dir() and not owner_alive(p):
                        shutil.rmtree(p, ignore_errors=True)
        host = self.path.parent if self.swap else self.path
        try:  # the pid in the name marks the folder as taken until the lock file is in place
            self.work = Path(tempfile.mkdtemp(prefix=f"{self._prefix()}{os.getpid()}-", dir=host))
            self._lock = _take_lock(self.work)
        except OSError as exc:
            raise ValueError(f"{self.name}={str(self.path)!r} is not writable ({exc.strerror}).") from None
        mode = (os.stat(self.path).st_mode & 0o7777) if self.path.is_dir() else 0o777 & ~_umask()
        os.chmod(self.work, mode)
        return self.work

    def _release(self, failed: bool) -> None:
        """End the run's hold on the folder: remove its lock file (then close the lock, so a
        run that opened the old file sees it gone) and, after a failure, the folder this run
        made if nothing else is in it."""
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None
        if self._folder_lock is not None or fcntl is None:
            self.path.joinpath(FOLDER_LOCK).unlink(missing_ok=True)
        if self._folder_lock is not None:
            os.close(self._folder_lock)
            self._folder_lock = None
        if failed and self._made:
            try:
                os.rmdir(self.path)  # only when empty
            except OSError:
                pass

    def __exit__(self, kind, exc, tb) -> bool:
        try:
            if kind is not None:
                if isinstance(exc, OSError) and self.work is not None:
                    self._name_final_path(exc)
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
            self._release(failed=kind is not None)

    def _name_final_path(self, exc: OSError) -> None:
        """An error writing a file of the staging folder (``exc.filename``, or the file
        HDF5 names in its message) names the file of ``--out`` it stands for: the same
        name in ``--out``, without the temporary prefix and suffix of an atomic write."""
        where = exc.filename
        if where is None:
            m = re.search(r"filename = '([^']*)'", str(exc))
            where = m.group(1) if m else None
        try:
            rel = Path(os.fsdecode(where)).absolute().relative_to(self.work)
        except (ValueError, TypeError):
            return
        name = rel.name
        if name.startswith(TMP_PREFIX):  # .jaxgear-tmp-result.nc.XXXXXXXX -> result.nc
            name = name[len(TMP_PREFIX):].rsplit(".", 1)[0]
        exc.filename = str(self.path / rel.parent / name)

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
