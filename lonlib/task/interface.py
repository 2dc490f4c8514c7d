"""What Algorithm 2 and the analysis need of a task (:class:`Task`), and the task of an
experiment (:func:`task_of`): the coupled pendulums (:class:`PendulumTask`, the paper's) or a
Gymnasium environment (:class:`lonlib.task.gymnasium_task.GymnasiumTask`)."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from lonlib.config import ExperimentConfig, PendulumConfig, Scoring
from lonlib.task.gymnasium_task import GymnasiumTask
from lonlib.task.policy import NetSpec, actor_spec, critic_spec
from lonlib.task.rollout import score_actors


class Task(Protocol):
    """A task ``e`` of Algorithm 2: the networks' shapes and the fitness of fixed Actors."""

    @property
    def name(self) -> str:
        """What the task is, in a few words."""
        ...

    @property
    def actor_spec(self) -> NetSpec:
        """The Actor's layer sizes (observations in, actions out)."""
        ...

    @property
    def critic_spec(self) -> NetSpec:
        """The Critic's layer sizes (observations and actions in, one value out)."""
        ...

    def fitness(self, thetas: np.ndarray) -> np.ndarray:
        """The fitness ``[m]`` in [0, 1] of ``m`` flat Actors ``[m, P]``, deterministic."""
        ...


class PendulumTask:
    """The coupled inverted pendulums (paper §III) as a :class:`Task`: the one rollout scores
    every Actor (:func:`lonlib.task.rollout.score_actors`)."""

    def __init__(self, env: PendulumConfig, scoring: Scoring = Scoring()) -> None:
        self.env, self.scoring = env, scoring

    @property
    def name(self) -> str:
        """``coupled pendulums (n carts)``."""
        return f"coupled pendulums ({self.env.n_carts} cart{'s' * (self.env.n_carts > 1)})"

    @property
    def actor_spec(self) -> NetSpec:
        """The paper's Actor for ``n`` carts."""
        return actor_spec(self.env.n_carts)

    @property
    def critic_spec(self) -> NetSpec:
        """The paper's Critic for ``n`` carts."""
        return critic_spec(self.env.n_carts)

    def fitness(self, thetas: np.ndarray) -> np.ndarray:
        """Algorithm 1's fitness (or the scoring's ``robust`` estimate) of each Actor."""
        return score_actors(np.atleast_2d(thetas), self.env, self.scoring).fitness


def task_of(config: ExperimentConfig) -> Any:
    """The task of an experiment: a :class:`GymnasiumTask` when it has a ``task`` section
    (made now: an unknown id or a discrete action space is refused here), else the coupled
    pendulums of its ``env``."""
    if config.task is not None:
        return GymnasiumTask(config.task)
    return PendulumTask(config.env, config.ddpg.scoring)


__all__ = ["PendulumTask", "Task", "task_of"]
