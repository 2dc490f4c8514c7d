"""In-flight checkpoints of a lockstep batch: a killed lockstep experiment resumes mid-search.

The stored trials are the experiment's results (:mod:`lonlib.store`); a search still
training when the process dies would be lost with them alone. At the paper's batch a search
runs for an hour or more on a laptop core, so the lockstep executor also writes its whole
batch (a :class:`lonlib.ddpg.SlotTrainer`: networks, targets, Adam state, replay buffers,
random stream counters, environments, queued greedy evaluations) every few minutes, and
again after every stored trial while a checkpoint exists, so that the checkpoint always
matches the trials stored beside it::

    data/<experiment>/.inflight/<id>.pt     the pickled batch (torch.save), atomic
    data/<experiment>/.inflight/<id>.json   its runs and their stored-trial counts, written
                                            after the .pt file (the commit point)

A batch restored from a checkpoint continues exactly where it was written: its runs' trials
are bit for bit those of an uninterrupted run (tested). A checkpoint is used only if each of
its runs still has the trials stored that it had then, the configuration is the same and
every slot's start parameters are what the run asks for; otherwise it is *stale* (the runs
went on without it), reported and removed. A batch deletes its checkpoint when it finishes.
These files are a cache of work in progress, never results: deleting ``.inflight/`` costs
at most the searches in flight.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from lonlib.store import atomic_write

log = logging.getLogger(__name__)

INFLIGHT_FOLDER = ".inflight"
FORMAT = 1
Job = tuple[float, int]


@dataclass(frozen=True)
class InflightCheckpoint:
    """A stored batch: where it is, its runs and how many trials each had stored."""

    path: Path  # the .pt file; its metadata is beside it as .json
    runs: tuple[Job, ...]
    trials: tuple[int, ...]
    write_id: str
    saved: float  # time.time() of the write
    steps: tuple[int, ...]  # env steps each run's search in flight had trained

    @property
    def env_steps(self) -> int:
        """Env steps trained by the searches in flight, all together."""
        return sum(self.steps)

    @property
    def metadata_path(self) -> Path:
        """The JSON file that commits the checkpoint."""
        return self.path.with_suffix(".json")


def inflight_folder(out: str | Path) -> Path:
    """Where the lockstep batches of experiment ``out`` keep their checkpoints."""
    return Path(out) / INFLIGHT_FOLDER


def new_checkpoint_path(out: str | Path) -> Path:
    """A fresh checkpoint file name for a new batch."""
    return inflight_folder(out) / f"{uuid.uuid4().hex[:12]}.pt"


def inflight_checkpoints(out: str | Path) -> list[InflightCheckpoint]:
    """The committed checkpoints of experiment ``out``, most searches first (a metadata file
    that cannot be read is reported and skipped)."""
    found = []
    for meta in sorted(inflight_folder(out).glob("*.json")):
        try:
            payload = json.loads(meta.read_text())
            found.append(
                InflightCheckpoint(
                    path=meta.with_suffix(".pt"),
                    runs=tuple((float(p), int(run)) for p, run in payload["runs"]),
                    trials=tuple(int(n) for n in payload["trials"]),
                    write_id=str(payload["write_id"]),
                    saved=float(payload["saved"]),
                    steps=tuple(int(n) for n in payload["steps"]),
                )
            )
        except (OSError, ValueError, KeyError, TypeError) as error:
            log.warning("%s: unreadable in-flight checkpoint skipped (%s)", meta, error)
    return sorted(found, key=lambda c: -len(c.runs))


def save_inflight(path: Path, trainer: Any, trials: dict[Job, int]) -> None:
    """Write ``trainer`` (a :class:`lonlib.ddpg.SlotTrainer`) to ``path`` with the number of
    stored trials of each run it trains (``trials``, keyed by the slots' tags)."""
    write_id = uuid.uuid4().hex
    busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
    runs = [trainer.tags()[slot] for slot in busy]
    buffer = io.BytesIO()
    payload = {
        "format": FORMAT,
        "write_id": write_id,
        "clock": time.perf_counter(),
        "trainer": trainer,
    }
    torch.save(payload, buffer)
    atomic_write(path, buffer.getvalue())
    metadata = {
        "format": FORMAT,
        "write_id": write_id,
        "saved": time.time(),
        "runs": [list(run) for run in runs],
        "trials": [trials[run] for run in runs],
        "steps": [int(trainer.steps[slot]) for slot in busy],
    }
    atomic_write(path.with_suffix(".json"), json.dumps(metadata, indent=1).encode())


def load_inflight(checkpoint: InflightCheckpoint, device: str = "cpu") -> Any:
    """The :class:`lonlib.ddpg.SlotTrainer` stored in ``checkpoint`` (on ``device``, the
    device it was trained on: the caller checks the configuration), its search clocks
    moved so that time spent dead does not count as search time. Raises ``ValueError``
    if the file is not the one its metadata committed."""
    try:
        # Our own pickled batch (this experiment's folder), hence weights_only=False.
        payload = torch.load(checkpoint.path, map_location=device, weights_only=False)
    except Exception as error:  # a truncated or foreign file: unusable, not fatal
        raise ValueError(f"{checkpoint.path}: cannot be read ({error})") from error
    if payload.get("format") != FORMAT or payload.get("write_id") != checkpoint.write_id:
        raise ValueError(f"{checkpoint.path}: not the batch its metadata describes")
    trainer = payload["trainer"]
    trainer.resume_clocks(time.perf_counter() - payload["clock"])
    return trainer


def split_inflight(checkpoint: InflightCheckpoint, parts: int, device: str = "cpu") -> None:
    """Replace ``checkpoint`` by ``parts`` checkpoints of about equal numbers of its runs
    (for as many processes; each part continues its searches exactly as the whole would).
    Raises ``ValueError`` if it cannot be read."""
    trainer = load_inflight(checkpoint, device)
    trials = dict(zip(checkpoint.runs, checkpoint.trials, strict=True))
    busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
    for index in range(min(parts, len(busy))):
        part = trainer.subset(busy[index::parts])
        save_inflight(new_checkpoint_path(checkpoint.path.parent.parent), part, trials)
    remove_inflight(checkpoint.path)


def remove_inflight(path: Path) -> None:
    """Delete a checkpoint (metadata first, so that a half-removed one is never used)."""
    for file in (path.with_suffix(".json"), path):
        with contextlib.suppress(FileNotFoundError):
            file.unlink()
