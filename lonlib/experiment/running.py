"""Experiments: configurations (:mod:`lonlib.config.experiment`) -> basin-hopping runs, executed in
this process, in local worker processes, on Dask or in lockstep batches.

An :class:`ExperimentConfig` expands to ``runs`` independent basin-hopping runs for each
perturbation strength ``p``. Run ``(p, run)`` draws everything from a seed derived from
``(experiment seed, p, run)``, so its result does not depend on where or in what order it
runs. :func:`run_experiment` skips finished runs, continues interrupted ones after their
last stored local search (see :mod:`lonlib.storage.trials`) and executes the rest serially, in local
worker processes, on a Dask cluster (:mod:`lonlib.experiment.executors`) or as lockstep batches
(:mod:`lonlib.experiment.lockstep`); :mod:`lonlib.storage.manifest`
records the configuration and each session.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import time
import warnings
from collections.abc import Collection
from functools import partial
from pathlib import Path
from typing import Any

import pandas as pd
from tqdm import tqdm

from lonlib.config import ExperimentConfig
from lonlib.ddpg.search_interface import ddpg_local_search, gymnasium_ddpg_local_search
from lonlib.ddpg.trainer import check_device
from lonlib.experiment.admission import check_memory, concurrent_searches
from lonlib.experiment.checkpoints import remove_inflight
from lonlib.experiment.executors import execute_runs, resolve_executor, session_executor
from lonlib.experiment.lockstep import CHECKPOINT_SECONDS, check_drain, check_lockstep, draining
from lonlib.experiment.lockstep_workers import run_lockstep_processes
from lonlib.experiment.runs import (
    check_behaviour_columns,
    check_task_descriptor,
    experiment_plan,
    experiment_task,
    hold_runs,
    open_run,
    run_failure,
    run_lock_path,
    run_summary,
)
from lonlib.sb3 import MISSING, check_search
from lonlib.search.algorithm import LocalSearch
from lonlib.storage.atomic import (
    DataWriteError,
    check_output_folder,
)
from lonlib.storage.inflight import checkpoint_lock_path, scan_inflight
from lonlib.storage.lock import LockHeld, exclusive_lock
from lonlib.storage.manifest import (
    capability_change,
    manifest_path,
)
from lonlib.storage.provenance import session_provenance
from lonlib.storage.session import SamplingSession
from lonlib.storage.status import experiment_status
from lonlib.storage.trials import (
    load_run_state,
    read_experiment_trials,
    save_step,
)
from lonlib.task.gymnasium_task import TaskEnvironmentError
from lonlib.util.cpu_kernels import CpuKernelWarning, torch_cpu_capability, unpinned_message
from lonlib.util.progress import progress_bar
from lonlib.util.validation import check_range

log = logging.getLogger(__name__)


def run_one(
    out: str | Path, config: ExperimentConfig, p: float, run: int, wait: bool = True
) -> dict[str, Any]:
    """Execute (or resume, or skip if finished) run ``(p, run)``, storing every local search.

    Holds the run's lock throughout, so no other process writes the run at the same time.
    If another process holds it: wait for it to finish or die, then continue from what it
    stored (``wait``), or return at once with ``held_by`` naming the holder.

    Returns a summary: p, run, local searches, best fitness, end reason, held_by (None
    unless the run was left to its holder).
    """
    try:
        with exclusive_lock(run_lock_path(Path(out), p, run), wait=wait):
            return _run_locked(Path(out), config, p, run)
    except LockHeld as held:
        return {"p": p, "run": run, "held_by": held.holder}


def _run_locked(out: Path, config: ExperimentConfig, p: float, run: int) -> dict[str, Any]:
    driver = open_run(out, config, p, run)
    try:
        for state, _, optimum in driver.steps(experiment_local_search(config)):
            check_behaviour_columns(out, config, p, run, state.trials)
            save_step(out, p, run, state.trials, optimum)
    except TaskEnvironmentError as error:  # what the run stored before stays
        raise run_failure(p, run, len(driver.state.trials), error) from None
    return run_summary(p, run, driver.state)


def experiment_local_search(config: ExperimentConfig) -> LocalSearch:
    """The experiment's ``F``: lonlib's DDPG on the coupled pendulums or on its Gymnasium
    task (``task.search``; Stable-Baselines3's searches need the extra ``lonlib[sb3]``)."""
    if config.task is None:
        return ddpg_local_search(config.env, config.ddpg)
    task = experiment_task(config)
    if config.task.search == "ddpg":
        return gymnasium_ddpg_local_search(task, config.ddpg)
    check_search(config.task.search, config.ddpg.device)
    try:
        from lonlib.sb3.search import sb3_gymnasium_local_search
    except ImportError as error:  # installed, yet it does not import
        raise ValueError(f"{MISSING.format(search=config.task.search)} ({error})") from None
    return sb3_gymnasium_local_search(task, config.ddpg, config.task.search)


# ---------------------------------------------------------------------------- experiments
def pending_runs(config: ExperimentConfig, out: Path) -> list[tuple[float, int]]:
    """Runs that are not finished yet (reads every stored run; corrupt files raise)."""
    pending = []
    for p in config.perturbations:
        bh = config.basin_hopping(p)
        for run in range(config.runs):
            state = load_run_state(out, p, run, bh)
            if state is None or not state.finished:
                pending.append((p, run))
    return pending


def remove_finished_checkpoints(
    out: Path, todo: list[tuple[float, int]], config: ExperimentConfig | None = None
) -> None:
    """Remove the in-flight checkpoints (:mod:`lonlib.experiment.checkpoints`) all of whose runs
    have ended since (they went on without them: nothing in them can be resumed), and those whose
    metadata is refused (truncated, planted, with ``config`` listing a run that is not one of the
    experiment's, :func:`experiment_plan`: their runs continue from their stored trials). A
    checkpoint whose runs another process holds is left to it."""
    checkpoints, refused = scan_inflight(
        out, None if config is None else experiment_plan(out, config)
    )
    for meta, reason in refused:
        with hold_runs(out, [], [checkpoint_lock_path(meta)]) as held:
            if held:
                log.warning("%s: refused in-flight checkpoint removed (%s)", meta, reason)
                remove_inflight(meta)
    for checkpoint in checkpoints:
        if not set(checkpoint.runs).isdisjoint(todo):
            continue
        with hold_runs(out, checkpoint.runs, [checkpoint_lock_path(checkpoint)]) as held:
            if held:
                log.warning("%s: in-flight checkpoint of ended runs removed", checkpoint.name)
                remove_inflight(checkpoint.metadata_path)


def _held_by_another(out: Path, run: tuple[float, int]) -> bool:
    """Does another process hold run ``run``'s lock? (One lock at a time: a folder of
    thousands of runs must not open them all at once.)"""
    with hold_runs(out, [run]) as free:
        return not free


def run_experiment(
    config: ExperimentConfig,
    out: str | Path,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    max_attempts: int = 3,
    executor: str | None = None,
    slots: int | None = None,
    checkpoint_seconds: float | None = CHECKPOINT_SECONDS,
    drain_after_seconds: float | None = None,
    allow_changes: Collection[str] = (),
) -> pd.DataFrame:
    """Run every unfinished run of ``config`` into ``out``; return all trials.

    ``executor`` (default: Dask when a ``scheduler`` is given, else the configuration's)
    picks where runs execute:
    ``"serial"`` in this process; ``"pool"``: ``workers`` local processes (one torch thread
    each); ``"dask"``: on ``scheduler``, a Dask scheduler address or ``"dask-local"`` for a
    LocalCluster of ``workers`` processes; ``"lockstep"``: the local searches of up to
    ``slots`` runs trained as one batch (:mod:`lonlib.experiment.lockstep`; on the device
    ``config.ddpg.device``), in this process, or with ``workers`` > 1 one batch per worker
    process, each over its share of the runs; it writes its batch to an in-flight
    checkpoint every ``checkpoint_seconds`` (``None``: never; :mod:`lonlib.experiment.checkpoints`)
    and resumes from it. ``"auto"``: Dask if a scheduler is given, else a pool for ``workers`` > 1,
    else serial. Every executor gives a run the same trials. A run whose worker dies is retried (up
    to ``max_attempts``) and resumes from its last stored local search.

    ``drain_after_seconds`` (lockstep only; ``None``: never) after the start of the call, the
    batches start no local search: the searches in flight are finished and stored, their runs
    left unfinished (and unlocked) when they would need more, and the call returns once none is
    in flight; calling it again continues them. The first batch is filled even at 0, so every
    call makes progress.

    ``allow_changes`` names settings of a stored experiment this call may change
    (:data:`lonlib.storage.manifest.CHANGEABLE_FIELDS`, e.g. a lowered
    ``max_local_searches``): accepted when every stored run stays a valid run under the new
    settings and no other process is sampling the folder, and recorded in the manifest's
    session (:func:`lonlib.storage.manifest.updated_manifest`).

    Before any compute: ``out`` must exist or be creatable in an existing folder and accept
    files (:class:`lonlib.storage.atomic.DataWriteError` otherwise; on Dask, every worker checks it
    too), and its stored runs must be readable. A run that another process is writing is
    left to it and waited for once everything else is done; if its holder dies, this
    process continues the run from what the holder stored.
    """
    started = time.monotonic()  # the drain time counts from here
    config, kind = _session_config(
        config, workers, scheduler, max_attempts, executor, slots, checkpoint_seconds
    )
    check_drain(kind, drain_after_seconds)
    check_memory(config, concurrent_searches(config, kind, workers, scheduler))  # before any folder
    drain_at = None if drain_after_seconds is None else started + drain_after_seconds
    out = Path(out)
    check_task_descriptor(config, out)
    check_output_folder(out)
    capability = torch_cpu_capability()
    session = SamplingSession.open(
        out,
        config,
        session_provenance(capability),
        allow_changes,
        pending=lambda: pending_runs(config, out),
        tidy=lambda todo: remove_finished_checkpoints(out, todo, config),
        held_by_another=partial(_held_by_another, out),
        started=started,
    )
    try:  # from here on the session records its end, however it stops
        if session.todo and config.ddpg.device == "cpu":
            warn_about_cpu_kernels(session.manifest, capability)
        with _progress(config, session.todo, progress) as bar:
            sampler = _Sampler(out, config, kind, bar, workers, scheduler, max_attempts)
            sampler.run(session.todo, checkpoint_seconds, drain_at)
    except DataWriteError:
        session.failed_write()  # a session stopped by a failed write writes nothing more
        raise
    finally:
        session.close()
    return read_experiment_trials(out)


def _session_config(
    config: ExperimentConfig,
    workers: int,
    scheduler: str | None,
    max_attempts: int,
    executor: str | None,
    slots: int | None,
    checkpoint_seconds: float | None,
) -> tuple[ExperimentConfig, str]:
    """The configuration this session uses (its executor kind and slots) and the kind, every
    argument of :func:`run_experiment` checked (ValueError naming it)."""
    check_range("workers", workers, 1, 4096)
    check_range("max_attempts", max_attempts, 1, 1000)
    requested = session_executor(executor, config.executor, scheduler)
    kind = resolve_executor(requested, workers, scheduler)
    slots = config.slots if slots is None else slots
    check_range("slots", slots, 1, 100_000)
    if checkpoint_seconds is not None:
        check_range("checkpoint_seconds", checkpoint_seconds, 0.0, 1e9)
    config = dataclasses.replace(config, executor=kind, slots=slots)  # what this session uses
    check_device(config.ddpg.device)
    if config.task is not None:
        check_search(config.task.search, config.ddpg.device)
    if kind == "lockstep":
        check_lockstep(config.ddpg, slots)
    return config, kind


def _progress(config: ExperimentConfig, todo: list[tuple[float, int]], progress: bool) -> tqdm:
    """The session's progress bar over the experiment's runs (those done count as done)."""
    total = len(config.perturbations) * config.runs
    return progress_bar(
        total=total,
        initial=total - len(todo),
        desc=f"{config.name} runs",
        disable=not progress,
        unit="run",
    )


class _Sampler:
    """The runs of a session executed on its executor ``kind``: :meth:`run` does the runs to
    do, then the runs another process was writing (waiting for them), then removes the
    in-flight checkpoints of the runs that ended."""

    def __init__(
        self,
        out: Path,
        config: ExperimentConfig,
        kind: str,
        bar: tqdm,
        workers: int,
        scheduler: str | None,
        max_attempts: int,
    ) -> None:
        self.out, self.config, self.kind, self.bar = out, config, kind, bar
        self.workers, self.scheduler, self.max_attempts = workers, scheduler, max_attempts
        self.held: dict[tuple[float, int], str] = {}

    def on_done(self, summary: dict[str, Any]) -> None:
        if summary["held_by"] is None:
            _refresh(self.bar, self.out, done=1)
        else:
            self.held[summary["p"], summary["run"]] = summary["held_by"]

    def run(
        self,
        todo: list[tuple[float, int]],
        checkpoint_seconds: float | None,
        drain_at: float | None,
    ) -> None:
        out, config = self.out, self.config
        if todo:
            self.execute(todo, False, checkpoint_seconds, drain_at)
        if self.held and draining(drain_at):  # waiting for them would start searches
            log.warning(
                "%s: drained; %d runs another process is writing left to it", out, len(self.held)
            )
        elif self.held:
            names = "; ".join(f"p={p} run {run}: {who}" for (p, run), who in self.held.items())
            log.warning("%s: waiting for runs another process is writing (%s)", out, names)
            jobs = list(self.held)
            self.held.clear()
            self.execute(jobs, True, checkpoint_seconds, drain_at)
        if todo:  # a batch that ended without resuming a checkpoint of its runs left it
            remove_finished_checkpoints(out, pending_runs(config, out), config)

    def execute(
        self,
        jobs: list[tuple[float, int]],
        wait: bool,
        checkpoint_seconds: float | None,
        drain_at: float | None,
    ) -> None:
        out, config, kind, bar = self.out, self.config, self.kind, self.bar
        if kind == "lockstep":
            run_lockstep_processes(
                out,
                config,
                jobs,
                self.on_done,
                config.slots,
                self.workers,
                wait,
                lambda info: _refresh(bar, out, batch=info),
                # a Gymnasium task's batch is not checkpointed: its searches re-run
                checkpoint_seconds=checkpoint_seconds if config.task is None else None,
                drain_at=drain_at,
            )
            return
        execute_runs(
            partial(run_one, out, config, wait=wait),
            jobs,
            self.on_done,
            workers=1 if kind == "serial" else self.workers,
            scheduler=self.scheduler if kind == "dask" else None,
            max_attempts=self.max_attempts,
            key_prefix=config.name,
            on_tick=lambda: _refresh(bar, out),
            worker_check=partial(check_worker_sees_folder, str(out)),
        )


def warn_about_cpu_kernels(manifest: dict[str, Any], capability: str) -> None:
    """Warn (:class:`lonlib.util.cpu_kernels.CpuKernelWarning`, and in the log) when this
    session's torch CPU kernels are not the ones lonlib pins, or not its earlier sessions'."""
    for message in (unpinned_message(capability), capability_change(manifest, capability)):
        if message:
            log.warning(message)
            warnings.warn(message, CpuKernelWarning, stacklevel=3)


def check_worker_sees_folder(out: str) -> None:
    """On an executor's worker, before any compute: the experiment folder the client set up
    is there (a worker without the shared file system would write elsewhere) and accepts
    files. Raises :class:`lonlib.storage.atomic.DataWriteError` naming the folder."""
    if not manifest_path(Path(out)).exists():
        raise DataWriteError(
            errno.ENOENT,
            f"cannot write {out}: this worker does not see the experiment's manifest there "
            "(every worker needs the same folder, on a shared file system)",
        )
    check_output_folder(Path(out))


DRAINING = " (draining)"  # what the progress bar's description says once a batch drains


def _refresh(bar: tqdm, out: Path, done: int = 0, batch: dict | None = None) -> None:
    """Advance the progress bar and show local searches and the best fitness so far (and,
    from the lockstep executor, its batch: searches in flight, env steps per second, and
    "(draining)" after the description once it drains)."""
    if bar.disable:
        return
    bar.update(done)
    trials = read_experiment_trials(out)
    postfix = dict(batch or {})
    if postfix.pop("draining", False) and not bar.desc.removesuffix(": ").endswith(DRAINING):
        bar.set_description_str(bar.desc.removesuffix(": ") + DRAINING, refresh=False)
    if len(trials):
        postfix.update(local_searches=len(trials), best=f"{trials['fitness'].max():.3f}")
    if postfix:
        bar.set_postfix(postfix)


status = experiment_status  # the name ``lonlib status`` and the notebooks call
