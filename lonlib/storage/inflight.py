"""In-flight checkpoints as files: their folder, names, locks and metadata (plain JSON).

What a killed lockstep experiment left mid-search is described in
:mod:`lonlib.experiment.checkpoints` (the format, and the tensors saved with torch); this module
lists and checks the checkpoints of an experiment folder from their metadata alone, without
torch, so that the status of an experiment (:mod:`lonlib.storage.status`) reads them.
"""

from __future__ import annotations

import json
import logging
import re
import uuid
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lonlib.storage.layout import INFLIGHT_FOLDER, Job
from lonlib.util.plain_data import (
    plain_float,
    plain_int,
    plain_list,
    plain_str,
    short_repr,
)

log = logging.getLogger(__name__)

# The checkpoint layout's version: bump it when the layout of
# lonlib.ddpg.checkpoint.to_checkpoint changes
# (tests/experiment/test_inflight.py fails until the new layout is written down there).
FORMAT = 3
# A batch's id and a write's id (the names of its files): what new_id makes. Files of other
# names are never read, and never used as patterns to find files by (a name "*" would be).
ID = re.compile(r"[0-9a-f]{12}")
# An experiment's runs: its perturbation strengths and its number of runs per strength.
Plan = tuple[Collection[float], int]


class CheckpointUnreadable(OSError):
    """A checkpoint's file could not be read now (kept: it may be readable later)."""


class OtherSettings(Exception):
    """A checkpoint trained with other settings than this session's (kept: a session with
    its settings continues it; meanwhile its runs restart from their stored trials)."""


@dataclass(frozen=True)
class InflightCheckpoint:
    """A stored batch: its metadata and data files, its runs, their stored-trial counts and
    the env steps each run's search had trained."""

    metadata_path: Path
    data_path: Path
    write_id: str
    runs: tuple[Job, ...]
    trials: tuple[int, ...]
    steps: tuple[int, ...]
    saved: float  # time.time() of the write

    @property
    def name(self) -> str:
        """The batch's id (its metadata file's stem)."""
        return self.metadata_path.stem


def inflight_folder(out: str | Path) -> Path:
    """Where the lockstep batches of experiment ``out`` keep their checkpoints."""
    return Path(out) / INFLIGHT_FOLDER


def checkpoint_lock_path(checkpoint: InflightCheckpoint | Path) -> Path:
    """The lock file the batch writing a checkpoint holds while it trains (a checkpoint or
    its metadata path)."""
    path = checkpoint.metadata_path if isinstance(checkpoint, InflightCheckpoint) else checkpoint
    return path.with_suffix(".lock")


def new_id() -> str:
    """A new batch or write id (:data:`ID`)."""
    return uuid.uuid4().hex[:12]


def new_checkpoint_path(out: str | Path) -> Path:
    """The metadata path of a new batch's checkpoint."""
    return inflight_folder(out) / f"{new_id()}.json"


def inflight_checkpoints(out: str | Path, plan: Plan | None = None) -> list[InflightCheckpoint]:
    """The committed checkpoints of experiment ``out``, most searches first. Metadata that
    cannot be read or does not add up (with ``plan``, the experiment's runs: a run that is
    not one of them) is reported and skipped; so is a checkpoint of another :data:`FORMAT`
    (once per process), which is never read further."""
    found, refused = scan_inflight(out, plan)
    for meta, reason in refused:
        log.warning("%s: refused in-flight checkpoint skipped (%s)", meta, reason)
    return found


def scan_inflight(
    out: str | Path, plan: Plan | None = None
) -> tuple[list[InflightCheckpoint], list[tuple[Path, str]]]:
    """The committed checkpoints of experiment ``out`` (most searches first), and the
    metadata files refused, with why (their content: truncated, planted, not adding up,
    with ``plan`` listing a run that is not one of the experiment's). A file that cannot be
    read now is reported and skipped, not refused; so is a checkpoint of another
    :data:`FORMAT` (once per process). Never raises for a file's content."""
    found, refused = [], []
    for meta in sorted(inflight_folder(out).glob("*.json")):
        if not ID.fullmatch(meta.stem):
            _report_once(
                meta,
                "%s: not the name of an in-flight checkpoint (12 hex digits): ignored, "
                "never read or removed",
            )
            continue
        try:
            data = meta.read_bytes()  # an error here is the file system's, past it the content's
        except OSError as error:
            log.warning("%s: unreadable in-flight checkpoint skipped (%s)", meta, error)
            continue
        try:
            payload = json.loads(data)
            if not isinstance(payload, dict):
                raise ValueError("not a JSON object")
            if type(payload.get("format")) is not int or payload["format"] != FORMAT:
                _report_other_format(meta, payload.get("format"))
                continue
            found.append(_listed(meta, payload, plan))
        except Exception as error:  # whatever the file holds: refused (RecursionError too)
            refused.append((meta, refusal_reason(error)))
    return sorted(found, key=lambda c: -len(c.runs)), refused


def refusal_reason(error: BaseException) -> str:
    """Why a file was refused, in a line (the error's type if its text says nothing)."""
    text = str(error).splitlines()[0] if str(error) else ""
    return text[:300] or type(error).__name__


def _listed(meta: Path, payload: dict[str, Any], plan: Plan | None) -> InflightCheckpoint:
    """The checkpoint whose metadata ``meta`` holds ``payload`` (raises if it does not add
    up, names a data file other than its own, or a run not of ``plan``)."""
    runs = tuple(
        _job(entry, f"runs[{i}]") for i, entry in enumerate(plain_list(payload["runs"], "runs"))
    )
    trials = tuple(plain_int(n, "trials", 0) for n in plain_list(payload["trials"], "trials"))
    steps = tuple(plain_int(n, "steps", 0) for n in plain_list(payload["steps"], "steps"))
    if not len(runs) == len(trials) == len(steps):
        raise ValueError("runs, trials and steps of other lengths")
    if len(set(runs)) != len(runs):
        raise ValueError("a run is listed twice")
    if plan is not None:
        perturbations, count = plan
        for p, run in runs:
            if p not in perturbations or run >= count:
                raise ValueError(f"run {run} of p={p} is not one of this experiment's")
    write_id = plain_str(payload["write_id"], "write_id")
    if not ID.fullmatch(write_id):
        raise ValueError(f"write_id must be 12 hex digits, not {short_repr(write_id)}")
    data = f"{meta.stem}.{write_id}.pt"
    if payload["data"] != data:
        raise ValueError(f"its data file must be {data}, not {short_repr(payload['data'])}")
    return InflightCheckpoint(
        metadata_path=meta,
        data_path=meta.parent / data,
        write_id=write_id,
        runs=runs,
        trials=trials,
        steps=steps,
        saved=plain_float(payload["saved"], "saved", finite=True),
    )


def _job(entry: Any, name: str) -> Job:
    """A listed run ``[p, run]``: a finite p and a run number >= 0."""
    p, run = plain_list(entry, name, 2)
    return plain_float(p, f"{name} p", finite=True), plain_int(run, f"{name} run", 0)


_reported: set[Path] = set()


def _report_once(meta: Path, message: str, *args: Any) -> None:
    """Log ``message`` (``%s``: ``meta``, then ``args``) about ``meta`` once per process."""
    if meta in _reported:
        return
    _reported.add(meta)
    log.warning(message, meta, *args)


def _report_other_format(meta: Path, found: Any) -> None:
    """Say (once per process) that the checkpoint ``meta`` of format ``found`` is not read,
    what that costs, and how to silence it."""
    kind = "a pickled checkpoint of an older lonlib" if found == 2 else "another lonlib's"
    _report_once(
        meta,
        "%s: in-flight checkpoint of format %s (%s), this lonlib reads format %d: not read "
        "(nothing in it runs). Its runs continue from their stored trials, losing at most the "
        "minutes they had in flight. Delete %s.* (or, with no lockstep batch running, %s/) to "
        "silence this message",
        short_repr(found)[:40],
        kind,
        FORMAT,
        meta.with_suffix(""),
        meta.parent,
    )
