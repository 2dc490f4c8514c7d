"""Executors: run independent jobs in this process, in local worker processes, or on Dask.

(The fourth executor, ``lockstep``, trains the local searches of many runs as one batch in
this process; it lives in :mod:`lonlib.experiment.lockstep`. :func:`resolve_executor` picks one.)

A job is one basin-hopping run ``(p, run)``; ``task(p, run)`` executes (or resumes) it and
must be picklable (a module-level function or a :func:`functools.partial` of one). Jobs
share nothing but the output folder, so they may run in any order and anywhere. After each
finished job the executor calls ``on_done(result)``; :func:`run_pool` also calls
``on_tick()`` every few seconds so that a progress display can show work inside runs. A
job that raises stops the executor: jobs not yet started are cancelled and the error
propagates. A job whose worker process dies is run again, at most ``max_attempts`` times.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import uuid
from collections.abc import Callable, Sequence
from typing import Any

from lonlib.config import EXECUTORS
from lonlib.storage.layout import Job

Task = Callable[[float, int], Any]
OnDone = Callable[[Any], None]


def session_executor(requested: str | None, configured: str, scheduler: str | None) -> str:
    """The executor a session asks for: ``requested`` (``--executor``) when given, else Dask
    when a ``scheduler`` is given (a scheduler says where to run, so it outranks the
    configuration's default executor), else the configuration's ``configured``."""
    if requested:
        return requested
    return "dask" if scheduler else configured


def resolve_executor(executor: str, workers: int, scheduler: str | None) -> str:
    """The executor that runs: ``"auto"`` is Dask with a scheduler, a pool for ``workers``
    > 1, else serial; an explicit choice must fit the other arguments (checked by name)."""
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {EXECUTORS}, got {executor!r}")
    if executor == "auto":
        return "dask" if scheduler else ("pool" if workers > 1 else "serial")
    if executor == "dask" and not scheduler:
        raise ValueError("executor 'dask' needs a scheduler (an address or 'dask-local')")
    if executor != "dask" and scheduler:
        raise ValueError(f"a scheduler was given, but executor {executor!r} does not use one")
    return executor


def execute_runs(
    task: Task,
    jobs: Sequence[Job],
    on_done: OnDone,
    workers: int,
    scheduler: str | None,
    max_attempts: int,
    key_prefix: str,
    on_tick: Callable[[], None] | None = None,
    worker_check: Callable[[], None] | None = None,
) -> None:
    """Run the jobs with the executor that ``workers`` and ``scheduler`` select: Dask if a
    scheduler is given, else a process pool for ``workers`` > 1, else this process.
    ``worker_check`` runs on every Dask worker before any job (local workers share this
    process's view of the file system and skip it)."""
    if scheduler is not None:
        run_dask(task, jobs, workers, scheduler, on_done, max_attempts, key_prefix, worker_check)
    elif workers > 1:
        run_pool(task, jobs, workers, on_done, max_attempts, on_tick)
    else:
        run_serial(task, jobs, on_done)


def run_serial(task: Task, jobs: Sequence[Job], on_done: OnDone) -> None:
    """Run every job in this process, one after the other."""
    for p, run in jobs:
        on_done(task(p, run))


def run_pool(
    task: Task,
    jobs: Sequence[Job],
    workers: int,
    on_done: OnDone,
    max_attempts: int,
    on_tick: Callable[[], None] | None = None,
) -> None:
    """Run the jobs in ``workers`` spawned processes. A job whose worker dies is submitted
    again in a fresh pool (at most ``max_attempts`` times in all)."""
    attempts = dict.fromkeys(jobs, 0)
    remaining = list(jobs)
    while remaining:
        context = multiprocessing.get_context("spawn")
        broken: list[Job] = []
        with cf.ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            futures = {pool.submit(task, p, run): (p, run) for p, run in remaining}
            pending = set(futures)
            try:
                while pending:
                    done, pending = cf.wait(pending, timeout=5, return_when=cf.FIRST_COMPLETED)
                    for future in done:
                        try:
                            result = future.result()
                        except cf.process.BrokenProcessPool:
                            broken.append(futures[future])
                        else:
                            on_done(result)
                    if on_tick is not None:
                        on_tick()
            except BaseException:
                pool.shutdown(wait=True, cancel_futures=True)  # running jobs end, no new ones
                raise
        for job in broken:
            attempts[job] += 1
            if attempts[job] >= max_attempts:
                raise RuntimeError(f"run p={job[0]} run={job[1]} failed {max_attempts} times")
        remaining = broken


def run_dask(
    task: Task,
    jobs: Sequence[Job],
    workers: int,
    scheduler: str,
    on_done: OnDone,
    max_attempts: int,
    key_prefix: str,
    worker_check: Callable[[], None] | None = None,
) -> None:
    """Run the jobs on Dask: ``scheduler`` is a scheduler address, or ``"dask-local"`` for
    a LocalCluster of ``workers`` single-threaded processes. Task keys are
    ``<key_prefix>-<p>-<run>-<session>``, unique to this call, so that two sessions on one
    scheduler never share a task. A job that raises is retried ``max_attempts - 1`` times;
    a worker that dies while running a job makes the scheduler run it elsewhere (on a
    LocalCluster at most ``max_attempts`` times in all; a remote scheduler uses its own
    ``distributed.scheduler.allowed-failures``). ``worker_check()`` runs on every worker
    first; if it fails anywhere, nothing is submitted and the error names the worker."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler == "dask-local":
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            scheduler_kwargs={"allowed_failures": max_attempts - 1},
        )
        client = Client(cluster)
    else:
        client = Client(scheduler, timeout="30s")
    session = uuid.uuid4().hex[:8]
    try:
        if worker_check is not None:
            _check_workers(client, worker_check)
        futures = [
            client.submit(
                task,
                p,
                run,
                key=f"{key_prefix}-{p}-{run}-{session}",
                retries=max_attempts - 1,
                pure=False,
            )
            for p, run in jobs
        ]
        for future in as_completed(futures):
            on_done(future.result())
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _check_workers(client, check: Callable[[], None]) -> None:
    """Run ``check()`` on every worker; re-raise the first failure, naming its worker."""
    outcomes = client.run(check, on_error="return")
    failures = [(w, e) for w, e in outcomes.items() if isinstance(e, BaseException)]
    if not failures:
        return
    worker, error = failures[0]
    where = f"Dask worker {worker} ({len(failures)} of {len(outcomes)} workers failed)"
    if isinstance(error, OSError):
        raise type(error)(error.errno, f"{where}: {error.strerror}") from error
    error.add_note(where)
    raise error
