"""A study folder's finished cells: each cell's record (``cells/<cell>.json``, the commit
point) and its searches' best Actors and Critics (``cells/<cell>.npz``), written atomically
and read back; a record made with other settings than the study's is refused by name."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from lonlib.config import CalibrationConfig, Cell
from lonlib.storage.atomic import atomic_write, read_json, write_json


def cell_paths(out: Path, cell: Cell) -> tuple[Path, Path]:
    """The record (JSON, the commit point) and Actors (npz) of one cell."""
    folder = Path(out) / "cells"
    return folder / f"{cell.name}.json", folder / f"{cell.name}.npz"


def write_cell(
    out: str | Path, cell: Cell, record: dict[str, Any], thetas: np.ndarray, omegas: np.ndarray
) -> None:
    """Store a finished cell atomically: its searches' best Actors and Critics first
    (``theta``, ``omega``: float32, one row per search), then the record (its commit point)."""
    record_path, actors_path = cell_paths(Path(out), cell)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, theta=thetas.astype(np.float32), omega=omegas.astype(np.float32))
    atomic_write(actors_path, buffer.getvalue())
    write_json(record_path, record, compact=True)  # ~15k episodes per search: ~1.3 MB, not 3.5


def read_cell(out: Path, cell: Cell, config: CalibrationConfig) -> dict[str, Any] | None:
    """A stored cell record, None if the cell has not finished. A record made with other
    settings (seeds, budget, base physics) raises ValueError naming the file."""
    path = cell_paths(out, cell)[0]
    if not path.exists():
        return None
    record: dict[str, Any] = read_json(path)
    if record.get("settings") != json_roundtrip(config.cell_settings(cell)):
        raise ValueError(
            f"{path} was computed with other settings than this study's; "
            "use another output folder or the stored settings"
        )
    return record


def read_arrays(out: Path, cell: Cell) -> dict[str, np.ndarray]:
    """The arrays a finished cell stored beside its record, by name: ``theta`` (the best
    Actors) and, in cells stored since the study kept them, ``omega`` (their Critics)."""
    with np.load(cell_paths(out, cell)[1]) as data:
        return {name: data[name] for name in data.files}


def json_roundtrip(value: Any) -> Any:
    """``value`` as it reads back from JSON (tuples become lists)."""
    if isinstance(value, dict):
        return {k: json_roundtrip(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_roundtrip(v) for v in value]
    return value


__all__ = [
    "cell_paths",
    "json_roundtrip",
    "read_arrays",
    "read_cell",
    "write_cell",
]
