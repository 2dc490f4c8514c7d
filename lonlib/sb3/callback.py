"""lonlib's judging rules on a Stable-Baselines3 model's training (:class:`JudgingCallback`):
the protocol of :mod:`lonlib.ddpg.gymnasium_search`, step for step.

SB3 calls its callback after each env step, before it stores the transition and before that
step's gradient update. The callback therefore closes env step ``t`` at the call of step
``t + 1`` (or at the end of training), once step ``t``'s update is done, which is where
lonlib's DDPG closes it:

1. the losses of step ``t``'s update are kept for its episode's record;
2. if an episode ended at step ``t``, its record is made and the trained Actor is judged by
   the task's greedy episode (:meth:`GymnasiumTask.greedy_episode`, the one fitness function)
   when there has been an update or ``count_start`` holds, and, with ``judge_every``, only when
   the episode's end crosses a multiple of it; a better ``(fitness, return)``
   (:func:`lonlib.ddpg.slots.is_improvement`, with ``plateau_tiebreak``) becomes the best so
   far and opens a new patience window;
3. the search stops (the callback returns False) once ``t >= min_steps`` and ``t`` lies
   ``patience_steps`` past the last improvement (counted from the end of the warm-up); SB3's
   ``learn`` stops at ``max_steps``. When patience stops a search at step ``t``, SB3 has
   already taken env step ``t + 1``: that step is discarded, the search's env steps are ``t``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from lonlib.config import DDPGConfig
from lonlib.ddpg.slots import EpisodeRecord, LocalSearchResult, is_improvement, starting_result
from lonlib.sb3.env import TrainingEnv
from lonlib.sb3.params import actor_theta, critic_omega
from lonlib.task.gymnasium_task import GymnasiumTask

LOSS_KEYS = ("train/critic_loss", "train/actor_loss")  # what SB3's TD3, DDPG and SAC log


class JudgingCallback(BaseCallback):
    """Judges an SB3 local search from ``theta``/``omega`` and keeps the best judged policy;
    :meth:`result` is the search's :class:`LocalSearchResult` once ``learn`` returns."""

    def __init__(
        self,
        task: GymnasiumTask,
        env: TrainingEnv,
        hp: DDPGConfig,
        theta: np.ndarray,
        omega: np.ndarray,
        where: str,
        started: float,
    ) -> None:
        super().__init__(verbose=0)
        self.task, self.env, self.hp, self.where = task, env, hp, where
        self.theta, self.omega = theta, omega
        self.started = started  # time.perf_counter() at the search's start
        start = self.greedy(theta)
        self.best = start if hp.count_start else (-np.inf, -np.inf)
        self.search = starting_result(theta, omega, start[0], hp.count_start)
        self.last_improvement = hp.warmup_steps  # the patience window opens with the warm-up
        self.ended: tuple[int, float, int] | None = None  # (step, return, length) to close
        self.losses: list[tuple[float, float]] = []
        self.closed = 0  # the last env step closed

    # ------------------------------------------------------------------ SB3's hooks
    def _on_step(self) -> bool:
        steps = self.num_timesteps
        if not self.close(steps - 1):
            return False
        if self.locals["dones"][0]:
            self.ended = (steps, *self.env.finished)
        return True

    def _on_training_end(self) -> None:
        if self.search.stop_reason != "patience":
            self.close(self.model.num_timesteps)

    # ------------------------------------------------------------------ the rules
    def greedy(self, actor: np.ndarray) -> tuple[float, float]:
        """The greedy ``(fitness, return)`` of a flat Actor."""
        episode = self.task.greedy_episode(actor, f"{self.where}, greedy episode")
        return episode.fitness, episode.episode_return

    def close(self, steps: int) -> bool:
        """Close env step ``steps`` after its update: keep its losses, judge the episode that
        ended there, apply the patience. False: the search stops at ``steps``."""
        if steps <= self.closed:
            return True
        self.closed = steps
        logged = self.model.logger.name_to_value
        critic, actor = (logged.pop(key, np.nan) for key in LOSS_KEYS)
        if not (np.isnan(critic) and np.isnan(actor)):
            self.losses.append((float(critic), float(actor)))
        if self.ended is not None and self.ended[0] == steps:
            self.episode_end(*self.ended)
            self.ended = None
        hp = self.hp
        if steps >= hp.min_steps and steps - self.last_improvement >= hp.patience_steps:
            self.search.stop_reason = "patience"
            self.search.env_steps = steps
            return False
        self.search.env_steps = steps
        return True

    def episode_end(self, steps: int, episode_return: float, episode_length: int) -> None:
        """The record of the episode that ended at ``steps``; judge it when it is due."""
        hp, history = self.hp, self.search.history
        updates = self.updates
        previous_end = history[-1].env_steps if history else 0
        judged = (updates > 0 or hp.count_start) and (
            not hp.judge_every or steps // hp.judge_every > previous_end // hp.judge_every
        )
        critic_losses = [c for c, _ in self.losses if not np.isnan(c)]
        actor_losses = [a for _, a in self.losses if not np.isnan(a)]
        record = EpisodeRecord(
            episode=len(history),
            env_steps=steps,
            episode_return=episode_return,
            episode_length=episode_length,
            greedy_fitness=np.nan,
            greedy_return=np.nan,
            critic_loss=float(np.mean(critic_losses)) if critic_losses else np.nan,
            actor_loss=float(np.mean(actor_losses)) if actor_losses else np.nan,
            seconds=time.perf_counter() - self.started,
        )
        if judged:
            actor, critic = self.parameters()
            score = self.greedy(actor)
            record.greedy_fitness, record.greedy_return = score
            if is_improvement(score, self.best, hp.plateau_tiebreak):
                self.best = score
                self.search.fitness, self.search.theta, self.search.omega = score[0], actor, critic
                self.last_improvement = max(steps, hp.warmup_steps)
        history.append(record)
        self.losses = []

    @property
    def updates(self) -> int:
        """SB3's gradient steps so far."""
        return int(self.model._n_updates)

    def parameters(self) -> tuple[np.ndarray, np.ndarray]:
        """The model's Actor and Critic as lonlib's flat ``theta`` and ``omega`` (the start's,
        exactly, before any update)."""
        if not self.updates:
            return self.theta.copy(), self.omega.copy()
        policy: Any = self.model.policy
        return actor_theta(policy), critic_omega(policy, self.task.action_size)

    def result(self) -> LocalSearchResult:
        """The search's result: the best judged policy, or the Actor at the stop when none
        was judged (``final_evaluation``)."""
        search = self.search
        if self.best[0] == -np.inf:
            actor, critic = self.parameters()
            search.fitness, search.theta, search.omega = self.greedy(actor)[0], actor, critic
            search.final_evaluation = True
        search.updates = self.updates
        search.seconds = time.perf_counter() - self.started
        return search


__all__ = ["JudgingCallback"]
