"""DDPG as Algorithm 2's local search ``F`` (:mod:`lonlib.search`): the paper's plug-in.

:func:`ddpg_local_search` binds the DDPG local search (:func:`lonlib.ddpg.search.local_search`)
to an environment and hyperparameters as a :data:`lonlib.search.algorithm.LocalSearch`;
:func:`local_optimum` turns one DDPG result into Algorithm 2's :class:`LocalOptimum`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from lonlib.ddpg.gymnasium_search import gymnasium_local_search
from lonlib.ddpg.search import local_search
from lonlib.search.algorithm import LocalOptimum, LocalSearch
from lonlib.task.behaviour import describe_columns
from lonlib.task.gymnasium_behaviour import describe_optimum
from lonlib.task.gymnasium_task import GymnasiumTask


def ddpg_local_search(env_config, hp, describe_optima: bool = True) -> LocalSearch:
    """The paper's ``F``: the DDPG local search bound to an environment and ``h``. With
    ``describe_optima`` every optimum also gets its behaviour descriptor and label
    (:mod:`lonlib.task.behaviour`) from one greedy rollout plus a batch of perturbed starts."""

    def search(theta: np.ndarray, omega: np.ndarray, seed: int) -> LocalOptimum:
        result = local_search(theta, omega, env_config, hp, seed)
        return local_optimum(result, env_config, hp, describe_optima)

    return search


def gymnasium_ddpg_local_search(task: GymnasiumTask, hp) -> LocalSearch:
    """``F`` on a Gymnasium task: lonlib's DDPG (:mod:`lonlib.ddpg.gymnasium_search`) bound
    to the task and ``h``; optima carry the task's behaviour descriptor if it has one."""

    def search(theta: np.ndarray, omega: np.ndarray, seed: int) -> LocalOptimum:
        return task_optimum(gymnasium_local_search(task, theta, omega, hp, seed), task, hp)

    return search


def task_optimum(result, task: GymnasiumTask, hp) -> LocalOptimum:
    """A local search's result on a Gymnasium task as Algorithm 2's :class:`LocalOptimum`,
    with the task's behaviour descriptor if it has one
    (:func:`lonlib.task.gymnasium_behaviour.describe_optimum`)."""
    optimum = local_optimum(result, None, hp, describe_optima=False)
    behaviour = describe_optimum(task, result.theta)
    return dataclasses.replace(optimum, behaviour=behaviour) if behaviour else optimum


def local_optimum(result, env_config, hp, describe_optima: bool = True) -> LocalOptimum:
    """A DDPG :class:`lonlib.ddpg.slots.LocalSearchResult` as Algorithm 2's :class:`LocalOptimum`
    (with its behaviour descriptor when ``describe_optima``)."""
    behaviour = describe_columns(result.theta, env_config, hp.scoring) if describe_optima else None
    return LocalOptimum(
        fitness=result.fitness,
        theta=result.theta,
        omega=result.omega,
        env_steps=result.env_steps,
        history=[dataclasses.asdict(record) for record in result.history],
        start_fitness=result.start_fitness,
        stop_reason=result.stop_reason,
        behaviour=behaviour,
    )
