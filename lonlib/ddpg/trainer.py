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
import dataclasses
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from lonlib.config import DDPGConfig, PendulumConfig, Scoring
from lonlib.config.ddpg import check_judging, without_default_judging
from lonlib.ddpg.devices import copy_to_device, host_tensor, to_device, to_host
from lonlib.ddpg.lean import learner_class
from lonlib.ddpg.plain_state import TensorReader
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.streams import (
    EXPLORATION_NOISE,
    REPLAY_SAMPLES,
    START_NOISE,
    WARMUP_ACTIONS,
    CounterStreams,
)
from lonlib.task import compiled
from lonlib.task.pendulum import CoupledPendulums, EndReason
from lonlib.task.policy import NetSpec, actor_spec, critic_spec
from lonlib.task.rollout import score_actors
from lonlib.util.plain_data import (
    StateLayoutError,
    config_from_plain,
    generator_from_state,
    generator_state,
    plain_bool,
    plain_dict,
    plain_float,
    plain_int,
    plain_list,
    plain_str,
    short_repr,
)
from lonlib.util.progress import progress_bar


@dataclass
class EpisodeRecord:
    """One training episode of one agent."""

    episode: int
    env_steps: int  # the agent's environment steps when the episode ended
    episode_return: float
    episode_length: int
    greedy_fitness: float
    greedy_return: float  # the greedy episode's reward sum (the plateau tie-breaker)
    critic_loss: float  # mean over the episode's updates (nan before the warm-up ends)
    actor_loss: float
    seconds: float  # since the local search started


@dataclass
class LocalSearchResult:
    """What ``F(theta, omega, e, h)`` returns for one agent."""

    fitness: float
    theta: np.ndarray  # Actor parameters at the best greedy fitness, float32 [P_actor]
    omega: np.ndarray  # Critic parameters at that point, float32 [P_critic]
    start_fitness: float  # greedy fitness of the (perturbed) start parameters
    env_steps: int
    seconds: float
    stop_reason: str  # "patience" or "budget"
    updates: int = 0  # DDPG updates of this agent
    final_evaluation: bool = False  # no policy was judged: the Actor at the stop was
    history: list[EpisodeRecord] = field(default_factory=list)

    @property
    def improved(self) -> bool:
        """Did DDPG return something strictly fitter than its start?"""
        return self.fitness > self.start_fitness


def is_improvement(
    candidate: tuple[float, float], incumbent: tuple[float, float], plateau_tiebreak: bool
) -> bool:
    """Does a greedy ``(fitness, return)`` beat the best so far? Higher fitness always does;
    with ``plateau_tiebreak``, equal fitness and a higher reward return does too."""
    if candidate[0] != incumbent[0] or not plateau_tiebreak:
        return candidate[0] > incumbent[0]
    return candidate[1] > incumbent[1] + 1e-9


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


def local_search(
    theta: np.ndarray,
    omega: np.ndarray,
    env_config: PendulumConfig,
    hp: DDPGConfig,
    seed: int,
    progress: bool = False,
) -> LocalSearchResult:
    """``F(theta, omega, e, h)`` for one agent: DDPG from the given Actor and Critic."""
    return local_search_batch(theta[None], omega[None], env_config, hp, [seed], progress)[0]


def local_search_batch(
    thetas: np.ndarray,
    omegas: np.ndarray,
    env_config: PendulumConfig,
    hp: DDPGConfig,
    seeds: Sequence[int],
    progress: bool = False,
) -> list[LocalSearchResult]:
    """Train ``k = len(seeds)`` independent agents together; one result per agent.

    Agent ``i`` starts from ``thetas[i]``, ``omegas[i]`` with an empty replay buffer and
    target networks copied from them, and draws every random number of its training
    (warm-up actions, exploration noise, replay sampling, episode start noise) from its own
    counter-based stream of ``seeds[i]`` (:mod:`lonlib.ddpg.streams`): its result does not
    depend on the other agents. Agents that stop early leave the batch
    (:meth:`SlotTrainer.shrink`), so the others train without carrying them.
    """
    trainer = SlotTrainer(thetas, omegas, seeds, env_config, hp)
    results: list[LocalSearchResult | None] = [None] * len(seeds)
    bar = progress_bar(
        total=hp.max_steps, desc=f"DDPG x{len(seeds)}", disable=not progress, leave=False
    )
    while trainer.busy.any():
        for tag, result in trainer.step():
            results[tag] = result
        if not trainer.busy.all():
            trainer.shrink()
        if progress and int(trainer.steps.max()) % 500 == 0:
            bar.update(500)
            best = max((r.fitness for r in trainer.results()), default=float("nan"))
            bar.set_postfix(best=f"{best:.3f}", active=int(trainer.busy.sum()))
    bar.close()
    return results


# The per-slot numpy arrays of a SlotTrainer (its other per-slot tensor is ``loss_sum``).
SLOT_ARRAYS = (
    "busy",
    "steps",
    "updates",
    "episodes",
    "episode_return",
    "last_improvement",
    "dirty",
    "loss_count",
    "obs",
)
JUDGE_BATCH = 16  # at most this many queued greedy evaluations per batched rollout
# Minibatch sizes that keep a batched agent's update bit-identical to its update alone
# (measured: sizes that are not a multiple of 4 take other vector-loop paths by batch).
BATCH_MULTIPLE = 8


def check_batch_size(hp: DDPGConfig, agents: int) -> None:
    """Refuse, naming ``batch_size``, a minibatch size that would make a batched agent's
    bits depend on its batch (only when more than one agent trains)."""
    if agents > 1 and hp.batch_size % BATCH_MULTIPLE:
        raise ValueError(
            f"batch_size must be a multiple of {BATCH_MULTIPLE} to train agents together "
            f"(other sizes make an agent's bits depend on its batch), got {hp.batch_size}"
        )


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


@dataclass
class _Search:
    """Host-side bookkeeping of the local search in one slot (touched only at events)."""

    tag: Any
    theta: np.ndarray  # start parameters
    omega: np.ndarray
    result: LocalSearchResult
    best: tuple[float, float]  # greedy (fitness, return) of the returned parameters so far
    started: float  # time.perf_counter() at its start
    pending: int = 0  # its policies queued for a greedy evaluation


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

    Two optional public attributes, neither part of :meth:`to_checkpoint` (a caller that
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
        self.searches: list[_Search | None] = [None] * k
        self._allocate_slots(k)
        # Greedy evaluations wait in a queue and run as one batched rollout once there are
        # ``judge_batch`` of them (or before a search they concern may stop).
        self.pending: list[tuple[_Search, EpisodeRecord, np.ndarray, np.ndarray]] = []
        self.judge_batch = min(k, JUDGE_BATCH)
        self.start_spread = start_spread
        self.on_judged = None
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
        self._device_steps = self._device_busy = None

    def _counters_to_device(self) -> None:
        """Send ``steps`` and ``busy`` to the device in one copy if an event changed them
        since they were last sent (between events each step advances the device's copies
        as the host's)."""
        if self._device_steps is None:
            counters = to_device(np.stack([self.steps, self.busy]), self.device)
            self._device_steps, self._device_busy = counters[0], counters[1].bool()

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
        if not hasattr(self.learner, "reset_agent"):
            raise ValueError(f"the {self.hp.update!r} learner cannot refill slots; use 'lean'")
        if any(self.busy[i] for i in slots) or len(set(slots)) != len(slots):
            raise ValueError(f"slots {list(slots)} are not all free and distinct")
        if not len(slots) == len(seeds) == len(tags):
            raise ValueError("start needs one seed and one tag per slot")
        thetas = check_parameters("theta", thetas, self.a_spec.n_params, len(slots))
        omegas = check_parameters("omega", omegas, self.c_spec.n_params, len(slots))
        for slot, theta, omega in zip(slots, thetas, omegas, strict=True):
            self.learner.reset_agent(slot, theta, omega)
        self._start(list(slots), thetas, omegas, seeds, list(tags))

    def _start(self, slots, thetas, omegas, seeds, tags) -> None:
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
            self.searches[slot] = _Search(
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
                search = self.searches[slot]
                self.learner.reset_agent(slot, search.theta, search.omega)
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
        if stop.any() and any(self.searches[i].pending for i in np.flatnonzero(stop)):
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
        level = self.env_config.initial_noise
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
                [h[-1].env_steps if (h := self.searches[s].result.history) else 0 for s in slots]
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
            search = self.searches[slot]
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
        unjudged = [i for i in slots if self.searches[i].best[0] == -np.inf]
        if unjudged:  # no training episode ended: judge the Actor at the stop
            rows = to_device(unjudged, self.device)
            flat_actor, flat_critic = self.learner.actor_flat(rows), self.learner.critic_flat(rows)
            fitness, returns = greedy_scores(flat_actor, self.env_config, self.hp.scoring)
            for j, slot in enumerate(unjudged):
                result = self.searches[slot].result
                result.fitness = float(fitness[j])
                result.theta = flat_actor[j].copy()
                result.omega = flat_critic[j].copy()
                result.final_evaluation = True
        now = time.perf_counter()
        finished = []
        for slot in slots:
            search = self.searches[slot]
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

    # ------------------------------------------------------------------ checkpoints
    def to_checkpoint(self) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
        """The whole batch as plain data (JSON-able: settings, searches, queue, stream
        seeds, generator state) and named CPU tensors (networks, targets, Adam state,
        replay buffers, environments, counters): nothing names a Python class.
        :meth:`from_checkpoint` continues it bit for bit. Needs the lean learner."""
        if not hasattr(self.learner, "load_state"):
            raise ValueError(f"the {self.hp.update!r} learner cannot be checkpointed; use 'lean'")
        tensors = {f"slots.{name}": _tensor(getattr(self, name)) for name in SLOT_ARRAYS}
        tensors["slots.loss_sum"] = host_tensor(to_host(self.loss_sum))
        for name, array in self.learner.state().items():
            tensors[f"learner.{name}"] = _tensor(array)
        tensors["learner.adam_steps"] = _tensor(self.learner.steps)
        for name, tensor in self.replay.state_tensors().items():
            tensors[f"replay.{name}"] = tensor
        for name in CoupledPendulums.STATE_ARRAYS:
            tensors[f"sim.{name}"] = _tensor(getattr(self.sim, name))
        searches, search_tensors = _searches_to_checkpoint(
            self.searches, self.pending, self.a_spec.n_params, self.c_spec.n_params
        )
        tensors.update(search_tensors)
        plain = {
            "slots": self.slots,
            "env": dataclasses.asdict(self.env_config),
            "ddpg": without_default_judging(dataclasses.asdict(self.hp)),
            "judge_batch": self.judge_batch,
            "stream_seeds": list(self.streams.seeds),
            "sim_generator": generator_state(self.sim.rng),
            **searches,
        }
        return plain, tensors

    @staticmethod
    def checkpoint_configs(plain: Any) -> tuple[PendulumConfig, DDPGConfig]:
        """The environment and DDPG settings a batch in :meth:`to_checkpoint`'s ``plain``
        data was trained with (:class:`~lonlib.ddpg.plain_state.StateLayoutError` if absent or
        invalid)."""
        plain = plain_dict(plain, "trainer", CHECKPOINT_KEYS)
        env_config = config_from_plain(PendulumConfig, plain["env"], "trainer.env")
        ddpg = plain["ddpg"]
        if isinstance(ddpg, dict) and "judge_every" not in ddpg:
            # written with judge_every 0, or before the setting existed (every episode then)
            ddpg = {**ddpg, "judge_every": 0}
        return env_config, config_from_plain(DDPGConfig, ddpg, "trainer.ddpg")

    @classmethod
    def from_checkpoint(cls, plain: Any, tensors: Any, device: str | None = None) -> SlotTrainer:
        """The batch :meth:`to_checkpoint` exported, continuing bit for bit, on ``device``
        (default: the device it was trained on). Everything is checked against the layout
        of a batch of its settings and slots before it is used: a missing, extra or
        misshapen tensor or value raises :class:`~lonlib.ddpg.plain_state.StateLayoutError`."""
        env_config, hp = cls.checkpoint_configs(plain)
        k = plain_int(plain["slots"], "trainer.slots", 1, 100_000)
        if hp.update != "lean":
            raise StateLayoutError(f"trainer.ddpg.update must be 'lean', got {hp.update!r}")
        reader = TensorReader(tensors)
        trainer = cls.__new__(cls)
        trainer._configure(env_config, hp, k, hp.device if device is None else device)
        trainer._allocate_slots(k)
        for name in SLOT_ARRAYS:
            array = reader.take_like(f"slots.{name}", getattr(trainer, name), finite=True)
            setattr(trainer, name, array)
        trainer.loss_sum = reader.take_like("slots.loss_sum", trainer.loss_sum)
        trainer.learner = _learner_from_checkpoint(reader, trainer)
        obs_size, n = env_config.observation_size, trainer.n
        trainer.replay = ReplayBuffer.from_state(
            reader, "replay.", k, hp.buffer_size, obs_size, n, trainer.device
        )
        seeds = plain_list(plain["stream_seeds"], "trainer.stream_seeds", k)
        try:
            trainer.streams = CounterStreams(seeds, trainer.device)
        except ValueError as error:
            raise StateLayoutError(f"trainer.stream_seeds: {error}") from None
        trainer.sim = CoupledPendulums(env_config, k)
        for name in CoupledPendulums.STATE_ARRAYS:
            array = reader.take_like(f"sim.{name}", getattr(trainer.sim, name), finite=True)
            setattr(trainer.sim, name, array)
        trainer.sim.rng = generator_from_state(plain["sim_generator"], "trainer.sim_generator")
        copy_to_device(trainer.obs, trainer._obs)
        trainer.searches, trainer.pending = _searches_from_checkpoint(plain, reader, trainer)
        # JUDGE_BATCH is the most the constructor sets (fewer slots: as many), and a step
        # leaves fewer evaluations queued than that
        trainer.judge_batch = plain_int(plain["judge_batch"], "trainer.judge_batch", 1, JUDGE_BATCH)
        trainer.start_spread, trainer.on_judged = None, None
        if len(trainer.pending) >= trainer.judge_batch:
            raise StateLayoutError("trainer.pending: more queued than a step leaves")
        reader.finish()
        if not np.array_equal(trainer.busy, [s is not None for s in trainer.searches]):
            raise StateLayoutError("trainer: the busy slots are not the slots with a search")
        _check_counters(trainer)
        trainer._counters_changed()
        return trainer

    # ------------------------------------------------------------------ fewer slots
    def shrink(self) -> None:
        """Drop the free slots so that the batch carries only busy ones (no work for
        searches that have stopped). Needs the lean learner; with another it does nothing."""
        keep = np.flatnonzero(self.busy).tolist()
        if len(keep) == self.slots or not keep or not hasattr(self.learner, "select"):
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
        if not hasattr(self.learner, "select"):
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


def make_learner(
    a_spec: NetSpec,
    c_spec: NetSpec,
    thetas: np.ndarray,
    omegas: np.ndarray,
    hp: DDPGConfig,
    device: torch.device | None = None,
):
    """The learner ``hp.update`` names for ``k`` agents starting from ``thetas``, ``omegas``
    (targets copied from them, Adam state empty) on ``device`` (default ``hp.device``)."""
    return learner_class(hp.update)(
        a_spec,
        c_spec,
        thetas,
        omegas,
        learning_rate=hp.learning_rate,
        gamma=hp.gamma,
        tau=hp.tau,
        device=torch.device(hp.device if device is None else device),
    )


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


# ---------------------------------------------------------------------- checkpoint layout
# The plain data of SlotTrainer.to_checkpoint, and of each search in it.
CHECKPOINT_KEYS = frozenset(
    {
        "slots",
        "env",
        "ddpg",
        "judge_batch",
        "stream_seeds",
        "sim_generator",
        "history_columns",
        "searches",
        "pending",
    }
)
SEARCH_KEYS = frozenset(
    {
        "tag",
        "best",
        "started",
        "pending",
        "fitness",
        "start_fitness",
        "env_steps",
        "seconds",
        "stop_reason",
        "updates",
        "final_evaluation",
        "episodes",
    }
)
LEARNER_STATE = (
    "actor",
    "actor_target",
    "actor_exp_avg",
    "actor_exp_avg_sq",
    "critic",
    "critic_target",
    "critic_exp_avg",
    "critic_exp_avg_sq",
)
HISTORY_COLUMNS = tuple(f.name for f in dataclasses.fields(EpisodeRecord))
_INT_COLUMNS = [f.type in ("int", int) for f in dataclasses.fields(EpisodeRecord)]
_SCALARS = (str, int, float, bool, type(None))


def _tensor(array: np.ndarray) -> torch.Tensor:
    """A CPU tensor of its own (exactly its bytes: no larger storage is saved with it)."""
    return torch.from_numpy(np.array(array, copy=True))


def _rows(arrays: list[np.ndarray], width: int) -> torch.Tensor:
    """Flat float32 vectors stacked as ``[m, width]`` (``m`` may be zero)."""
    stacked = np.stack(arrays) if arrays else np.zeros((0, width))
    return torch.from_numpy(stacked.astype(np.float32))


def _plain_tag(tag: Any) -> Any:
    """A slot's tag as plain data: a number, text, None, or a tuple of them (as a list)."""
    if isinstance(tag, np.generic):
        tag = tag.item()
    if isinstance(tag, tuple):
        tag = [t.item() if isinstance(t, np.generic) else t for t in tag]
        if all(isinstance(t, _SCALARS) for t in tag):
            return tag
    elif isinstance(tag, _SCALARS):
        return tag
    raise ValueError(f"a checkpointed slot's tag must be plain data or a tuple of it: {tag!r}")


def _tag_from_plain(value: Any, name: str) -> Any:
    """:func:`_plain_tag` reversed (a list is a tuple)."""
    if isinstance(value, list) and all(isinstance(v, _SCALARS) for v in value):
        return tuple(value)
    if isinstance(value, _SCALARS):
        return value
    raise StateLayoutError(f"{name} must be plain data or a list of it, got {short_repr(value)}")


def _search_to_plain(search: _Search) -> dict[str, Any]:
    """A search's bookkeeping but its parameters and history (tensors) as plain data."""
    result = search.result
    return {
        "tag": _plain_tag(search.tag),
        "best": [float(search.best[0]), float(search.best[1])],
        "started": float(search.started),
        "pending": int(search.pending),
        "fitness": float(result.fitness),
        "start_fitness": float(result.start_fitness),
        "env_steps": int(result.env_steps),
        "seconds": float(result.seconds),
        "stop_reason": str(result.stop_reason),
        "updates": int(result.updates),
        "final_evaluation": bool(result.final_evaluation),
        "episodes": len(result.history),
    }


def _searches_to_checkpoint(
    searches: list[_Search | None],
    pending: list[tuple[_Search, EpisodeRecord, np.ndarray, np.ndarray]],
    a_size: int,
    c_size: int,
) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """The slots' searches and the queued evaluations: plain data (a queued evaluation is
    its slot and the index of its episode in that search's history) and tensors."""
    held = [search for search in searches if search is not None]
    slot_of = {id(search): slot for slot, search in enumerate(searches) if search}
    queue = []
    for search, record, _, _ in pending:
        history = search.result.history
        index = next(i for i in range(len(history) - 1, -1, -1) if history[i] is record)
        queue.append([slot_of[id(search)], index])
    history = [[getattr(r, c) for c in HISTORY_COLUMNS] for s in held for r in s.result.history]
    plain = {
        "history_columns": list(HISTORY_COLUMNS),
        "searches": [None if s is None else _search_to_plain(s) for s in searches],
        "pending": queue,
    }
    tensors = {
        "searches.theta": _rows([s.theta for s in held], a_size),
        "searches.omega": _rows([s.omega for s in held], c_size),
        "searches.best_theta": _rows([s.result.theta for s in held], a_size),
        "searches.best_omega": _rows([s.result.omega for s in held], c_size),
        "searches.history": torch.tensor(history, dtype=torch.float64).reshape(
            -1, len(HISTORY_COLUMNS)
        ),
        "pending.theta": _rows([item[2] for item in pending], a_size),
        "pending.omega": _rows([item[3] for item in pending], c_size),
    }
    return plain, tensors


def _search_fields(entry: Any, name: str, hp: DDPGConfig) -> dict[str, Any]:
    """A search's plain data (:func:`_search_to_plain`), every value checked: counts within
    a search's budget, times finite, scores a number or ``-inf`` (none yet)."""
    entry = plain_dict(entry, name, SEARCH_KEYS)
    best = plain_list(entry["best"], f"{name}.best", 2)
    fields = {"tag": _tag_from_plain(entry["tag"], f"{name}.tag")}
    fields["best"] = tuple(_score(v, f"{name}.best") for v in best)
    fields["fitness"] = _score(entry["fitness"], f"{name}.fitness")
    for key in ("started", "start_fitness"):
        fields[key] = plain_float(entry[key], f"{name}.{key}", finite=True)
    fields["seconds"] = plain_float(entry["seconds"], f"{name}.seconds", finite=True)
    if fields["seconds"] < 0:
        raise StateLayoutError(f"{name}.seconds must be >= 0, got {fields['seconds']}")
    for key in ("pending", "env_steps", "updates", "episodes"):
        fields[key] = plain_int(entry[key], f"{name}.{key}", 0, hp.max_steps)
    fields["stop_reason"] = plain_str(entry["stop_reason"], f"{name}.stop_reason")
    if fields["stop_reason"] not in ("patience", "budget"):
        raise StateLayoutError(f"{name}.stop_reason must be 'patience' or 'budget'")
    fields["final_evaluation"] = plain_bool(entry["final_evaluation"], f"{name}.final_evaluation")
    return fields


def _score(value: Any, name: str) -> float:
    """A greedy score: a number, or ``-inf`` before the first (not NaN nor ``+inf``)."""
    score = plain_float(value, name)
    if np.isnan(score) or score == np.inf:
        raise StateLayoutError(f"{name} must be a number or -Infinity, got {score}")
    return score


def _history(rows: np.ndarray) -> list[EpisodeRecord]:
    """Episode records from ``[m, len(HISTORY_COLUMNS)]`` float64 rows."""
    ints = rows[:, _INT_COLUMNS]
    if not (np.isfinite(ints) & (ints == np.round(ints))).all():
        raise StateLayoutError("searches.history: an integer column holds a fraction")
    if (ints < 0).any():
        raise StateLayoutError("searches.history: a negative count")
    kinds = [int if is_int else float for is_int in _INT_COLUMNS]
    return [
        EpisodeRecord(*(kind(v) for kind, v in zip(kinds, row.tolist(), strict=True)))
        for row in rows
    ]


def _searches_from_checkpoint(
    plain: dict[str, Any], reader: TensorReader, trainer: SlotTrainer
) -> tuple[list[_Search | None], list[tuple[_Search, EpisodeRecord, np.ndarray, np.ndarray]]]:
    """:func:`_searches_to_checkpoint` reversed, every value checked."""
    k = len(trainer.busy)
    a_size, c_size = trainer.a_spec.n_params, trainer.c_spec.n_params
    columns = plain_list(plain["history_columns"], "trainer.history_columns")
    if tuple(columns) != HISTORY_COLUMNS:
        raise StateLayoutError(f"trainer.history_columns: {columns}, expected {HISTORY_COLUMNS}")
    entries = plain_list(plain["searches"], "trainer.searches", k)
    fields = [
        None if entry is None else _search_fields(entry, f"trainer.searches[{slot}]", trainer.hp)
        for slot, entry in enumerate(entries)
    ]
    held = [slot for slot, entry in enumerate(fields) if entry is not None]
    arrays = {
        name: reader.take_numpy(f"searches.{name}", (len(held), size), torch.float32, True)
        for name, size in (
            ("theta", a_size),
            ("omega", c_size),
            ("best_theta", a_size),
            ("best_omega", c_size),
        )
    }
    total = sum(fields[slot]["episodes"] for slot in held)
    rows = reader.take_numpy("searches.history", (total, len(HISTORY_COLUMNS)), torch.float64)
    searches: list[_Search | None] = [None] * k
    offset = 0
    for j, slot in enumerate(held):
        f = fields[slot]
        history = _history(rows[offset : offset + f["episodes"]])
        offset += f["episodes"]
        result = LocalSearchResult(
            fitness=f["fitness"],
            theta=arrays["best_theta"][j].copy(),
            omega=arrays["best_omega"][j].copy(),
            start_fitness=f["start_fitness"],
            env_steps=f["env_steps"],
            seconds=f["seconds"],
            stop_reason=f["stop_reason"],
            updates=f["updates"],
            final_evaluation=f["final_evaluation"],
            history=history,
        )
        theta, omega = arrays["theta"][j].copy(), arrays["omega"][j].copy()
        searches[slot] = _Search(f["tag"], theta, omega, result, f["best"], f["started"])
        searches[slot].pending = f["pending"]
    return searches, _pending_from_checkpoint(plain, reader, searches, a_size, c_size)


def _pending_from_checkpoint(
    plain: dict[str, Any],
    reader: TensorReader,
    searches: list[_Search | None],
    a_size: int,
    c_size: int,
) -> list[tuple[_Search, EpisodeRecord, np.ndarray, np.ndarray]]:
    """The queued evaluations: each names a slot with a search and an episode of its
    history, and every search queues as many as its count says."""
    queue = plain_list(plain["pending"], "trainer.pending")
    thetas = reader.take_numpy("pending.theta", (len(queue), a_size), torch.float32, True)
    omegas = reader.take_numpy("pending.omega", (len(queue), c_size), torch.float32, True)
    pending = []
    for i, item in enumerate(queue):
        slot, index = plain_list(item, f"trainer.pending[{i}]", 2)
        search = searches[plain_int(slot, f"trainer.pending[{i}] slot", 0, len(searches) - 1)]
        if search is None:
            raise StateLayoutError(f"trainer.pending[{i}]: slot {slot} holds no search")
        history = search.result.history
        index = plain_int(index, f"trainer.pending[{i}] episode", 0, len(history) - 1)
        pending.append((search, history[index], thetas[i], omegas[i]))
    for slot, search in enumerate(searches):
        if search is not None and search.pending != sum(item[0] is search for item in pending):
            raise StateLayoutError(f"trainer.searches[{slot}].pending: not its queued count")
    return pending


def _check_counters(trainer: SlotTrainer) -> None:
    """Refuse counters no batch of ``trainer``'s settings reaches. The ranges follow from
    :meth:`SlotTrainer.step`: a search stops at ``max_steps``; a slot updates, ends an
    episode and counts a loss at most once per env step (the losses since its last episode
    end); its patience counts from the warm-up's end or an episode end it has reached; an
    environment ends at its step limit, counts at most one upright step per step, and a busy
    slot's is reset as soon as it ends; a busy slot's search holds one record per episode."""
    hp, sim = trainer.hp, trainer.sim
    steps, busy = trainer.steps, trainer.busy
    valid = {
        "slots.steps": (steps >= 0) & (steps <= hp.max_steps),
        "slots.updates": (trainer.updates >= 0) & (trainer.updates <= steps),
        "slots.episodes": (trainer.episodes >= 0) & (trainer.episodes <= steps),
        "slots.loss_count": (trainer.loss_count >= 0) & (trainer.loss_count <= trainer.updates),
        "slots.last_improvement": (trainer.last_improvement >= 0)
        & (trainer.last_improvement <= np.maximum(steps, hp.warmup_steps)),
        "sim.step_count": (sim.step_count >= 0) & (sim.step_count <= trainer.env_config.steps),
        "sim.end_reason": np.isin(sim.end_reason, [reason.value for reason in EndReason])
        & (~busy | (sim.end_reason == EndReason.RUNNING)),
    }
    for name in ("upright_sum", "upright_all_sum", "upright_mean_sum"):
        total = getattr(sim, name)
        valid[f"sim.{name}"] = (total >= 0) & (total <= sim.step_count)
    episodes = [len(s.result.history) if s else 0 for s in trainer.searches]
    valid["trainer.searches"] = ~busy | (np.asarray(episodes) == trainer.episodes)
    for name, fits in valid.items():
        if not fits.all():
            slot = int(np.flatnonzero(~fits)[0])
            raise StateLayoutError(f"{name}: slot {slot} holds a value no search reaches")


def _learner_from_checkpoint(reader: TensorReader, trainer: SlotTrainer) -> Any:
    """The lean learner of ``trainer``'s slots from the ``learner.*`` tensors (Eq. 1 order
    and Adam step counts)."""
    k = len(trainer.busy)
    sizes = {"actor": trainer.a_spec.n_params, "critic": trainer.c_spec.n_params}
    arrays = {
        name: reader.take_numpy(
            f"learner.{name}", (k, sizes[name.split("_")[0]]), torch.float32, finite=True
        )
        for name in LEARNER_STATE
    }
    if any((arrays[name] < 0).any() for name in ("actor_exp_avg_sq", "critic_exp_avg_sq")):
        raise StateLayoutError("learner: negative Adam second moments")
    steps = reader.take_numpy("learner.adam_steps", (k,), torch.int64)
    if (steps < 0).any():
        raise StateLayoutError("learner.adam_steps: negative step counts")
    learner = make_learner(
        trainer.a_spec,
        trainer.c_spec,
        arrays["actor"],
        arrays["critic"],
        trainer.hp,
        trainer.device,
    )
    learner.load_state(arrays, steps)
    return learner
