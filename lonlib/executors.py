"""Executors: run independent jobs in this process, in local worker processes, or on Dask.

A job is one basin-hopping run ``(p, run)``; ``task(p, run)`` executes (or resumes) it and
must be picklable (a module-level function or a :func:`functools.partial` of one). Jobs
share nothing but the output folder, so they may run in any order and anywhere. After each
finished job the executor calls ``on_done(result)``; :func:`run_pool` also calls
``on_tick()`` every few seconds so that a progress display can show work inside runs.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from collections.abc import Callable, Sequence
from typing import Any

Job = tuple[float, int]
Task = Callable[[float, int], Any]
OnDone = Callable[[Any], None]


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
) -> None:
    """Run the jobs on Dask: ``scheduler`` is a scheduler address, or ``"dask-local"`` for
    a LocalCluster of ``workers`` single-threaded processes. Task keys are
    ``<key_prefix>-<p>-<run>``."""
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler == "dask-local":
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    else:
        client = Client(scheduler, timeout="30s")
    try:
        futures = [
            client.submit(
                task,
                p,
                run,
                key=f"{key_prefix}-{p}-{run}",
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
