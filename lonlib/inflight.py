"""In-flight checkpoints of a lockstep batch: a killed lockstep experiment resumes mid-search.

The stored trials are the experiment's results (:mod:`lonlib.store`); a search still
training when the process dies would be lost with them alone. At the paper's batch a search
runs for an hour or more on a laptop core, so the lockstep executor also writes its whole
batch (a :class:`lonlib.ddpg.SlotTrainer`: networks, targets, Adam state, replay buffers,
random stream counters, environments, queued greedy evaluations) every few minutes::

    data/<experiment>/.inflight/<id>.<write>.pt   the pickled batch (torch.save), atomic
    data/<experiment>/.inflight/<id>.json         its data file, runs, their stored-trial
                                                  counts and env steps: the commit point,
                                                  written after the data file

A write never replaces the data file the metadata points to: a kill at any moment leaves the
previous checkpoint whole. The batch's process removes its superseded data files; a process
restoring a batch removes the leftovers of a killed write (it holds the batch's run locks).

Restoring is per slot (the lockstep executor, :func:`lonlib.lockstep.run_lockstep`): a slot
continues only if its run still has the trials stored that it had at the write and asks for
the start parameters the slot holds; a slot whose run went on (a search ended after the
write) is dropped and its run continues from its stored trials. A restored search continues
bit for bit as an uninterrupted one would (tested). These files are a cache of work in
progress, never results: deleting ``.inflight/`` costs at most the searches in flight.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import pickle
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from lonlib.store import atomic_write

log = logging.getLogger(__name__)

INFLIGHT_FOLDER = ".inflight"
FORMAT = 2
# Digest of the names of the attributes a SlotTrainer and its parts hold (layout_digest):
# a checkpoint written with another layout is stale. tests/test_lockstep.py fails when the
# layout changes, asking for the new value here.
LAYOUT_DIGEST = "a20ab573a108"
Job = tuple[float, int]


class CheckpointUnreadable(OSError):
    """A checkpoint's file could not be read now (kept: it may be readable later)."""


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


def new_checkpoint_path(out: str | Path) -> Path:
    """The metadata path of a new batch's checkpoint."""
    return inflight_folder(out) / f"{uuid.uuid4().hex[:12]}.json"


def inflight_checkpoints(out: str | Path) -> list[InflightCheckpoint]:
    """The committed checkpoints of experiment ``out``, most searches first (metadata that
    cannot be read or does not add up is reported and skipped)."""
    found = []
    for meta in sorted(inflight_folder(out).glob("*.json")):
        try:
            payload = json.loads(meta.read_text())
            runs = tuple((float(p), int(run)) for p, run in payload["runs"])
            trials = tuple(int(n) for n in payload["trials"])
            steps = tuple(int(n) for n in payload["steps"])
            if payload["format"] != FORMAT or not len(runs) == len(trials) == len(steps):
                raise ValueError("another format, or runs, trials and steps of other lengths")
            found.append(
                InflightCheckpoint(
                    metadata_path=meta,
                    data_path=meta.parent / str(payload["data"]),
                    write_id=str(payload["write_id"]),
                    runs=runs,
                    trials=trials,
                    steps=steps,
                    saved=float(payload["saved"]),
                )
            )
        except (OSError, ValueError, KeyError, TypeError) as error:
            log.warning("%s: unreadable in-flight checkpoint skipped (%s)", meta, error)
    return sorted(found, key=lambda c: -len(c.runs))


def layout_digest(trainer: Any) -> str:
    """A digest of the attribute names of ``trainer`` and of its learner, replay buffer,
    streams and simulator: what a checkpoint's pickle must match to be resumed here."""
    parts = {"trainer": trainer}
    parts.update({name: getattr(trainer, name) for name in ("learner", "replay", "streams", "sim")})
    names = {key: sorted(vars(part)) for key, part in parts.items()}
    return hashlib.sha256(json.dumps(names, sort_keys=True).encode()).hexdigest()[:12]


def save_inflight(metadata_path: Path, trainer: Any, trials: dict[Job, int]) -> None:
    """Write ``trainer`` (a :class:`lonlib.ddpg.SlotTrainer`) as the checkpoint committed by
    ``metadata_path``, with the number of stored trials of each run it trains (``trials``,
    keyed by the slots' tags); then remove the data file it supersedes."""
    write_id = uuid.uuid4().hex[:12]
    data_path = metadata_path.with_name(f"{metadata_path.stem}.{write_id}.pt")
    busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
    runs = [trainer.tags()[slot] for slot in busy]
    buffer = io.BytesIO()
    payload = {
        "format": FORMAT,
        "layout": LAYOUT_DIGEST,
        "write_id": write_id,
        "clock": time.perf_counter(),
        "trainer": trainer,
    }
    torch.save(payload, buffer)
    atomic_write(data_path, buffer.getvalue())
    metadata = {
        "format": FORMAT,
        "write_id": write_id,
        "data": data_path.name,
        "saved": time.time(),
        "runs": [list(run) for run in runs],
        "trials": [trials[run] for run in runs],
        "steps": [int(trainer.steps[slot]) for slot in busy],
    }
    atomic_write(metadata_path, json.dumps(metadata, indent=1).encode())
    remove_leftovers(metadata_path, keep=data_path)


def load_inflight(checkpoint: InflightCheckpoint, device: str = "cpu") -> Any:
    """The :class:`lonlib.ddpg.SlotTrainer` stored in ``checkpoint`` (on ``device``, the
    device it was trained on: the caller checks the configuration), its search clocks
    moved so that time spent dead does not count as search time.

    Raises :class:`CheckpointUnreadable` if the file cannot be read now, ``ValueError`` if
    it is not a batch this code can continue (truncated, another format or layout)."""
    try:
        # Our own pickled batch (this experiment's folder), hence weights_only=False.
        payload = torch.load(checkpoint.data_path, map_location=device, weights_only=False)
    except FileNotFoundError as error:
        raise ValueError(f"{checkpoint.data_path}: missing") from error
    except OSError as error:
        raise CheckpointUnreadable(f"{checkpoint.data_path}: {error}") from error
    except (pickle.UnpicklingError, EOFError, RuntimeError, AttributeError, ImportError) as error:
        raise ValueError(f"{checkpoint.data_path}: cannot be unpickled ({error})") from error
    if not isinstance(payload, dict) or payload.get("write_id") != checkpoint.write_id:
        raise ValueError(f"{checkpoint.data_path}: not the batch its metadata describes")
    if payload.get("format") != FORMAT or payload.get("layout") != LAYOUT_DIGEST:
        raise ValueError(f"{checkpoint.data_path}: written by another version of lonlib")
    trainer = payload["trainer"]
    trainer.resume_clocks(time.perf_counter() - payload["clock"])
    return trainer


def remove_leftovers(metadata_path: Path, keep: Path | None = None) -> None:
    """Remove the batch's data files other than ``keep`` and its interrupted writes (call
    as the batch's owner, i.e. holding its runs' locks)."""
    folder, stem = metadata_path.parent, metadata_path.stem
    for file in [*folder.glob(f"{stem}.*.pt"), *folder.glob(f".{stem}.*.tmp")]:
        if file != keep:
            with contextlib.suppress(FileNotFoundError):
                file.unlink()


def remove_inflight(metadata_path: Path) -> None:
    """Delete a checkpoint: its metadata first (so a half-removed one is never used), then
    its data files."""
    with contextlib.suppress(FileNotFoundError):
        metadata_path.unlink()
    remove_leftovers(metadata_path)
    with contextlib.suppress(FileNotFoundError):
        checkpoint_lock_path(metadata_path).unlink()


def split_inflight(checkpoint: InflightCheckpoint, parts: int, device: str = "cpu") -> None:
    """Replace ``checkpoint`` by ``parts`` checkpoints of about equal numbers of its runs
    (for as many processes; each part continues its searches exactly as the whole would).
    Raises as :func:`load_inflight`, or :class:`lonlib.store.DataWriteError` (then no part
    is left)."""
    trainer = load_inflight(checkpoint, device)
    trials = dict(zip(checkpoint.runs, checkpoint.trials, strict=True))
    busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
    written: list[Path] = []
    try:
        for index in range(min(parts, len(busy))):
            written.append(new_checkpoint_path(checkpoint.metadata_path.parent.parent))
            save_inflight(written[-1], trainer.subset(busy[index::parts]), trials)
    except BaseException:
        for path in written:  # the whole stays the one checkpoint of its runs
            remove_inflight(path)
        raise
    remove_inflight(checkpoint.metadata_path)
