"""One basin-hopping run of an experiment: its random start, its lock, its resumed driver, its
summary, and the plan of an experiment's runs (what every executor needs, below them)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from lonlib.config import ExperimentConfig
from lonlib.search.algorithm import (
    BasinHoppingRun,
    RunState,
    Trial,
    random_networks,
    random_parameters,
)
from lonlib.storage.atomic import CorruptDataError, remove_temporary_files
from lonlib.storage.digests import check_experiment_seal, drop_unwritten_trials
from lonlib.storage.inflight import Plan
from lonlib.storage.layout import (
    RUN_LOCK,
    config_of_manifest,
    read_manifest,
    run_dir,
    stored_config,
    trials_path,
)
from lonlib.storage.lock import LockHeld, exclusive_lock
from lonlib.storage.trials import load_run_state, stored_trial_columns
from lonlib.task.gymnasium_behaviour import behaviour_names, check_descriptor
from lonlib.task.gymnasium_task import TaskEnvironmentError
from lonlib.task.interface import task_of


def initial_parameters(config: ExperimentConfig, p: float, run: int) -> tuple[np.ndarray, ...]:
    """Algorithm 2's random initial Actor and Critic for run ``(p, run)``."""
    if config.task is None:
        return random_parameters(config.run_seed(p, run), config.env.n_carts)
    task = experiment_task(config)
    return random_networks(
        config.run_seed(p, run), task.actor_spec, task.critic_spec, task.critic_count
    )


_TASKS: dict[Any, Any] = {}


def experiment_task(config: ExperimentConfig) -> Any:
    """The experiment's task (:func:`lonlib.task.task_of`), made once per process for a
    Gymnasium task (making an environment can take a while)."""
    if config.task is None:
        return task_of(config)
    if config.task not in _TASKS:
        _TASKS[config.task] = task_of(config)
    return _TASKS[config.task]


def run_lock_path(out: Path, p: float, run: int) -> Path:
    """The lock file held by the one process writing run ``(p, run)``."""
    return run_dir(Path(out), p, run) / RUN_LOCK


@contextmanager
def hold_runs(
    out: Path, runs: Sequence[tuple[float, int]], also: Sequence[Path] = ()
) -> Iterator[bool]:
    """Hold the locks of ``runs`` (and the lock files ``also``) for the ``with`` block,
    yielding True; yield False (holding none) if another process holds one of them."""
    with ExitStack() as locks:
        try:
            for path in [*(run_lock_path(out, p, run) for p, run in runs), *also]:
                locks.enter_context(exclusive_lock(path, wait=False))
        except LockHeld:
            locks.close()
            yield False
            return
        yield True


def open_run(out: Path, config: ExperimentConfig, p: float, run: int) -> BasinHoppingRun:
    """Algorithm 2's driver of run ``(p, run)``, resumed from what is stored (call with the
    run's lock held: a holder before us may have stored more than the caller saw)."""
    remove_temporary_files(run_dir(out, p, run))
    drop_unwritten_trials(run_dir(out, p, run), out)  # sealed ahead, its row never written
    bh = config.basin_hopping(p)
    state = load_run_state(out, p, run, bh)
    return BasinHoppingRun(initial_parameters(config, p, run), bh, config.run_seed(p, run), state)


def run_failure(p: float, run: int, done: int, error: Exception) -> TaskEnvironmentError:
    """The error of a run whose task environment failed in its local search ``done`` (the
    ``done`` local searches it stored before are kept)."""
    return TaskEnvironmentError(
        f"run (p={p:g}, run={run}), local search {done}: {error} (its {done} stored "
        "local search(es) are kept)"
    )


def check_task_descriptor(config: ExperimentConfig, out: Path) -> None:
    """Before any compute and before any folder is made (``lonlib run`` and its
    ``--dry-run``): a Gymnasium task's descriptor describes a short trace
    (:func:`lonlib.task.gymnasium_behaviour.check_descriptor`), with the names the trials
    already stored in ``out`` for this task have; ValueError naming ``task.descriptor``
    otherwise."""
    if config.task is None or not config.task.descriptor:
        return
    names = check_descriptor(experiment_task(config))
    try:
        manifest = read_manifest(out)
        stored = config_of_manifest(manifest, Path(out) / "manifest.json")
    except (OSError, CorruptDataError):  # none there yet, or unreadable: the session says so
        return
    # a hand edit is named as such, not as a changed descriptor (an unsealed folder: the
    # session warns once)
    seal = check_experiment_seal(out, manifest, figures=False, recordings=False, files=False)
    if seal.sealed:
        seal.raise_if_tampered("lonlib run")
    same_task = stored.task == config.task
    columns = stored_trial_columns(out) if same_task else None  # else the session refuses it
    if columns is not None and behaviour_names(columns) != names:
        raise ValueError(
            _changed_names(
                config.task.descriptor, names, behaviour_names(columns), "the stored trials"
            )
        )


def check_behaviour_columns(
    out: Path, config: ExperimentConfig, p: float, run: int, trials: Sequence[Trial]
) -> None:
    """Before a Gymnasium task's trial is saved: its behaviour columns (``b_*``, ``label``)
    are those of the run's stored trials (for a run's first trial, another stored run's), or
    ValueError naming the run and ``task.descriptor``, and nothing is written: a table whose
    rows have other columns would not verify."""
    if config.task is None:
        return
    names = behaviour_names(trials[-1].behaviour)
    if len(trials) > 1:
        stored, whose = behaviour_names(trials[0].behaviour), "the run's stored trials"
    else:
        columns = stored_trial_columns(out, skip=trials_path(out, p, run))
        if columns is None:
            return
        stored, whose = behaviour_names(columns), "the experiment's stored trials"
    if names != stored:
        raise ValueError(
            f"run (p={p:g}, run={run}): "
            + _changed_names(config.task.descriptor, names, stored, whose)
        )


def _changed_names(descriptor: str, names: list[str], stored: list[str], whose: str) -> str:
    return (
        f"task.descriptor ({descriptor or 'none'}) now gives the columns {names}, "
        f"{whose} have {stored}: every optimum of an experiment needs the same ones (did the "
        "descriptor change? restore it, or sample into a new folder); nothing stored"
    )


def run_summary(p: float, run: int, state: RunState) -> dict[str, Any]:
    """What an executor reports for a finished run."""
    return {
        "p": p,
        "run": run,
        "local_searches": len(state.trials),
        "best_fitness": state.incumbent.fitness if state.incumbent else float("nan"),
        "end_reason": state.end_reason,
        "held_by": None,
    }


def experiment_plan(out: str | Path, config: ExperimentConfig) -> Plan:
    """The runs of the experiment in ``out`` (:data:`lonlib.experiment.checkpoints.Plan`): those of
    ``config`` and of the configuration its manifest holds (a session may run fewer p values
    or runs than earlier ones did)."""
    perturbations, runs = set(config.perturbations), config.runs
    try:
        stored = stored_config(Path(out))
    except Exception:  # none yet, or unreadable (sampling refuses to start then)
        return perturbations, runs
    return perturbations | set(stored.perturbations), max(runs, stored.runs)
