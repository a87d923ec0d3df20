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

One run per output folder at a time.
"""

from __future__ import annotations

import ctypes
import errno
import fnmatch
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path

from ._io import TMP_PREFIX, remove_stale_temporaries

__all__ = ["OutputFolder", "check_output_folder"]

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def check_output_folder(path, name: str = "--out") -> Path:
    """``path`` as a ``Path`` if it can be an output folder: not an existing file, and
    its nearest existing ancestor is a writable folder (``ValueError`` naming ``name``
    otherwise). Nothing is created."""
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
        olds = sorted(p for p in parent.glob(f"{self._prefix()}*.old") if p.is_dir())
        if olds and not self.path.exists():
            os.rename(olds[-1], self.path)
        for p in parent.glob(f"{self._prefix()}*"):
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
                    shutil.rmtree(p, ignore_errors=True)
        host = self.path.parent if self.swap else self.path
        host.mkdir(parents=True, exist_ok=True)
        try:
            self.work = Path(tempfile.mkdtemp(prefix=self._prefix(), dir=host))
        except OSError as exc:
            raise ValueError(f"--out={str(self.path)!r} is not writable ({exc.strerror}).") from None
        mode = (os.stat(self.path).st_mode & 0o7777) if self.path.is_dir() else 0o777 & ~_umask()
        os.chmod(self.work, mode)
        return self.work

    def __exit__(self, kind, exc, tb) -> bool:
        if kind is not None:
            shutil.rmtree(self.work, ignore_errors=True)
            return False
        if self.swap:
            self._commit_swap()
        else:
            self._commit_in_place()
        return False

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
