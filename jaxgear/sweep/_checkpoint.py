"""Kill-and-resume of long sweeps: finished blocks saved under a manifest of the settings."""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .._checks import article
from .._io import atomic_write

__all__ = ["Checkpoint", "diff_settings", "open_shared_checkpoint"]


def _hash(settings: Mapping) -> str:
    return hashlib.sha256(json.dumps(settings, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


class Checkpoint:
    """Blocks of a sweep saved in ``DIR/parts`` under a manifest of the settings' hash.

    ``out=None`` keeps nothing (every block is computed). A directory with a manifest
    of other settings raises ``ValueError`` naming the differing settings, unless
    ``restart`` (then the old parts are removed).
    """

    def __init__(self, out, kind: str, settings: dict, restart: bool = False):
        self.dir = None if out is None else Path(out)
        if self.dir is None:
            return
        self.parts = self.dir / "parts"
        man = self.dir / "manifest.json"
        key = _hash(settings)
        if man.is_file():
            try:
                old = json.loads(man.read_text())
                if not isinstance(old, dict):
                    raise ValueError
            except (OSError, ValueError):  # unreadable manifest: its parts cannot be trusted
                old = {"hash": None, "settings": {}}
                restart = True
            if old.get("hash") != key:
                if not restart:
                    diff = diff_settings(old.get("settings", {}), settings)
                    raise ValueError(f"{self.dir} holds {article(str(old.get('kind', '?')))} sweep with other settings "
                                     f"(differing: {diff}); resume it with the same settings, use another "
                                     "output folder, or restart (restart=True, --restart) to discard it.")
                shutil.rmtree(self.parts, ignore_errors=True)
        elif self.parts.exists() and restart:
            shutil.rmtree(self.parts, ignore_errors=True)
        self.parts.mkdir(parents=True, exist_ok=True)
        text = json.dumps({"kind": kind, "hash": key, "settings": settings}, indent=1, sort_keys=True)
        atomic_write(man, lambda tmp: Path(tmp).write_text(text))

    def path(self, name: str) -> Path | None:
        """Where part ``name`` is saved (``None`` without an output folder)."""
        return None if self.dir is None else self.parts / name

    def has(self, name: str) -> bool:
        """Whether part ``name`` was saved by an earlier run."""
        return self.dir is not None and (self.parts / name).is_file()

    def load(self, name: str) -> dict[str, np.ndarray] | None:
        """The arrays of a saved block, or ``None`` when the part is unreadable (it is then
        removed and the block is computed again)."""
        try:
            with np.load(self.parts / name) as z:
                return {k: z[k] for k in z.files}
        except Exception:  # truncated or corrupted part: recompute it
            (self.parts / name).unlink(missing_ok=True)
            return None

    def load_result(self, name: str, loader):
        """A saved result part read with ``loader(path)``, or ``None`` when unreadable
        (removed, to be computed again)."""
        try:
            return loader(self.parts / name)
        except Exception:  # truncated or corrupted part (any reader error): recompute it
            (self.parts / name).unlink(missing_ok=True)
            return None

    def save(self, name: str, **arrays) -> None:
        """Save a finished block (atomically)."""
        if self.dir is not None:
            _save_part(self.parts / name, arrays)


def open_shared_checkpoint(out, kind: str, settings: dict, restart: bool = False, timeout: float = 600.0):
    """:class:`Checkpoint` of a sweep that several processes share (one JAX program,
    :func:`jaxgear._devices.initialize`): process 0 opens (or restarts) the folder; the
    others wait until its manifest holds these settings, then open it without
    discarding anything. One process: ``Checkpoint(out, kind, settings, restart)``."""
    import time

    from .._devices import process_count, process_index

    if out is None or process_count() == 1 or process_index() == 0:
        return Checkpoint(out, kind, settings, restart)
    man, key, t0 = Path(out) / "manifest.json", _hash(settings), time.monotonic()
    while True:
        try:
            if json.loads(man.read_text()).get("hash") == key:
                return Checkpoint(out, kind, settings, False)
        except (OSError, ValueError, AttributeError):
            pass
        if time.monotonic() - t0 > timeout:
            raise TimeoutError(f"process 0 did not open {out} for this sweep within {timeout:.0f} s.")
        time.sleep(0.2)


def _save_part(path: Path, arrays: dict) -> None:
    """Write one finished block (atomically: a kill never leaves a half-written part)."""

    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)

    atomic_write(path, write)


def diff_settings(a: Mapping, b: Mapping) -> str:
    """The settings that differ between ``a`` (saved) and ``b`` (now), compared as JSON
    (so a tuple now and the list it was saved as are equal)."""
    a, b = (json.loads(json.dumps(x, sort_keys=True)) for x in (a, b))
    keys = sorted(set(a) | set(b))
    out = []
    for k in keys:
        if a.get(k) != b.get(k):
            va, vb = json.dumps(a.get(k)), json.dumps(b.get(k))
            short = lambda s: s if len(s) <= 40 else s[:37] + "..."
            out.append(f"{k}: {short(va)} saved vs {short(vb)} now")
    return "; ".join(out) or "format"


