"""In-flight checkpoints of a lockstep batch: a killed lockstep experiment resumes mid-search.

The stored trials are the experiment's results (:mod:`lonlib.storage.store`); a search still
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

Data, not code: the batch is exported by :meth:`lonlib.ddpg.trainer.SlotTrainer.to_checkpoint` as
named tensors and JSON that name no Python class, and read back with ``torch.load(...,
weights_only=True)`` (which builds tensors and plain containers only) and :mod:`json`, every
tensor's shape and dtype and every value's kind and range checked against a batch of the
stored settings and the experiment's runs before anything is used or locked
(:meth:`~lonlib.ddpg.trainer.SlotTrainer.from_checkpoint`). So a planted or damaged file is refused
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
slot
continues only if its run still has the trials stored that it had at the write and asks for
the start parameters the slot holds; a slot whose run went on (a search ended after the
write) is dropped and its run continues from its stored trials. A restored search continues
bit for bit as an uninterrupted one would (tested). These files are a cache of work in
progress, never results: deleting ``.inflight/`` costs at most the searches in flight.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import logging
import re
import time
import uuid
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from lonlib.ddpg.plain_state import (
    plain_dict,
    plain_float,
    plain_int,
    plain_list,
    plain_str,
    short_repr,
)
from lonlib.ddpg.trainer import DDPGConfig, SlotTrainer
from lonlib.storage.store import atomic_write
from lonlib.task.pendulum import PendulumConfig

log = logging.getLogger(__name__)

INFLIGHT_FOLDER = ".inflight"
# The checkpoint layout's version: bump it when SlotTrainer.to_checkpoint's layout changes
# (tests/test_inflight.py fails until the new layout is written down there).
FORMAT = 3
Job = tuple[float, int]
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
            refused.append((meta, _reason(error)))
    return sorted(found, key=lambda c: -len(c.runs)), refused


def _reason(error: BaseException) -> str:
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


def save_inflight(metadata_path: Path, trainer: SlotTrainer, trials: dict[Job, int]) -> None:
    """Write ``trainer`` as the checkpoint committed by ``metadata_path``, with the number
    of stored trials of each run it trains (``trials``, keyed by the slots' tags): its
    tensors first, then the metadata with its plain data; then remove the data file it
    supersedes."""
    write_id = new_id()
    data_path = metadata_path.with_name(f"{metadata_path.stem}.{write_id}.pt")
    busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
    runs = [trainer.tags()[slot] for slot in busy]
    plain, tensors = trainer.to_checkpoint()
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
    plain: dict[str, Any]  # SlotTrainer.to_checkpoint's plain data
    tensors: dict[str, Any]  # and its tensors
    clock: float  # time.perf_counter() at the write
    runs: tuple[Job, ...]  # the runs its metadata lists, the tags of its busy slots
    steps: tuple[int, ...]  # and their searches' env steps

    def settings(self) -> tuple[PendulumConfig, DDPGConfig]:
        """The environment and DDPG settings the batch was trained with (``ValueError``
        if they are missing or invalid)."""
        try:
            return SlotTrainer.checkpoint_configs(self.plain)
        except Exception as error:  # whatever the file holds is refused, never raised
            raise ValueError(f"{self.source}: refused, {_reason(error)}") from None

    def trainer(self, device: str | None = None) -> SlotTrainer:
        """The batch, on ``device`` (default: where it was trained), its search clocks moved
        so that time spent dead does not count as search time. ``ValueError`` (naming the
        first misfit) if anything in it does not fit a batch of its settings."""
        try:
            trainer = SlotTrainer.from_checkpoint(self.plain, self.tensors, device)
            self._check_runs(trainer)
        except Exception as error:  # whatever the file holds is refused, never raised
            raise ValueError(f"{self.source}: refused, {_reason(error)}") from None
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
        raise ValueError(f"{meta}: refused, {_reason(error)}") from None
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
    (default:
    where it was trained; the caller checks the settings, :func:`check_settings`).
    Raises as :func:`read_inflight` and :meth:`StoredBatch.trainer`."""
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
    :func:`load_inflight`, or :class:`lonlib.storage.store.DataWriteError` (then no part is
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
