"""Lockstep batches in several worker processes, dealt out again when one runs out of runs.

For machines with a few cores and no GPU: one lockstep batch
(:func:`lonlib.experiment.lockstep.run_lockstep`) per process, each over its share of the runs. The
shares are fixed while every process has work. When one process's runs have all ended while
the others still hold more work (searches in flight and runs not started) than there are
busy processes, every busy process writes its in-flight checkpoint and stops at its next
tick, and a new round deals out what is left again: the checkpoints are split so that each
process resumes searches, and the runs not started go to the process with the fewest. A
checkpoint carries each search exactly, so a run's trials are the same as in one batch
(tested); the rounds only change how soon the experiment ends. A process that cannot write
its checkpoint keeps its searches (and the round waits for it); runs held by another process
and waited for (``wait``) are never dealt out again. From a drain time on, every process drains
its batch (:func:`~lonlib.experiment.lockstep.run_lockstep`) and no work is dealt out again.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from lonlib.experiment.checkpoints import remove_inflight, split_inflight
from lonlib.experiment.lockstep import CHECKPOINT_SECONDS, draining, run_lockstep
from lonlib.experiment.runs import experiment_plan, hold_runs
from lonlib.storage.atomic import DataWriteError
from lonlib.storage.inflight import (
    CheckpointUnreadable,
    OtherSettings,
    checkpoint_lock_path,
    inflight_checkpoints,
)
from lonlib.storage.layout import Job
from lonlib.util.messages import show_lonlib_messages
from lonlib.util.validation import check_range

log = logging.getLogger(__name__)

# Set in each worker process by the pool's initializer: the round's "yield" signal and every
# process's load (searches in flight plus runs not started), which the parent reads.
_yield_signal: Any = None
_loads: Any = None


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
    checkpoint_seconds: float | None = CHECKPOINT_SECONDS,
    drain_at: float | None = None,
) -> None:
    """:func:`~lonlib.experiment.lockstep.run_lockstep` in ``workers`` spawned processes, each a
    batch of up to ``slots`` searches over its share of the jobs. A process first gets the runs of
    one in-flight checkpoint, if any, so that it resumes that batch; the other jobs are dealt out in
    turn. With checkpoints (``checkpoint_seconds`` not None), the processes are stopped and the work
    left dealt out again whenever a process runs out of runs while the others could use its core
    (module docstring). ``on_done`` gets each run's summary once; ``on_tick`` the number of
    processes busy (and ``draining``). A run's trials are the same as in one batch.

    From ``drain_at`` on (a :func:`time.monotonic` value, the same clock in every process of
    this machine; ``None``: never) each process drains its batch, and no round starts a
    search: a round that begins past it only finishes the searches of the checkpoints it
    resumes. Only the first round fills its batches past it (every call makes progress)."""
    check_range("workers", workers, 1, 4096)
    checkpoints = checkpoint_seconds is not None
    remaining = list(jobs)
    reported: set[Job] = set()

    def report(summary: dict[str, Any]) -> None:
        reported.add((summary["p"], summary["run"]))
        on_done(summary)

    start_first = True  # the first round fills its batches even past the drain time
    while remaining:
        if checkpoints:
            spread_checkpoints(out, config, remaining, workers)
        groups = [group for group in split_jobs(out, remaining, workers, checkpoints) if group]
        if len(groups) <= 1:
            run_lockstep(
                out,
                config,
                remaining,
                on_done,
                slots,
                wait,
                on_tick,
                tick_seconds,
                checkpoint_seconds,
                drain_at=drain_at,
                start_first=start_first,
            )
            return
        dealt_again = _round(
            out,
            config,
            groups,
            report,
            slots=slots,
            wait=wait,
            on_tick=on_tick,
            tick_seconds=tick_seconds,
            checkpoint_seconds=checkpoint_seconds,
            drain_at=drain_at,
            start_first=start_first,
        )
        if not dealt_again:
            return
        start_first = False
        remaining = [job for job in remaining if job not in reported]


def _round(
    out: str | Path,
    config: Any,
    groups: list[list[Job]],
    on_done: Callable[[dict[str, Any]], None],
    slots: int,
    wait: bool,
    on_tick: Callable[[dict[str, Any]], None] | None,
    tick_seconds: float,
    checkpoint_seconds: float | None,
    drain_at: float | None = None,
    start_first: bool = True,
) -> bool:
    """One process per group until every process has ended; True when they were asked to
    yield (their work is then left in checkpoints and pending runs for the next round;
    never past the drain time ``drain_at``, when each process drains its batch instead).
    Never with ``wait``: a process waiting for a run another process holds cannot yield
    while it waits. If this process fails (or is interrupted), the workers are asked to
    yield too, so that they write their checkpoints and stop within a tick."""
    context = multiprocessing.get_context("spawn")
    signal = context.Event()
    loads = context.RawArray("q", len(groups))  # 0 until a process has said otherwise
    rebalance = checkpoint_seconds is not None and not wait
    with cf.ProcessPoolExecutor(
        len(groups), mp_context=context, initializer=_share, initargs=(signal, loads)
    ) as pool:
        futures = {
            pool.submit(
                _lockstep_group,
                str(out),
                config,
                group,
                slots,
                wait,
                os.getpid(),
                checkpoint_seconds,
                tick_seconds,
                index,
                drain_at,
                start_first,
            ): index
            for index, group in enumerate(groups)
        }
        busy = set(futures)
        try:
            while busy:
                done, busy = cf.wait(busy, timeout=tick_seconds)
                for future in done:
                    for summary in future.result():  # the runs it ended
                        on_done(summary)
                left = sum(loads[futures[future]] for future in busy)
                idle = len(busy) < len(futures)
                drained = draining(drain_at)  # the processes drain: nothing to deal out
                if rebalance and idle and not signal.is_set() and left > len(busy) and not drained:
                    log.info(
                        "%s: a process ran out of runs; %d searches in flight or runs not "
                        "started are dealt out again",
                        out,
                        left,
                    )
                    signal.set()
                if on_tick is not None:
                    on_tick({"processes": len(busy)} | ({"draining": True} if drained else {}))
        except BaseException:
            signal.set()
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return signal.is_set()


def _share(signal: Any, loads: Any) -> None:
    """Pool initializer: the round's yield signal and loads, for :func:`_lockstep_group`."""
    global _yield_signal, _loads
    _yield_signal, _loads = signal, loads


def spread_checkpoints(out: str | Path, config: Any, jobs: Sequence[Job], workers: int) -> None:
    """Split in-flight checkpoints of ``jobs`` until there is one per worker process (or
    each holds one run), so that every process resumes searches; a checkpoint whose runs
    another process holds is left alone."""

    wanted = set(jobs)
    plan = experiment_plan(out, config)  # a checkpoint listing other runs is refused
    while True:
        stored = [c for c in inflight_checkpoints(out, plan) if not wanted.isdisjoint(c.runs)]
        if not stored or len(stored) >= workers or len(stored[0].runs) < 2:
            return
        largest = stored[0]
        with hold_runs(out, largest.runs, [checkpoint_lock_path(largest)]) as held:
            if not held:
                return
            try:
                parts = min(workers - len(stored) + 1, len(largest.runs))
                split_inflight(largest, parts, (config.env, config.ddpg))
            except OtherSettings as error:  # kept for a session with those settings
                log.warning("%s", error)
                return
            except (CheckpointUnreadable, DataWriteError) as error:
                log.warning("%s: not split (%s)", largest.metadata_path, error)
                return
            except ValueError as error:
                path = largest.metadata_path
                log.warning("%s: stale in-flight checkpoint removed (%s)", path, error)
                remove_inflight(path)


def split_jobs(
    out: str | Path, jobs: Sequence[Job], workers: int, checkpoints: bool = True
) -> list[list[Job]]:
    """``jobs`` dealt to ``workers`` processes: with ``checkpoints``, each of the first gets
    the runs (those among ``jobs``: the others have ended) of one in-flight checkpoint of
    ``out`` first; then the other jobs go in turn to the process with the fewest."""
    groups: list[list[Job]] = [[] for _ in range(workers)]
    taken: set[Job] = set()
    wanted = set(jobs)
    stored = inflight_checkpoints(out) if checkpoints else []
    stored = [c for c in stored if not wanted.isdisjoint(c.runs)]
    for group, checkpoint in zip(groups, stored, strict=False):
        if taken.isdisjoint(checkpoint.runs):
            group.extend(run for run in checkpoint.runs if run in wanted)
            taken.update(checkpoint.runs)
    for job in jobs:
        if job not in taken:
            min(groups, key=len).append(job)
    return groups


ORPHAN_CHECK_SECONDS = 1.0
"""How often a lockstep worker process checks that the process that started it is alive."""
ORPHAN_WATCH_THREAD = "lonlib-orphan-watch"


def _exit_when_orphaned(parent: int) -> None:
    """Watch, from a daemon thread, that ``parent`` still is this process's parent, and exit
    at once when it is not. A thread, not a check between batch steps: a search's final
    judging can run for minutes without a step."""

    if any(thread.name == ORPHAN_WATCH_THREAD for thread in threading.enumerate()):
        return  # a pool process runs several groups: one watcher is enough

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(ORPHAN_CHECK_SECONDS)
        print(f"lockstep worker {os.getpid()}: parent {parent} died; exiting", flush=True)
        os._exit(1)  # the kernel releases the run locks; stored files are written atomically

    threading.Thread(target=watch, name=ORPHAN_WATCH_THREAD, daemon=True).start()


def _lockstep_group(
    out: str,
    config: Any,
    jobs: list[Job],
    slots: int,
    wait: bool,
    parent: int,
    checkpoint_seconds: float | None,
    tick_seconds: float,
    index: int,
    drain_at: float | None = None,
    start_first: bool = True,
) -> list[dict[str, Any]]:
    """One worker process's lockstep batch: the summaries of its runs that ended (whether
    it yielded is the round's signal). It stops (losing only its searches in flight since its last
    checkpoint) when the process that started it has died."""

    def on_tick(info: dict[str, Any]) -> None:
        _loads[index] = info["in_flight"] + info["pending"]

    _exit_when_orphaned(parent)
    show_lonlib_messages()  # a spawned process: its messages would be lost otherwise
    summaries: list[dict[str, Any]] = []
    run_lockstep(
        out,
        config,
        jobs,
        summaries.append,
        slots,
        wait,
        on_tick,
        tick_seconds,
        checkpoint_seconds,
        should_yield=_yield_signal.is_set,
        drain_at=drain_at,
        start_first=start_first,
    )
    return summaries
