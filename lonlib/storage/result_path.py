"""The result path's version: one string that names what lonlib computes and stores.

``RESULT_PATH_VERSION`` changes whenever a change alters trials or stored numbers (fitness,
parameters, descriptors, labels, training histories) for the same configuration: the
physics, a network's arithmetic, DDPG, random streams, Algorithm 2, what a trial records.
Each session of an experiment records it in the manifest (:mod:`lonlib.storage.manifest`), so a
reader knows which sessions' numbers came from which code;
:func:`lonlib.storage.manifest.sessions_with_other_result_path` lists the others.

The golden test ``tests/storage/test_result_path.py`` guards it: it samples a tiny experiment and
compares :func:`experiment_digest` with a committed value. If that test fails and the change
is meant to alter results, bump ``RESULT_PATH_VERSION`` and update the golden digest in the
same commit. Changes that keep every stored number (speed, storage layout readers, plots,
messages) keep the version.

History:

* "1" (2026-11-25): the first recorded version (the code that sampled the first
  ``data/reference``, 2 x 6 runs, whose sessions predate the stamp and record none).
* "2" (2026-11-25): the one rollout (:mod:`lonlib.task.rollout`): defined float64 arithmetic for
  the greedy Actor and ``sin``/``cos``/``exp`` from IEEE basic operations in the physics
  (:mod:`lonlib.util.portable_math`); trials record both aggregations and the conditioning;
  every trial's Actor is stored.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

RESULT_PATH_VERSION = "2"
KNOWN_RESULT_PATH_VERSIONS = ("1", "2")
"""Every version in the history above. Numbers sampled under an older one may differ from
this code's (a mismatch is a warning there); a version not listed (a future one, or a
hand-edited manifest) is never a reason to excuse a mismatch."""

# Stored columns that measure time, not results.
TIMING_COLUMNS = ("seconds",)


def _frame_digest(hasher: Any, frame: pd.DataFrame) -> None:
    """Feed ``frame``'s values, column by column in name order, into ``hasher`` (floats and
    integers as their exact 8-byte values, anything else as its text)."""
    for name in sorted(frame.columns):
        if name in TIMING_COLUMNS:
            continue
        values = frame[name].to_numpy()
        hasher.update(f"{name}:{values.dtype.kind}:".encode())
        if values.dtype.kind == "f":
            hasher.update(np.ascontiguousarray(values, dtype="<f8").tobytes())
        elif values.dtype.kind in "iub":
            hasher.update(np.ascontiguousarray(values, dtype="<i8").tobytes())
        else:
            hasher.update("\x1f".join(map(str, values)).encode())


def experiment_digest(out: str | Path) -> str:
    """sha256 over every stored result of the experiment folder ``out``: each run's trials
    (all columns but wall times), training histories (likewise) and optimum parameters, in
    a fixed order. Two folders with the same digest hold the same numbers bit for bit,
    whoever wrote them, in whatever order or executor."""
    hasher = hashlib.sha256()
    for run in sorted(Path(out).glob("p=*/run_*")):
        hasher.update(f"{run.parent.name}/{run.name}".encode())
        for path in sorted(run.glob("*.parquet")):
            hasher.update(path.name.encode())
            _frame_digest(hasher, pd.read_parquet(path))
        for path in sorted(run.glob("optimum_*.npz")):
            hasher.update(path.name.encode())
            with np.load(path) as arrays:
                for key in sorted(arrays.files):
                    array = np.ascontiguousarray(arrays[key])
                    hasher.update(f"{key}:{array.dtype.str}:".encode() + array.tobytes())
    return hasher.hexdigest()
