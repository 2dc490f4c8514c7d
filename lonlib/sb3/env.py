"""The task's environment as Stable-Baselines3 trains on it (:class:`TrainingEnv`): what the
SB3 networks read and write is what lonlib's Actor and Critic read and write.

* Observations are the task's scaled ones (:meth:`GymnasiumTask.observe`), in float32 (SB3's
  networks compute in float32 whatever the space's dtype).
* Actions are in [0, 1], the Actor's sigmoid units: SB3 maps its tanh output in [-1, 1] onto
  them (``(a + 1) / 2``), and :meth:`GymnasiumTask.step` maps them onto the Box bounds, as it
  does for lonlib's DDPG.
* Every ``reset`` and ``step`` goes through the task's guarded calls, so an environment that
  fails raises :class:`lonlib.task.gymnasium_task.TaskEnvironmentError` out of SB3's
  ``learn`` naming the step.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from lonlib.task.gymnasium_task import GymnasiumTask


class TrainingEnv(gymnasium.Env):
    """A fresh environment of ``task`` (:meth:`GymnasiumTask.make_env`) with scaled float32
    observations and actions in [0, 1]; it counts the search's env steps and keeps the
    return and length of the last finished episode (SB3's vectorised env resets it before
    the callback sees the episode's end)."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, task: GymnasiumTask, where: str) -> None:
        self.task, self.where = task, where
        self.env = task.make_env()
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (task.obs_size,), np.float32)
        self.action_space = gymnasium.spaces.Box(0.0, 1.0, (task.action_size,), np.float32)
        self.steps = 0  # env steps since the search started
        self.episode_return, self.episode_length = 0.0, 0
        self.finished: tuple[float, int] = (np.nan, 0)  # the last ended episode's return, length

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """The task's guarded ``reset`` (SB3 seeds the first; later ones continue the
        environment's own random stream)."""
        super().reset(seed=seed)
        obs = self.task.reset(self.env, seed, self.where)
        self.episode_return, self.episode_length = 0.0, 0
        return obs.astype(np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The task's guarded ``step`` of an action in [0, 1]."""
        self.steps += 1
        unit = np.asarray(action, dtype=np.float64)
        obs, reward, terminated, truncated = self.task.step(self.env, unit, self.where, self.steps)
        self.episode_return += reward
        self.episode_length += 1
        if terminated or truncated:
            self.finished = (self.episode_return, self.episode_length)
        return obs.astype(np.float32), reward, terminated, truncated, {}

    def close(self) -> None:
        """Close the task's environment."""
        self.env.close()


__all__ = ["TrainingEnv"]
