"""In-flight checkpoints of a calibration cell: a killed study resumes mid-cell.

A cell is stored (``<out>/cells/<cell>.json``) only when all its searches finish; at a
million env steps per search that is a day on one core, longer than a session. So a cell's
batch of searches (a :class:`lonlib.ddpg.trainer.SlotTrainer`) is also written every few
minutes, in the safe format of the lockstep checkpoints (:mod:`lonlib.experiment.checkpoints`)::

    <out>/inflight/<cell>.<write>.pt   the batch's tensors: a torch.save of {"format",
                                       "write_id", "tensors": {name: tensor}}, read back with
                                       torch.load(..., weights_only=True)
    <out>/inflight/<cell>.json         the commit point, written after the data file: format,
                                       write id, data file, the cell and its settings, the
                                       trainer's plain data and the study's own per-search
                                       state (plain JSON)

Data, not code: nothing in either file names a Python class. A write never replaces the
data file the metadata points to, so a kill at any moment leaves the previous checkpoint
whole. A checkpoint of other settings than the study's is refused by name (the study keeps
it); a damaged one is reported and set aside (the cell restarts). These files are a cache of
work in progress: deleting ``inflight/`` costs at most the cell's searches so far.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import time
from pathlib import Path
from typing import Any

import torch

from lonlib.ddpg.checkpoint import from_checkpoint, to_checkpoint
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.storage.atomic import atomic_write
from lonlib.storage.inflight import new_id, refusal_reason

log = logging.getLogger(__name__)

# The layout's version: bump it when what a cell checkpoint holds changes.
FORMAT = 1
FOLDER = "inflight"
METADATA_KEYS = frozenset({"format", "write_id", "data", "saved", "settings", "trainer", "state"})


class CellCheckpoint:
    """The in-flight checkpoint of the cell named ``name`` in study folder ``out``."""

    def __init__(self, out: str | Path, name: str) -> None:
        self.folder = Path(out) / FOLDER
        self.name = name
        self.metadata_path = self.folder / f"{name}.json"

    def save(self, trainer: SlotTrainer, settings: dict[str, Any], state: dict[str, Any]) -> None:
        """Write ``trainer`` with the cell's ``settings`` and the study's plain ``state``:
        the tensors first, then the metadata (the commit point); then remove the data file
        it supersedes."""
        write_id = new_id()
        data_path = self.folder / f"{self.name}.{write_id}.pt"
        plain, tensors = to_checkpoint(trainer)
        buffer = io.BytesIO()
        torch.save({"format": FORMAT, "write_id": write_id, "tensors": tensors}, buffer)
        atomic_write(data_path, buffer.getvalue())
        metadata = {
            "format": FORMAT,
            "write_id": write_id,
            "data": data_path.name,
            "saved": time.time(),
            "settings": settings,
            "trainer": plain,
            "state": state,
        }
        atomic_write(self.metadata_path, json.dumps(metadata).encode())
        self._remove_data(keep=data_path)

    def load(self, settings: dict[str, Any]) -> tuple[SlotTrainer, dict[str, Any]] | None:
        """The stored batch and study state, or None if there is none (or it is damaged:
        then it is reported and removed). A checkpoint of other ``settings`` raises
        ValueError naming its file, before anything in it is used."""
        try:
            raw = self.metadata_path.read_bytes()
        except FileNotFoundError:
            self._remove_data()  # the leftovers of a write killed before its commit
            return None
        try:
            meta = json.loads(raw)
            if not isinstance(meta, dict) or set(meta) != METADATA_KEYS:
                raise ValueError(f"not a cell checkpoint (keys {sorted(meta)[:10]})")
            if meta["format"] != FORMAT:
                raise ValueError(f"format {meta['format']!r}, this lonlib reads {FORMAT}")
        except Exception as error:
            return self._discard(error)
        if meta["settings"] != json.loads(json.dumps(settings)):
            raise ValueError(
                f"{self.metadata_path}: in-flight checkpoint of other settings than this "
                "study's; resume with those, or delete it to restart the cell"
            )
        try:
            data_path = self.folder / str(meta["data"])
            if data_path.name != f"{self.name}.{meta['write_id']}.pt":
                raise ValueError(f"data file {data_path.name!r} is not its own")
            payload = torch.load(
                io.BytesIO(data_path.read_bytes()), map_location="cpu", weights_only=True
            )
            if (
                type(payload) is not dict
                or set(payload) != {"format", "write_id", "tensors"}
                or payload["write_id"] != meta["write_id"]
            ):
                raise ValueError("the data file is not the one its metadata describes")
            trainer = from_checkpoint(meta["trainer"], payload["tensors"])
            if not isinstance(meta["state"], dict):
                raise ValueError("state must be a mapping")
        except Exception as error:
            return self._discard(error)
        return trainer, meta["state"]

    def remove(self) -> None:
        """Delete the checkpoint: its metadata first, then its data files."""
        with contextlib.suppress(FileNotFoundError):
            self.metadata_path.unlink()
        self._remove_data()

    def _discard(self, error: BaseException) -> None:
        """Report a damaged checkpoint and remove it (the cell restarts)."""
        log.warning(
            "%s: damaged in-flight checkpoint removed, the cell restarts (%s)",
            self.metadata_path,
            refusal_reason(error),
        )
        self.remove()
        return None

    def _remove_data(self, keep: Path | None = None) -> None:
        """Remove this cell's data files (and interrupted writes) other than ``keep``."""
        if not self.folder.is_dir():
            return
        for path in self.folder.iterdir():
            ours = path.name.startswith(f"{self.name}.") and path.suffix == ".pt"
            partial = path.name.startswith(f".{self.name}.") and path.suffix == ".tmp"
            if (ours or partial) and path != keep and path != self.metadata_path:
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
