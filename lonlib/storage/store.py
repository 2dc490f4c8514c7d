"""Resumable, atomic storage of basin-hopping runs under ``data/<experiment>/``.

Layout::

    data/<experiment>/
        manifest.json                 configuration, lonlib version, git commit, packages, times
        p=<p>/run_<run>/trials.parquet    every local search of the run (the commit point)
        p=<p>/run_<run>/optimum_<i>.npz   optimum of local search i: theta, omega (float32,
                                      compressed); older experiments kept accepted ones only
        p=<p>/run_<run>/history_<i>.parquet  local search i's training curve (per episode)

Every file is written to a temporary name in the same folder (``.<name>.<random>.tmp``),
flushed to disk and renamed into place, so a reader never sees half a file; readers open
exact names and never read a temporary. After each local search the history and optimum
(if accepted) are written first and the trials table last: the table is the single source
of truth, and a run's state (incumbent, failure count, end reason) is recomputed from it on
resume. A file that cannot be read raises :class:`CorruptDataError` naming it; a file that
cannot be written raises :class:`DataWriteError` naming it and the cause, leaving what was
stored before unchanged. Nothing but temporaries is ever deleted.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import io
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from lonlib.search.algorithm import BasinHoppingConfig, LocalOptimum, RunState, Trial

Job = tuple[float, int]  # a run of an experiment: (p, run index)
TRIAL_FIELDS = [f.name for f in dataclasses.fields(Trial) if f.name != "behaviour"]
TRIAL_COLUMNS = ["p", "run", *TRIAL_FIELDS]  # then the behaviour columns (b_*, label), if any


class CorruptDataError(RuntimeError):
    """A stored file exists but cannot be read; the message names the file."""


class MissingExperimentError(FileNotFoundError):
    """No experiment has been sampled into a folder yet; the message says what to run."""


class DataWriteError(OSError):
    """A file could not be written (disk full, read-only folder, missing folder...). The
    message names the file and the cause; ``errno`` is the cause's. What was stored before
    is unchanged."""


TEMPORARY_SUFFIX = ".tmp"


def temporary_files(folder: Path, name: str = "*") -> list[Path]:
    """Temporary files that writes of ``name`` (any file by default) left in ``folder``
    when they were interrupted; never read as data."""
    return sorted(Path(folder).glob(f".{name}.*{TEMPORARY_SUFFIX}"))


def remove_temporary_files(folder: Path, name: str = "*") -> None:
    """Delete what interrupted writes of ``name`` left in ``folder``. Call it only while
    holding the lock that guards those writes (a live writer's file would vanish)."""
    for path in temporary_files(folder, name):
        try:
            path.unlink()
        except FileNotFoundError:
            pass
        except OSError as error:
            raise write_error(path, error) from error


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, flush it to disk, rename it into
    place and flush the folder entry, so ``path`` holds either its old or its new content.

    Raises :class:`DataWriteError` naming ``path`` and the cause (e.g. ENOSPC, EROFS); the
    temporary file is removed where the file system still allows it.
    """
    path = Path(path)
    tmp: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, name = tempfile.mkstemp(
            prefix=f".{path.name}.", suffix=TEMPORARY_SUFFIX, dir=path.parent
        )
        tmp = Path(name)
        try:
            _write_all(handle, data)
            os.fsync(handle)
        finally:
            os.close(handle)
        os.replace(tmp, path)
        tmp = None
        _fsync_folder(path.parent)
    except OSError as error:
        raise write_error(path, error) from error
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):  # a read-only folder keeps it; see temporary_files
                tmp.unlink()


def write_error(path: Path, error: OSError) -> DataWriteError:
    """The :class:`DataWriteError` for ``error`` while writing ``path``."""
    cause = error.strerror or str(error)
    return DataWriteError(
        error.errno,
        f"cannot write {path}: {cause}. Files stored before are unchanged; fix the cause "
        "(free space, permissions, mount) and run again to resume",
    )


def _write_all(handle: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(handle, view) :]


def _fsync_folder(folder: Path) -> None:
    """Make a rename durable. Some file systems cannot sync a folder (EINVAL): the rename
    itself has succeeded there, so that case is not an error."""
    handle = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(handle)
    except OSError as error:
        if error.errno != errno.EINVAL:
            raise
    finally:
        os.close(handle)


def write_json(path: Path, payload: dict) -> None:
    """Atomically write ``payload`` as indented JSON."""
    atomic_write(path, json.dumps(payload, indent=2, default=str).encode())


def read_json(path: Path) -> dict:
    """Read a JSON file written by :func:`write_json` (CorruptDataError if unreadable)."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise CorruptDataError(f"{path}: cannot read JSON ({error})") from error


def check_output_folder(out: Path) -> None:
    """Before any compute: ``out`` exists or can be created inside an existing folder, and
    accepts a new file. A missing parent is refused rather than created (a typo, or a shared
    file system that is not mounted, would otherwise silently write elsewhere).

    Raises :class:`DataWriteError` naming the folder and the cause.
    """
    out = Path(out)
    if not out.parent.is_dir():
        raise DataWriteError(
            errno.ENOENT,
            f"cannot write {out}: its parent folder {out.parent} does not exist "
            "(a typo, or a file system that is not mounted?); create it first",
        )
    if out.exists() and not out.is_dir():
        raise DataWriteError(errno.ENOTDIR, f"cannot write {out}: it is a file, not a folder")
    try:
        out.mkdir(exist_ok=True)
        handle, name = tempfile.mkstemp(prefix=".write-check.", suffix=TEMPORARY_SUFFIX, dir=out)
        os.close(handle)
        os.unlink(name)
    except OSError as error:
        raise write_error(out, error) from error


def parquet_bytes(table: pd.DataFrame) -> bytes:
    """A table as Parquet file content."""
    return table.to_parquet(None, index=False)


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
    """Persist one finished local search: its training history and optimum (every trial's,
    accepted or not, so that every stored number replays), then the trials table (the
    commit point)."""
    last = trials[-1]
    if optimum is not None and optimum.history:
        path = history_path(root, p, run, last.index)
        atomic_write(path, parquet_bytes(pd.DataFrame(optimum.history)))
    if optimum is not None:
        buffer = io.BytesIO()
        np.savez_compressed(
            buffer,
            theta=optimum.theta.astype(np.float32),
            omega=optimum.omega.astype(np.float32),
            fitness=np.float64(optimum.fitness),
        )
        atomic_write(optimum_path(root, p, run, last.index), buffer.getvalue())
    atomic_write(trials_path(root, p, run), parquet_bytes(trials_frame(p, run, trials)))


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
    state = replay_trials(read_trials(path), config)
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


def read_finished_trials(root: Path) -> pd.DataFrame:
    """:func:`read_experiment_trials` of a folder that must hold an experiment with at least
    one finished local search: MissingExperimentError (no manifest) or ValueError otherwise,
    both naming the folder."""
    read_manifest(root)
    trials = read_experiment_trials(root)
    if trials.empty:
        raise ValueError(f"{root} holds no finished local search yet")
    return trials
