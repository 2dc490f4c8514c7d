"""The seal of a folder that is not an experiment (a study's summaries,
:mod:`lonlib.storage.digests`): each kept file's digest, written and checked."""

from __future__ import annotations

from fnmatch import fnmatch
from pathlib import Path

from lonlib.storage._digests_check import SealCheck
from lonlib.storage._digests_format import (
    SEAL_FORMAT,
    SEAL_NAME,
    TamperedDataError,
    file_digest,
    is_sealed,
    read_seal,
    write_seal,
)


def _patterns(folder: Path) -> list[str]:
    ignore = folder / ".gitignore"
    lines = ignore.read_text().splitlines() if ignore.is_file() else []
    return [line.strip() for line in lines if line.strip() and not line.startswith("#")]


def _sealable_files(folder: Path, top: Path | None = None) -> dict[str, Path]:
    """The files of a study folder that are kept: not matched by a ``.gitignore`` on the
    way down (``*.npz``, ``inflight/``; names only, the patterns these folders use) nor
    temporaries, except the seal, the ``.gitignore`` files and any subfolder with a seal of
    its own (sealed by itself)."""
    top = folder if top is None else top
    patterns = [*_patterns(folder), ".*.tmp", "*.tmp"]
    return _walk(folder, top, patterns)


def _walk(folder: Path, top: Path, patterns: list[str]) -> dict[str, Path]:
    out: dict[str, Path] = {}
    patterns = [*patterns, *_patterns(folder)]
    for path in sorted(folder.iterdir()):
        name = path.name
        if path.is_dir():
            ignored = any(p.rstrip("/") == name for p in patterns if p.endswith("/"))
            if not ignored and not (path / SEAL_NAME).is_file():
                out.update(_walk(path, top, patterns))
        elif name not in (SEAL_NAME, ".gitignore") and not any(
            fnmatch(name, p) for p in patterns if not p.endswith("/")
        ):
            out[path.relative_to(top).as_posix()] = path
    return out


def seal_files(folder: Path) -> int:
    """Seal a folder that is not an experiment (a study's stored summaries): each kept
    file's digest. Returns the number of files sealed."""
    folder = Path(folder)
    if any(folder.glob("p=*/run_*")) or (folder / "manifest.json").exists():
        raise ValueError(f"{folder}: an experiment's folder: its seal comes from a full verify")
    if not _sealable_files(folder):
        raise ValueError(f"{folder}: no file to seal (a typo in the folder's name?)")
    return _write_files_seal(folder)


def _write_files_seal(folder: Path) -> int:
    files = _sealable_files(folder)
    write_seal(
        folder / SEAL_NAME,
        {
            "format": SEAL_FORMAT,
            "kind": "files",
            "files": {name: file_digest(path) for name, path in files.items()},
        },
    )
    return len(files)


def reseal_files_if_sealed(folder: Path) -> None:
    """A writer of a sealed study folder reseals what it wrote (nothing if unsealed)."""
    if is_sealed(folder):
        _write_files_seal(Path(folder))


def check_files_seal(folder: Path) -> SealCheck:
    """Compare a ``files`` seal with the folder: a missing or changed file is a problem, a
    kept file the seal does not list is pending (written since; sealed by the next writer
    or ``lonlib verify --seal``)."""
    folder = Path(folder)
    check = SealCheck(folder, is_sealed(folder))
    if not check.sealed:
        return check
    try:
        seal = read_seal(folder / SEAL_NAME)
    except TamperedDataError as error:
        check.problems.append((SEAL_NAME, str(error).split(": ", 1)[-1]))
        return check
    if seal.get("kind") != "files":
        check.problems.append(
            ("manifest.json", "missing: the seal is an experiment's, and its manifest is gone")
        )
        return check
    listed = seal.get("files", {})
    present = _sealable_files(folder)
    for name, digest in sorted(listed.items()):
        if name not in present:
            check.problems.append((name, "a sealed file is missing"))
        elif file_digest(present[name]) != digest:
            check.problems.append((name, "differs from its seal"))
    for name in sorted(set(present) - set(listed)):
        check.pending.append((name, "not in the seal (written since it was sealed)"))
    return check


__all__ = [
    "check_files_seal",
    "reseal_files_if_sealed",
    "seal_files",
]
