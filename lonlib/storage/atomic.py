"""Atomic file I/O of experiment folders, and its errors.

Every file is written to a temporary name in the same folder (``.<name>.<random>.tmp``),
flushed to disk and renamed into place, so a reader never sees half a file; readers open
exact names and never read a temporary. A file that cannot be read raises
:class:`CorruptDataError` naming it; a file that cannot be written raises
:class:`DataWriteError` naming it and the cause, leaving what was stored before unchanged.
Nothing but temporaries is ever deleted.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import tempfile
from pathlib import Path

import pandas as pd


class CorruptDataError(RuntimeError):
    """A stored file exists but cannot be read; the message names the file."""


class MissingExperimentError(FileNotFoundError):
    """No experiment has been sampled into a folder yet; the message says what to run."""


class DataWriteError(OSError):
    """A file could not be written (disk full, read-only folder, missing folder...). The
    message names the file and the cause; ``errno`` is the cause's. What was stored before
    is unchanged."""


TEMPORARY_SUFFIX = ".tmp"


def temporary_files(folder: Path, name: str = "*") -> list[Path]:
    """Temporary files that writes of ``name`` (any file by default) left in ``folder``
    when they were interrupted; never read as data."""
    return sorted(Path(folder).glob(f".{name}.*{TEMPORARY_SUFFIX}"))


def remove_temporary_files(folder: Path, name: str = "*") -> None:
    """Delete what interrupted writes of ``name`` left in ``folder``. Call it only while
    holding the lock that guards those writes (a live writer's file would vanish)."""
    for path in temporary_files(folder, name):
        try:
            path.unlink()
        except FileNotFoundError:
            pass
        except OSError as error:
            raise write_error(path, error) from error


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, flush it to disk, rename it into
    place and flush the folder entry, so ``path`` holds either its old or its new content.

    Raises :class:`DataWriteError` naming ``path`` and the cause (e.g. ENOSPC, EROFS); the
    temporary file is removed where the file system still allows it.
    """
    path = Path(path)
    tmp: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, name = tempfile.mkstemp(
            prefix=f".{path.name}.", suffix=TEMPORARY_SUFFIX, dir=path.parent
        )
        tmp = Path(name)
        try:
            _write_all(handle, data)
            os.fsync(handle)
        finally:
            os.close(handle)
        os.replace(tmp, path)
        tmp = None
        _fsync_folder(path.parent)
    except OSError as error:
        raise write_error(path, error) from error
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):  # a read-only folder keeps it; see temporary_files
                tmp.unlink()


def write_error(path: Path, error: OSError) -> DataWriteError:
    """The :class:`DataWriteError` for ``error`` while writing ``path``."""
    cause = error.strerror or str(error)
    return DataWriteError(
        error.errno,
        f"cannot write {path}: {cause}. Files stored before are unchanged; fix the cause "
        "(free space, permissions, mount) and run again to resume",
    )


def _write_all(handle: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(handle, view) :]


def _fsync_folder(folder: Path) -> None:
    """Make a rename durable. Some file systems cannot sync a folder (EINVAL): the rename
    itself has succeeded there, so that case is not an error."""
    handle = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(handle)
    except OSError as error:
        if error.errno != errno.EINVAL:
            raise
    finally:
        os.close(handle)


def write_json(path: Path, payload: dict, compact: bool = False) -> None:
    """Atomically write ``payload`` as indented JSON (``compact``: without whitespace, for
    records holding long lists, such as a study cell's per-episode histories)."""
    layout = {"separators": (",", ":")} if compact else {"indent": 2}
    atomic_write(path, json.dumps(payload, default=str, **layout).encode())


def read_json(path: Path) -> dict:
    """Read a JSON file written by :func:`write_json` (CorruptDataError if unreadable)."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise CorruptDataError(f"{path}: cannot read JSON ({error})") from error


def check_output_place(out: Path) -> None:
    """What :func:`check_output_folder` checks without creating or writing anything: the
    parent of ``out`` is an existing folder and ``out`` is not a file (DataWriteError
    naming the cause otherwise)."""
    out = Path(out)
    if out.is_symlink() and not out.exists():
        raise DataWriteError(
            errno.ENOENT,
            f"cannot write {out}: it is a symbolic link to {os.readlink(out)}, which does not "
            "exist; create that folder or give another --out",
        )
    parent = out.parent
    if parent.exists() and not parent.is_dir():
        raise DataWriteError(
            errno.ENOTDIR, f"cannot write {out}: its parent {parent} is a file, not a folder"
        )
    if not parent.is_dir():
        missing = next(p for p in [parent, *parent.parents] if p.parent.is_dir() or p == p.parent)
        if missing.exists() and not missing.is_dir():  # a file further up
            raise DataWriteError(
                errno.ENOTDIR, f"cannot write {out}: {missing} is a file, not a folder"
            )
        raise DataWriteError(
            errno.ENOENT,
            f"cannot write {out}: its parent folder {parent} does not exist "
            "(a typo, or a file system that is not mounted?); create it first",
        )
    if out.exists() and not out.is_dir():
        raise DataWriteError(errno.ENOTDIR, f"cannot write {out}: it is a file, not a folder")


def check_output_folder(out: Path) -> None:
    """Before any compute: ``out`` exists or can be created inside an existing folder, and
    accepts a new file. A missing parent is refused rather than created (a typo, or a shared
    file system that is not mounted, would otherwise silently write elsewhere).

    Raises :class:`DataWriteError` naming the folder and the cause.
    """
    out = Path(out)
    check_output_place(out)
    try:
        out.mkdir(exist_ok=True)
        handle, name = tempfile.mkstemp(prefix=".write-check.", suffix=TEMPORARY_SUFFIX, dir=out)
        os.close(handle)
        os.unlink(name)
    except OSError as error:
        raise write_error(out, error) from error


def parquet_bytes(table: pd.DataFrame) -> bytes:
    """A table as Parquet file content."""
    return table.to_parquet(None, index=False)
