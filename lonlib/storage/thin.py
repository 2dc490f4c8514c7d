"""Thinning an experiment's training histories before committing it.

A local search's history (``history_<i>.parquet``) holds one row per training episode. With
``judge_every`` > 0 most rows are episodes whose policy was not judged (no greedy fitness),
and on one cart a search that keeps falling off early runs thousands of short episodes: the
one-cart LON's histories were ~80 % of its folder. Thinning keeps the rows that carry a
greedy fitness (the judged policies: the search's fitness curve) and the last row (its
last training episode's env steps and losses), and drops the others. Nothing else in the folder
changes; no stored fitness, optimum, label or recording depends on a history, so `lonlib
verify` replays a thinned folder as before. A thinned history is a summary: the dropped rows
come back only by re-running the search (the result path repeats bit for bit). Thinning
changes the folder's :func:`lonlib.storage.result_path.experiment_digest` (it hashes the
histories): compare a re-run with a thinned folder after thinning the re-run too. In a sealed
folder (:mod:`lonlib.storage.digests`) thinning first checks the seal, then reseals the
histories it rewrote.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from lonlib.storage.atomic import CorruptDataError, atomic_write, parquet_bytes
from lonlib.storage.digests import (
    bytes_digest,
    check_readable,
    is_sealed,
    reseal_files,
    seal_ahead,
    settle_ahead,
)
from lonlib.storage.layout import MANIFEST_LOCK, read_manifest
from lonlib.storage.lock import exclusive_lock, sampling_lock_or_refuse

HISTORY_GLOB = "p=*/run_*/history_*.parquet"
"""Where an experiment folder keeps its training histories (:mod:`lonlib.storage.layout`)."""


@dataclass(frozen=True)
class ThinReport:
    """What :func:`thin_histories` did (or, on a dry run, would do)."""

    files: int
    """History files found."""
    thinned: int
    """Files that lost rows (the others already held judged rows only)."""
    rows_before: int
    """Rows in all histories before."""
    rows_after: int
    """Rows in all histories after."""
    bytes_before: int
    """Bytes of all history files before."""
    bytes_after: int
    """Bytes of all history files after (on a dry run: of the thinned tables)."""

    def summary(self) -> str:
        """One line: files, rows and megabytes before and after."""
        return (
            f"{self.files} histories ({self.thinned} thinned): {self.rows_before:,} -> "
            f"{self.rows_after:,} rows, {self.bytes_before / 1e6:.2f} -> "
            f"{self.bytes_after / 1e6:.2f} MB"
        )


def thinned_history(history: pd.DataFrame) -> pd.DataFrame:
    """The rows of ``history`` with a greedy fitness (the judged episodes) and its last row,
    in their order. ValueError if it has no ``greedy_fitness`` column."""
    if "greedy_fitness" not in history:
        raise ValueError("a training history must have a 'greedy_fitness' column")
    keep = history["greedy_fitness"].notna()
    if len(keep):
        keep.iloc[-1] = True
    return history[keep.to_numpy()].reset_index(drop=True)


def thin_histories(folder: str | Path, dry_run: bool = False) -> ThinReport:
    """Thin every training history of the experiment in ``folder`` in place
    (:func:`thinned_history`, each file written atomically); ``dry_run`` reports and
    writes nothing. Idempotent: a thinned history is left as it is."""
    root = Path(folder)
    manifest = read_manifest(root)  # an experiment folder, or the error that says how to make one
    linked = [
        p
        for pattern in ("p=*", "p=*/run_*", "p=*/run_*/*")
        for p in sorted(root.glob(pattern))
        if p.is_symlink()
    ]
    if linked:
        raise CorruptDataError(
            f"{linked[0]}: a symbolic link in an experiment's run folder; thin rewrites files "
            "in place and follows no link: copy the experiment instead of linking its files"
        )
    check_readable(root, manifest, "lonlib thin")  # before any file is rewritten
    files = sorted(root.glob(HISTORY_GLOB))
    plans = []
    thinned = rows_before = rows_after = bytes_before = bytes_after = 0
    for path in files:
        history = pd.read_parquet(path)
        try:
            kept = thinned_history(history)
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None
        size = path.stat().st_size
        rows_before += len(history)
        rows_after += len(kept)
        bytes_before += size
        if len(kept) == len(history):
            bytes_after += size
            continue
        data = parquet_bytes(kept)
        bytes_after += len(data)
        thinned += 1
        plans.append((path, data))
    if not dry_run and (plans or _ahead(root)):
        _rewrite(root, plans)
    return ThinReport(len(files), thinned, rows_before, rows_after, bytes_before, bytes_after)


def _ahead(root: Path) -> bool:
    """Whether a run of a sealed folder still holds a rewrite sealed ahead (a thin killed
    part-way, which this thin completes)."""
    return is_sealed(root) and any(
        '"next"' in path.read_text() for path in root.glob("p=*/run_*/digests.json")
    )


def _rewrite(root: Path, plans: list[tuple[Path, bytes]]) -> None:
    """Rewrite the histories, with no sampling session on the folder (it appends to the runs'
    digests that a reseal rewrites); in a sealed folder their new digests are sealed ahead
    (a kill part-way leaves each history accepted as old or new), then made the seal."""
    with sampling_lock_or_refuse(root, "thin"):
        sealed = is_sealed(root)
        if sealed:
            seal_ahead(root, {path: bytes_digest(data) for path, data in plans})
        for path, data in plans:
            atomic_write(path, data)
        if sealed:
            for run in sorted(root.glob("p=*/run_*")):  # and an earlier thin killed part-way
                settle_ahead(run, root)
            with exclusive_lock(root / MANIFEST_LOCK, record_holder=False):
                reseal_files(root, read_manifest(root), [path for path, _ in plans])


__all__ = ["HISTORY_GLOB", "ThinReport", "thin_histories", "thinned_history"]
