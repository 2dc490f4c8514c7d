"""What the ``lonlib`` verbs share: the folders and pages they are given, checked, and a
reader's ``--dry-run``."""

from __future__ import annotations

import os
from pathlib import Path

from lonlib.storage.atomic import DataWriteError, check_output_place


def experiment_folder(text: str) -> Path:
    """``text`` as a folder that exists: ValueError saying "no such folder" or "not a folder"
    otherwise (whether it holds an experiment is the reader's check)."""
    path = Path(text)
    if not path.exists():
        raise ValueError(f"{path}: no such folder")
    if not path.is_dir():
        raise ValueError(f"{path}: not a folder (it is a file); give an experiment's folder")
    return path


def markdown_page(text: str | None) -> Path | None:
    """The Markdown page of ``--docs`` (or ``None``): ValueError if it is missing."""
    if text is None:
        return None
    page = Path(text)
    if page.is_dir():
        raise ValueError(f"--docs {page}: is a folder, not a file")
    if not page.is_file():
        raise ValueError(f"--docs {page}: no such file")
    return page


def check_output_folder(out: Path) -> str:
    """What ``lonlib run`` checks of its output folder before computing, without creating or
    writing anything: the parent exists, ``out`` is not a file and, if it exists, is
    writable. Returns "new" or "exists"."""
    check_output_place(out)
    if out.exists() and not os.access(out, os.W_OK | os.X_OK):
        raise DataWriteError(13, f"cannot write {out}: permission denied")
    return "exists" if out.exists() else "new"


def dry_run_reader(verb: str, root: Path) -> None:
    """``--dry-run`` of a verb that reads an experiment: the folder holds one, and (but for
    verify) its data match their seal."""
    from lonlib.storage.digests import check_readable
    from lonlib.storage.layout import read_manifest

    manifest = read_manifest(root)
    if verb != "verify":  # a reader refuses changed data (status says so); verify reports it
        reads = verb != "status"  # status reads the tables, not every trial's files
        check_readable(root, manifest, f"lonlib {verb}", refuse=reads, files=reads)
    name = manifest["config"].get("name", "?")
    print(f"dry run: lonlib {verb} would read the experiment {name!r} in {root}. Nothing done.")


__all__ = [
    "check_output_folder",
    "dry_run_reader",
    "experiment_folder",
    "markdown_page",
]
