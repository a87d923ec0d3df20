"""Kill-and-resume of long sweeps: finished blocks saved under a manifest of the settings.

The private helper of :class:`~jaxgear.Runner` (:mod:`._runner`), which alone opens
these checkpoints for the sweep functions."""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .._checks import article
from .._devices import allgather, cell_processes, process_count, process_index
from .._io import atomic_write

__all__ = ["Checkpoint", "diff_settings", "mismatch_message", "open_shared_checkpoint", "checkpoint_on_zero",
           "saved_parts"]


def _hash(settings: Mapping) -> str:
    return hashlib.sha256(json.dumps(settings, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


TAG_SUFFIX = ".settings"
"""Suffix of a part's tag: ``parts/NAME.settings`` holds the settings (and their hash) of
the sweep that wrote ``parts/NAME``."""


class Checkpoint:
    """Blocks of a sweep saved in ``DIR/parts`` under a manifest of the settings' hash.

    ``out=None`` keeps nothing (every block is computed). A directory with a manifest
    of other settings raises ``ValueError`` naming the differing settings, unless
    ``restart`` (then the old parts are removed).

    Every part is tagged: ``parts/NAME.settings`` holds the settings and their hash,
    written before the part by :meth:`path` and :meth:`save`. A part counts as saved
    (:meth:`has`) only with a tag of these settings, so a part that another sweep wrote
    into the same folder (two runs at once, a manifest replaced under a running sweep) is
    never read as this one's; opening a folder that holds parts of other settings raises
    ``ValueError`` naming the differing fields (``restart`` removes them).
    """

    def __init__(self, out, kind: str, settings: dict, restart: bool = False):
        self.dir = None if out is None else Path(out)
        self.key = _hash(settings)
        if self.dir is None:
            return
        self.parts = self.dir / "parts"
        self.kind, self.settings = kind, settings
        man = self.dir / "manifest.json"
        key = self.key
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
                    raise ValueError(mismatch_message(self.dir, old.get("kind", "?"),
                                                      diff_settings(old.get("settings", {}), settings)))
                shutil.rmtree(self.parts, ignore_errors=True)
        elif self.parts.exists() and restart:
            shutil.rmtree(self.parts, ignore_errors=True)
        for name, saved in self._foreign_parts():
            if restart:  # parts another sweep wrote here: discarded with the old ones
                (self.parts / name).unlink(missing_ok=True)
                (self.parts / (name + TAG_SUFFIX)).unlink(missing_ok=True)
                continue
            diff = diff_settings(saved.get("settings", {}), settings)
            raise ValueError(f"{mismatch_message(self.dir, saved.get('kind', '?'), diff)} (the part {name} in "
                             f"{self.parts} was saved with those settings)")
        self.parts.mkdir(parents=True, exist_ok=True)
        text = json.dumps({"kind": kind, "hash": key, "settings": settings}, indent=1, sort_keys=True)
        atomic_write(man, lambda tmp: Path(tmp).write_text(text))
        self._tag_text = json.dumps({"kind": kind, "hash": key, "settings": settings}, sort_keys=True)

    def _foreign_parts(self):
        """``(name, tag)`` of every part in ``parts`` tagged with other settings."""
        if not self.parts.is_dir():
            return
        for tag in sorted(self.parts.glob(f"*{TAG_SUFFIX}")):
            saved = _read_tag(tag)
            name = tag.name[: -len(TAG_SUFFIX)]
            if saved is not None and saved.get("hash") != self.key and (self.parts / name).is_file():
                yield name, saved  # (an unreadable tag: its part is not read, but computed again)

    def _tag(self, name: str) -> None:
        """Tag part ``name`` with these settings (before it is written)."""
        atomic_write(self.parts / (name + TAG_SUFFIX), lambda tmp: Path(tmp).write_text(self._tag_text))

    def path(self, name: str) -> Path | None:
        """Where part ``name`` is to be saved (``None`` without an output folder), its tag
        of these settings written (a part of the same name with another tag is removed)."""
        if self.dir is None:
            return None
        if (self.parts / name).exists() and not self._tagged(name):
            (self.parts / name).unlink(missing_ok=True)
        self._tag(name)
        return self.parts / name

    def _tagged(self, name: str) -> bool:
        saved = _read_tag(self.parts / (name + TAG_SUFFIX))
        return saved is not None and saved.get("hash") == self.key

    def has(self, name: str) -> bool:
        """Whether part ``name`` was saved by an earlier run of these settings (its tag)."""
        return self.dir is not None and (self.parts / name).is_file() and self._tagged(name)

    def load(self, name: str) -> dict[str, np.ndarray] | None:
        """The arrays of a saved block, or ``None`` when the part is unreadable or not
        tagged with these settings (it is then removed and the block is computed again)."""
        if not self._tagged(name):
            (self.parts / name).unlink(missing_ok=True)
            return None
        try:
            with open(self.parts / name, "rb") as f, np.load(f) as z:  # closed also when np.load fails
                return {k: z[k] for k in z.files}
        except Exception:  # truncated or corrupted part: recompute it
            (self.parts / name).unlink(missing_ok=True)
            return None

    def load_result(self, name: str, loader):
        """A saved result part read with ``loader(path)``, or ``None`` when unreadable or
        not tagged with these settings (removed, to be computed again)."""
        if not self._tagged(name):
            (self.parts / name).unlink(missing_ok=True)
            return None
        try:
            return loader(self.parts / name)
        except Exception:  # truncated or corrupted part (any reader error): recompute it
            (self.parts / name).unlink(missing_ok=True)
            return None

    def save(self, name: str, **arrays) -> None:
        """Save a finished block (atomically), tagged with these settings."""
        if self.dir is not None:
            self._tag(name)
            _save_part(self.parts / name, arrays)

    def block(self, name: str, compute, like: Mapping[str, tuple], collective: bool = True) -> dict:
        """The arrays of block ``name`` of a sweep, the same on every process (every process calls
        it for every block, in the same order): the saved part when process 0 has a readable
        one (sent to the others), else ``compute()`` (saved by process 0). ``collective``:
        ``compute`` runs on every process and exchanges the parts itself (an independent
        block split over the processes); otherwise process 0 alone computes the block (a
        sequential one) and sends it. ``like``: ``{name: (shape, dtype)}`` of the arrays.
        One process: the saved part, or ``compute()`` saved."""
        me, count = cell_processes()
        z = self.load(name) if self.has(name) else None
        if count > 1:
            saved = bool(allgather(np.int32(z is not None))[0])
            if not saved and collective:
                z = compute()
                self.save(name, **z)
                return z
            if not saved and me == 0:
                z = compute()
                self.save(name, **z)
            return {k: allgather(np.asarray(z[k], dtype) if me == 0 else np.zeros(shape, dtype))[0]
                    for k, (shape, dtype) in like.items()}
        if z is None:
            z = compute()
            self.save(name, **z)
        return z

def _read_tag(path: Path) -> dict | None:
    """The tag ``{"kind", "hash", "settings"}`` of a part, ``None`` where missing or unreadable."""
    try:
        tag = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return tag if isinstance(tag, dict) else None


def saved_parts(out) -> list[Path]:
    """The parts in ``out/parts`` tagged with the settings of ``out``'s manifest (those a
    resume with the same settings reads); ``[]`` without a readable manifest."""
    try:
        key = json.loads((Path(out) / "manifest.json").read_text()).get("hash")
    except (OSError, ValueError, AttributeError):
        return []
    parts = Path(out) / "parts"
    found = []
    for tag in sorted(parts.glob(f"*{TAG_SUFFIX}")) if parts.is_dir() else ():
        part = parts / tag.name[: -len(TAG_SUFFIX)]
        saved = _read_tag(tag)
        if saved is not None and saved.get("hash") == key and part.is_file():
            found.append(part)
    return found


def open_shared_checkpoint(out, kind: str, settings: dict, restart: bool = False, timeout: float = 600.0):
    """:class:`Checkpoint` of a sweep that several processes share (one JAX program,
    :func:`jaxgear._devices.initialize`): process 0 opens (or restarts) the folder; the
    others wait until its manifest holds these settings, then open it without
    discarding anything. One process: ``Checkpoint(out, kind, settings, restart)``."""
    import time

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


def checkpoint_on_zero(out, kind: str, settings: dict, restart: bool = False) -> Checkpoint:
    """:class:`Checkpoint` of a sweep whose processes compute every block together
    (:meth:`Checkpoint.block`): process 0 alone opens ``out`` (which need not be shared); the
    others keep nothing. When process 0 cannot open it, every process raises. One process
    (:func:`jaxgear._devices.cell_processes`): ``Checkpoint(out, kind, settings, restart)``."""
    me, count = cell_processes()
    if count == 1:
        return Checkpoint(out, kind, settings, restart)
    ck, err = Checkpoint(None, kind, settings), None
    if me == 0:
        try:
            ck = Checkpoint(out, kind, settings, restart)
        except Exception as e:  # raised below, once the others know
            err = e
    if int(allgather(np.int32(err is not None))[0]):
        if err is not None:
            raise err
        raise RuntimeError(f"process 0 could not open the sweep folder {out} (see its error).")
    return ck



def _save_part(path: Path, arrays: dict) -> None:
    """Write one finished block (atomically: a kill never leaves a half-written part)."""

    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)

    atomic_write(path, write)


def mismatch_message(folder, kind, diff: str, restart: str = "jaxgear.Runner(restart=True), --restart") -> str:
    """The refusal to resume the ``kind`` sweep saved in ``folder`` with other settings
    (``diff``: :func:`diff_settings`; ``restart``: how to discard it)."""
    return (f"{folder} holds {article(str(kind))} sweep with other settings (differing: {diff}); resume it with "
            f"the same settings, use another output folder, or restart ({restart}) to discard it.")


def _show_json(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _diff(a, b, where: str, out: list) -> None:
    """Append ``where: A saved vs B now`` for every leaf where ``a`` and ``b`` differ:
    dictionaries are compared key by key and lists of one length item by item (so the
    field that differs is named, not cut off), unless the whole value is short."""
    if a == b:
        return
    whole = f"{where}: {_show_json(a)} saved vs {_show_json(b)} now"
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{where}.{k}: {_show_json(a.get(k)) if k in a else '(none)'} saved vs "
                           f"{_show_json(b.get(k)) if k in b else '(none)'} now")
            else:
                _diff(a[k], b[k], f"{where}.{k}", out)
    elif (isinstance(a, list) and isinstance(b, list) and len(a) == len(b)
          and len(json.dumps(a)) + len(json.dumps(b)) > 80):
        items: list[str] = []
        for i, (x, y) in enumerate(zip(a, b)):
            _diff(x, y, f"{where}[{i}]", items)
        if len(items) > 3:  # many entries (a range of values): how many, and the first
            items = [f"{where}: {sum(x != y for x, y in zip(a, b))} of {len(a)} entries differ, first "
                     + items[0]]
        out.extend(items)
    elif isinstance(a, list) and isinstance(b, list) and len(a) != len(b) and len(json.dumps(a)) > 80:
        out.append(f"{where}: {len(a)} entries saved vs {len(b)} now")
    else:
        out.append(whole)


def diff_settings(a: Mapping, b: Mapping) -> str:
    """The settings that differ between ``a`` (saved) and ``b`` (now), compared as JSON
    (so a tuple now and the list it was saved as are equal): every differing field by its
    path (``grid.counts``, ``params.c_sp``, ``values[3]``) with both values."""
    a, b = (json.loads(json.dumps(x, sort_keys=True)) for x in (a, b))
    out: list[str] = []
    for k in sorted(set(a) | set(b)):
        if k not in a or k not in b:
            out.append(f"{k}: {_show_json(a.get(k)) if k in a else '(none)'} saved vs "
                       f"{_show_json(b.get(k)) if k in b else '(none)'} now")
        else:
            _diff(a[k], b[k], k, out)
    return "; ".join(out) or "format"
