"""The lockstep executor: the local searches of many basin-hopping runs trained as one batch.

One process holds a :class:`lonlib.ddpg.trainer.SlotTrainer` of ``K`` slots. Each slot trains the
current local search of one run; all ``K`` step and update together (one batched matrix
product per layer). When a slot's search ends, Algorithm 2 accepts or rejects it for its run
at once (:class:`lonlib.search.algorithm.BasinHoppingRun`), the trial is stored, and the slot is
refilled with that run's next search, or with the next pending run once the run has ended
(continuous batching): the batch stays full while work is pending; once it runs out, the
batch sheds finished slots (:meth:`~lonlib.ddpg.trainer.SlotTrainer.shrink`).

Every random number a search draws comes from its own ``(run seed, trial)`` streams and no
reduction mixes slots, so a run's trials do not depend on ``K``, on its slot, or on the runs
sharing the batch: on the CPU they are bit for bit the serial executor's (tested). Storage
is the other executors' (:func:`lonlib.storage.trials.save_step` after every search, each run's lock
held while it is in the batch), and every few minutes the whole batch is also written to an
in-flight checkpoint (:mod:`lonlib.experiment.checkpoints`): a killed lockstep experiment resumes
its searches in flight from there, losing at most the minutes since.

A batch given a drain time (``drain_at``, for a machine whose time runs out) starts no search
from then on: a slot whose search ends is stored and left empty (its run's lock released,
finished or not, so that a later call continues it from its stored trials), the batch shrinks,
and it ends once no search is in flight. Runs it has not started stay unstarted.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lonlib.config import DDPGConfig
from lonlib.config.ddpg import check_batch_size
from lonlib.ddpg.gymnasium_search import GymnasiumSlotTrainer, SlotEnvironmentError
from lonlib.ddpg.search_interface import local_optimum, task_optimum
from lonlib.ddpg.slots import LocalSearchResult
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.experiment.checkpoints import (
    check_settings,
    read_inflight,
    remove_inflight,
    remove_leftovers,
    save_inflight,
)
from lonlib.experiment.runs import (
    check_behaviour_columns,
    experiment_plan,
    experiment_task,
    open_run,
    run_failure,
    run_lock_path,
    run_summary,
)
from lonlib.search.algorithm import BasinHoppingRun, LocalOptimum, SearchRequest
from lonlib.storage.atomic import DataWriteError
from lonlib.storage.inflight import (
    CheckpointUnreadable,
    InflightCheckpoint,
    OtherSettings,
    checkpoint_lock_path,
    inflight_checkpoints,
    new_checkpoint_path,
)
from lonlib.storage.layout import Job
from lonlib.storage.lock import LockHeld, exclusive_lock
from lonlib.storage.trials import save_step
from lonlib.task.gymnasium_task import TaskEnvironmentError
from lonlib.util.validation import check_range

log = logging.getLogger(__name__)

CHECKPOINT_SECONDS = 600.0  # how often a batch writes its in-flight checkpoint


def draining(drain_at: float | None) -> bool:
    """Whether the drain time ``drain_at`` (a :func:`time.monotonic` value; ``None``: never)
    has come: from then on a lockstep batch starts no local search."""
    return drain_at is not None and time.monotonic() >= drain_at


def check_drain(executor: str, drain_after_seconds: float | None) -> None:
    """Refuse, by name, a drain time out of range or for an executor that cannot drain: only
    the lockstep executor starts each local search itself (the others hand whole runs to
    their workers, which cannot be told to stop between two searches)."""
    if drain_after_seconds is None:
        return
    check_range("drain_after_seconds", drain_after_seconds, 0.0, 1e9)
    if executor != "lockstep":
        raise ValueError(
            f"a drain time (--drain-after) needs the lockstep executor; executor {executor!r} "
            "runs whole runs in its workers and cannot stop between their local searches "
            "(use --executor lockstep, or leave --drain-after out)"
        )


class _Yielded(Exception):
    """A batch stopped, its checkpoint written, because it was asked to yield."""


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


class LockstepBatch:
    """The lockstep executor's batch (:func:`run_lockstep`): runs of one experiment whose
    local searches train as one :class:`~lonlib.ddpg.trainer.SlotTrainer`, each slot refilled
    with its run's next search as one ends, resumed from and saved to in-flight checkpoints.
    The arguments are :func:`run_lockstep`'s; :meth:`run` trains until the runs end (or the
    batch yields, or drains)."""

    def __init__(
        self,
        out: str | Path,
        config: Any,
        jobs: Sequence[Job],
        on_done: Callable[[dict[str, Any]], None],
        slots: int,
        wait: bool = False,
        on_tick: Callable[[dict[str, Any]], None] | None = None,
        tick_seconds: float = 5.0,
        checkpoint_seconds: float | None = CHECKPOINT_SECONDS,
        should_yield: Callable[[], bool] | None = None,
        drain_at: float | None = None,
        start_first: bool = True,
    ) -> None:
        self.config, self.slots, self.wait, self.on_done = config, slots, wait, on_done
        self.drain_at, self.start_first = drain_at, start_first
        self.on_tick, self.tick_seconds = on_tick, tick_seconds
        self.checkpoint_seconds, self.should_yield = checkpoint_seconds, should_yield
        check_lockstep(config.ddpg, slots)
        if checkpoint_seconds is not None:
            check_range("checkpoint_seconds", checkpoint_seconds, 0.0, 1e9)
        if config.task is not None:  # a Gymnasium task's batch is not checkpointed
            self.checkpoint_seconds = None
        self.out = Path(out)
        self.plan = experiment_plan(self.out, config)  # a checkpoint listing other runs is refused
        self.pending: deque[Job] = deque(jobs)
        self.active: dict[Job, _Run] = {}

        self.deferred: list[Job] = []  # runs another process holds, waited for once the batch ends
        # the lock of the batch's checkpoint, held while the batch trains (and a Gymnasium
        # batch's environments, closed when it ends)
        self.owner = ExitStack()

    def lock_and_open(self, job: Job, block: bool) -> _Run:
        """Run ``job`` locked, its driver resumed from storage (raises LockHeld)."""
        p, run = job
        lock = ExitStack()
        lock.enter_context(exclusive_lock(run_lock_path(self.out, p, run), wait=block))
        try:
            return _Run(p, run, open_run(self.out, self.config, p, run), lock)
        except BaseException:
            lock.close()
            raise

    def open_next(self, block: bool = False) -> _Run | None:
        """The next pending run that still needs a search, locked; None when none is left.
        A run another process holds is reported (or, with ``wait``, deferred: waiting for
        it here would stall every search in flight); ``block`` waits for the first one."""
        while self.pending:
            job = self.pending.popleft()
            try:
                run = self.lock_and_open(job, block)
            except LockHeld as held:
                if self.wait:
                    self.deferred.append(job)
                else:
                    self.on_done({"p": job[0], "run": job[1], "held_by": held.holder})
                continue
            if run.driver.finished:
                run.lock.close()
                self.on_done(run_summary(run.p, run.run, run.driver.state))
                continue
            return run
        return None

    def ask(self, run: _Run) -> _Run:
        """Make ``run`` active and ask its driver for its next search."""
        self.active[run.p, run.run] = run  # first, so that the lock is released if asking fails
        run.request = run.driver.next_search()
        return run

    def restore(self) -> tuple[SlotTrainer, Path] | None:
        """The batch of an in-flight checkpoint of pending runs, the runs of its slots that
        continue made active (the others go back to the front of ``pending``)."""
        for checkpoint in inflight_checkpoints(self.out, self.plan):
            if self.checkpoint_seconds is None or set(checkpoint.runs).isdisjoint(self.pending):
                continue
            ours = ExitStack()  # a live batch holds its checkpoint's lock
            try:
                ours.enter_context(exclusive_lock(checkpoint_lock_path(checkpoint), wait=False))
            except LockHeld:
                continue
            restored = _restore(checkpoint, self.lock_and_open, self.config, set(self.pending))
            if restored is None:
                ours.close()
                continue
            self.owner.enter_context(ours)
            trainer, kept, dropped = restored
            for run in kept:
                self.pending.remove((run.p, run.run))
                self.active[run.p, run.run] = run
            for job in reversed(dropped):  # they restart from their stored trials, first
                if job in self.pending:  # (not if it has ended)
                    self.pending.remove(job)
                    self.pending.appendleft(job)
            log.info(
                "%s: resumed %d searches in flight (%s env steps) from %s%s",
                self.out,
                len(kept),
                f"{sum(int(trainer.steps[s]) for s in range(trainer.slots) if trainer.busy[s]):,}",
                checkpoint.name,
                f"; {len(dropped)} whose runs went on since restart" if dropped else "",
            )
            return trainer, checkpoint.metadata_path
        return None

    def refill(self, trainer: SlotTrainer, runs: list[_Run]) -> None:
        """Start the searches ``runs`` asked for in free slots of ``trainer``."""
        with self.naming_runs():
            self._start(trainer, runs)

    def _start(self, trainer: SlotTrainer, runs: list[_Run]) -> None:
        trainer.start(
            trainer.free_slots()[: len(runs)],
            np.stack([r.request.theta for r in runs]),
            np.stack([r.request.omega for r in runs]),
            [r.request.seed for r in runs],
            [(r.p, r.run) for r in runs],
        )

    def new_trainer(self, first: list[_Run]) -> SlotTrainer | GymnasiumSlotTrainer:
        """A batch of the searches ``first`` asked for: the coupled pendulums' slot trainer, or
        a Gymnasium task's (:class:`~lonlib.ddpg.gymnasium_search.GymnasiumSlotTrainer`)."""
        thetas = np.stack([r.request.theta for r in first])
        omegas = np.stack([r.request.omega for r in first])
        seeds, tags = [r.request.seed for r in first], [(r.p, r.run) for r in first]
        if self.config.task is not None:
            task = experiment_task(self.config)
            return GymnasiumSlotTrainer(task, thetas, omegas, seeds, self.config.ddpg, tags)
        return SlotTrainer(thetas, omegas, seeds, self.config.env, self.config.ddpg, tags=tags)

    def step(
        self, trainer: SlotTrainer | GymnasiumSlotTrainer
    ) -> list[tuple[Job, LocalSearchResult]]:
        """One step of ``trainer``; a Gymnasium environment's failure names its run (what the
        run stored before stays)."""
        with self.naming_runs():
            return trainer.step()

    @contextmanager
    def naming_runs(self) -> Iterator[None]:
        """A Gymnasium environment's failure in a search of the batch names its run."""
        try:
            yield
        except SlotEnvironmentError as error:
            run = self.active[error.tag]
            raise run_failure(run.p, run.run, len(run.driver.state.trials), error) from None

    def optimum(self, result: LocalSearchResult) -> LocalOptimum:
        """Algorithm 2's optimum of a finished search, with its behaviour descriptor (a
        Gymnasium task's, if it has one)."""
        if self.config.task is not None:
            return task_optimum(result, experiment_task(self.config), self.config.ddpg)
        return local_optimum(result, self.config.env, self.config.ddpg)

    def may_fill(self) -> bool:
        """Whether the batch may start searches in its free slots now: before the drain
        time, or for its first fill when ``start_first`` (every call makes progress)."""
        return self.start_first or not draining(self.drain_at)

    def release(self, tag: Job) -> None:
        """Take the run ``tag`` out of the batch, its lock released (reported if it ended)."""
        run = self.active.pop(tag)
        run.lock.close()
        if run.driver.finished:
            self.on_done(run_summary(run.p, run.run, run.driver.state))

    def batch(self, block_first: bool) -> None:
        """Train until the pending runs are done (those held by others are deferred)."""
        with self.owner:
            self.train(block_first)

    def write_checkpoint(self, trainer: SlotTrainer, checkpoint: Path | None) -> tuple[Path, bool]:
        """Write the batch to its in-flight checkpoint (a new one, locked, if it has none):
        the checkpoint's path (kept for the next write even if this one failed) and whether
        it was written."""
        if checkpoint is None:
            checkpoint = new_checkpoint_path(self.out)
            self.owner.enter_context(exclusive_lock(checkpoint_lock_path(checkpoint)))
        counts = {tag: len(run.driver.state.trials) for tag, run in self.active.items()}
        try:
            save_inflight(checkpoint, trainer, counts)
        except DataWriteError as error:  # a cache: the experiment goes on without it
            log.warning("in-flight checkpoint not written (%s)", error)
            return checkpoint, False
        return checkpoint, True

    def train(self, block_first: bool) -> None:
        """One batch: restored from a checkpoint or filled anew, trained until its runs end
        (raises :class:`_Yielded` when asked to yield, its checkpoint written)."""
        restored = self.restore()
        if restored is not None:
            trainer, checkpoint = restored
            checkpoint_written = time.monotonic()
            more = []
            while (
                self.may_fill()
                and len(more) < len(trainer.free_slots())
                and (run := self.open_next()) is not None
            ):
                more.append(self.ask(run))
            if more:
                self.refill(trainer, more)
        else:
            first = []
            while (
                self.may_fill()
                and len(first) < self.slots
                and (run := self.open_next(block_first and not first))
            ):
                first.append(self.ask(run))
            if not first:
                return
            with self.naming_runs():
                trainer = self.new_trainer(first)
            checkpoint, checkpoint_written = None, time.monotonic()
        if isinstance(trainer, GymnasiumSlotTrainer):  # its environments, however it ends
            self.owner.callback(trainer.close)
        self.start_first = False  # the first fill is over: the drain time holds from here
        last_tick, steps_at_tick = time.monotonic(), 0
        steps = 0
        yielding = self.should_yield is not None and self.checkpoint_seconds is not None
        drained = False
        while trainer.busy.any():
            steps += int(trainer.busy.sum())
            refills: list[_Run] = []
            ended = self.step(trainer)
            if not drained and draining(self.drain_at):
                drained = True
                log.info(
                    "%s: draining: no new local searches; the %d in flight are finished and stored",
                    self.out,
                    int(trainer.busy.sum()) + len(ended),
                )
            for tag, result in ended:
                run = self.active[tag]
                try:
                    optimum = self.optimum(result)
                except TaskEnvironmentError as error:  # its descriptor's episode
                    done = len(run.driver.state.trials)
                    raise run_failure(run.p, run.run, done, error) from None
                run.driver.record(run.request, optimum, result.seconds)
                trials = run.driver.state.trials
                check_behaviour_columns(self.out, self.config, run.p, run.run, trials)
                save_step(self.out, run.p, run.run, trials, optimum)
                if run.driver.finished or drained:
                    self.release(tag)  # draining: a later call continues the run
                    run = None if drained else self.open_next()
                    if run is None:
                        continue
                refills.append(self.ask(run))
            if refills:
                self.refill(trainer, refills)
            elif (drained or not self.pending) and not trainer.busy.all():
                trainer.shrink()
            now = time.monotonic()
            due = (
                self.checkpoint_seconds is not None
                and now - checkpoint_written >= self.checkpoint_seconds
            )
            if due and trainer.busy.any():
                checkpoint, _ = self.write_checkpoint(trainer, checkpoint)
                checkpoint_written = now
            if now - last_tick < self.tick_seconds:
                continue
            if self.on_tick is not None:
                rate = (steps - steps_at_tick) / (now - last_tick)
                info = {
                    "in_flight": int(trainer.busy.sum()),
                    "pending": len(self.pending),
                    "env_steps/s": f"{rate:,.0f}",
                }
                self.on_tick(info | ({"draining": True} if drained else {}))
            last_tick, steps_at_tick = now, steps
            if yielding and trainer.busy.any() and self.should_yield():
                checkpoint, written = self.write_checkpoint(trainer, checkpoint)
                if written:
                    log.info(
                        "%s: batch of %d searches yielded (checkpoint %s)",
                        self.out,
                        int(trainer.busy.sum()),
                        checkpoint.name,
                    )
                    raise _Yielded
                log.warning("%s: could not yield; its searches continue in this batch", self.out)
                yielding = False  # without a checkpoint it would lose its searches
        if checkpoint is not None:
            remove_inflight(checkpoint)  # every run of the batch has ended

    def run(self) -> bool:
        """Train until every run has ended (or, past the drain time, until no search is in
        flight): True if the batch yielded first (its checkpoint written), False otherwise."""
        try:
            self.batch(block_first=False)
            # runs another process held: now wait for them, one batch at a time
            while self.deferred and self.may_fill():
                self.pending.extend(self.deferred)
                self.deferred.clear()
                self.batch(block_first=True)
        except _Yielded:
            return True
        finally:
            for run in self.active.values():
                run.lock.close()
        return False


def run_lockstep(
    out: str | Path,
    config: Any,
    jobs: Sequence[Job],
    on_done: Callable[[dict[str, Any]], None],
    slots: int,
    wait: bool = False,
    on_tick: Callable[[dict[str, Any]], None] | None = None,
    tick_seconds: float = 5.0,
    checkpoint_seconds: float | None = CHECKPOINT_SECONDS,
    should_yield: Callable[[], bool] | None = None,
    drain_at: float | None = None,
    start_first: bool = True,
) -> bool:
    """Run (or resume) the runs ``jobs`` of experiment ``config`` in ``out`` through one
    lockstep batch of at most ``slots`` local searches. True when the batch yielded (below)
    before its runs ended.

    ``on_done(summary)`` is called as each run ends (the summary of
    :func:`lonlib.experiment.running.run_summary`), and for a run another process holds, at once
    with ``held_by`` naming the holder (unless ``wait``: then its lock is waited for).
    ``on_tick(info)`` runs every ``tick_seconds`` for progress displays, with the searches
    in flight, the runs still pending and the env steps per second of the batch since the
    last tick. ``should_yield()`` is asked at each tick: when it says so, the batch writes
    its in-flight checkpoint and stops, to be resumed (split, for example) by a new batch;
    the runs it has not started stay pending, and nothing is lost.

    Every ``checkpoint_seconds`` (``None``: never) the batch is written to an in-flight
    checkpoint (:mod:`lonlib.experiment.checkpoints`), kept in step with the stored trials after
    that;
    a batch whose runs a checkpoint holds restarts from it instead of from the stored trials
    (it keeps the checkpoint's number of slots).

    From the drain time ``drain_at`` on (a :func:`time.monotonic` value; ``None``: never) the
    batch starts no search: each search in flight is finished and stored, its slot left
    empty and its run's lock released (``on_done`` only for a run that ended), and the batch
    returns (False) once none is left in flight; the runs it has not started stay pending, and
    those held by another process are not waited for. Its first fill (or a checkpoint's free
    slots) starts searches even past the drain time when ``start_first``, so that every call
    makes progress.
    """
    return LockstepBatch(
        out,
        config,
        jobs,
        on_done,
        slots,
        wait,
        on_tick,
        tick_seconds,
        checkpoint_seconds,
        should_yield,
        drain_at,
        start_first,
    ).run()


def _restore(
    checkpoint: InflightCheckpoint,
    lock_and_open: Callable[[Job, bool], _Run],
    config: Any,
    jobs: set[Job],
) -> tuple[SlotTrainer, list[_Run], list[Job]] | None:
    """Lock and open the runs of ``checkpoint`` and load its batch: the trainer, the runs of
    the slots that continue (locked) and those of the slots dropped because their runs went
    on since the write (unlocked). Each of its runs must be one of ``jobs`` or have ended.
    ``None`` (every lock released) if a run is held by another process or is someone else's
    job, or the file cannot be read now or was trained with other settings (kept), or if no
    slot continues or its files are refused (truncated, planted, another layout: removed,
    stale)."""
    runs: list[_Run] = []
    stale = None
    try:
        for job in checkpoint.runs:
            runs.append(lock_and_open(job, False))
            if job not in jobs and not runs[-1].driver.finished:
                return None
        remove_leftovers(checkpoint.metadata_path, keep=checkpoint.data_path)
        try:
            stored = read_inflight(checkpoint)
            check_settings(checkpoint, stored, config.env, config.ddpg)
            trainer = stored.trainer()
        except OtherSettings as error:  # kept for a session with those settings
            log.warning("%s", error)
            return None
        except ValueError as error:  # truncated, planted, or not of this layout
            stale = str(error)
            return None
        dropped = _slots_gone_on(checkpoint, trainer, runs)
        if len(dropped) < len(runs):
            trainer.drop([slot for slot in dropped.values() if slot is not None])
            kept = [run for run in runs if (run.p, run.run) not in dropped]
            runs = [run for run in runs if (run.p, run.run) in dropped]  # unlocked below
            return trainer, kept, list(dropped)
        stale = "every run went on since it was written"
    except LockHeld:
        pass
    except CheckpointUnreadable as error:
        log.warning("%s: in-flight checkpoint skipped (%s)", checkpoint.metadata_path, error)
    finally:
        for run in runs:
            run.lock.close()
        if stale is not None:
            path = checkpoint.metadata_path
            log.warning("%s: stale in-flight checkpoint removed (%s)", path, stale)
            remove_inflight(path)
    return None


def _slots_gone_on(
    checkpoint: InflightCheckpoint, trainer: SlotTrainer, runs: list[_Run]
) -> dict[Job, int | None]:
    """The runs (and their slots) whose stored trials or next search differ from what the
    checkpoint's slot holds; every other run's next request is set (its slot's search)."""
    slot_of = {tag: slot for slot, tag in enumerate(trainer.tags()) if trainer.busy[slot]}
    gone: dict[Job, int | None] = {}
    for run, trials in zip(runs, checkpoint.trials, strict=True):
        job = (run.p, run.run)
        slot = slot_of.get(job)
        if slot is None or run.driver.finished or len(run.driver.state.trials) != trials:
            gone[job] = slot
            continue
        run.request = run.driver.next_search()
        search = trainer.searches[slot]
        if not (
            np.array_equal(search.theta, run.request.theta)
            and np.array_equal(search.omega, run.request.omega)
        ):
            gone[job] = slot
    return gone
