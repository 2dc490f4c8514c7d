"""In-flight checkpoints of a lockstep batch: a killed lockstep experiment resumes mid-search.

The stored trials are the experiment's results (:mod:`lonlib.storage.trials`); a search still
training when the process dies would be lost with them alone. At the paper's batch a search
runs for an hour or more on a laptop core, so the lockstep executor also writes its whole
batch (a :class:`lonlib.ddpg.trainer.SlotTrainer`: networks, targets, Adam state, replay buffers,
random stream seeds, environments, queued greedy evaluations) every few minutes::

    data/<experiment>/.inflight/<id>.<write>.pt   the batch's tensors, atomic: a torch.save
                                                  of {"format", "write_id", "tensors": {name:
                                                  tensor}}, read with weights_only=True
    data/<experiment>/.inflight/<id>.json         the commit point, written after the data
                                                  file: format, write_id, data file, runs,
                                                  their stored-trial counts and env steps,
                                                  and "trainer", the batch's plain data
                                                  (settings, searches, queue, stream seeds,
                                                  the simulator's generator state)

Data, not code: the batch is exported by :func:`lonlib.ddpg.checkpoint.to_checkpoint` as
named tensors and JSON that name no Python class, and read back with ``torch.load(...,
weights_only=True)`` (which builds tensors and plain containers only) and :mod:`json`, every
tensor's shape and dtype and every value's kind and range checked against a batch of the
stored settings and the experiment's runs before anything is used or locked
(:func:`~lonlib.ddpg.checkpoint.from_checkpoint`). So a planted or damaged file is refused
with a reason (and removed) without running anything, never a traceback; files not named by
lonlib's ids (:data:`ID`) are ignored. A checkpoint does not depend on module paths or
class layouts. Every checkpoint carries :data:`FORMAT`;
one of another format, such as the pickled checkpoints (format 2) of lonlib before, is
refused with a message and left in place: its runs continue from their stored trials.
There is no converter: reading format 2 means unpickling it, the hazard this format removes.

A write never replaces the data file the metadata points to: a kill at any moment leaves the
previous checkpoint whole. The batch's process removes its superseded data files; a process
restoring a batch removes the leftovers of a killed write (it holds the batch's run locks).

Restoring is per slot (the lockstep executor, :func:`lonlib.experiment.lockstep.run_lockstep`): a
slot continues only if its run still has the trials stored that it had at the write and asks for the
start parameters the slot holds; a slot whose run went on (a search ended after the write) is
dropped and its run continues from its stored trials. A restored search continues bit for bit as an
uninterrupted one would (tested). These files are a cache of work in progress, never results:
deleting ``.inflight/`` costs at most the searches in flight.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from lonlib.config import DDPGConfig, PendulumConfig
from lonlib.ddpg.checkpoint import checkpoint_configs, from_checkpoint, to_checkpoint
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.storage.atomic import atomic_write
from lonlib.storage.inflight import (
    FORMAT,
    ID,
    CheckpointUnreadable,
    InflightCheckpoint,
    OtherSettings,
    checkpoint_lock_path,
    new_checkpoint_path,
    new_id,
    refusal_reason,
)
from lonlib.storage.layout import Job
from lonlib.util.plain_data import plain_dict, plain_float


def save_inflight(metadata_path: Path, trainer: SlotTrainer, trials: dict[Job, int]) -> None:
    """Write ``trainer`` as the checkpoint committed by ``metadata_path``, with the number
    of stored trials of each run it trains (``trials``, keyed by the slots' tags): its
    tensors first, then the metadata with its plain data; then remove the data file it
    supersedes."""
    write_id = new_id()
    data_path = metadata_path.with_name(f"{metadata_path.stem}.{write_id}.pt")
    busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
    runs = [trainer.tags()[slot] for slot in busy]
    plain, tensors = to_checkpoint(trainer)
    buffer = io.BytesIO()
    torch.save({"format": FORMAT, "write_id": write_id, "tensors": tensors}, buffer)
    atomic_write(data_path, buffer.getvalue())
    metadata = {
        "format": FORMAT,
        "write_id": write_id,
        "data": data_path.name,
        "saved": time.time(),
        "clock": time.perf_counter(),
        "runs": [list(run) for run in runs],
        "trials": [trials[run] for run in runs],
        "steps": [int(trainer.steps[slot]) for slot in busy],
        "trainer": plain,
    }
    atomic_write(metadata_path, json.dumps(metadata, indent=1).encode())
    remove_leftovers(metadata_path, keep=data_path)


METADATA_KEYS = frozenset(
    {"format", "write_id", "data", "saved", "clock", "runs", "trials", "steps", "trainer"}
)


@dataclass(frozen=True)
class StoredBatch:
    """A checkpoint's batch as read: plain data and tensors, nothing built from them yet."""

    source: Path  # the data file
    plain: dict[str, Any]  # lonlib.ddpg.checkpoint.to_checkpoint's plain data
    tensors: dict[str, Any]  # and its tensors
    clock: float  # time.perf_counter() at the write
    runs: tuple[Job, ...]  # the runs its metadata lists, the tags of its busy slots
    steps: tuple[int, ...]  # and their searches' env steps

    def settings(self) -> tuple[PendulumConfig, DDPGConfig]:
        """The environment and DDPG settings the batch was trained with (``ValueError``
        if they are missing or invalid)."""
        try:
            return checkpoint_configs(self.plain)
        except Exception as error:  # whatever the file holds is refused, never raised
            raise ValueError(f"{self.source}: refused, {refusal_reason(error)}") from None

    def trainer(self, device: str | None = None) -> SlotTrainer:
        """The batch, on ``device`` (default: where it was trained), its search clocks moved
        so that time spent dead does not count as search time. ``ValueError`` (naming the
        first misfit) if anything in it does not fit a batch of its settings."""
        try:
            trainer = from_checkpoint(self.plain, self.tensors, device)
            self._check_runs(trainer)
        except Exception as error:  # whatever the file holds is refused, never raised
            raise ValueError(f"{self.source}: refused, {refusal_reason(error)}") from None
        trainer.resume_clocks(time.perf_counter() - self.clock)
        return trainer

    def _check_runs(self, trainer: SlotTrainer) -> None:
        """Refuse a batch whose busy slots do not train the runs (and env steps) its
        metadata lists, in slot order, as :func:`save_inflight` writes them."""
        busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
        tags = [trainer.searches[slot].tag for slot in busy]
        if tags != list(self.runs) or not all(
            type(tag) is tuple and len(tag) == 2 and type(tag[1]) is int for tag in tags
        ):
            raise ValueError("its busy slots' searches are not the runs its metadata lists")
        if [int(trainer.steps[slot]) for slot in busy] != list(self.steps):
            raise ValueError("its busy slots' env steps are not those its metadata lists")


def read_inflight(checkpoint: InflightCheckpoint) -> StoredBatch:
    """The batch stored in ``checkpoint``, read without running anything in it: JSON, and
    tensors with ``torch.load(..., weights_only=True)``.

    Raises :class:`CheckpointUnreadable` if a file cannot be read now, ``ValueError`` if
    they are not a pair of this format's files (truncated, planted, another format)."""
    meta = checkpoint.metadata_path
    try:
        data = meta.read_bytes()  # an error here is the file system's, past it the content's
    except FileNotFoundError as error:
        raise ValueError(f"{meta}: missing") from error
    except OSError as error:
        raise CheckpointUnreadable(f"{meta}: {error}") from error
    try:  # whatever the file holds is refused, never raised (RecursionError, OverflowError)
        payload = plain_dict(json.loads(data), str(meta), METADATA_KEYS)
        rewritten = payload["format"] != FORMAT or payload["write_id"] != checkpoint.write_id
        clock = None if rewritten else plain_float(payload["clock"], "clock", finite=True)
        trainer = payload["trainer"]
        if not isinstance(trainer, dict):
            raise ValueError("trainer must be a mapping")
    except Exception as error:
        raise ValueError(f"{meta}: refused, {refusal_reason(error)}") from None
    if rewritten:
        raise ValueError(f"{meta}: rewritten since it was listed")
    tensors = _read_tensors(checkpoint)
    return StoredBatch(
        checkpoint.data_path, trainer, tensors, clock, checkpoint.runs, checkpoint.steps
    )


def _read_tensors(checkpoint: InflightCheckpoint) -> dict[str, Any]:
    """The named tensors of ``checkpoint``'s data file (checked to be its own write)."""
    path = checkpoint.data_path
    try:
        data = path.read_bytes()  # an error here is the file system's, past it the content's
    except FileNotFoundError as error:
        raise ValueError(f"{path}: missing") from error
    except OSError as error:
        raise CheckpointUnreadable(f"{path}: {error}") from error
    try:
        payload = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception as error:  # whatever the file holds is refused: nothing in it runs
        raise ValueError(
            f"{path}: refused, not tensors and plain data ({_load_error(error)}); nothing "
            "in it was run"
        ) from None
    try:  # values of any kind: a tensor's == is no bool, so compare kinds first
        ours = (
            type(payload) is dict
            and set(payload) == {"format", "write_id", "tensors"}
            and type(payload["format"]) is int
            and payload["format"] == FORMAT
            and type(payload["write_id"]) is str
            and payload["write_id"] == checkpoint.write_id
        )
    except Exception:
        ours = False
    if not ours:
        raise ValueError(f"{path}: refused, not the data file its metadata describes")
    return payload["tensors"]


def _load_error(error: Exception) -> str:
    """The gist of a ``torch.load`` error: the restricted unpickler's own line (what it
    refused), else the first sentence (torch's advice to retry unrestricted is left out)."""
    lines = str(error).splitlines() or [type(error).__name__]
    for line in lines:
        if "WeightsUnpickler error:" in line:
            return line.split("WeightsUnpickler error:")[1].split(". Please")[0].strip()
    return lines[0].split(". ")[0].strip()


def check_settings(
    checkpoint: InflightCheckpoint, stored: StoredBatch, env_config: PendulumConfig, hp: DDPGConfig
) -> None:
    """Raise :class:`OtherSettings`, naming each setting that differs and its value in this
    session, if ``stored`` (``checkpoint``'s batch) was trained with settings other than
    ``env_config`` and ``hp`` (``ValueError`` if its settings are refused)."""
    env_theirs, hp_theirs = stored.settings()
    differ = []
    for prefix, ours, theirs in (("", hp, hp_theirs), ("env.", env_config, env_theirs)):
        for field in dataclasses.fields(ours):
            mine, its = getattr(ours, field.name), getattr(theirs, field.name)
            if mine != its:
                differ.append(f"{prefix}{field.name}={its!r} (this session: {mine!r})")
    if differ:
        raise OtherSettings(
            f"{checkpoint.metadata_path}: in-flight checkpoint trained with {', '.join(differ)}: "
            "resume with those to continue it; its runs restart from their stored trials"
        )


def load_inflight(checkpoint: InflightCheckpoint, device: str | None = None) -> SlotTrainer:
    """The :class:`lonlib.ddpg.trainer.SlotTrainer` stored in ``checkpoint``, on ``device``
    (default: where it was trained; the caller checks the settings, :func:`check_settings`). Raises
    as :func:`read_inflight` and :meth:`StoredBatch.trainer`."""
    return read_inflight(checkpoint).trainer(device)


def remove_leftovers(metadata_path: Path, keep: Path | None = None) -> None:
    """Remove the batch's data files other than ``keep`` and its interrupted writes (call
    as the batch's owner, i.e. holding its runs' locks). Only for a batch id (:data:`ID`):
    another name is never made a pattern."""
    folder, stem = metadata_path.parent, metadata_path.stem
    if not ID.fullmatch(stem):
        return
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


def split_inflight(
    checkpoint: InflightCheckpoint,
    parts: int,
    settings: tuple[PendulumConfig, DDPGConfig] | None = None,
) -> None:
    """Replace ``checkpoint`` by ``parts`` checkpoints of about equal numbers of its runs
    (for as many processes; each part continues its searches exactly as the whole would).
    With ``settings`` (this session's environment and DDPG settings), a batch trained with
    others is not read further (:class:`OtherSettings`, :func:`check_settings`). Raises as
    :func:`load_inflight`, or :class:`lonlib.storage.atomic.DataWriteError` (then no part is
    left)."""
    stored = read_inflight(checkpoint)
    if settings is not None:
        check_settings(checkpoint, stored, *settings)
    trainer = stored.trainer()
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
