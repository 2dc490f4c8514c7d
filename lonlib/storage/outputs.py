"""Putting an analysis's outputs in place: figures and tables (``lonlib analyse``) and
recordings (``lonlib record``), so that a kill at any point never leaves a folder that reads
as tampered.

**Write order**, the trials' own (:mod:`lonlib.storage.digests`): each output is written
under a temporary name first, in a hidden folder beside its place (:func:`staging_folder`,
``figures/.staging.tmp/``, ``recordings/.staging.tmp/``, which no reader and no seal looks
into, and git ignores as a temporary); then their digests are sealed ahead in the root
(:func:`lonlib.storage.digests.seal_outputs_ahead`); then each is renamed into place (a
figure an analysis no longer makes is removed); then the root is resealed
(:func:`lonlib.storage.digests.reseal_outputs`), which settles what was sealed ahead; then the
hidden folder is removed. One command at a time writes a folder's outputs (its lock,
:data:`OUTPUTS_LOCK`). A kill while the outputs are written leaves the folder as it was
(and the hidden folder, which the next run empties first); a kill after the seal ahead leaves
each output as sealed or as sealed ahead, which ``lonlib verify`` reports as pending, and the
same command again completes. An unsealed folder gets the same renames, and no seal.
"""

from __future__ import annotations

import errno
import os
import shutil
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from lonlib.storage.atomic import DataWriteError, write_error
from lonlib.storage.digests import file_digest, reseal_outputs, seal_outputs_ahead
from lonlib.storage.lock import exclusive_lock

STAGING = ".staging.tmp"
"""The hidden folder, inside the outputs' folder, where they are written first."""
OUTPUTS_LOCK = ".lock"
"""Inside the outputs' folder: held while they are written and put in place."""


@contextmanager
def staging_folder(folder: Path) -> Iterator[Path]:
    """For the ``with`` block: an empty hidden folder inside ``folder`` (created, with
    ``folder``, if missing) to write outputs into before :func:`publish_figures` or
    :func:`publish_recordings` (called in the block) puts them in place. ``folder``'s lock
    (:data:`OUTPUTS_LOCK`) is held meanwhile: another ``analyse`` or ``record`` of the same
    folder waits, and what a killed one left in the hidden folder is removed first (a file
    or link found under :data:`STAGING`, lonlib's reserved name, is unlinked). Use the
    outputs' own file names (a rerun recording's id is made from its name)."""
    folder = Path(folder)
    with exclusive_lock(folder / OUTPUTS_LOCK, record_holder=False):
        staging = folder / STAGING
        _clear(staging)
        try:
            staging.mkdir()
        except OSError as error:
            raise write_error(staging, error) from error
        yield staging


def _clear(staging: Path) -> None:
    """Make way for the hidden folder: what a killed run left in it removed, and a file or
    link found under its reserved name unlinked (a link never followed)."""
    planted = staging.is_symlink() or (staging.exists() and not staging.is_dir())
    try:
        if planted:
            staging.unlink()
        else:
            shutil.rmtree(staging, ignore_errors=True)
        if os.path.lexists(staging):
            raise FileExistsError(errno.EEXIST, "it is still there")
    except OSError as error:
        raise DataWriteError(
            error.errno,
            f"{staging}: lonlib's reserved staging name ({STAGING}, where analyse and record "
            f"write their outputs first) could not be cleared ({error.strerror or error}); "
            "remove it, then run again",
        ) from error


def publish_figures(
    root: Path,
    staged: Iterable[Path],
    removed: Iterable[str] = (),
    *,
    staging: Path | None = None,
    inputs: str | None = None,
) -> list[Path]:
    """Put the figures and tables ``staged`` (files of :func:`staging_folder`'s folder,
    ``staging``, which names it when nothing is staged) in place in the folder above it,
    and remove those named ``removed`` (file names there that this analysis no longer
    makes), sealed ahead and resealed in a sealed experiment ``root`` (see the module
    docstring; ``inputs``: the digest of the trials they were drawn from, as the analysis
    loaded them, :func:`lonlib.storage.digests.loaded_inputs`; None: the trials as sealed
    now): their final paths, in the order given (each once). The 3-D LON's HTML pages are
    put in place too, not sealed (kept out of git)."""
    root, staged = Path(root), list(dict.fromkeys(Path(p) for p in staged))
    folder = _target(staged, staging)
    if folder is None:
        return []
    gone = sorted({name for name in removed if (folder / name).exists()})
    if not staged and not gone:
        return []
    final = [folder / path.name for path in staged]
    for path in staged:
        _sync(path)
    ahead: dict[str, str | None] = {
        _key(root, folder / path.name): file_digest(path)
        for path in staged
        if path.suffix != ".html"
    }
    ahead.update({_key(root, folder / name): None for name in gone})
    seal_outputs_ahead(root, figures=ahead, inputs=inputs)
    _rename(staged, folder, gone)
    reseal_outputs(root, figures=final, inputs=inputs)
    shutil.rmtree(folder / STAGING, ignore_errors=True)
    return final


def publish_recordings(
    root: Path, staged: Iterable[Path], index: Mapping[str, Mapping[str, Any]]
) -> list[Path]:
    """Put the recordings ``staged`` (files of :func:`staging_folder`'s folder inside
    ``<root>/recordings``) in place, sealed ahead and resealed in a sealed experiment
    ``root`` with ``index``, the index of every recording the folder then holds (file name →
    its trial's ``p``, ``run``, ``index``, ``fitness``; see the module docstring): their
    final paths, in the order given (each once)."""
    root, staged = Path(root), list(dict.fromkeys(Path(p) for p in staged))
    folder = _target(staged)
    if folder is None:
        return []
    by_name = {path.name: path for path in staged}
    for path in staged:
        _sync(path)
    ahead = {
        name: {**dict(info), "sha256": file_digest(by_name.get(name, folder / name))}
        for name, info in index.items()
        if name in by_name or (folder / name).is_file()
    }
    seal_outputs_ahead(root, recordings=ahead)
    _rename(staged, folder, [])
    reseal_outputs(root, recordings=index)
    shutil.rmtree(staged[0].parent, ignore_errors=True)
    return [folder / path.name for path in staged]


def _target(staged: list[Path], staging: Path | None = None) -> Path | None:
    """The folder the staged files (of ``staging``, when given) go to: the one above their
    staging folder (None: nothing staged and no staging folder named)."""
    folders = {path.parent for path in staged} | ({Path(staging)} if staging else set())
    if not folders:
        return None
    if len(folders) != 1 or next(iter(folders)).name != STAGING:
        raise ValueError(f"not the files of one staging folder ({STAGING}): {sorted(folders)}")
    return next(iter(folders)).parent


def _key(root: Path, path: Path) -> str:
    return path.relative_to(root).as_posix()


def _sync(path: Path) -> None:
    """Flush a staged file to disk before its digest is sealed ahead (it is renamed next)."""
    try:
        handle = os.open(path, os.O_RDONLY)
        try:
            os.fsync(handle)
        finally:
            os.close(handle)
    except OSError as error:
        raise write_error(path, error) from error


def _rename(staged: list[Path], folder: Path, gone: Iterable[str]) -> None:
    """Each staged file renamed into ``folder``, the ``gone`` files removed, the folder's
    entries flushed."""
    try:
        for path in staged:
            os.replace(path, folder / path.name)
        for name in gone:
            (folder / name).unlink(missing_ok=True)
        handle = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(handle)
        except OSError as error:  # a file system that cannot sync a folder: renamed all the same
            if error.errno != errno.EINVAL:
                raise
        finally:
            os.close(handle)
    except OSError as error:
        raise write_error(folder, error) from error


__all__ = ["OUTPUTS_LOCK", "STAGING", "publish_figures", "publish_recordings", "staging_folder"]
