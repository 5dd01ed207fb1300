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

    def __init__(self, path: str | os.PathLike, *, force: bool = False, resume: bool = False) -> None:
        self.path = Path(path)
        marker = self.path / MARKER
        previous = self.check(self.path, force=force, resume=resume)
        self.files: list[str] = []
        if previous is not None:
            if resume and not force:
                # a resumed run: the files listed are the tool's own (only plain files inside it)
                self.files = [f for f in previous if self._inside(f)]
            else:
                self._remove_previous(marker)
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except FileExistsError:  # a dangling symbolic link, say
            raise ValueError(f"{self.path} exists and is not a folder") from None
        if not os.access(self.path, os.W_OK | os.X_OK):
            raise PermissionError(f"cannot write into {self.path}: the folder is not writable")
        self._save_marker()

    @staticmethod
    def check(path: str | os.PathLike, *, force: bool = False, resume: bool = False) -> list[str] | None:
        """Refuse ``path`` as an output folder, without touching anything, when it could not
        be prepared (so that a command can say so before its computation).

        Returns the files a previous run listed in the marker (None: no marker).
        ``resume``: a folder with the marker is taken over as it is (a run that
        continues), without ``force``.
        """
        path = Path(path)
        if path.is_symlink() and not path.exists():
            raise ValueError(f"{path} is a broken symbolic link, not an output folder")
        if path.exists() and not path.is_dir():
            raise ValueError(f"{path} exists and is a file, not an output folder")
        if not path.is_dir():
            return None
        marker = path / MARKER
        owned = marker.is_file() and not marker.is_symlink()
        if not owned:
            if any(path.iterdir()):
                raise FileExistsError(
                    f"{path} is not empty and was not written by rotor-id (no {MARKER}); "
                    "choose an empty or new folder — --force never deletes files rotor-id did not write"
                )
            return None
        try:
            listed = json.loads(marker.read_text(encoding="utf-8")).get("files", [])
        except (OSError, ValueError, AttributeError) as exc:
            raise ValueError(f"{marker}: unreadable marker ({str(exc)[:200]}); remove the folder by hand") from None
        if not isinstance(listed, list):
            raise ValueError(f"{marker}: unreadable marker (its 'files' is not a list); remove the folder by hand")
        if not (force or resume):
            raise FileExistsError(f"{path} holds a previous output; use --force to replace it")
        return [str(f) for f in listed]

    def _remove_previous(self, marker: Path) -> None:
        listed = self.check(self.path, force=True) or []
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
        """Register ``relative`` as written by the tool and return its full path.

        A file already there that the tool did not write (a user's, or a link) is refused:
        ``--force`` replaces only the tool's own files.
        """
        self.register([relative])
        return self.path / relative

    def register(self, relatives) -> None:
        """Register many files at once (one marker write), refusing any a user owns."""
        new = [str(r) for r in relatives if str(r) not in self.files]
        if not new:
            return
        for rel in dict.fromkeys(new):
            target = self.path / rel
            if not self._inside(rel):
                raise ValueError(f"{rel[:200]}: an output file must lie inside {self.path}")
            if target.exists() or target.is_symlink():
                raise FileExistsError(f"{target} exists and was not written by rotor-id; "
                                      "move it away — rotor-id never replaces a file it did not write")
        self.files.extend(dict.fromkeys(new))
        self._save_marker()
        for rel in new:
            (self.path / rel).parent.mkdir(parents=True, exist_ok=True)

    def _inside(self, relative: str) -> bool:
        """``relative`` names a place inside the folder (no '..', no absolute path, no link out)."""
        if Path(relative).is_absolute():
            return False
        return self.path.resolve() in (self.path / relative).resolve().parents

    def adopt_new(self, before: set[Path]) -> None:
        """Register the files that appeared in the folder since ``before`` (:meth:`snapshot`),
        e.g. log files a library named itself."""
        mine = {self.path / f for f in self.files} | {self.path / MARKER}
        new = sorted(p for p in self.snapshot() - before if p not in mine)
        self.files.extend(str(p.relative_to(self.path)) for p in new)
        if new:
            self._save_marker()

    def snapshot(self) -> set[Path]:
        """Every file under the folder now."""
        return {p for p in self.path.rglob("*") if p.is_file() or p.is_symlink()}

    @contextlib.contextmanager
    def staging(self):
        """A hidden temporary folder inside this one: a writer that picks its own file names
        (``save_figures``) writes there; on success each file is moved in (registered
        first, so a user's file of that name is refused, never replaced)."""
        import shutil
        import tempfile

        tmp = Path(tempfile.mkdtemp(prefix=".rotor-id-staging-", dir=self.path))
        try:
            yield tmp
            files = sorted(p for p in tmp.rglob("*") if p.is_file())
            self.register([str(p.relative_to(tmp)) for p in files])
            for p in files:
                os.replace(p, self.path / p.relative_to(tmp))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    def write(self, relative: str, write: Callable[[Path], None]) -> Path:
        """Write one file atomically (replacing the tool's own file of that name)."""
        return atomic_write(self.file(relative), write, overwrite=True)

    def write_bytes(self, relative: str, data: bytes) -> Path:
        return self.write(relative, lambda p: p.write_bytes(data))

    def write_text(self, relative: str, text: str) -> Path:
        return self.write(relative, lambda p: p.write_text(text, encoding="utf-8"))
