"""DDPG as the local search ``F(theta, omega, e, h)`` on a Gymnasium task: ``K`` searches in
lockstep, their training environments batched through Gymnasium's vector API.

The same algorithm and rules as the coupled pendulums' slot trainer
(:mod:`lonlib.ddpg.trainer`); the update is the same learner
(:func:`lonlib.ddpg.learner.make_learner`, ``hp.update``) on the task's network shapes, all
``K`` agents in one batched update. One :meth:`GymnasiumSlotTrainer.step` is, for every busy
slot:

1. act: uniform random actions in [0, 1] during the warm-up, then the Actor plus
   N(0, noise_std) noise, clipped to [0, 1]; the task maps [0, 1] onto its Box bounds;
2. step the environments (one ``gymnasium.vector.SyncVectorEnv``, autoreset disabled); store
   ``(s, a, r, s', terminated)`` (a truncation bootstraps);
3. update (after the warm-up) on ``batch_size`` transitions drawn uniformly from the slot's
   own buffer;
4. when an episode ends: judge the trained Actor by the task's greedy episode (with
   ``hp.judge_every``, only when the episode's end crosses a multiple of it); keep the best
   (the start and warm-up policies are not candidates unless ``hp.count_start``); reset.

A search stops after ``patience_steps`` without a better greedy fitness (counted from the end
of the warm-up, never before ``min_steps``) or at ``max_steps``. Every random number a search
draws comes from its own ``numpy`` generator seeded with the search's seed (warm-up actions,
noise, replay draws, each episode's ``reset`` seed), it trains in a fresh environment, and no
reduction mixes agents: a search is a deterministic function of its start, its seed and the
machine's arithmetic, the same in any slot of any batch (:func:`gymnasium_local_search` is a
batch of one). A batch is not checkpointed: an interrupted search re-runs from its start.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import gymnasium
import numpy as np
import torch

from lonlib.config import DDPGConfig
from lonlib.config.ddpg import check_batch_size, check_judging
from lonlib.ddpg.devices import to_device, to_host
from lonlib.ddpg.learner import make_learner
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.slots import EpisodeRecord, LocalSearchResult, is_improvement, starting_result
from lonlib.ddpg.trainer import check_parameters, check_refill
from lonlib.task.gymnasium_task import GymnasiumTask, TaskEnvironmentError

SEARCH_STREAM = 7  # a search's generator is default_rng([seed, SEARCH_STREAM])


class SlotEnvironmentError(TaskEnvironmentError):
    """A slot's environment failed: :class:`TaskEnvironmentError` with the ``tag`` of the
    search it failed in."""

    def __init__(self, message: str, tag: Any) -> None:
        super().__init__(message)
        self.tag = tag


@dataclass
class _Search:
    """One slot's local search: its start, random stream and bookkeeping."""

    tag: Any
    theta: np.ndarray  # start parameters
    omega: np.ndarray
    rng: np.random.Generator
    result: LocalSearchResult
    best: tuple[float, float]  # greedy (fitness, return) of the returned parameters so far
    last_improvement: int
    started: float  # time.perf_counter() at its start
    steps: int = 0
    updates: int = 0
    episode: int = 0
    episode_return: float = 0.0
    episode_length: int = 0
    losses: list[tuple[float, float]] = field(default_factory=list)
    dirty: bool = False  # the batch updated its learner state during its warm-up


class _TrainingEnv(gymnasium.Wrapper):
    """One slot's training environment in the vector env: it takes the Actor's output in
    [0, 1] and runs the task's guarded ``reset`` and ``step`` (an error names ``where`` and
    the step), keeping the scaled float64 observation in :attr:`observation` (the vector env
    batches it in the space's dtype; the learner reads this). A slot without a search is
    ``idle``: its environment is not stepped."""

    def __init__(self, task: GymnasiumTask) -> None:
        super().__init__(task.make_env())
        self.task = task
        self.where, self.step_number, self.idle = "local search", 0, True
        self.failed = False
        self.observation = np.zeros(task.obs_size)
        # what the vector env batches: the scaled float64 observation, whatever the space's dtype
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (task.obs_size,), np.float64)

    def renew(self) -> None:
        """A fresh environment for a new search (the old one closed)."""
        self.env.close()
        self.env = self.task.make_env()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        try:
            self.observation = self.task.reset(self.env, seed, self.where)
        except TaskEnvironmentError:
            self.failed = True
            raise
        return self.observation, {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self.idle:
            return self.observation, 0.0, False, False, {}
        try:
            self.observation, reward, terminated, truncated = self.task.step(
                self.env, action, self.where, self.step_number
            )
        except TaskEnvironmentError:
            self.failed = True
            raise
        return self.observation, reward, terminated, truncated, {}


def _itself(env: _TrainingEnv) -> _TrainingEnv:
    return env


def _vector_env(envs: list[_TrainingEnv]) -> gymnasium.vector.SyncVectorEnv:
    """The slots' environments as one vector env (episodes reset by the trainer)."""
    return gymnasium.vector.SyncVectorEnv(
        [partial(_itself, env) for env in envs],
        copy=False,
        autoreset_mode=gymnasium.vector.AutoresetMode.DISABLED,
    )


class GymnasiumSlotTrainer:
    """``K`` slots, each training one DDPG local search on ``task``; all ``K`` step together
    (:meth:`step`: one vector-env step, one batched update). A slot's search ends by its own
    patience or budget; :meth:`step` returns it, and :meth:`start` refills the slot (the
    lockstep executor's continuous batching, :mod:`lonlib.experiment.lockstep`). Refills
    and :meth:`shrink` need the lean learner (``hp.update``)."""

    def __init__(
        self,
        task: GymnasiumTask,
        thetas: np.ndarray,
        omegas: np.ndarray,
        seeds: Sequence[int],
        hp: DDPGConfig,
        tags: Sequence[Any] | None = None,
    ) -> None:
        k = len(seeds)
        if k < 1:
            raise ValueError("at least one local search is needed")
        check_judging(hp)
        check_batch_size(hp, k)
        self.task, self.hp, self.device = task, hp, torch.device(hp.device)
        if self.device.type == "cpu":
            torch.set_num_threads(hp.threads)  # the thread count can change float reductions
        a_size, c_size = task.actor_spec.n_params, task.critic_spec.n_params
        thetas = check_parameters("theta", thetas, a_size, k)
        self._omega_size = c_size * task.critic_count
        omegas = check_parameters("omega", omegas, self._omega_size, k)
        self.learner = make_learner(
            task.actor_spec, task.critic_spec, thetas, omegas, hp, self.device
        )
        self.replay = ReplayBuffer(k, hp.buffer_size, task.obs_size, task.action_size, self.device)
        self.searches: list[_Search | None] = [None] * k
        self.busy = np.zeros(k, dtype=bool)
        self.envs: list[_TrainingEnv] = []
        self.closed = False
        try:  # an environment that fails while the batch is made is closed with the others
            self.envs.extend(_TrainingEnv(task) for _ in range(k))
            self.vector = _vector_env(self.envs)
            self._start(list(range(k)), thetas, omegas, seeds, list(tags or range(k)))
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> GymnasiumSlotTrainer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ slots
    @property
    def slots(self) -> int:
        """Number of slots ``K``."""
        return len(self.searches)

    @property
    def steps(self) -> np.ndarray:
        """Env steps of each slot's search so far (0 for a free slot)."""
        return np.array([s.steps if s else 0 for s in self.searches], dtype=np.int64)

    def free_slots(self) -> list[int]:
        """Slots without a search."""
        return np.flatnonzero(~self.busy).tolist()

    def tags(self) -> list[Any]:
        """The tag of each slot's search (``None`` for a free slot)."""
        return [search.tag if search else None for search in self.searches]

    def _search(self, slot: int | np.integer[Any]) -> _Search:
        search = self.searches[slot]
        if search is None:
            raise ValueError(f"slot {slot} holds no search")
        return search

    def start(
        self,
        slots: Sequence[int],
        thetas: np.ndarray,
        omegas: np.ndarray,
        seeds: Sequence[int],
        tags: Sequence[Any],
    ) -> None:
        """Refill free ``slots`` with new searches (parameters, seeds, tags to report them
        by): parameters, targets, Adam state, replay buffer, generator and a fresh
        environment."""
        check_refill(self.learner, self.hp, self.busy, slots, seeds, tags)
        thetas = check_parameters("theta", thetas, self.task.actor_spec.n_params, len(slots))
        omegas = check_parameters("omega", omegas, self._omega_size, len(slots))
        for slot, theta, omega in zip(slots, thetas, omegas, strict=True):
            self.learner.reset_agent(slot, theta, omega)
            self.envs[slot].renew()
        self._start(list(slots), thetas, omegas, seeds, list(tags))

    def _start(
        self,
        slots: list[int],
        thetas: np.ndarray,
        omegas: np.ndarray,
        seeds: Sequence[int],
        tags: list[Any],
    ) -> None:
        hp, now = self.hp, time.perf_counter()
        for j, slot in enumerate(slots):
            rng = np.random.default_rng([seeds[j], SEARCH_STREAM])
            with _Failures(tags[j]):
                start_fitness = self._greedy(thetas[j])
            result = starting_result(thetas[j], omegas[j], start_fitness[0], hp.count_start)
            self.searches[slot] = _Search(
                tags[j],
                thetas[j].copy(),
                omegas[j].copy(),
                rng,
                result,
                best=start_fitness if hp.count_start else (-np.inf, -np.inf),
                last_improvement=hp.warmup_steps,  # the patience window opens with updates
                started=now,
            )
            self.replay.clear(slot)
            self.busy[slot] = True
            self.envs[slot].idle = False
        self._reset(slots)

    # ------------------------------------------------------------------ one step
    def step(self) -> list[tuple[Any, LocalSearchResult]]:
        """One environment step and one batched update of every busy slot; returns
        ``(tag, result)`` of the searches that ended in this step (their slots are free).
        An environment's failure raises :class:`SlotEnvironmentError` naming its search."""
        hp, task = self.hp, self.task
        busy = [int(slot) for slot in np.flatnonzero(self.busy)]
        for slot in busy:
            self._search(slot).steps += 1
        # 1. act
        obs = self._observations()
        actions, mu = np.full((self.slots, task.action_size), 0.5), None
        if any(self._search(slot).steps > hp.warmup_steps for slot in busy):
            mu = to_host(self.learner.act(obs))
        for slot in busy:
            search = self._search(slot)
            if search.steps <= hp.warmup_steps:
                actions[slot] = search.rng.uniform(0.0, 1.0, task.action_size)
            else:
                assert mu is not None
                noise = search.rng.standard_normal(task.action_size)
                actions[slot] = np.clip(mu[slot].astype(np.float64) + hp.noise_std * noise, 0, 1)
            self.envs[slot].step_number = search.steps
        # 2. step and store
        try:
            _, rewards, terminated, truncated, _ = self.vector.step(actions)
        except TaskEnvironmentError as error:
            self._raise_for_failed(error)
        next_obs = np.stack([env.observation for env in self.envs]).astype(np.float32)
        self.replay.add(
            obs,
            torch.as_tensor(actions, dtype=torch.float32, device=self.device),
            rewards,
            next_obs,
            terminated,
        )
        # 3. update the slots past their warm-up (one batched update of all slots)
        training = [slot for slot in busy if self._search(slot).steps >= hp.warmup_steps]
        if training:
            sizes = to_host(self.replay.size)
            indices = np.zeros((self.slots, hp.batch_size), dtype=np.int64)
            for slot in training:
                search = self._search(slot)
                if search.updates == 0 and search.dirty:  # back to its start
                    self.learner.reset_agent(slot, search.theta, search.omega)
                indices[slot] = search.rng.integers(0, int(sizes[slot]), size=hp.batch_size)
            critic_loss, actor_loss = self.learner.update(self.replay.sample(indices))
            for slot in busy:
                search = self._search(slot)
                if slot in training:
                    search.losses.append((float(critic_loss[slot]), float(actor_loss[slot])))
                    search.updates += 1
                else:
                    search.dirty = True
        # 4. episode ends: judge, reset
        ended = []
        for slot in busy:
            search = self._search(slot)
            search.episode_return += float(rewards[slot])
            search.episode_length += 1
            if terminated[slot] or truncated[slot]:
                with _Failures(search.tag):
                    self._end_episode(slot, search)
                ended.append(slot)
        if ended:
            self._reset(ended)
        return self._stop(busy)

    def _observations(self) -> torch.Tensor:
        """The slots' current observations ``[K, o]`` on the device (float32)."""
        obs = np.stack([env.observation for env in self.envs])
        return torch.as_tensor(obs, dtype=torch.float32, device=self.device)

    def _greedy(self, actor: np.ndarray) -> tuple[float, float]:
        episode = self.task.greedy_episode(actor, "local search, greedy episode")
        return episode.fitness, episode.episode_return

    def _end_episode(self, slot: int, search: _Search) -> None:
        """Record the episode that ended in ``slot`` and judge the policy it trained."""
        hp, result = self.hp, search.result
        previous_end = result.history[-1].env_steps if result.history else 0
        judged = (search.updates > 0 or hp.count_start) and (
            not hp.judge_every or search.steps // hp.judge_every > previous_end // hp.judge_every
        )
        losses = search.losses
        record = EpisodeRecord(
            episode=search.episode,
            env_steps=search.steps,
            episode_return=search.episode_return,
            episode_length=search.episode_length,
            greedy_fitness=np.nan,
            greedy_return=np.nan,
            critic_loss=float(np.mean([c for c, _ in losses])) if losses else np.nan,
            actor_loss=float(np.mean([a for _, a in losses])) if losses else np.nan,
            seconds=time.perf_counter() - search.started,
        )
        if judged:
            actor, critic = self._policy(slot) if search.updates else (search.theta, search.omega)
            score = self._greedy(actor)
            record.greedy_fitness, record.greedy_return = score
            if is_improvement(score, search.best, hp.plateau_tiebreak):
                search.best = score
                result.fitness, result.theta, result.omega = score[0], actor, critic
                search.last_improvement = max(search.steps, hp.warmup_steps)
        result.history.append(record)
        search.episode, search.episode_return, search.episode_length = search.episode + 1, 0.0, 0
        search.losses = []

    def _policy(self, slot: int) -> tuple[np.ndarray, np.ndarray]:
        """The trained Actor and Critic of ``slot`` (flat, Eq. 1 order)."""
        rows = to_device([slot], self.device)
        return self.learner.actor_flat(rows)[0], self.learner.critic_flat(rows)[0]

    def _reset(self, slots: list[int]) -> None:
        """Reset the environments of ``slots``, each with a seed from its search's stream."""
        seeds: list[int | None] = [None] * self.slots
        mask = np.zeros(self.slots, dtype=bool)
        for slot in slots:
            seeds[slot] = int(self._search(slot).rng.integers(2**31))
            self.envs[slot].step_number = 0
            mask[slot] = True
        try:
            self.vector.reset(seed=seeds, options={"reset_mask": mask})
        except TaskEnvironmentError as error:
            self._raise_for_failed(error)

    def _stop(self, busy: list[int]) -> list[tuple[Any, LocalSearchResult]]:
        """Finish the searches of ``busy`` slots that stop now and free their slots."""
        hp, finished = self.hp, []
        for slot in busy:
            search = self._search(slot)
            stale = (
                search.steps >= hp.min_steps
                and search.steps - search.last_improvement >= hp.patience_steps
            )
            if not stale and search.steps < hp.max_steps:
                continue
            result = search.result
            if stale:
                result.stop_reason = "patience"
            if search.best[0] == -np.inf:  # no trained policy was judged: the Actor at the stop
                actor, critic = self._policy(slot)
                with _Failures(search.tag):
                    result.fitness = self._greedy(actor)[0]
                result.theta, result.omega, result.final_evaluation = actor, critic, True
            result.env_steps, result.updates = search.steps, search.updates
            result.seconds = time.perf_counter() - search.started
            finished.append((search.tag, result))
            self.searches[slot], self.busy[slot], self.envs[slot].idle = None, False, True
        return finished

    # ------------------------------------------------------------------ failures
    def _raise_for_failed(self, error: TaskEnvironmentError) -> None:
        """Re-raise ``error`` of a vector-env call naming the search whose env failed."""
        for slot, env in enumerate(self.envs):
            if env.failed:
                env.failed = False
                search = self.searches[slot]
                raise SlotEnvironmentError(str(error), search.tag if search else None) from None
        raise error

    # ------------------------------------------------------------------ fewer slots
    def shrink(self) -> None:
        """Drop the free slots so that the batch carries only busy ones."""
        keep = np.flatnonzero(self.busy).tolist()
        if len(keep) == self.slots or not keep or not self.learner.per_agent_state:
            return
        self.learner = self.learner.select(keep)
        self.replay = self.replay.select(keep)
        for slot in set(range(self.slots)) - set(keep):
            self.envs[slot].env.close()
        self.envs = [self.envs[i] for i in keep]
        self.searches = [self.searches[i] for i in keep]
        self.busy = self.busy[keep]
        self.vector = _vector_env(self.envs)

    def close(self) -> None:
        """Close every slot's environment (once; the trainer is done with then). The
        trainer is a context manager that closes them however its block ends."""
        if self.closed:
            return
        self.closed = True
        for env in self.envs:
            env.env.close()


class _Failures:
    """Turn a :class:`TaskEnvironmentError` inside the block into a
    :class:`SlotEnvironmentError` of the search ``tag``."""

    def __init__(self, tag: Any) -> None:
        self.tag = tag

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: Any, error: Any, trace: Any) -> None:
        if isinstance(error, TaskEnvironmentError) and not isinstance(error, SlotEnvironmentError):
            raise SlotEnvironmentError(str(error), self.tag) from None


def gymnasium_local_search(
    task: GymnasiumTask,
    theta: np.ndarray,
    omega: np.ndarray,
    hp: DDPGConfig,
    seed: int,
) -> LocalSearchResult:
    """``F(theta, omega, e, h)`` on a Gymnasium task: DDPG from the given Actor and Critic
    (targets copied from them, an empty replay buffer); the best judged policy and its
    fitness. A batch of one :class:`GymnasiumSlotTrainer` slot."""
    try:
        with GymnasiumSlotTrainer(task, theta[None], omega[None], [seed], hp) as trainer:
            while True:
                ended = trainer.step()
                if ended:
                    return ended[0][1]
    except SlotEnvironmentError as error:
        raise TaskEnvironmentError(str(error)) from None


__all__ = ["GymnasiumSlotTrainer", "SlotEnvironmentError", "gymnasium_local_search"]
