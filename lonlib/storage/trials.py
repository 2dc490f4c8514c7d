"""The trial schema: what a run stores after each local search, and its state read back.

After each local search the history and optimum are written first and the trials table
last (:func:`save_step`): the table is the single source of truth, and a run's state
(incumbent, failure count, end reason) is replayed from it on resume (:func:`replay_trials`,
Algorithm 2's own bookkeeping, :class:`lonlib.search.algorithm.RunState`).
"""

from __future__ import annotations

import dataclasses
import io
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.config import BasinHoppingConfig
from lonlib.search.algorithm import LocalOptimum, RunState, Trial
from lonlib.storage.atomic import (
    CorruptDataError,
    atomic_write,
    parquet_bytes,
)
from lonlib.storage.digests import append_trial, check_readable
from lonlib.storage.layout import (
    history_path,
    optimum_path,
    read_manifest,
    run_dir,
    trials_path,
)

TRIAL_FIELDS = [f.name for f in dataclasses.fields(Trial) if f.name != "behaviour"]


TRIAL_COLUMNS = ["p", "run", *TRIAL_FIELDS]  # then the behaviour columns (b_*, label), if any


def save_step(
    root: Path, p: float, run: int, trials: list[Trial], optimum: LocalOptimum | None
) -> None:
    """Persist one finished local search: its training history and optimum (every trial's,
    accepted or not, so that every stored number replays), then the trials table (the
    commit point)."""
    last = trials[-1]
    written: dict[str, bytes] = {}
    if optimum is not None and optimum.history:
        path = history_path(root, p, run, last.index)
        written[path.name] = parquet_bytes(pd.DataFrame(optimum.history))
        atomic_write(path, written[path.name])
    if optimum is not None:
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer,
            theta=optimum.theta.astype(np.float32),
            omega=optimum.omega.astype(np.float32),
            fitness=np.float64(optimum.fitness),
        )
        path = optimum_path(root, p, run, last.index)
        written[path.name] = buffer.getvalue()
        atomic_write(path, written[path.name])
    table = parquet_bytes(trials_frame(p, run, trials))
    append_trial(run_dir(root, p, run), Path(root), table, written)  # sealed ahead of its row
    atomic_write(trials_path(root, p, run), table)


def trials_frame(p: float, run: int, trials: list[Trial]) -> pd.DataFrame:
    """Trials as a table with the run's coordinates."""
    rows = [
        {"p": p, "run": run, **{name: getattr(t, name) for name in TRIAL_FIELDS}, **t.behaviour}
        for t in trials
    ]
    behaviour = list(dict.fromkeys(key for t in trials for key in t.behaviour))
    return pd.DataFrame(rows, columns=TRIAL_COLUMNS + behaviour).astype(
        {
            "run": "int64",
            "index": "int64",
            "parent": "int64",
            "env_steps": "int64",
            "accepted": "bool",
            "start_fitness": "float64",
            "improved": "bool",
            "stop_reason": "str",
        }
    )


def read_trials(path: Path) -> pd.DataFrame:
    """Read one run's trials table, checking its columns (CorruptDataError names the file)."""
    try:
        # One read of the whole file, then parse: pyarrow takes a path's size and its
        # contents in two steps, and a writer's atomic rename between them (a run storing
        # its next search while `lonlib status` reads) would look like a damaged file.
        table = pd.read_parquet(io.BytesIO(path.read_bytes()))
    except Exception as error:  # pyarrow raises several types for a damaged file
        raise CorruptDataError(f"{path}: cannot read the trials table ({error})") from error
    missing = set(TRIAL_COLUMNS) - set(table.columns)
    if missing and missing <= {"start_fitness", "improved", "stop_reason"}:
        raise CorruptDataError(
            f"{path}: written by an older lonlib, before trials recorded {sorted(missing)} "
            "(and before only trained policies could be accepted); analyse it with that "
            "version, or sample the experiment again into a new folder"
        )
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


def replay_trials(table: pd.DataFrame, config: BasinHoppingConfig) -> RunState:
    """The :class:`RunState` of one run's stored trials (a ``trials.parquet`` table) by
    Algorithm 2's bookkeeping, without the incumbent's parameters (``incumbent`` None)."""
    state = RunState(trials=[], incumbent=None, incumbent_index=-1, failures=0)
    for row in table.to_dict("records"):
        behaviour = {k: v for k, v in row.items() if k.startswith("b_") or k == "label"}
        trial = Trial(**{name: row[name] for name in TRIAL_FIELDS}, behaviour=behaviour)
        state.record(trial, None, config)
    return state


def load_run_state(root: Path, p: float, run: int, config: BasinHoppingConfig) -> RunState | None:
    """Rebuild a run's :class:`RunState` from disk (None if it has not started) by
    replaying its stored trials through Algorithm 2's bookkeeping."""
    path = trials_path(root, p, run)
    if not path.exists():
        return None
    table = read_trials(path)
    state = replay_trials(table, config)
    if state.incumbent_index >= 0:
        stored = read_optimum(optimum_path(root, p, run, state.incumbent_index))
        # f* from the table (its row is what the seal covers), not the file's second copy
        fitness = float(table["fitness"].iloc[state.incumbent_index])
        state.incumbent = LocalOptimum(fitness, stored.theta, stored.omega)
    return state


def runs_ending_early(
    root: Path, basin_hopping: Callable[[float], BasinHoppingConfig]
) -> list[str]:
    """The stored runs of ``root`` that Algorithm 2 under ``basin_hopping(p)`` would have
    ended before their last stored local search (each as ``'p=..., run i: n local
    searches'``); empty when every stored run is a valid start of a run under those
    settings, e.g. after ``max_local_searches`` is lowered to no less than any run's count."""
    early = []
    for path in sorted(Path(root).glob("p=*/run_*/trials.parquet")):
        table = read_trials(path)
        if table.empty:
            continue
        p, run = float(table["p"].iloc[0]), int(table["run"].iloc[0])
        try:
            settings = basin_hopping(p)
        except ValueError as error:
            raise CorruptDataError(f"{path}: stored p={p!r} is not a valid p ({error})") from error
        if replay_trials(table.iloc[:-1], settings).finished:
            early.append(f"p={p:g}, run {run}: {len(table)} local searches")
    return early


def stored_trial_columns(root: Path, skip: Path | None = None) -> list[str] | None:
    """The columns of one stored trials table of the experiment in ``root`` (the first run's
    but ``skip``'s), read from its schema alone; None when no other run is stored."""
    import pyarrow.parquet as pq

    for path in sorted(Path(root).glob("p=*/run_*/trials.parquet")):
        if skip is not None and path == Path(skip):
            continue
        try:
            return list(pq.read_schema(io.BytesIO(path.read_bytes())).names)
        except Exception as error:  # pyarrow raises several types for a damaged file
            raise CorruptDataError(f"{path}: cannot read the trials table ({error})") from error
    return None


def read_experiment_trials(root: Path) -> pd.DataFrame:
    """All trials of every run of an experiment folder, one table (sorted by p, run, index)."""
    root = Path(root)
    paths = sorted(root.glob("p=*/run_*/trials.parquet"))
    if not paths:
        return pd.DataFrame(columns=TRIAL_COLUMNS)
    table = pd.concat([read_trials(path) for path in paths], ignore_index=True)
    return table.sort_values(["p", "run", "index"], ignore_index=True)


def read_finished_trials(
    root: Path, check_seal: bool = True, reader: str = "lonlib analyse"
) -> pd.DataFrame:
    """:func:`read_experiment_trials` of a folder that must hold an experiment with at least
    one finished local search: MissingExperimentError (no manifest) or ValueError otherwise,
    both naming the folder. With ``check_seal`` (every reader but ``lonlib verify``, which
    reports what differs instead) data that no longer matches its seal is refused first
    (:func:`lonlib.storage.digests.check_readable`; ``reader``, the command that reads,
    names it in the message)."""
    manifest = read_manifest(root)
    if check_seal:
        check_readable(Path(root), manifest, reader)
    trials = read_experiment_trials(root)
    if trials.empty:
        raise ValueError(f"{root} holds no finished local search yet")
    return trials
