"""DDPG as the local search ``F(theta, omega, e, h)`` of the paper, k agents at a time.

One call trains ``k`` independent agents in lockstep: each has its own environment, replay
buffer, exploration noise, sampling stream and Adam state, and all ``k`` updates run as one
batched matrix product per layer (the learner, :mod:`lonlib.ddpg.lean`). ``k = 1`` is the
single-agent case of the same code. Read top to bottom, one environment step is:

1. act: uniform random actions during the warm-up, then the Actor plus N(0, sigma) noise,
   clipped to [0, 1];
2. step every agent's environment, store ``(s, a, r, s', terminated)`` in its replay buffer;
3. update (after the warm-up): sample ``batch_size`` transitions per agent, critic towards
   ``r + gamma (1 - terminated) Q'(s', mu'(s'))`` (no bootstrapping past a collision, tether
   or boundary end; the step limit bootstraps), actor up the critic's gradient, soft targets;
4. when an agent's episode ends: greedy fitness (Algorithm 1, no noise) of its current
   Actor; keep the parameters if they beat the best so far; reset its environment.

What ``F`` returns (SPEC §4): the best greedy fitness among the policies DDPG **trained**
and the parameters that scored it. The (perturbed) start is not a candidate, and neither is
any policy evaluated before the first update (during the warm-up the Actor still *is* the
start). ``count_start=True`` restores the older semantics (the start and warm-up
evaluations count as seen) for comparison. The start's fitness is always measured and
returned, with whether DDPG improved on it. A search always trains at least once
(``warmup_steps <= max_steps``); if no training episode ended after the first update, the
Actor at the stop is evaluated and returned (``final_evaluation``).

An agent stops when its greedy fitness has not improved for ``patience_steps`` environment
steps counted from the end of the warm-up (never before ``min_steps``) or at ``max_steps``.

The agents live in the slots of a :class:`SlotTrainer`: every random number an agent draws
comes from its own counter-based stream (:mod:`lonlib.ddpg.streams`), so an agent's search
is bit for bit the same alone, batched with others, or in any slot, and a slot whose search
ended can be refilled with a new one (the lockstep executor, :mod:`lonlib.experiment.lockstep`) or
dropped from the batch (:meth:`SlotTrainer.shrink`).

Steps 1 and 3 run on the learner's device, the environments and the greedy evaluations on
the host; per step only the actions come to the host and the environment's outputs go to
the device (:mod:`lonlib.ddpg.devices`). The device keeps its own copy of the slots' step
counters and busy mask (stream counters, warm-up and training masks), advanced by each step
as the host's are and sent again, in one copy, by the first step after an event changed
them (a search's start or stop, a drop, a shrink, a restore). An event copies only what its
slots need: an episode end brings back the Actors and Critics of the slots whose episodes
ended, selected on the device. That discipline holds with the lean learner, which lockstep
batches need; the autograd reference learner copies by itself (:mod:`lonlib.ddpg.reference`).
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch

from lonlib.config import DDPGConfig, PendulumConfig, Scoring
from lonlib.config.ddpg import check_batch_size, check_judging
from lonlib.ddpg.devices import copy_to_device, to_device, to_host
from lonlib.ddpg.learner import Learner, make_learner
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.slots import (
    JUDGE_BATCH,
    SLOT_ARRAYS,
    EpisodeRecord,
    LocalSearchResult,
    SlotSearch,
    is_improvement,
)
from lonlib.ddpg.streams import (
    EXPLORATION_NOISE,
    REPLAY_SAMPLES,
    START_NOISE,
    WARMUP_ACTIONS,
    CounterStreams,
)
from lonlib.task import compiled
from lonlib.task.pendulum import CoupledPendulums
from lonlib.task.policy import actor_spec, critic_spec
from lonlib.task.rollout import Rollout, score_actors


def check_refill(
    learner: Learner,
    hp: DDPGConfig,
    busy: np.ndarray,
    slots: Sequence[int],
    seeds: Sequence[int],
    tags: Sequence[Any],
) -> None:
    """Refuse a refill of a batch's ``slots`` (``busy``: which are taken) that its learner
    cannot make, of taken or repeated slots, or without one seed and one tag per slot."""
    if not learner.per_agent_state:
        raise ValueError(f"the {hp.update!r} learner cannot refill slots; use 'lean'")
    if any(busy[i] for i in slots) or len(set(slots)) != len(slots):
        raise ValueError(f"slots {list(slots)} are not all free and distinct")
    if not len(slots) == len(seeds) == len(tags):
        raise ValueError("start needs one seed and one tag per slot")


def check_parameters(name: str, values: np.ndarray, size: int, agents: int) -> np.ndarray:
    """Validate flat parameter vectors ``[k, size]`` (finite, right shape) and return float32."""
    values = np.asarray(values, dtype=np.float32)
    if values.ndim == 1:
        values = values[None]
    if values.shape != (agents, size):
        raise ValueError(f"{name} must have shape ({agents}, {size}), got {values.shape}")
    if not np.isfinite(values).all():
        raise ValueError(f"{name} contains NaN or infinite parameters")
    return values


def check_device(device: str) -> None:
    """Refuse, naming ``device``, a torch device this machine cannot compute on (asks
    torch which devices exist: a check on the device outside :mod:`lonlib.ddpg.devices`,
    made once per batch, never in a step)."""
    kind = torch.device(device)
    if kind.type == "cpu":
        return
    if kind.type == "cuda" and torch.cuda.is_available():
        if kind.index is None or kind.index < torch.cuda.device_count():
            return
        raise ValueError(
            f"device {device!r}: this machine has {torch.cuda.device_count()} CUDA device(s)"
        )
    raise ValueError(
        f"device must be 'cpu' or, on a machine with a CUDA GPU, 'cuda[:index]'; got {device!r}"
        + (" (torch sees no CUDA device here)" if kind.type == "cuda" else "")
    )


# What SlotTrainer.on_judged receives: (tag, record, flat Actor) per judged policy, and the
# judge's traced nominal episodes (row j: entry j's).
OnJudged = Callable[[list[tuple[Any, EpisodeRecord, np.ndarray]], Rollout], None]


class SlotTrainer:
    """``K`` slots, each training one DDPG local search; all ``K`` step in lockstep.

    Every slot has its own environment, replay buffer, random streams, Actor, Critic,
    targets and Adam state; one :meth:`step` advances every busy slot by one environment
    step and runs one batched update of all of them. A slot's search ends by its own
    patience or budget; :meth:`step` returns it, and :meth:`start` refills the slot with a
    new search (the lockstep executor's continuous batching). Per step there is no Python
    loop over slots: actions, noise, replay writes and samples are array operations; work
    per slot happens only at events (an episode end, a search's start and end), and the
    greedy evaluations of all slots whose episodes end in the same step are one batched
    rollout.

    A slot in its warm-up acts uniformly at random and is not updated: the batched update
    runs over every slot, so a slot's learner state is restored to its start parameters
    when its warm-up ends if the batch touched it meanwhile (one copy per search).

    A training episode's policy is judged after every episode, or with ``hp.judge_every``
    = ``J`` > 0 only when the episode's end crosses a multiple of ``J`` env steps of its
    search.

    Two optional public attributes, neither part of a checkpoint
    (:func:`lonlib.ddpg.checkpoint.to_checkpoint`; a caller that
    sets them sets them again on the restored batch): ``start_spread`` (four half-widths for
    x, x_dot, phi, phi_dot; constructor argument) makes every **training** episode start
    from the nominal state plus U[-w, w] per coordinate, drawn from the slot's start-noise
    stream, instead of ``initial_noise`` (exploring starts; the greedy evaluations keep the
    scoring's starts); ``on_judged`` (a callable) receives, after every batched greedy
    evaluation, the list of ``(tag, EpisodeRecord, flat Actor)`` it judged, in episode
    order, and the judge's own nominal episodes (a :class:`lonlib.task.rollout.Rollout`,
    traced, row ``j`` the episode of entry ``j``): what a judged policy did comes from the
    rollout that scored it.
    """

    def __init__(
        self,
        thetas: np.ndarray,
        omegas: np.ndarray,
        seeds: Sequence[int],
        env_config: PendulumConfig,
        hp: DDPGConfig,
        tags: Sequence[Any] | None = None,
        start_spread: Sequence[float] | None = None,
    ) -> None:
        k = len(seeds)
        if k < 1:
            raise ValueError("at least one local search is needed")
        check_judging(hp)
        self._configure(env_config, hp, k, hp.device)
        thetas = check_parameters("theta", thetas, self.a_spec.n_params, k)
        omegas = check_parameters("omega", omegas, self.c_spec.n_params, k)
        self.learner = make_learner(self.a_spec, self.c_spec, thetas, omegas, hp)
        self.replay = ReplayBuffer(
            k, hp.buffer_size, env_config.observation_size, self.n, self.device
        )
        self.streams = CounterStreams([0] * k, self.device)
        self.sim = CoupledPendulums(env_config, k)
        self.searches: list[SlotSearch | None] = [None] * k
        self._allocate_slots(k)
        # Greedy evaluations wait in a queue and run as one batched rollout once there are
        # ``judge_batch`` of them (or before a search they concern may stop).
        self.pending: list[tuple[SlotSearch, EpisodeRecord, np.ndarray, np.ndarray]] = []
        self.judge_batch = min(k, JUDGE_BATCH)
        self.start_spread = start_spread
        self.on_judged: OnJudged | None = None
        self._start(list(range(k)), thetas, omegas, seeds, list(tags or range(k)))

    def _configure(self, env_config: PendulumConfig, hp: DDPGConfig, k: int, device: str) -> None:
        """Settings of a batch of ``k`` slots computing on ``device``."""
        check_device(device)
        check_batch_size(hp, k)
        self.env_config, self.hp, self.n = env_config, hp, env_config.n_carts
        self.a_spec, self.c_spec = actor_spec(self.n), critic_spec(self.n)
        torch.set_num_threads(hp.threads)  # the thread count can change float reductions
        # The greedy rollouts between updates run their rows in parallel (a row's bits do not
        # depend on it): on the CPU on torch's threads, never more; beside a GPU on every
        # core this process may use, idle while the card trains.
        on_cpu = torch.device(device).type == "cpu"
        compiled.set_threads(hp.threads if on_cpu else len(os.sched_getaffinity(0)))
        self.device = torch.device(device)

    def _allocate_slots(self, k: int) -> None:
        """The per-slot counters and buffers (:data:`SLOT_ARRAYS`, ``loss_sum``), zero."""
        self.busy = np.zeros(k, dtype=bool)
        self.steps = np.zeros(k, dtype=np.int64)  # env steps of each slot's search
        self.updates = np.zeros(k, dtype=np.int64)
        self.episodes = np.zeros(k, dtype=np.int64)
        self.episode_return = np.zeros(k)
        self.last_improvement = np.zeros(k, dtype=np.int64)
        self.dirty = np.zeros(k, dtype=bool)  # learner state changed while in the warm-up
        self.loss_sum = torch.zeros(2, k, dtype=torch.float64, device=self.device)
        self.loss_count = np.zeros(k, dtype=np.int64)
        self.obs = np.zeros((k, self.env_config.observation_size), dtype=np.float32)
        self._obs = torch.zeros(self.obs.shape, device=self.device)  # the device's copy
        self._counters_changed()

    def _counters_changed(self) -> None:
        """An event changed ``steps`` or ``busy``: the device's copies are stale until
        :meth:`_counters_to_device` sends them (the next step does, so a stop followed by a
        refill sends them once)."""
        self._device_steps: torch.Tensor | None = None
        self._device_busy: torch.Tensor | None = None

    def _counters_to_device(self) -> None:
        """Send ``steps`` and ``busy`` to the device in one copy if an event changed them
        since they were last sent (between events each step advances the device's copies
        as the host's)."""
        if self._device_steps is None:
            counters = to_device(np.stack([self.steps, self.busy]), self.device)
            self._device_steps, self._device_busy = counters[0], counters[1].bool()

    def _search(self, slot: int | np.integer[Any]) -> SlotSearch:
        """The search in ``slot`` (a busy slot's)."""
        search = self.searches[slot]
        if search is None:
            raise ValueError(f"slot {slot} holds no search")
        return search

    @property
    def slots(self) -> int:
        """Number of slots ``K``."""
        return len(self.searches)

    def free_slots(self) -> list[int]:
        """Slots without a search."""
        return np.flatnonzero(~self.busy).tolist()

    def tags(self) -> list[Any]:
        """The tag of each slot's search (``None`` for a slot never filled)."""
        return [search.tag if search else None for search in self.searches]

    def resume_clocks(self, offset: float) -> None:
        """Shift the searches' start times by ``offset`` seconds (a batch restored from an
        in-flight checkpoint: ``seconds`` then counts training time, not time spent dead)."""
        for search in self.searches:
            if search is not None:
                search.started += offset

    def results(self) -> list[LocalSearchResult]:
        """The results so far of the searches in progress."""
        return [s.result for s, busy in zip(self.searches, self.busy, strict=True) if busy and s]

    # ------------------------------------------------------------------ starting searches
    def start(
        self,
        slots: Sequence[int],
        thetas: np.ndarray,
        omegas: np.ndarray,
        seeds: Sequence[int],
        tags: Sequence[Any],
    ) -> None:
        """Refill free ``slots`` with new searches (parameters, seeds, tags to report them
        by): parameters, targets, Adam state, replay buffer, streams and environment reset."""
        check_refill(self.learner, self.hp, self.busy, slots, seeds, tags)
        thetas = check_parameters("theta", thetas, self.a_spec.n_params, len(slots))
        omegas = check_parameters("omega", omegas, self.c_spec.n_params, len(slots))
        for slot, theta, omega in zip(slots, thetas, omegas, strict=True):
            self.learner.reset_agent(slot, theta, omega)
        self._start(list(slots), thetas, omegas, seeds, list(tags))

    def _start(
        self,
        slots: list[int],
        thetas: np.ndarray,
        omegas: np.ndarray,
        seeds: Sequence[int],
        tags: list[Any],
    ) -> None:
        now = time.perf_counter()
        start_scores = greedy_scores(thetas, self.env_config, self.hp.scoring)
        self.streams.set_seeds(slots, seeds)
        for j, slot in enumerate(slots):
            self.replay.clear(slot)
            score = (float(start_scores[0][j]), float(start_scores[1][j]))
            counted = self.hp.count_start
            result = LocalSearchResult(
                fitness=score[0] if counted else -np.inf,
                theta=thetas[j].copy(),
                omega=omegas[j].copy(),
                start_fitness=score[0],
                env_steps=0,
                seconds=0.0,
                stop_reason="budget",
            )
            best = score if counted else (-np.inf, -np.inf)
            self.searches[slot] = SlotSearch(
                tags[j], thetas[j].copy(), omegas[j].copy(), result, best, now
            )
        index = np.asarray(slots)
        self.busy[index] = True
        for array in (self.steps, self.updates, self.episodes, self.loss_count):
            array[index] = 0
        self.episode_return[index] = 0.0
        self.dirty[index] = False
        # The patience window opens when training starts (the first update).
        self.last_improvement[index] = self.hp.warmup_steps
        self.loss_sum[:, to_device(index, self.device)] = 0.0
        self._counters_changed()
        mask = np.zeros(self.slots, dtype=bool)
        mask[index] = True
        self._reset_environments(mask)

    # ------------------------------------------------------------------ one step
    def step(self) -> list[tuple[Any, LocalSearchResult]]:
        """One environment step and one batched update of every busy slot; returns
        ``(tag, result)`` of the searches that ended in this step (their slots are free)."""
        hp = self.hp
        busy = self.busy
        self._counters_to_device()  # if an event changed them
        assert self._device_steps is not None and self._device_busy is not None
        # 1. act: uniform during the warm-up, then the Actor plus clipped Gaussian noise
        actions = self._actions()
        # 2. step every environment and store the transitions
        outcome = self.sim.step(to_host(actions))
        next_obs = self.sim.observe().astype(np.float32)
        device_next_obs = self.replay.add_step(self._obs, actions, outcome, next_obs)
        self.episode_return += outcome.reward
        self.steps += busy
        self._device_steps += self._device_busy
        # 3. update the slots past their warm-up (one batched update of all slots)
        training = busy & (self.steps >= hp.warmup_steps)
        if training.any():
            for slot in np.flatnonzero(training & (self.updates == 0) & self.dirty):
                search = self._search(slot)
                self.learner.reset_agent(int(slot), search.theta, search.omega)
            indices = self.streams.integers(
                REPLAY_SAMPLES, self._device_steps, hp.batch_size, self.replay.size
            )
            losses = self.learner.train(self.replay.sample(indices))
            self.dirty |= ~training
            mask = self._device_busy & (self._device_steps >= hp.warmup_steps)
            self.loss_sum += torch.where(mask, losses.double(), 0.0)
            self.loss_count += training
            self.updates += training
        # 4. episode ends: queue the greedy fitness of the trained Actors, reset
        ended = (outcome.terminated | outcome.truncated) & busy
        if ended.any():
            self._end_episodes(ended)
            self._reset_environments(ended)
        else:
            self.obs = next_obs
            self._obs.copy_(device_next_obs)
        if len(self.pending) >= self.judge_batch:
            self._judge_pending()
        # stopping rules: patience (counted from the end of the warm-up) or budget
        stop, stale = self._stopping()
        if stop.any() and any(self._search(i).pending for i in np.flatnonzero(stop)):
            self._judge_pending()  # a queued improvement may keep a search going
            stop, stale = self._stopping()
        return self._stop(stop, stale) if stop.any() else []

    def _stopping(self) -> tuple[np.ndarray, np.ndarray]:
        """Which busy slots stop now, and which of them by patience."""
        hp = self.hp
        stale = (self.steps >= hp.min_steps) & (
            self.steps - self.last_improvement >= hp.patience_steps
        )
        return self.busy & (stale | (self.steps >= hp.max_steps)), stale

    def _actions(self) -> torch.Tensor:
        """``[K, n]`` actions in [0, 1] on the device (float64): uniform for slots in their
        warm-up, else the Actor plus N(0, noise_std) noise, clipped; every draw from the
        slot's own streams."""
        n, steps, warmup = self.n, self._device_steps, self.hp.warmup_steps
        assert steps is not None  # sent by the step
        actions = self.streams.uniform(WARMUP_ACTIONS, steps, n)
        if (self.busy & (self.steps >= warmup)).any():
            mu = self.learner.act(self._obs)
            noise = self.streams.normal(EXPLORATION_NOISE, steps, n)
            explore = exploration_actions(mu, noise, self.hp.noise_std)
            actions = torch.where((steps < warmup)[:, None], actions, explore)
        return actions

    def _reset_environments(self, mask: np.ndarray) -> None:
        """Reset the masked environments, each with start noise from its own stream (the
        episode number is the counter), and observe."""
        level: float | np.ndarray = self.env_config.initial_noise
        if self.start_spread is not None:
            level = np.asarray(self.start_spread, dtype=np.float64).reshape(4, 1, 1)
        noise = None
        if np.any(level > 0):
            u = self.streams.host_uniform(START_NOISE, self.episodes, 4 * self.n)
            noise = level * (2.0 * u[mask].reshape(-1, 4, self.n).transpose(1, 0, 2) - 1.0)
        self.sim.reset(mask, noise)
        self.obs = self.sim.observe().astype(np.float32)
        copy_to_device(self.obs, self._obs)

    def _end_episodes(self, ended: np.ndarray) -> None:
        """Record the training episodes that ended and queue their policies for a greedy
        evaluation (the trained Actor and Critic as they are now; the start during the
        warm-up, when the Actor still is the start); with ``hp.judge_every``, only those
        whose end crosses a multiple of it."""
        hp = self.hp
        slots = np.flatnonzero(ended)
        trained = self.updates[slots] > 0
        candidate = trained | hp.count_start
        if every := hp.judge_every:
            previous_end = np.array(
                [h[-1].env_steps if (h := self._search(s).result.history) else 0 for s in slots]
            )
            crossed = self.steps[slots] // every > previous_end // every
            candidate &= crossed
        rows = to_device(slots, self.device)
        flat_actor = flat_critic = None
        if trained[candidate].any():  # only the ended slots' parameters cross
            flat_actor, flat_critic = self.learner.actor_flat(rows), self.learner.critic_flat(rows)
        counts = np.maximum(self.loss_count[slots], 1)
        loss_means = to_host(self.loss_sum[:, rows]) / counts
        now = time.perf_counter()
        for j, slot in enumerate(slots):
            search = self._search(slot)
            no_losses = self.loss_count[slot] == 0
            record = EpisodeRecord(
                episode=int(self.episodes[slot]),
                env_steps=int(self.steps[slot]),
                episode_return=float(self.episode_return[slot]),
                episode_length=int(self.sim.step_count[slot]),
                greedy_fitness=np.nan,
                greedy_return=np.nan,
                critic_loss=np.nan if no_losses else float(loss_means[0, j]),
                actor_loss=np.nan if no_losses else float(loss_means[1, j]),
                seconds=now - search.started,
            )
            search.result.history.append(record)
            if candidate[j]:
                if trained[j]:
                    assert flat_actor is not None and flat_critic is not None
                    policy = (flat_actor[j].copy(), flat_critic[j].copy())
                else:
                    policy = (search.theta, search.omega)
                self.pending.append((search, record, *policy))
                search.pending += 1
        self.episodes[slots] += 1
        self.episode_return[slots] = 0.0
        self.loss_count[slots] = 0
        self.loss_sum[:, rows] = 0.0

    def _judge_pending(self) -> None:
        """Greedy-evaluate every queued policy in one batched rollout and apply the results
        in episode order: a better score keeps that episode's parameters and moves the
        search's last improvement to that episode's end. Deferring changes nothing: a
        search's queue is judged before any decision that depends on it (its stop), and a
        policy scores the same whenever and with whatever it is evaluated."""
        if not self.pending:
            return
        thetas = np.stack([entry[2] for entry in self.pending])
        traced = self.on_judged is not None
        scores = score_actors(thetas, self.env_config, self.hp.scoring, trace=traced)
        fitness, returns = scores.fitness, scores.episode_return
        slot_of = {id(search): slot for slot, search in enumerate(self.searches) if search}
        for (search, record, theta, omega), f, r in zip(
            self.pending, fitness, returns, strict=True
        ):
            score = (float(f), float(r))
            record.greedy_fitness, record.greedy_return = score
            search.pending -= 1
            if is_improvement(score, search.best, self.hp.plateau_tiebreak):
                search.best = score
                search.result.fitness = score[0]
                search.result.theta, search.result.omega = theta.copy(), omega.copy()
                self.last_improvement[slot_of[id(search)]] = record.env_steps
        if self.on_judged is not None:
            self.on_judged(
                [(search.tag, record, theta) for search, record, theta, _ in self.pending],
                scores.nominal,
            )
        self.pending = []

    def _stop(self, stop: np.ndarray, stale: np.ndarray) -> list[tuple[Any, LocalSearchResult]]:
        """Finish the searches of the ``stop`` slots and free them."""
        slots = np.flatnonzero(stop)
        unjudged = [i for i in slots if self._search(i).best[0] == -np.inf]
        if unjudged:  # no training episode ended: judge the Actor at the stop
            rows = to_device(unjudged, self.device)
            flat_actor, flat_critic = self.learner.actor_flat(rows), self.learner.critic_flat(rows)
            fitness, returns = greedy_scores(flat_actor, self.env_config, self.hp.scoring)
            for j, slot in enumerate(unjudged):
                result = self._search(slot).result
                result.fitness = float(fitness[j])
                result.theta = flat_actor[j].copy()
                result.omega = flat_critic[j].copy()
                result.final_evaluation = True
        now = time.perf_counter()
        finished = []
        for slot in slots:
            search = self._search(slot)
            result = search.result
            result.stop_reason = "patience" if stale[slot] else "budget"
            result.env_steps = int(self.steps[slot])
            result.updates = int(self.updates[slot])
            result.seconds = now - search.started
            finished.append((search.tag, result))
            self.searches[slot] = None
        self.busy[slots] = False
        self._counters_changed()
        return finished

    # ------------------------------------------------------------------ restoring
    @classmethod
    def blank(cls, env_config: PendulumConfig, hp: DDPGConfig, k: int, device: str) -> SlotTrainer:
        """``k`` slots of these settings on ``device`` with zero counters and nothing else
        (no learner, replay, streams, environments or searches): what a stored batch is
        restored into (:func:`lonlib.ddpg.checkpoint.from_checkpoint`), then :meth:`restored`."""
        trainer = cls.__new__(cls)
        trainer._configure(env_config, hp, k, device)
        trainer._allocate_slots(k)
        return trainer

    def restored(self) -> None:
        """The host-side state was set from outside (a checkpoint): the observations go to the
        device, and the counters with the next step."""
        copy_to_device(self.obs, self._obs)
        self._counters_changed()

    # ------------------------------------------------------------------ fewer slots
    def shrink(self) -> None:
        """Drop the free slots so that the batch carries only busy ones (no work for
        searches that have stopped). Needs the lean learner; with another it does nothing."""
        keep = np.flatnonzero(self.busy).tolist()
        if len(keep) == self.slots or not keep or not self.learner.per_agent_state:
            return
        self._keep(keep)

    def drop(self, slots: Sequence[int]) -> None:
        """Abandon the searches in ``slots`` (their slots become free; nothing is returned
        for them): a batch restored from an in-flight checkpoint whose runs went on."""
        dropped = {id(self.searches[slot]) for slot in slots}
        self.pending = [item for item in self.pending if id(item[0]) not in dropped]
        for slot in slots:
            self.searches[slot] = None
            self.busy[slot] = False
        self._counters_changed()

    def subset(self, slots: Sequence[int]) -> SlotTrainer:
        """A new trainer of only ``slots``, their searches continuing exactly as here (to
        split a batch restored from an in-flight checkpoint over processes)."""
        if not self.learner.per_agent_state:
            raise ValueError(f"the {self.hp.update!r} learner cannot be split; use 'lean'")
        part = copy.copy(self)
        part._keep(list(slots))
        return part

    def _keep(self, keep: list[int]) -> None:
        """Keep only the slots ``keep`` (new arrays and lists; the searches' bookkeeping
        objects are shared with a shallow copy this was made from)."""
        self.learner = self.learner.select(keep)
        self.replay = self.replay.select(keep)
        self.streams = self.streams.select(keep)
        self.sim = self.sim.select(keep)
        self.searches = [self.searches[i] for i in keep]
        kept = {id(search) for search in self.searches}
        self.pending = [item for item in self.pending if id(item[0]) in kept]
        for name in SLOT_ARRAYS:
            setattr(self, name, getattr(self, name)[keep])
        rows = to_device(keep, self.device)
        self.loss_sum, self._obs = self.loss_sum[:, rows], self._obs[rows]
        self._counters_changed()


def exploration_actions(mu: torch.Tensor, noise: torch.Tensor, noise_std: float) -> torch.Tensor:
    """The Actor's actions ``mu [k, n]`` plus ``noise_std`` times standard normal ``noise``
    (``noise_std`` is a standard deviation), clipped to the action range [0, 1], float64."""
    return torch.clamp(mu.to(torch.float64) + noise_std * noise, 0.0, 1.0)


def greedy_scores(
    thetas: np.ndarray, env_config: PendulumConfig, scoring: Scoring
) -> tuple[np.ndarray, np.ndarray]:
    """Greedy (noise-free) score of ``m`` flat Actors ``[m, P]`` by the one rollout
    (:func:`lonlib.task.rollout.score_actors`): the fitness the scoring's estimate names and the
    nominal episode's reward return (the plateau tie-breaker). A row's numbers are bit for
    bit what that Actor scores alone, anywhere."""
    scores = score_actors(thetas, env_config, scoring)
    return scores.fitness.copy(), scores.episode_return.copy()
