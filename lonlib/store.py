"""Resumable, atomic storage of basin-hopping runs under ``data/<experiment>/``.

Layout::

    data/<experiment>/
        manifest.json                 configuration, lonlib version, git commit, packages, times
        p=<p>/run_<run>/trials.parquet    every local search of the run (the commit point)
        p=<p>/run_<run>/optimum_<i>.npz   accepted optimum i: theta, omega (float32, compressed)
        p=<p>/run_<run>/history_<i>.parquet  local search i's training curve (per episode)

Every file is written to a temporary name in the same folder and renamed into place, so a
reader never sees half a file. After each local search the optimum (if accepted) is written
first and the trials table second: the table is the single source of truth, and a run's
state (incumbent, failure count, end reason) is recomputed from it on resume. A file that
cannot be read raises :class:`CorruptDataError` naming it; nothing is ever deleted.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.basin_hopping import BasinHoppingConfig, LocalOptimum, RunState, Trial

TRIAL_COLUMNS = ["p", "run", "index", "parent", "fitness", "accepted", "seconds", "env_steps"]


class CorruptDataError(RuntimeError):
    """A stored file exists but cannot be read; the message names the file."""


class MissingExperimentError(FileNotFoundError):
    """No experiment has been sampled into a folder yet; the message says what to run."""


def atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(handle)
    tmp_path = Path(tmp)
    try:
        write(tmp_path)
        with open(tmp_path, "rb") as stream:
            os.fsync(stream.fileno())
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_json(path: Path, payload: dict) -> None:
    """Atomically write ``payload`` as indented JSON."""
    atomic_write(path, lambda tmp: tmp.write_text(json.dumps(payload, indent=2, default=str)))


def read_json(path: Path) -> dict:
    """Read a JSON file written by :func:`write_json` (CorruptDataError if unreadable)."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise CorruptDataError(f"{path}: cannot read JSON ({error})") from error


def read_manifest(root: Path) -> dict:
    """The manifest of experiment folder ``root``: MissingExperimentError when nothing has
    been sampled there yet, CorruptDataError when it cannot be read."""
    path = Path(root) / "manifest.json"
    if not path.exists():
        raise MissingExperimentError(
            f"no experiment in {root} yet (no manifest.json). Sample one first: `make reproduce` "
            "(CONFIG=quick writes data/quick, CONFIG=paper data/paper), the sample_lon notebook, "
            f"or `lonlib run quick --out {root}`"
        )
    return read_json(path)


def p_label(p: float) -> str:
    """Folder-safe, exact label of a perturbation strength (``1e-04``)."""
    return f"{p:.6g}".replace("e-0", "e-")


def run_dir(root: Path, p: float, run: int) -> Path:
    """Folder of run ``run`` at perturbation strength ``p``."""
    return Path(root) / f"p={p_label(p)}" / f"run_{run:04d}"


def trials_path(root: Path, p: float, run: int) -> Path:
    """The trials table of one run."""
    return run_dir(root, p, run) / "trials.parquet"


def optimum_path(root: Path, p: float, run: int, index: int) -> Path:
    """The parameters of accepted local search ``index`` of one run."""
    return run_dir(root, p, run) / f"optimum_{index:04d}.npz"


def history_path(root: Path, p: float, run: int, index: int) -> Path:
    """The per-episode training record of local search ``index`` of one run."""
    return run_dir(root, p, run) / f"history_{index:04d}.parquet"


def save_step(
    root: Path, p: float, run: int, trials: list[Trial], optimum: LocalOptimum | None
) -> None:
    """Persist one finished local search: its training history and optimum (if accepted),
    then the trials table (the commit point)."""
    last = trials[-1]
    if optimum is not None and optimum.history:
        history = pd.DataFrame(optimum.history)
        atomic_write(
            history_path(root, p, run, last.index),
            lambda tmp: history.to_parquet(tmp, index=False),
        )
    if optimum is not None and last.accepted:
        path = optimum_path(root, p, run, last.index)

        def write_npz(tmp: Path) -> None:
            with open(tmp, "wb") as stream:
                np.savez_compressed(
                    stream,
                    theta=optimum.theta.astype(np.float32),
                    omega=optimum.omega.astype(np.float32),
                    fitness=np.float64(optimum.fitness),
                )

        atomic_write(path, write_npz)
    table = trials_frame(p, run, trials)
    atomic_write(trials_path(root, p, run), lambda tmp: table.to_parquet(tmp, index=False))


def trials_frame(p: float, run: int, trials: list[Trial]) -> pd.DataFrame:
    """Trials as a table with the run's coordinates."""
    rows = [
        {
            "p": p,
            "run": run,
            "index": t.index,
            "parent": t.parent,
            "fitness": t.fitness,
            "accepted": t.accepted,
            "seconds": t.seconds,
            "env_steps": t.env_steps,
        }
        for t in trials
    ]
    return pd.DataFrame(rows, columns=TRIAL_COLUMNS).astype(
        {
            "run": "int64",
            "index": "int64",
            "parent": "int64",
            "env_steps": "int64",
            "accepted": "bool",
        }
    )


def read_trials(path: Path) -> pd.DataFrame:
    """Read one run's trials table, checking its columns (CorruptDataError names the file)."""
    try:
        table = pd.read_parquet(path)
    except Exception as error:  # pyarrow raises several types for a damaged file
        raise CorruptDataError(f"{path}: cannot read the trials table ({error})") from error
    missing = set(TRIAL_COLUMNS) - set(table.columns)
    if missing:
        raise CorruptDataError(f"{path}: trials table lacks columns {sorted(missing)}")
    if list(table["index"]) != list(range(len(table))):
        raise CorruptDataError(f"{path}: trial indices are not 0..{len(table) - 1}")
    return table


def read_optimum(path: Path) -> LocalOptimum:
    """Read one stored optimum (CorruptDataError names the file)."""
    try:
        with np.load(path) as data:
            return LocalOptimum(float(data["fitness"]), data["theta"], data["omega"])
    except Exception as error:
        raise CorruptDataError(f"{path}: cannot read the stored optimum ({error})") from error


def load_run_state(root: Path, p: float, run: int, config: BasinHoppingConfig) -> RunState | None:
    """Rebuild a run's :class:`RunState` from disk (None if it has not started) by
    replaying its stored trials through Algorithm 2's bookkeeping."""
    path = trials_path(root, p, run)
    if not path.exists():
        return None
    state = RunState(trials=[], incumbent=None, incumbent_index=-1, failures=0)
    for r in read_trials(path).itertuples():
        trial = Trial(
            int(r.index),
            int(r.parent),
            float(r.fitness),
            bool(r.accepted),
            float(r.seconds),
            int(r.env_steps),
        )
        state.record(trial, None, config)
    if state.incumbent_index >= 0:
        state.incumbent = read_optimum(optimum_path(root, p, run, state.incumbent_index))
    return state


def read_experiment_trials(root: Path) -> pd.DataFrame:
    """All trials of every run of an experiment folder, one table (sorted by p, run, index)."""
    root = Path(root)
    paths = sorted(root.glob("p=*/run_*/trials.parquet"))
    if not paths:
        return pd.DataFrame(columns=TRIAL_COLUMNS)
    table = pd.concat([read_trials(path) for path in paths], ignore_index=True)
    return table.sort_values(["p", "run", "index"], ignore_index=True)
