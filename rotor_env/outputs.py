"""Writing outputs without losing anything: atomic files and folders the tool owns.

Two rules keep a user's data safe:

* **A file appears whole or not at all.**  :func:`atomic_write` writes to a hidden
  temporary file in the target's folder and then moves it into place in one step
  (``os.replace`` when overwriting is allowed, ``os.link`` otherwise — which fails if
  the target appeared meanwhile, so two runs writing the same report cannot silently
  overwrite each other).  An interrupted write (Ctrl-C, a full disk) leaves the target
  as it was and removes the temporary file.
* **``--force`` replaces only what the tool wrote.**  An :class:`OutputFolder` keeps a
  marker file (:data:`MARKER`) listing every file the tool wrote there.  Re-running
  with ``force`` deletes exactly those files; anything else in the folder (a thesis
  that happened to be there, the current directory's contents for ``--out .``) is
  never touched, and a non-empty folder without a marker is refused even with
  ``force``.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable
from pathlib import Path

__all__ = ["MARKER", "OutputFolder", "atomic_write", "atomic_write_text", "check_writable"]

#: The marker an output folder of rotor-id carries (JSON: the files written there).
MARKER = ".rotor-id-output.json"


def _temporary(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def check_writable(path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Fail early (before any computation) if ``path`` cannot be written.

    Raises :class:`FileExistsError` if it exists and ``overwrite`` is false,
    :class:`ValueError` for a folder in the way or a missing parent, and
    :class:`PermissionError` for a read-only folder.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder, not an output file")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; use --force (overwrite=True) to replace it")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"cannot write {path}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot write {path}: folder {parent} is not writable")
    return path


def atomic_write(path: str | os.PathLike, write: Callable[[Path], None], *, overwrite: bool = False) -> Path:
    """Call ``write(tmp)`` to fill a temporary file, then move it to ``path`` atomically.

    Without ``overwrite`` an existing ``path`` — also one created by another process
    while ``write`` ran — raises :class:`FileExistsError` and is left untouched.
    """
    path = check_writable(path, overwrite=overwrite)
    tmp = _temporary(path)
    try:
        write(tmp)
        if overwrite:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)  # atomic "create if absent": fails if the target exists
    except FileExistsError:
        raise FileExistsError(f"{path} exists; use --force (overwrite=True) to replace it") from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    return path


def atomic_write_text(path: str | os.PathLike, text: str, *, overwrite: bool = False) -> Path:
    """:func:`atomic_write` for a UTF-8 text."""
    return atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"), overwrite=overwrite)


class OutputFolder:
    """A folder rotor-id writes into, and may later replace — only what it wrote.

    ``OutputFolder(path, force=...)`` prepares the folder: it creates it when absent;
    an empty folder is taken over; a folder carrying :data:`MARKER` is refused unless
    ``force``, in which case exactly the files listed in the marker are deleted (then
    any of its sub-folders left empty); any other non-empty folder is refused.  Files
    are then written with :meth:`write` (atomically, recorded in the marker *before*
    they are written, so an interrupted run can be replaced too).
    """

    def __init__(self, path: str | os.PathLike, *, force: bool = False) -> None:
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise ValueError(f"{self.path} exists and is a file, not an output folder")
        marker = self.path / MARKER
        if self.path.is_dir() and any(self.path.iterdir()):
            if not marker.is_file():
                raise FileExistsError(
                    f"{self.path} is not empty and was not written by rotor-id (no {MARKER}); "
                    "choose an empty or new folder — --force never deletes files rotor-id did not write"
                )
            if not force:
                raise FileExistsError(f"{self.path} holds a previous output; use --force to replace it")
            self._remove_previous(marker)
        self.path.mkdir(parents=True, exist_ok=True)
        if not os.access(self.path, os.W_OK | os.X_OK):
            raise PermissionError(f"cannot write into {self.path}: the folder is not writable")
        self.files: list[str] = []
        self._save_marker()

    def _remove_previous(self, marker: Path) -> None:
        try:
            listed = json.loads(marker.read_text(encoding="utf-8")).get("files", [])
        except (OSError, ValueError, AttributeError) as exc:
            raise ValueError(f"{marker}: unreadable marker ({exc}); remove the folder by hand") from None
        root = self.path.resolve()
        dirs = set()
        for rel in listed:
            target = (self.path / str(rel)).resolve()
            # only plain files inside the folder: a tampered marker cannot reach outside it
            if root not in target.parents or not target.is_file() or target.is_symlink():
                continue
            target.unlink()
            dirs.update(p for p in target.parents if root in p.parents)
        for d in sorted(dirs, key=lambda p: len(p.parts), reverse=True):
            with contextlib.suppress(OSError):  # not empty: a user's file is inside
                d.rmdir()
        marker.unlink()

    def _save_marker(self) -> None:
        atomic_write_text(self.path / MARKER, json.dumps({"tool": "rotor-id", "files": self.files}, indent=1),
                          overwrite=True)

    def file(self, relative: str) -> Path:
        """Register ``relative`` as written by the tool and return its full path."""
        if relative not in self.files:
            self.files.append(relative)
            self._save_marker()
        target = self.path / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        return target

    def write(self, relative: str, write: Callable[[Path], None]) -> Path:
        """Write one file atomically (replacing the tool's own file of that name)."""
        return atomic_write(self.file(relative), write, overwrite=True)

    def write_text(self, relative: str, text: str) -> Path:
        return self.write(relative, lambda p: p.write_text(text, encoding="utf-8"))
