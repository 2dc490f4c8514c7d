"""The lockstep executor: the local searches of many basin-hopping runs trained as one batch.

One process holds a :class:`lonlib.ddpg.SlotTrainer` of ``K`` slots. Each slot trains the
current local search of one run; all ``K`` step and update together (one batched matrix
product per layer). When a slot's search ends, Algorithm 2 accepts or rejects it for its run
at once (:class:`lonlib.basin_hopping.BasinHoppingRun`), the trial is stored, and the slot is
refilled with that run's next search, or with the next pending run once the run has ended
(continuous batching): the batch stays full while work is pending; once it runs out, the
batch sheds finished slots (:meth:`~lonlib.ddpg.SlotTrainer.shrink`).

Every random number a search draws comes from its own ``(run seed, trial)`` streams and no
reduction mixes slots, so a run's trials do not depend on ``K``, on its slot, or on the runs
sharing the batch: on the CPU they are bit for bit the serial executor's (tested). Storage
is the other executors' (:func:`lonlib.store.save_step` after every search, each run's lock
held while it is in the batch): a killed lockstep experiment resumes and loses at most the
searches in flight.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import time
from collections import deque
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lonlib.basin_hopping import BasinHoppingRun, SearchRequest, local_optimum
from lonlib.ddpg import DDPGConfig, SlotTrainer, check_batch_size
from lonlib.lock import LockHeld, exclusive_lock
from lonlib.store import save_step
from lonlib.validation import check_range

Job = tuple[float, int]


@dataclass
class _Run:
    """A run in the batch: its Algorithm 2 driver, the search it waits for, its lock."""

    p: float
    run: int
    driver: BasinHoppingRun
    lock: ExitStack
    request: SearchRequest | None = None


def check_lockstep(hp: DDPGConfig, slots: int) -> None:
    """Refuse, by name, settings the lockstep executor cannot run."""
    check_range("slots", slots, 1, 100_000)
    if hp.update != "lean":
        raise ValueError(
            f"the lockstep executor needs ddpg.update='lean' (slot refills), got {hp.update!r}"
        )
    check_batch_size(hp, slots)


def run_lockstep(
    out: str | Path,
    config: Any,
    jobs: Sequence[Job],
    on_done: Callable[[dict[str, Any]], None],
    slots: int,
    wait: bool = False,
    on_tick: Callable[[dict[str, Any]], None] | None = None,
    tick_seconds: float = 5.0,
) -> None:
    """Run (or resume) the runs ``jobs`` of experiment ``config`` in ``out`` through one
    lockstep batch of at most ``slots`` local searches.

    ``on_done(summary)`` is called as each run ends (the summary of
    :func:`lonlib.experiment.run_summary`), and for a run another process holds, at once
    with ``held_by`` naming the holder (unless ``wait``: then its lock is waited for).
    ``on_tick(info)`` runs every ``tick_seconds`` for progress displays, with the searches
    in flight and the env steps per second of the batch since the last tick.
    """
    from lonlib.experiment import open_run, run_lock_path, run_summary

    check_lockstep(config.ddpg, slots)
    out = Path(out)
    pending: deque[Job] = deque(jobs)
    active: dict[Job, _Run] = {}

    deferred: list[Job] = []  # runs another process holds, waited for once the batch ends

    def open_next(block: bool = False) -> _Run | None:
        """The next pending run that still needs a search, locked; None when none is left.
        A run another process holds is reported (or, with ``wait``, deferred: waiting for
        it here would stall every search in flight); ``block`` waits for the first one."""
        while pending:
            p, run = pending.popleft()
            lock = ExitStack()
            try:
                lock.enter_context(exclusive_lock(run_lock_path(out, p, run), wait=block))
            except LockHeld as held:
                if wait:
                    deferred.append((p, run))
                else:
                    on_done({"p": p, "run": run, "held_by": held.holder})
                continue
            try:
                driver = open_run(out, config, p, run)
            except BaseException:
                lock.close()
                raise
            if driver.finished:
                lock.close()
                on_done(run_summary(p, run, driver.state))
                continue
            return _Run(p, run, driver, lock)
        return None

    def ask(run: _Run) -> _Run:
        active[run.p, run.run] = run  # first, so that the lock is released if asking fails
        run.request = run.driver.next_search()
        return run

    def batch(block_first: bool) -> None:
        """Train until the pending runs are done (those held by others are deferred)."""
        first = []
        while len(first) < slots and (run := open_next(block_first and not first)) is not None:
            first.append(ask(run))
        if not first:
            return
        trainer = SlotTrainer(
            np.stack([r.request.theta for r in first]),
            np.stack([r.request.omega for r in first]),
            [r.request.seed for r in first],
            config.env,
            config.ddpg,
            tags=[(r.p, r.run) for r in first],
        )
        last_tick, steps_at_tick = time.monotonic(), 0
        steps = 0
        while trainer.busy.any():
            steps += int(trainer.busy.sum())
            refill: list[_Run] = []
            for tag, result in trainer.step():
                run = active[tag]
                optimum = local_optimum(result, config.env, config.ddpg)
                run.driver.record(run.request, optimum, result.seconds)
                save_step(out, run.p, run.run, run.driver.state.trials, optimum)
                if run.driver.finished:
                    del active[tag]
                    run.lock.close()
                    on_done(run_summary(run.p, run.run, run.driver.state))
                    run = open_next()
                    if run is None:
                        continue
                refill.append(ask(run))
            if refill:
                trainer.start(
                    trainer.free_slots()[: len(refill)],
                    np.stack([r.request.theta for r in refill]),
                    np.stack([r.request.omega for r in refill]),
                    [r.request.seed for r in refill],
                    [(r.p, r.run) for r in refill],
                )
            elif not pending and not trainer.busy.all():
                trainer.shrink()
            now = time.monotonic()
            if on_tick is not None and now - last_tick >= tick_seconds:
                rate = (steps - steps_at_tick) / (now - last_tick)
                on_tick({"in_flight": int(trainer.busy.sum()), "env_steps/s": f"{rate:,.0f}"})
                last_tick, steps_at_tick = now, steps

    try:
        batch(block_first=False)
        while deferred:  # runs another process held: now wait for them, one batch at a time
            pending.extend(deferred)
            deferred.clear()
            batch(block_first=True)
    finally:
        for run in active.values():
            run.lock.close()


def run_lockstep_processes(
    out: str | Path,
    config: Any,
    jobs: Sequence[Job],
    on_done: Callable[[dict[str, Any]], None],
    slots: int,
    workers: int,
    wait: bool = False,
    on_tick: Callable[[dict[str, Any]], None] | None = None,
    tick_seconds: float = 5.0,
) -> None:
    """:func:`run_lockstep` in ``workers`` spawned processes, each a batch of up to
    ``slots`` searches over every ``workers``-th job (for machines with a few cores and no
    GPU: one lockstep batch per core). A run's trials are the same as in one batch."""
    check_range("workers", workers, 1, 4096)
    groups = [list(jobs[i::workers]) for i in range(workers)]
    groups = [group for group in groups if group]
    if len(groups) <= 1:
        run_lockstep(out, config, jobs, on_done, slots, wait, on_tick, tick_seconds)
        return
    context = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(len(groups), mp_context=context) as pool:
        futures = [
            pool.submit(_lockstep_group, str(out), config, group, slots, wait, os.getpid())
            for group in groups
        ]
        pending = set(futures)
        try:
            while pending:
                done, pending = cf.wait(pending, timeout=tick_seconds)
                for future in done:
                    for summary in future.result():
                        on_done(summary)
                if on_tick is not None:
                    on_tick({"processes": len(pending)})
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _lockstep_group(
    out: str, config: Any, jobs: list[Job], slots: int, wait: bool, parent: int
) -> list[dict[str, Any]]:
    """One worker process's lockstep batch; the summaries of its runs. It stops (losing
    only its searches in flight) when the process that started it has died."""

    def stop_if_orphaned(_info: dict[str, Any]) -> None:
        if os.getppid() != parent:  # the pool machinery would swallow an exception
            print(f"lockstep worker {os.getpid()}: parent {parent} died; exiting", flush=True)
            os._exit(1)  # the kernel releases the run locks; stored trials are complete

    summaries: list[dict[str, Any]] = []
    run_lockstep(out, config, jobs, summaries.append, slots, wait, stop_if_orphaned)
    return summaries
